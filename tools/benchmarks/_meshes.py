"""Benchmark meshes of the FEM core's model sizes (used by ``fem_core`` and ``linear_solvers``)."""

from __future__ import annotations

from simfab.fem.materials import PLA
from simfab.fem.meshing import structured_box, triangulate_polygon
from simfab.fem.model import FemModel, make_model


def box_model(target_tets: int) -> FemModel:
    """PLA 3:1:1 box (0.06 x 0.02 x 0.02 m) of 6-tet cubes with about ``target_tets`` tets (valence
    like fTetWild's): cells (nx, ny, ny) with nx / ny in [2, 4] and 6 nx ny^2 closest to the target."""
    options = [(max(1, round(target_tets / (6.0 * ny * ny))), ny, ny) for ny in range(1, 60)]
    options = [c for c in options if 2 <= c[0] / c[1] <= 4] or options
    cells = min(options, key=lambda c: abs(6 * c[0] * c[1] * c[2] - target_tets))
    V, T = structured_box((0.06, 0.02, 0.02), cells)
    return make_model(V, T, PLA)


def rect_model(target_tris: int) -> FemModel:
    """PLA 0.06 x 0.02 m rectangle (plane strain, 5 mm thick), a Triangle mesh of about
    ``target_tris`` triangles."""
    L, H = 0.06, 0.02
    V, F = triangulate_polygon([[0, 0], [L, 0], [L, H], [0, H]], max_area=L * H / target_tris * 1.6)
    return make_model(V, F, PLA, thickness=0.005)
