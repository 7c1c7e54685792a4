"""Quadratic (P2) simplicial FEM models: 6-node triangles (2D plane strain) and 10-node tetrahedra.

Linear simplices lock in bending; P2 elements represent the linear strain variation of bending
exactly. A P2 model is built from a linear mesh by adding one node at the midpoint of every edge
(affine elements): :func:`to_p2` lifts a :class:`~simfab.fem.model.FemModel`, :func:`make_p2_model`
does the same from points and elements. The linear mesh's vertices keep their indices; the midpoint
of edge ``edges[i]`` is node ``n_corners + i``. Local node order (VTK's QUADRATIC_TRIANGLE / TETRA):

    triangle: v0 v1 v2 | m01 m12 m20
    tet:      v0 v1 v2 v3 | m01 m12 m20 m03 m13 m23

Shape functions in barycentric coordinates: corner N_a = L_a (2 L_a - 1), edge N_ab = 4 L_a L_b.
F is linear over the element, the energy integrated by quadrature (:data:`RULES`: degree 2 by
default, 3-point triangle / 4-point tet, exact for the small-strain stiffness and free of spurious
modes; degree 4 / 5 for strongly nonlinear states). det F is a polynomial of degree dim:
:func:`det_F_lower_bound` bounds it over the whole element through its Bernstein coefficients. The
choice of rules and their measured effect: docs/methods.md, "simfab.fem.p2".
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from simfab.errors import InputError
from simfab.fem.assembly import HessianPattern
from simfab.fem.materials import Material
from simfab.fem.model import FemModel, MeshModel, make_model
from simfab.fem.subdivide import subdivide

#: local corner pairs of the edge nodes, in the node order above
EDGE_PAIRS = {2: np.array([[0, 1], [1, 2], [2, 0]]),
              3: np.array([[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]])}


def _orbit_tri(a):
    """The 3 barycentric points (a, a, 1 - 2a) and permutations."""
    b = 1.0 - 2.0 * a
    return [[a, a, b], [a, b, a], [b, a, a]]


def _orbit_tet4(a):
    """The 4 points (a, a, a, 1 - 3a) and permutations."""
    b = 1.0 - 3.0 * a
    return [[b, a, a, a], [a, b, a, a], [a, a, b, a], [a, a, a, b]]


def _orbit_tet6(a):
    """The 6 points (a, a, b, b), b = 1/2 - a, and permutations."""
    b = 0.5 - a
    return [[a, a, b, b], [a, b, a, b], [a, b, b, a], [b, a, a, b], [b, a, b, a], [b, b, a, a]]


def _rule(groups):
    pts, wts = [], []
    for orbit, w in groups:
        pts += orbit
        wts += [w] * len(orbit)
    return np.array(pts), np.array(wts)


#: (dim, degree) -> (barycentric points (nq, dim+1), weights (nq,) summing to 1 = fractions of the
#: element measure). Exactness for all polynomials up to ``degree`` is checked in tests/fem/test_p2.py.
RULES = {
    (2, 2): _rule([(_orbit_tri(1.0 / 6.0), 1.0 / 3.0)]),
    # Dunavant (1985) degree 4, 6 points
    (2, 4): _rule([(_orbit_tri(0.445948490915965), 0.223381589678011),
                   (_orbit_tri(0.091576213509771), 0.109951743655322)]),
    (3, 2): _rule([(_orbit_tet4(0.1381966011250105), 0.25)]),
    # Walkington (2000) degree 5, 14 points (weights of the unit tet times 6)
    (3, 5): _rule([(_orbit_tet4(0.0927352503108912), 6 * 0.01224884051939366),
                   (_orbit_tet4(0.3108859192633006), 6 * 0.01878132095300264),
                   (_orbit_tet6(0.0455037041256496), 6 * 0.007091003462846911)]),
}
DEFAULT_DEGREE = {2: 2, 3: 2}


def shape_functions(L: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """P2 shape functions and their barycentric derivatives at points L (q, dim+1).

    Returns N (q, k) and dN/dL (q, k, dim+1), k = 6 (2D) or 10 (3D), local node order as above.
    """
    L = np.asarray(L, dtype=np.float64)
    q, nb = L.shape
    pairs = EDGE_PAIRS[dim]
    k = nb + len(pairs)
    N = np.zeros((q, k))
    dN = np.zeros((q, k, nb))
    for a in range(nb):
        N[:, a] = L[:, a] * (2.0 * L[:, a] - 1.0)
        dN[:, a, a] = 4.0 * L[:, a] - 1.0
    for i, (a, b) in enumerate(pairs):
        N[:, nb + i] = 4.0 * L[:, a] * L[:, b]
        dN[:, nb + i, a] = 4.0 * L[:, b]
        dN[:, nb + i, b] = 4.0 * L[:, a]
    return N, dN


@dataclass(frozen=True, kw_only=True)
class P2Model(MeshModel):
    """Quadratic simplicial FEM discretization of an elastic body (immutable), affine elements.

    Args:
        dim: 2 (6-node triangles, plane strain) or 3 (10-node tetrahedra)
        rest: (n, dim) float64 [m] rest node positions: the corners (``n_corners`` first), then the
            edge midpoints
        elements: (m, k) int32 node indices, k = 6 / 10, local order in the module docstring,
            positively oriented corners
        n_corners: number of corner nodes (the linear mesh's vertices)
        edges: (n - n_corners, 2) int32 corner pairs (sorted): node n_corners + i is edges[i]'s midpoint
        corner_elements: (m, dim+1) int32 the linear simplices (= elements[:, :dim+1])
        Dm_inv: (m, dim, dim) float64 [1/m] inverse rest edge matrix of the linear simplex; the
            element map is affine, so this is the inverse Jacobian at every quadrature point
        volume: (m,) float64 [m^3] rest volume; 2D: triangle area * thickness
        degree: polynomial degree the quadrature rule integrates exactly (see :data:`RULES`)
        qp_bary: (nq, dim+1) float64 quadrature points in barycentric coordinates
        qp_weight: (m, nq) float64 [m^3] quadrature weights: volume * rule weight
        grad_N: (m, nq, k, dim) float64 [1/m] rest gradient of each shape function at each
            quadrature point: F(X_q) = sum_a x_a (x) grad_N[e, q, a]
        mu, lam: (m,) float64 [Pa] Lame parameters
        thickness: [m] out-of-plane extent of a 2D body; 1.0 for 3D
        boundary_facets: 2D (f, 3) quadratic boundary edges [v0, v1, m01]; 3D (f, 6) quadratic boundary
            triangles [v0, v1, v2, m01, m12, m20]; corners oriented like FemModel.boundary_facets
            (2D: body on the left; 3D: counter-clockwise seen from outside)
        boundary_subfacets: linear pieces of the boundary facets with the same orientation: 2D
            (2f, 2) segments [v0, m01], [m01, v1]; 3D (4f, 3) triangles [v0, m01, m20], [m01, v1, m12],
            [m20, m12, v2], [m01, m12, m20] (facet i's pieces are rows 2i.. / 4i..)
        boundary_vertices: (b,) int32 sorted boundary nodes (corners and midpoints)
        pattern: :class:`HessianPattern` of the (n*dim, n*dim) Hessian (node pairs sharing an element)
        material: the material the Lame parameters came from (None if given per element)
        device: Warp device the kernels run on
        linear: the linear :class:`FemModel` on the corner mesh this model was lifted from
    """

    n_corners: int
    edges: np.ndarray
    corner_elements: np.ndarray
    degree: int
    qp_bary: np.ndarray
    qp_weight: np.ndarray
    grad_N: np.ndarray
    boundary_subfacets: np.ndarray
    linear: FemModel

    @property
    def n_quadrature(self) -> int:
        return self.qp_bary.shape[0]

    def mean_edge_length(self) -> float:
        """Mean length [m] of the corner-mesh edges at rest (as FemModel.mean_edge_length)."""
        return self.linear.mean_edge_length()

    @property
    def element_order(self) -> int:
        return 2

    def element_geometry(self) -> tuple[np.ndarray, np.ndarray]:
        """(grad_N (m, nq, k, dim) [1/m], qp_weight (m, nq) [m^3]): F_q = sum_a x_a (x) grad_N[e, q, a]
        at each quadrature point, weighted by w_q."""
        return self.grad_N, self.qp_weight

    def shape_functions(self, L) -> np.ndarray:
        """P2 shape functions (q, k) at barycentric points L (q, dim+1) (:func:`shape_functions`)."""
        return shape_functions(L, self.dim)[0]

    def linear_facets(self) -> np.ndarray:
        """(f', dim) the boundary as linear pieces over corner and midpoint nodes
        (``boundary_subfacets``: 2 segments / 4 triangles per quadratic facet). Their nodes share an
        element, so points interpolated on them stay inside the Hessian's sparsity pattern."""
        return self.boundary_subfacets

    def lift(self, x_corners) -> np.ndarray:
        """P2 node positions (n, dim) from corner positions (n_corners, dim): midpoints at the
        average of their edge's corners (straight edges; e.g. a linear solution as a start)."""
        xc = np.asarray(x_corners, dtype=np.float64)
        if xc.shape != (self.n_corners, self.dim):
            raise InputError(f"corner positions have shape {xc.shape}, expected {(self.n_corners, self.dim)}",
                             where="x")
        return np.vstack([xc, 0.5 * (xc[self.edges[:, 0]] + xc[self.edges[:, 1]])])

    def linear_elements(self) -> np.ndarray:
        """Linear simplices on the same nodes (4m triangles / 8m tets, positively oriented): the red
        refinement of the corner mesh (:func:`simfab.fem.subdivide.subdivide`, whose midpoint
        numbering this model shares), e.g. to write a P2 state as a linear mesh (USD) or to run
        linear-mesh geometry (contact, stress plots) on it."""
        return subdivide(self.linear.rest, self.corner_elements)[1].astype(np.int32)

    def interpolate(self, x, L) -> np.ndarray:
        """Deformed positions at barycentric points L (q, dim+1) of every element: (m, q, dim)."""
        N, _ = shape_functions(np.atleast_2d(L), self.dim)
        return np.einsum("qa,mad->mqd", N, self.check_positions(x)[self.elements])


def corner_gradients(model: P2Model, x) -> np.ndarray:
    """F at the corners of every element (m, dim+1, dim, dim) [-]: F is affine over a P2 element,
    F(L) = sum_i L_i F_i, so these determine it everywhere. F_c = sum_a x_a (x) grad N_a(corner c):
    per element and corner the (dim, k) @ (k, dim) product of the nodes' positions and the shape
    functions' rest gradients there (those depend on the rest shape only: kept on the model)."""
    x = model.check_positions(x)
    grad_N = model._cache.get("corner_grad_N")
    if grad_N is None:
        dim = model.dim
        _, dNdL = shape_functions(np.eye(dim + 1), dim)  # (dim+1 corners, k, dim+1)
        gradL = np.concatenate([-model.Dm_inv.sum(axis=1, keepdims=True), model.Dm_inv], axis=1)  # (m, dim+1, dim)
        grad_N = model._cache["corner_grad_N"] = np.einsum("cal,mld->mcad", dNdL, gradL)  # (m, dim+1, k, dim)
    return np.matmul(np.swapaxes(x[model.elements], 1, 2)[:, None], grad_N)


def det_F_lower_bound(model: P2Model, x) -> np.ndarray:
    """A guaranteed lower bound (m,) of det F over each whole element (not just its quadrature
    points): the smallest Bernstein coefficient of J(L) = det(sum_i L_i F_i), a homogeneous
    polynomial of degree dim in the barycentrics (Bernstein polynomials are non-negative and sum
    to 1, so J >= min coefficient; equal to J where J is constant, e.g. affine states).

    Coefficients: the symmetric multilinear form D of det at the corner gradients F_i: b_(ii..i) =
    det F_i, 2D b_ij = D(F_i, F_j) = (det(F_i + F_j) - det F_i - det F_j) / 2, 3D b_ijk = D(F_i, F_j,
    F_k) by polarization, (det(A+B+C) - det(A+B) - det(A+C) - det(B+C) + det A + det B + det C) / 6.
    A bound > 0 proves the element is nowhere inverted (use it as the admissibility test of a
    line search where elements bend strongly); <= 0 is conservative (J may still be positive).
    """
    Fc = corner_gradients(model, x)
    det = np.linalg.det
    nb = model.dim + 1
    coeffs = [det(Fc[:, i]) for i in range(nb)]
    if model.dim == 2:
        for i, j in itertools.combinations(range(nb), 2):
            coeffs.append(0.5 * (det(Fc[:, i] + Fc[:, j]) - coeffs[i] - coeffs[j]))
    else:
        def D(A, B, C):
            return (det(A + B + C) - det(A + B) - det(A + C) - det(B + C) + det(A) + det(B) + det(C)) / 6.0

        for i, j in itertools.permutations(range(nb), 2):
            coeffs.append(D(Fc[:, i], Fc[:, i], Fc[:, j]))
        for i, j, k in itertools.combinations(range(nb), 3):
            coeffs.append(D(Fc[:, i], Fc[:, j], Fc[:, k]))
    return np.min(np.stack(coeffs, axis=1), axis=1)


def to_p2(model: FemModel, *, degree: int | None = None) -> P2Model:
    """The P2 counterpart of a linear model: same corners, material, thickness and device, one
    midpoint node per edge.

    Args:
        degree: quadrature degree, one of :data:`RULES` for the dimension (default
            :data:`DEFAULT_DEGREE`)
    """
    if getattr(model, "element_order", None) != 1:
        raise InputError(f"to_p2 needs a linear FemModel, got {type(model).__name__}", where="model")
    dim = model.dim
    if degree is None:
        degree = DEFAULT_DEGREE[dim]
    if (dim, degree) not in RULES:
        have = sorted(d for (dd, d) in RULES if dd == dim)
        raise InputError(f"no {dim}D quadrature rule of degree {degree} (have {have})", where="degree")
    el = model.elements.astype(np.int64)
    n, m = model.n_vertices, model.n_elements
    pairs = EDGE_PAIRS[dim]
    # unique edges: key = lo * n + hi over all element edges
    a, b = el[:, pairs[:, 0]], el[:, pairs[:, 1]]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keys, inverse = np.unique((lo * n + hi).ravel(), return_inverse=True)
    edges = np.stack([keys // n, keys % n], axis=1)
    mid_nodes = n + inverse.reshape(m, len(pairs))
    elements = np.hstack([el, mid_nodes]).astype(np.int32)
    rest = np.vstack([model.rest, 0.5 * (model.rest[edges[:, 0]] + model.rest[edges[:, 1]])])

    def midpoint(p, q):
        k = np.minimum(p, q).astype(np.int64) * n + np.maximum(p, q)
        return n + np.searchsorted(keys, k)

    bf = model.boundary_facets.astype(np.int64)
    if dim == 2:
        m01 = midpoint(bf[:, 0], bf[:, 1])
        facets = np.stack([bf[:, 0], bf[:, 1], m01], axis=1)
        sub = np.stack([np.stack([bf[:, 0], m01], 1), np.stack([m01, bf[:, 1]], 1)], axis=1).reshape(-1, 2)
    else:
        v0, v1, v2 = bf.T
        m01, m12, m20 = midpoint(v0, v1), midpoint(v1, v2), midpoint(v2, v0)
        facets = np.stack([v0, v1, v2, m01, m12, m20], axis=1)
        sub = np.stack([np.stack(t, 1) for t in ((v0, m01, m20), (m01, v1, m12), (m20, m12, v2), (m01, m12, m20))],
                       axis=1).reshape(-1, 3)

    L, w = RULES[(dim, degree)]
    _, dNdL = shape_functions(L, dim)  # (nq, k, dim+1)
    gradL = np.concatenate([-model.Dm_inv.sum(axis=1, keepdims=True), model.Dm_inv], axis=1)  # (m, dim+1, dim)
    grad_N = np.einsum("qal,mld->mqad", dNdL, gradL)
    arrays = dict(rest=rest, elements=elements, edges=edges.astype(np.int32),
                  corner_elements=model.elements.copy(), Dm_inv=model.Dm_inv.copy(), volume=model.volume.copy(),
                  qp_bary=L.copy(), qp_weight=model.volume[:, None] * w[None, :], grad_N=np.ascontiguousarray(grad_N),
                  mu=model.mu.copy(), lam=model.lam.copy(), boundary_facets=facets.astype(np.int32),
                  boundary_subfacets=sub.astype(np.int32), boundary_vertices=np.unique(facets).astype(np.int32))
    for arr in arrays.values():
        arr.flags.writeable = False
    return P2Model(dim=dim, n_corners=n, degree=int(degree), thickness=model.thickness,
                   pattern=HessianPattern(elements, rest.shape[0], dim), linear=model, material=model.material,
                   device=model.device, **arrays)


def make_p2_model(points, elements, material: Material | str, *, thickness: float = 1.0, degree: int | None = None,
                  device: str = "cpu") -> P2Model:
    """Build a :class:`P2Model` from a linear simplicial mesh (points (n, dim), elements (m, dim+1)):
    validated and oriented as :func:`simfab.fem.model.make_model`, then lifted by :func:`to_p2`."""
    return to_p2(make_model(points, elements, material, thickness=thickness, device=device), degree=degree)
