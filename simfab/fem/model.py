"""The immutable FEM model: rest shape, connectivity and per-element precomputations.

A state is just the deformed vertex positions ``x`` (n, dim) [m]; every FEM function is a
function of ``(model, x)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simfab.errors import InputError
from simfab.fem.assembly import HessianPattern
from simfab.fem.materials import Material, material_by_name
from simfab.fem.tolerances import DEGENERATE_REL


@dataclass(frozen=True, kw_only=True)
class MeshModel:
    """What every immutable FEM model (linear :class:`FemModel`, quadratic
    :class:`simfab.fem.p2.P2Model`) shares: sizes from ``rest`` (n, dim) and ``elements`` (m, k),
    position validation, and pickling without ``_cache`` (device buffers and recorded launches,
    rebuilt on demand). What depends on the element order is a method of the subclass:

    ``element_order``, ``element_geometry()``, ``shape_functions(L)``, ``linear_facets()``,
    ``linear_elements()``, ``mean_edge_length()`` and the ``corner_elements`` (m, dim+1). The fields
    every order has are described in :class:`FemModel` and :class:`simfab.fem.p2.P2Model`.
    """

    dim: int
    rest: np.ndarray
    elements: np.ndarray
    Dm_inv: np.ndarray
    volume: np.ndarray
    mu: np.ndarray
    lam: np.ndarray
    thickness: float
    boundary_facets: np.ndarray
    boundary_vertices: np.ndarray
    pattern: HessianPattern
    material: Material | None = None
    device: str = "cpu"
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)  # fresh on replace

    def __getstate__(self):
        return {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "_cache"}

    def __setstate__(self, state):
        for k, v in state.items():
            if isinstance(v, np.ndarray):
                v.flags.writeable = False  # unpickled arrays are fresh copies: keep them read-only
            object.__setattr__(self, k, v)
        object.__setattr__(self, "_cache", {})

    @property
    def n_vertices(self) -> int:
        """Number of nodes (P2: corners and midpoints): the row count of positions ``x``."""
        return self.rest.shape[0]

    @property
    def youngs_modulus(self) -> float:
        """Young's modulus [Pa]: the material's, or 3 times the mean shear modulus when the Lame
        parameters were given per element (the incompressible limit, E = 2 mu (1 + nu), nu -> 1/2)."""
        return self.material.youngs_modulus if self.material is not None else 3.0 * float(np.mean(self.mu))

    @property
    def n_elements(self) -> int:
        return self.elements.shape[0]

    @property
    def n_dofs(self) -> int:
        return self.rest.size

    @property
    def element_order(self) -> int:
        """Polynomial order of the shape functions: 1 (linear) or 2 (P2); selects the kernels in
        :mod:`simfab.fem.elastic`."""
        raise NotImplementedError

    def element_geometry(self) -> tuple[np.ndarray, np.ndarray]:
        """(rest geometry F is computed from at each quadrature point, weights (m, ...) [m^3]): what
        the element order's kernels read (:mod:`simfab.fem.workspace`)."""
        raise NotImplementedError

    def shape_functions(self, L) -> np.ndarray:
        """Nodal shape functions (q, k) at barycentric points L (q, dim+1) of an element."""
        raise NotImplementedError

    def linear_facets(self) -> np.ndarray:
        """(f, dim) the boundary as linear facets over the model's nodes, oriented like
        ``boundary_facets`` (contact is checked and refined on them)."""
        raise NotImplementedError

    def linear_elements(self) -> np.ndarray:
        """(m', dim+1) the body as linear simplices over the model's nodes (output: USD, MJCF, plots)."""
        raise NotImplementedError

    def mean_edge_length(self) -> float:
        """Mean length [m] of the (corner-mesh) element edges at rest."""
        raise NotImplementedError

    def check_positions(self, x, where: str = "x") -> np.ndarray:
        """``x`` (n, dim) or (n*dim,) as a (n, dim) float64 array; InputError naming ``where`` if the
        shape is wrong or it holds NaN/inf."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape == (self.n_dofs,):
            x = x.reshape(self.n_vertices, self.dim)
        if x.shape != self.rest.shape:
            raise InputError(f"positions have shape {x.shape}, expected {self.rest.shape}", where=where)
        if np.count_nonzero(np.isfinite(x)) != x.size:  # (np.all's dispatch costs more than the test)
            raise InputError("positions contain NaN or inf", where=where)
        return x


@dataclass(frozen=True, kw_only=True)
class FemModel(MeshModel):
    """Linear simplicial FEM discretization of an elastic body (immutable).

    Args:
        dim: 2 (triangles, plane strain) or 3 (tetrahedra)
        rest: (n, dim) float64 [m] rest positions X
        elements: (m, dim+1) int32 vertex indices, positively oriented (det Dm > 0)
        Dm_inv: (m, dim, dim) float64 [1/m] inverse of the rest edge matrix Dm = [X1-X0, X2-X0(, X3-X0)]
        volume: (m,) float64 [m^3] rest volume; 2D: triangle area * thickness
        mu, lam: (m,) float64 [Pa] Lame parameters
        thickness: [m] out-of-plane extent of a 2D (plane-strain) body; 1.0 for 3D (unused)
        boundary_facets: 2D (f, 2) boundary edges oriented with the body on their left (counter-
            clockwise outer boundary; outward normal (dy, -dx)); 3D (f, 3) boundary triangles with
            counter-clockwise winding seen from outside (right-hand normal points out)
        boundary_vertices: (b,) int32 sorted vertices on the boundary
        pattern: :class:`HessianPattern` of the (n*dim, n*dim) Hessian
        material: the material the Lame parameters came from (None if given per element)
        device: Warp device the kernels run on ("cpu", "cuda:0")
    """

    @property
    def element_order(self) -> int:
        return 1

    @property
    def corner_elements(self) -> np.ndarray:
        """(m, dim+1) the simplices' corners: the elements themselves."""
        return self.elements

    def mean_edge_length(self) -> float:
        """Mean length [m] of the element edges at rest (each element edge counted once per element)."""
        return _mean_edge_length(self.rest, self.elements)

    def element_geometry(self) -> tuple[np.ndarray, np.ndarray]:
        """(Dm^-1 (m, dim, dim) [1/m], volume (m,) [m^3]): F = Ds Dm^-1 is constant over a linear
        simplex, so it is the one-quadrature-point case with weight = volume."""
        return self.Dm_inv, self.volume

    def shape_functions(self, L) -> np.ndarray:
        """Linear shape functions (q, dim+1) at barycentric points L (q, dim+1): the barycentrics."""
        return np.asarray(L, dtype=np.float64)

    def linear_facets(self) -> np.ndarray:
        """(f, dim) the boundary facets (``boundary_facets``)."""
        return self.boundary_facets

    def linear_elements(self) -> np.ndarray:
        """(m, dim+1) the elements."""
        return self.elements


def edge_matrices(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """The elements' edge matrices.

    Args:
        points: (n, dim) positions [m].
        elements: (m, dim + 1) vertex indices.

    Returns:
        (m, dim, dim) matrices whose columns are the edge vectors x_i - x_0, i = 1..dim [m].
    """
    p = points[elements]  # (m, dim+1, dim)
    return np.swapaxes(p[:, 1:, :] - p[:, :1, :], 1, 2)


def _mean_edge_length(points: np.ndarray, elements: np.ndarray) -> float:
    k = elements.shape[1]
    i, j = np.triu_indices(k, 1)
    return float(np.linalg.norm(points[elements[:, i]] - points[elements[:, j]], axis=-1).mean())


def mean_edge_length_gradient(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """d(mean element edge length)/d(points) (n, dim) [-] of a linear mesh (each element edge counted once
    per element, as :meth:`FemModel.mean_edge_length`): h = sum_e |X_a - X_b| / N, so each edge adds
    +-(X_a - X_b) / (|X_a - X_b| N) to its two end points.

    Args:
        points: (n, dim) vertex positions [m].
        elements: (m, dim + 1) simplices.

    Returns:
        The gradient, (n, dim).
    """
    X = np.asarray(points, float)
    el = np.asarray(elements, np.int64)
    i, j = np.triu_indices(el.shape[1], 1)
    a, b = el[:, i].ravel(), el[:, j].ravel()
    u = X[a] - X[b]
    u /= np.linalg.norm(u, axis=1, keepdims=True) * len(a)
    g = np.zeros_like(X)
    np.add.at(g, a, u)
    np.add.at(g, b, -u)
    return g


def boundary_facets(elements: np.ndarray, dim: int) -> np.ndarray:
    """The facets (edges in 2D, triangles in 3D) that belong to exactly one element, oriented outward.

    Args:
        elements: (m, dim + 1) vertex indices of positively oriented simplices.
        dim: 2 or 3.

    Returns:
        (f, dim) int32 vertex indices, in the order of the elements they belong to.
    """
    if dim == 2:
        local = np.array([[0, 1], [1, 2], [2, 0]])  # counter-clockwise around a positive triangle
    else:
        local = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward normals of a positive tet
    facets = elements[:, local].reshape(-1, dim)
    key = np.sort(facets, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return facets[np.sort(first[counts == 1])].astype(np.int32)


def make_model(points, elements, material: Material | str, *, thickness: float = 1.0, device: str = "cpu") -> FemModel:
    """Build a :class:`FemModel` from a simplicial mesh.

    Args:
        points: (n, 2) or (n, 3) rest positions [m]; dim = points.shape[1].
        elements: (m, dim+1) vertex indices; negatively oriented elements are re-oriented (two
            vertices swapped).
        material: :class:`~simfab.fem.materials.Material` or a built-in material name ("PLA",
            "VeroWhite"); homogeneous body.
        thickness: [m] out-of-plane extent for 2D plane strain (volume = area * thickness).
        device: Warp device name.

    Returns:
        The model. InputError for: wrong shapes, NaN/inf coordinates, out-of-range indices, vertices
        used by no element, degenerate elements (|det Dm| <= DEGENERATE_REL * h^dim, h = mean edge
        length), thickness <= 0.
    """
    # deferred: importing simfab._warp loads Warp, which building a model needs only for the device name
    from simfab._warp import device as _validate_device

    if isinstance(material, str):
        material = material_by_name(material)
    if not isinstance(material, Material):
        raise InputError(f"material must be a Material or a material name, got {type(material).__name__}",
                         where="material")

    where = "mesh"
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or pts.shape[0] < pts.shape[1] + 1:
        raise InputError(f"points must be an (n, 2) or (n, 3) array with n >= dim+1, got shape {pts.shape}",
                         where=where)
    if not np.all(np.isfinite(pts)):
        raise InputError("points contain NaN or inf", where=where)
    dim = pts.shape[1]
    el = np.asarray(elements)
    if el.ndim != 2 or el.shape[1] != dim + 1 or el.shape[0] == 0:
        raise InputError(f"elements must be an (m, {dim + 1}) array for {dim}D points, got shape {el.shape}",
                         where=where)
    if not np.issubdtype(el.dtype, np.integer):
        if not np.all(np.equal(np.mod(el, 1), 0)):
            raise InputError("element indices must be integers", where=where)
    el = el.astype(np.int64)
    n = pts.shape[0]
    if el.min() < 0 or el.max() >= n:
        bad = int(np.flatnonzero((el < 0).any(1) | (el >= n).any(1))[0])
        raise InputError(f"element {bad} has a vertex index out of range [0, {n})", where=where)
    repeats = np.any(np.diff(np.sort(el, axis=1), axis=1) == 0, axis=1)
    if repeats.any():
        raise InputError(f"element {int(np.flatnonzero(repeats)[0])} repeats a vertex", where=where)
    used = np.zeros(n, bool)
    used[el.ravel()] = True
    if not used.all():
        first = int(np.flatnonzero(~used)[0])
        raise InputError(f"{int((~used).sum())} vertices are not used by any element (first: {first})",
                         where=where)
    if not (np.isfinite(thickness) and thickness > 0):
        raise InputError(f"thickness must be > 0, got {thickness}", where=where)

    Dm = edge_matrices(pts, el)
    det = np.linalg.det(Dm)
    h = _mean_edge_length(pts, el)
    degenerate = np.abs(det) <= DEGENERATE_REL * h**dim
    if degenerate.any():
        bad = int(np.flatnonzero(degenerate)[0])
        raise InputError(f"{int(degenerate.sum())} degenerate elements (zero area/volume), first: element {bad}",
                         where=where)
    neg = det < 0
    if neg.any():  # swap the last two vertices: flips the orientation
        el[neg, -2:] = el[neg, -1:-3:-1]
        Dm = edge_matrices(pts, el)
        det = np.linalg.det(Dm)
    # simplex measure = det Dm / dim!  (triangle area = det/2, tet volume = det/6)
    volume = det / 6.0 if dim == 3 else det / 2.0 * thickness
    mu, lam = material.lame()
    m = el.shape[0]
    el32 = el.astype(np.int32)
    bfacets = boundary_facets(el32, dim)
    arrays = dict(rest=pts.copy(), elements=el32, Dm_inv=np.linalg.inv(Dm), volume=volume, mu=np.full(m, mu),
                  lam=np.full(m, lam), boundary_facets=bfacets, boundary_vertices=np.unique(bfacets).astype(np.int32))
    for a in arrays.values():
        a.flags.writeable = False  # the model is immutable: states are separate arrays
    return FemModel(
        dim=dim,
        thickness=float(thickness) if dim == 2 else 1.0,
        pattern=HessianPattern(el32, n, dim),
        material=material,
        device=_validate_device(device),
        **arrays,
    )
