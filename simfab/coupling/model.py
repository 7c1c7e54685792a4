"""The insertion model: A's FEM model, O's field and path, the steps along it, boundary conditions
and barrier scales (:class:`CouplingModel`, built by :func:`make_coupling_model`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from simfab.contact.imls import ImlsField
from simfab.coupling.config import ContactConfig, InsertionConfig
from simfab.errors import InputError
from simfab.fem.model import make_model
from simfab.fem.p2 import to_p2
from simfab.rotations import pose_matrix


@dataclass(frozen=True, kw_only=True, eq=False)
class CouplingModel:
    """Immutable description of one insertion simulation (built by :func:`make_coupling_model`).

    Args:
        name: the scene's name.
        fem: A's FEM model (SI units): a linear :class:`simfab.fem.model.FemModel` or, with
            ``options.element_order = 2``, a quadratic :class:`simfab.fem.p2.P2Model` (energies through
            :mod:`simfab.fem.elastic`; the facets contact works on: :attr:`contact_facets`).
        field: :class:`ImlsField` of O in O's body frame.
        path: :class:`simfab.io.mjcf.Trajectory` of O's pose, parameterized by path length [m].
        s_steps: (K+1,) path length at each step [m]; step 0 is the start pose.
        fixed_vertices: (f,) vertices of A in the fixed region.
        free: (n*dim,) bool, dofs solved for (fixed: the fixed vertices' dofs along the insertion axis,
            along ``options.fixed_axes``, or along all axes with ``options.fix_all_axes``).
        axis: (dim,) unit insertion axis (coordinate axis closest to O's overall translation).
        options: the scene's :class:`InsertionConfig`.
        h: A's mean edge length h_A [m].
        dhat: the barrier's activation distance [m].
        kappa: the barrier stiffness [N/m].
        tol: penetration tolerance [m].
        force_scale: E h width, the force unit of the solver's tolerances [N].
        object_vertices, object_faces: O's display geometry in its body frame (3D mesh, or a closed
            curve (k, 2) with faces None in 2D).
        contact: :class:`ContactConfig` (friction between O and A).
    """

    name: str
    fem: object
    field: ImlsField
    path: object
    s_steps: np.ndarray
    fixed_vertices: np.ndarray
    free: np.ndarray
    axis: np.ndarray
    options: InsertionConfig
    h: float
    dhat: float
    kappa: float
    tol: float
    force_scale: float
    object_vertices: np.ndarray
    object_faces: np.ndarray | None = None
    contact: ContactConfig = field(default_factory=ContactConfig)
    _cache: dict = field(default_factory=dict, repr=False, init=False)  # fresh on dataclasses.replace

    @property
    def dim(self) -> int:
        return self.fem.dim

    @property
    def contact_facets(self) -> np.ndarray:
        """(f, dim) int64 linear boundary facets (2D segments, 3D triangles; body on the left /
        counter-clockwise from outside) that contact is checked and refined on; refinement facet
        ids index its rows. ``fem.linear_facets()``: the boundary facets of linear elements; for P2
        the 2 segments / 4 triangles per quadratic facet over its corner and midpoint nodes, whose
        nodes share an element, so points interpolated on them stay inside the Hessian's sparsity
        pattern. (Memoized, read-only.)"""
        out = self._cache.get("contact_facets")
        if out is None:
            out = self._cache["contact_facets"] = np.asarray(self.fem.linear_facets(), dtype=np.int64)
            out.flags.writeable = False
        return out

    @property
    def display_elements(self) -> np.ndarray:
        """(m', dim+1) int64 linear simplices over A's nodes for output (USD, MJCF, plots): the
        elements, or for P2 the red refinement on its nodes (``fem.linear_elements()``, 4 / 8
        per element). (Memoized, read-only.)"""
        out = self._cache.get("display_elements")
        if out is None:
            out = self._cache["display_elements"] = np.asarray(self.fem.linear_elements(), dtype=np.int64)
            out.flags.writeable = False
        return out

    def pose(self, s: float):
        """O's pose at a path length (memoized).

        Args:
            s: path length [m].

        Returns:
            A tuple (R (3, 3), p (3,) [m]) with world x = R x_body + p.
        """
        key = ("pose", float(s))
        out = self._cache.get(key)
        if out is None:
            pos, quat = self.pos_quat(s)
            rkey = ("rotation", quat.tobytes())  # (one matrix per quaternion: a translating O has one)
            R = self._cache.get(rkey)
            if R is None:
                R = self._cache[rkey] = pose_matrix((pos, quat))[0]
            out = self._cache[key] = pose_matrix((R, pos))
        return out

    def motion(self, s_a: float, s_b: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """O's rigid motion between two path lengths.

        Args:
            s_a, s_b: path lengths from and to [m].

        Returns:
            A tuple (M (3, 3), p_a (3,) [m], p_b (3,) [m]) with y -> M (y - p_a) + p_b for O's material points.
        """
        Ra, pa = self.pose(s_a)
        Rb, pb = self.pose(s_b)
        return Rb @ Ra.T, pa, pb

    def carry(self, y: np.ndarray, s_a: float, s_b: float) -> np.ndarray:
        """Points moved with O from one path length to another (:meth:`motion`).

        Args:
            y: (k, dim) points [m].
            s_a, s_b: path lengths from and to [m].

        Returns:
            The moved points, (k, dim) [m].
        """
        M, pa, pb = self.motion(s_a, s_b)
        dim = y.shape[1]
        y3 = np.zeros((len(y), 3))
        y3[:, :dim] = y
        return ((y3 - pa) @ M.T + pb)[:, :dim]

    def pos_quat(self, s: float):
        """O's pose at a path length as the path gives it (memoized; do not modify the arrays).

        Args:
            s: path length [m]; past the last keyframe O goes on along a translating last segment.

        Returns:
            A tuple (pos (3,) [m], quat_wxyz (4,)).
        """
        key = ("pos_quat", float(s))
        out = self._cache.get(key)
        if out is None:  # (past the last keyframe the orientation is the last one: pose_at clamps s)
            quat = self.path.pose_at(s)[1]
            out = self._cache[key] = (self.position(s), np.asarray(quat, dtype=float))
        return out

    def position(self, s: float) -> np.ndarray:
        """O's position at a path length (:meth:`pos_quat`'s, without the orientation).

        Args:
            s: path length [m]; past the last keyframe O goes on along a translating last segment.

        Returns:
            (3,) position [m].
        """
        L = float(self.path.length)
        u = self.end_direction
        if s > L and u is not None:  # past the last keyframe: straight on along the last segment
            return np.asarray(self.path.position_at(L), dtype=float) + (s - L) * u
        return np.asarray(self.path.position_at(s), dtype=float)

    @property
    def end_direction(self) -> np.ndarray | None:
        """(3,) unit translation of the path's last segment when that segment is a pure
        translation (O may then continue past the last keyframe until it comes to rest), else None."""
        key = "end_direction"
        if key not in self._cache:
            pos = self.path.positions
            d = np.asarray(pos[-1] - pos[-2], dtype=float)
            n = float(np.linalg.norm(d))
            self._cache[key] = None if (self.path.segment_turns[-1] or n == 0) else d / n
        return self._cache[key]

    def direction(self, s: float) -> np.ndarray:
        """O's unit translation direction at a path length (memoized).

        Args:
            s: path length [m].

        Returns:
            A (dim,) unit vector (zero during a pure rotation).
        """
        key = ("direction", float(s))
        out = self._cache.get(key)
        if out is None:
            L = float(self.path.length)
            past = s > L and self.end_direction is not None
            u = (self.end_direction if past else np.asarray(self.path.direction_at(s), dtype=float))[: self.dim]
            n = np.linalg.norm(u)
            out = self._cache[key] = u / n if n > 0 else u
        return out.copy()


def with_rest_shape(cm: CouplingModel, X: np.ndarray) -> CouplingModel:
    """``cm`` with A's rest shape X (n, dim) [m] on its linear mesh (``cm.fem.linear`` for quadratic
    elements, whose edge nodes then sit at the new midpoints): the same elements, element order,
    material, object, path, supports, options and contact. The steps are planned again for X (see
    :func:`make_coupling_model`). Raises InputError for an invalid mesh."""
    lin = cm.fem.linear if cm.fem.element_order == 2 else cm.fem
    fem = make_model(X, lin.elements, lin.material, thickness=lin.thickness, device=lin.device)
    if cm.fem.element_order == 2:
        fem = to_p2(fem, degree=cm.fem.degree)
    return make_coupling_model(name=cm.name, fem=fem, field=cm.field, path=cm.path, fixed_vertices=cm.fixed_vertices,
                               options=cm.options, object_vertices=cm.object_vertices, object_faces=cm.object_faces,
                               contact=cm.contact)


def make_coupling_model(*, name: str, fem, field: ImlsField, path, fixed_vertices, options: InsertionConfig,
                        object_vertices, object_faces=None, contact: ContactConfig | None = None) -> CouplingModel:
    """Assemble a :class:`CouplingModel`: steps along the path, boundary conditions, barrier scales."""
    dim = fem.dim
    n = fem.n_vertices
    fixed_vertices = np.unique(np.asarray(fixed_vertices, dtype=np.int64))
    if fixed_vertices.size == 0:
        raise InputError("the fixed region contains no vertex of the compliant part", where="fixed")
    total = float(path.length)
    L = default_insertion_length(fem, path) if options.L_max is None else min(float(options.L_max), total)
    if not L > 0:
        raise InputError("the object's path has zero length (keyframes do not move it)", where="keyframes")
    if options.h_in is not None:
        k = int(np.floor(L / options.h_in + 1e-9))
        s = np.arange(k + 1) * options.h_in
        if L - s[-1] > 1e-9 * L:
            s = np.append(s, L)
    else:
        s = np.linspace(0.0, L, (options.steps or 35) + 1)
    move = np.asarray(path.positions[-1] - path.positions[0])[:dim]
    if np.linalg.norm(move) == 0:
        move = np.asarray(path.direction_at(0.0))[:dim]
    ax = int(np.argmax(np.abs(move))) if np.linalg.norm(move) > 0 else 0
    axis = np.zeros(dim)
    axis[ax] = 1.0
    free = np.ones((n, dim), dtype=bool)
    if options.fix_all_axes:
        free[fixed_vertices] = False
    elif options.fixed_axes is not None:
        held = ["xyz".index(a) for a in options.fixed_axes]
        if any(a >= dim for a in held):
            raise InputError(f"fixed_axes={options.fixed_axes!r} names an axis a {dim}D part does not have",
                             where="[simulation]")
        if ax not in held:
            raise InputError(f"fixed_axes={options.fixed_axes!r} must include the insertion axis {'xyz'[ax]!r}",
                             where="[simulation]")
        free[np.ix_(fixed_vertices, held)] = False
    else:
        free[fixed_vertices, ax] = False
    h = fem.mean_edge_length()
    E = fem.youngs_modulus
    width = h if dim == 3 else fem.thickness
    return CouplingModel(
        name=name, fem=fem, field=field, path=path, s_steps=s, fixed_vertices=fixed_vertices, free=free.ravel(),
        axis=axis, options=options, h=h, dhat=options.dhat_rel * h, kappa=options.kappa_rel * E * width,
        tol=options.penetration_tol_rel * h, force_scale=E * h * width,
        object_vertices=np.asarray(object_vertices, float),
        object_faces=None if object_faces is None else np.asarray(object_faces, int),
        contact=ContactConfig() if contact is None else contact,
    )


def default_insertion_length(fem, path, samples: int = 2000) -> float:
    """L_max by default: the path length at which O's centre passes A's farthest point along the
    insertion direction (the overall translation of the path), or the whole path if it never does.
    """
    dim = fem.dim
    move = np.asarray(path.positions[-1] - path.positions[0], dtype=float)[:dim]
    total = float(path.length)
    if np.linalg.norm(move) == 0:
        return total
    u = move / np.linalg.norm(move)
    far = float(np.max(fem.rest @ u))
    past = np.flatnonzero(path.sampled_positions(samples)[:, :dim] @ u > far)
    return float(np.linspace(0.0, total, samples)[past[0]]) if past.size else total
