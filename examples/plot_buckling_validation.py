"""
Validation: discrete elastic rods against the exact elastica
============================================================

``simfab validate buckling`` compresses a pinned strip to gap ratios g/L and compares the
discrete-elastic-rod equilibrium with the exact elastica (elliptic integrals): the error falls
with the segment count at the order the table reports::

    simfab validate buckling --n 10 20 40 --g-over-L 0.95 0.8 --support pinned --path direct
"""

# %%
from _common import show_png, simfab, workdir

d = workdir("buckling")
res = simfab("validate", "buckling", "--n", "10", "20", "40", "--g-over-L", "0.95", "0.8", "--support", "pinned",
             "--path", "direct", "--out", d)
print(res.get("table", ""))
show_png(d / "buckling_shapes.png")
