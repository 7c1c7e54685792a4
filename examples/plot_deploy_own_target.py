"""
Your own target surface: a deployable laser-cut pattern
=======================================================

A user has the surface they want a flat sheet to buckle into as an OBJ in millimetres (here a
spherical cap of radius 60 mm). ``simfab deploy surface`` flattens it, cuts a pattern of beams,
torsional springs and inserts (SVG and DXF for the laser cutter, in mm), deploys it and measures
its deviation from the target::

    simfab deploy surface cap.obj --units mm --out my_pattern
"""

# %%
import trimesh
from _common import show_png, simfab, workdir

d = workdir("deploy")
cap = trimesh.creation.icosphere(subdivisions=3, radius=60.0).slice_plane([0, 0, 30.0], [0, 0, 1], cap=False)
cap.export(d / "cap.obj")

res = simfab("deploy", "surface", d / "cap.obj", "--units", "mm", "--no-mujoco-check", "--out", d / "out")
print(sorted(k for k in res if k.endswith(("_png", "svg", "dxf"))))
show_png(d / "out" / "pattern.png")

# %%
# The deployed surface against the target
# ---------------------------------------
show_png(d / "out" / "deviation.png")
