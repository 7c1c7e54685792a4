"""
Your own clip and cylinder: an insertion profile
================================================

A user has a C-clip and the cylinder it should snap onto as STL files in millimetres, exported
from CAD in assembly position (the cylinder sits in the clip's seat). ``simfab couple new`` writes
the coupling scene - no MJCF or TOML by hand - and ``simfab couple simulate`` runs it.

In a shell the same two steps are::

    simfab couple new clip.stl cylinder.stl --into=-x --dim 2 --out my_scene
    simfab couple simulate my_scene/clip.xml --out my_run

(``--into=-x``: a leading minus needs the ``=``.) ``--dim 2`` simulates the section through the
cylinder's centre in plane strain, which takes seconds; leave it out for the 3D part.
"""

# %%
# The user's files
# ----------------
# Here we make them: the clip's outline extruded 5 mm, a 20 mm cylinder, both in millimetres.
import numpy as np
import trimesh
from _common import show_png, simfab, workdir

from simfab.coupling.geometry import c_clamp_outline, extrude

d = workdir("clip")
outline = c_clamp_outline(inner_radius=9.5, width=2.5, opening_deg=60.0, base_depth=4.0, base_height=20.0,
                          segments=48)
extrude(outline, 5.0).export(d / "clip.stl")
trimesh.creation.cylinder(radius=10.0, height=10.0, sections=64).export(d / "cylinder.stl")

# %%
# Write the scene
# ---------------
# The path starts just before the first contact (the cylinder started inside the clip, so it
# was moved back: the notes say so) and ends just before the seat; the simulation continues
# from there to the rest point by itself.
made = simfab("couple", "new", d / "clip.stl", d / "cylinder.stl", "--into=-x", "--dim", "2",
              "--elements", "600", "--steps", "25", "--out", d / "scene")
for note in made["notes"]:
    print(note)
print("next:", made["next_commands"][0])

# %%
# Simulate
# --------
run = simfab("couple", "simulate", made["outputs"]["scene_xml"], "--out", d / "run")
print({k: run[k] for k in ("category", "F_in", "F_rm", "F_grip", "E_max", "coupling_ratio")})
show_png(d / "run" / "clip_profile.png")

# %%
# Read the profile
# ----------------
# One row per record; ``phase`` tells the planned insertion steps (``insert``) from the rest
# search's (``rest``). ``force_N`` is negative where the part resists the object (pushing it
# in takes ``-force_N``), positive where it draws the object in; the summary's
# ``profile_columns`` states every column's meaning.
rows = np.genfromtxt(d / "run" / "clip_profile.csv", delimiter=",", names=True, dtype=None, encoding="ascii")
for phase in ("insert", "rest"):
    sel = rows["phase"] == phase
    s_mm = 1e3 * rows["s_m"][sel]
    print(f"{phase}: {sel.sum()} records, s = {s_mm.min():.2f}..{s_mm.max():.2f} mm")
