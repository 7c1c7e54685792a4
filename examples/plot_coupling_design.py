"""
Designing the clip: a rest shape that meets a brief
===================================================

The clip of :doc:`the previous example <plot_coupling_own_clip>` needs about 14 N to push onto the
cylinder. Asked for a tight grip with at most 10 N to insert, ``simfab couple optimize`` changes
the clip's rest shape as little as possible until its simulated insertion meets that brief::

    simfab couple new clip.stl cylinder.stl --into=-x --dim 2 --brief grip=tight \\
        --brief 'insertion_force=[0, 10]' --out my_design
    simfab couple optimize my_design/clip.xml --out my_optimized

It writes the optimized part (STL in mm, outline), a scene that ``couple simulate`` runs, and the
before/after profiles. ``--no-mesh-check`` skips re-checking the design on refined quadratic
meshes (which a real design should keep) to keep this example short.
"""

# %%
import trimesh
from _common import show_png, simfab, workdir

from simfab.coupling.geometry import c_clamp_outline, extrude

d = workdir("design")
extrude(c_clamp_outline(inner_radius=9.5, width=2.5, opening_deg=60.0, base_depth=4.0, base_height=20.0,
                        segments=48), 5.0).export(d / "clip.stl")
trimesh.creation.cylinder(radius=10.0, height=10.0, sections=64).export(d / "cylinder.stl")
made = simfab("couple", "new", d / "clip.stl", d / "cylinder.stl", "--into=-x", "--dim", "2", "--elements", "600",
              "--steps", "25", "--brief", "grip=tight", "--brief", "insertion_force=[0, 10]", "--out", d / "scene")

# %%
# Optimize
# --------
opt = simfab("couple", "optimize", made["outputs"]["scene_xml"], "--iterations", "10", "--no-mesh-check",
             "--out", d / "opt")
before, after = opt["profile_initial"], opt["profile"]
print(f"feasible: {opt['feasible']}; F_in {before['F_in_N']:.1f} N -> {after['F_in_N']:.1f} N, "
      f"F_grip {before['F_grip_N']:.1f} N -> {after['F_grip_N']:.1f} N ({opt['insertions']} insertions)")
show_png(d / "opt" / "clip_design_shape.png")
