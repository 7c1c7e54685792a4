"""Consistent nodal loads for linear and P2 models: f_a = integral of N_a times the load.

Linear and quadratic meshes of the same body under the same distributed load then carry the
same resultant, and compliances f.u converge with refinement (nodal point loads would not: the
displacement under a point load is singular). P2 vertex functions integrate to negative values
over an element (a tet's corner: -V/20, its edge nodes V/5; a 6-node triangle's corners 0), so P2
nodal loads can point against the load at the corners.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from simfab.fem.model import FemModel
from simfab.fem.p2 import RULES, P2Model


def body_force_loads(model: FemModel | P2Model, density: Callable[[np.ndarray], np.ndarray], *,
                     degree: int | None = None) -> np.ndarray:
    """Nodal forces (n, dim) [N] of a body force density b(X) [N/m^3] (plane strain: per unit
    volume of the extruded body), integrated with the rule of ``degree`` (default: the highest
    in :data:`simfab.fem.p2.RULES`) on every element.

    Args:
        density: maps rest points (q, dim) [m] to force densities (q, dim)
    """
    dim = model.dim
    if degree is None:
        degree = max(d for (dd, d) in RULES if dd == dim)
    L, w = RULES[(dim, degree)]
    N = model.shape_functions(L)  # (q, k)
    corners = model.rest[model.corner_elements]
    Xq = np.einsum("ql,mld->mqd", L, corners)
    b = np.asarray(density(Xq.reshape(-1, dim)), dtype=np.float64).reshape(Xq.shape)
    fe = np.einsum("m,q,qa,mqd->mad", model.volume, w, N, b)
    f = np.zeros_like(model.rest)
    np.add.at(f, model.elements, fe)
    return f


def traction_loads(model: FemModel | P2Model, facets: np.ndarray, traction) -> np.ndarray:
    """Nodal forces (n, dim) [N] of a uniform traction (dim,) [Pa] on the given boundary facets
    (boolean mask or indices into ``model.boundary_facets``).

    Weights of the facet measure (2D: length * thickness): linear segment 1/2, 1/2; linear triangle
    1/3 each; 3-node edge 1/6, 1/6, 2/3; 6-node triangle 0 at the corners and 1/3 at the midpoints.
    """
    dim = model.dim
    f = model.boundary_facets[facets]
    corners = model.rest[f[:, :dim]]
    if dim == 2:
        measure = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1) * model.thickness
    else:
        measure = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    if f.shape[1] == dim:
        w = np.full(dim, 1.0 / dim)
    else:
        w = np.array([1 / 6, 1 / 6, 2 / 3]) if dim == 2 else np.array([0, 0, 0, 1 / 3, 1 / 3, 1 / 3])
    share = np.zeros(model.n_vertices)
    np.add.at(share, f, measure[:, None] * w[None, :])
    return share[:, None] * np.asarray(traction, dtype=np.float64)[None, :]
