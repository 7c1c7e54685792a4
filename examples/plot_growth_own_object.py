"""
Your own object on a plate: a grown support
===========================================

A user wants a printed support under a 40 x 40 x 10 mm block held 30 mm above a plate. They have
the block as an STL in millimetres. ``simfab grow new`` writes the growth scene (the block as a
body, a plate under the root, the root and target sites) and ``simfab grow`` grows the support::

    simfab grow new block.stl --root 0,0,0 --target=15,15,30 --target=-15,15,30 \\
        --target=15,-15,30 --target=-15,-15,30 --mass 0.25 --out my_scene
    simfab grow my_scene/block.xml --out my_support
    simfab grow my_scene/block.xml --out my_support --check    # stress under the block's weight

Without ``--mass`` the block would weigh MuJoCo's default density (1000 kg/m^3) times its volume
in the structural check; ``grow new`` says so in its notes.
"""

# %%
import trimesh
from _common import show_png, simfab, workdir

d = workdir("grow")
block = trimesh.creation.box(extents=[40.0, 40.0, 10.0])
block.apply_translation([0.0, 0.0, 35.0])
block.export(d / "block.stl")

made = simfab("grow", "new", d / "block.stl", "--root", "0,0,0", "--target=15,15,30", "--target=-15,15,30",
              "--target=15,-15,30", "--target=-15,-15,30", "--mass", "0.25", "--out", d / "scene")
print("masses [kg]:", made["masses"])

# %%
# Grow
# ----
grown = simfab("grow", made["outputs"]["scene_xml"], "--attractors", "800", "--check", "--out", d / "grown")
print(f"{grown['targets_reached']} of {grown['targets_total']} targets reached in {grown['steps']} steps")
show_png(d / "grown" / "block_preview.png")

# %%
# Its stress under the block's weight
# -----------------------------------
# ``--check`` meshes the skin in tetrahedra, clamps it on the plate and loads it with the block's
# 0.25 kg (shared among the targets that touch it) and its own weight: the safety factor against
# yield, the peak von Mises stress and the deflection at each target.
check = grown["check"]
print({k: check[k] for k in ("safety_factor", "max_von_mises_Pa", "max_deflection_m", "mass_kg") if k in check})
show_png(d / "grown" / "block_check.png")
