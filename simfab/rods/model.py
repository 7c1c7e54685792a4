"""Rod networks: immutable model (topology, rest shape, stiffness, attachments) and state.

A network is a set of rods (open polylines) plus rigid bodies (inserts and junction
frames). Rod ends attach to bodies:

- **clamp**: both nodes of the end edge and the end edge's material frame follow the body;
- **pin**: only the end node follows the body (the edge turns freely about it).

Degrees of freedom: node positions (3 per node, [m]), one twist angle per edge ([rad]),
and 6 per free rigid body (translation [m] + rotation-vector update [rad]). Nodes/angles
that are attached to a body or marked fixed are not unknowns; fixed ones are prescribed by
the driver (quasi-static loading).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from simfab.errors import InputError
from simfab.rods import frames as fr


# ----------------------------------------------------------------------------- materials
@dataclass(frozen=True, kw_only=True)
class RodMaterial:
    """Linear elastic material.

    Args:
        young: Young's modulus [Pa], > 0.
        poisson: Poisson ratio [-], in (-1, 0.5).

    Raises:
        InputError: a modulus or ratio out of range.
    """

    young: float
    poisson: float = 0.35

    def __post_init__(self):
        if not (self.young > 0 and -1.0 < self.poisson < 0.5):
            raise InputError(f"material needs young > 0 and -1 < poisson < 0.5 (got {self.young}, {self.poisson})")

    @property
    def shear(self) -> float:
        """Shear modulus G = E / (2 (1 + nu)) [Pa]."""
        return self.young / (2.0 * (1.0 + self.poisson))


@dataclass(frozen=True, kw_only=True)
class Section:
    """Rod cross-section.

    Args:
        shape: ``"rect"`` or ``"circle"``.
        width: a rectangle's side along the material director m2 (in the sheet plane for laser-cut
            beams) [m].
        thickness: a rectangle's side along m1 (the sheet normal) [m], so bending out of the sheet
            (kappa1) is the weak direction.
        radius: a circle's radius [m].

    Raises:
        InputError: an unknown shape or a non-positive size.
    """

    shape: str = "rect"
    width: float = 0.0
    thickness: float = 0.0
    radius: float = 0.0

    def __post_init__(self):
        if self.shape == "rect":
            if not (self.width > 0 and self.thickness > 0):
                raise InputError("rectangular section needs width > 0 and thickness > 0 "
                                 f"(got {self.width}, {self.thickness})")
        elif self.shape == "circle":
            if not self.radius > 0:
                raise InputError(f"circular section needs radius > 0 (got {self.radius})")
        else:
            raise InputError(f"section shape must be 'rect' or 'circle' (got {self.shape!r})")

    def area(self) -> float:
        """The cross-section's area.

        Returns:
            The area [m^2].
        """
        return self.width * self.thickness if self.shape == "rect" else np.pi * self.radius**2

    def stiffness(self, mat: RodMaterial) -> dict:
        """The section's stiffnesses in a material.

        Rectangle: B1 = E w t^3/12, B2 = E t w^3/12, J = a b^3 (1/3 - 0.21 b/a (1 - b^4/(12 a^4)))
        (a >= b the sides; Roark). Circle: B1 = B2 = E pi r^4/4, J = pi r^4/2.

        Args:
            mat: the rod's material.

        Returns:
            A dict: axial ``EA`` [N], bending ``B1`` (about m2) and ``B2`` (about m1) [N m^2], torsion ``GJ`` [N m^2].
        """
        E, G = mat.young, mat.shear
        if self.shape == "rect":
            w, t = self.width, self.thickness
            a, b = max(w, t), min(w, t)
            J = a * b**3 * (1.0 / 3.0 - 0.21 * (b / a) * (1.0 - b**4 / (12.0 * a**4)))
            return dict(EA=E * w * t, B1=E * w * t**3 / 12.0, B2=E * t * w**3 / 12.0, GJ=G * J)
        r = self.radius
        return dict(EA=E * np.pi * r**2, B1=E * np.pi * r**4 / 4.0, B2=E * np.pi * r**4 / 4.0,
                    GJ=G * np.pi * r**4 / 2.0)

    def half_extents(self) -> tuple[float, float]:
        """Distances from the centreline to the outer fibre.

        Returns:
            A tuple (along m1: half the thickness, along m2: half the width) [m]; ``(radius, radius)``
            for a circle.
        """
        if self.shape == "rect":
            return 0.5 * self.thickness, 0.5 * self.width
        return self.radius, self.radius

    def draw_width(self) -> float:
        """Width used for drawing (USD curve widths, capsule radii).

        Returns:
            The width [m].
        """
        return self.width if self.shape == "rect" else 2.0 * self.radius


# ----------------------------------------------------------------------------- model/state
@dataclass(frozen=True)
class RodInfo:
    """One rod of a network: its nodes (k+1,) and edges (k,) in the global arrays."""

    name: str
    nodes: np.ndarray
    edges: np.ndarray
    section: Section


@dataclass(frozen=True, kw_only=True)
class RodModel:
    """Immutable description of a rod network (arrays are float64 / int32, SI units).

    Built by :class:`NetworkBuilder`.

    Args:
        n_nodes: N, the number of nodes.
        edges: (E,2) node indices; edge vector = x[b] - x[a].
        rest_len: (E,) rest lengths [m].
        stretch_stiff: (E,) EA [N].
        hinge_nodes: (H,3) (x0, x1, x2) of each interior vertex.
        hinge_edges: (H,2) (e, f), the incoming and outgoing edge of each hinge.
        vor_len: (H,) Voronoi length (|e|+|f|)/2 at rest [m].
        kappa_bar: (H,2) rest material curvatures (kappa1, kappa2) [-] (integrated, 2 tan(phi/2)).
        bend_stiff: (H,2) (B1, B2) [N m^2].
        twist_stiff: (H,) GJ [N m^2].
        twist_bar: (H,) rest twist [rad].
        rods: one :class:`RodInfo` per rod.
        body_names: (B,) names.
        body_driven: (B,) bool (pose prescribed by the driver).
        node_body: (N,) body index or -1.
        node_offset: (N,3) position in the body frame [m].
        edge_body: (E,) body index or -1 (clamped edges).
        edge_m1_local: (E,3) m1 in the body frame.
        node_fixed: (N,3) bool prescribed coordinates.
        theta_fixed: (E,) bool prescribed angles.
        length_scale: mean rest edge length [m] (scales angle unknowns so all have length units).
        force_scale: max bending stiffness / (longest rod)^2 [N], the force unit of tolerances.
    """

    n_nodes: int
    edges: np.ndarray
    rest_len: np.ndarray
    stretch_stiff: np.ndarray
    hinge_nodes: np.ndarray
    hinge_edges: np.ndarray
    vor_len: np.ndarray
    kappa_bar: np.ndarray
    bend_stiff: np.ndarray
    twist_stiff: np.ndarray
    twist_bar: np.ndarray
    rods: tuple
    body_names: tuple
    body_driven: np.ndarray
    node_body: np.ndarray
    node_offset: np.ndarray
    edge_body: np.ndarray
    edge_m1_local: np.ndarray
    node_fixed: np.ndarray
    theta_fixed: np.ndarray
    length_scale: float
    force_scale: float

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @property
    def n_hinges(self) -> int:
        return len(self.hinge_nodes)

    @property
    def n_bodies(self) -> int:
        return len(self.body_names)

    def body_index(self, name: str) -> int:
        """The index of a rigid body.

        Args:
            name: the body's name.

        Returns:
            Its index into ``body_names``.

        Raises:
            InputError: no body has that name.
        """
        try:
            return self.body_names.index(name)
        except ValueError:
            raise InputError(f"no body named {name!r} (bodies: {', '.join(self.body_names)})") from None

    def rod(self, name: str) -> RodInfo:
        """One rod of the network.

        Args:
            name: the rod's name.

        Returns:
            Its :class:`RodInfo` (global node and edge indices, section).

        Raises:
            InputError: no rod has that name.
        """
        for r in self.rods:
            if r.name == name:
                return r
        raise InputError(f"no rod named {name!r}")


@dataclass(frozen=True, kw_only=True)
class RodState:
    """Configuration of a network (a new object per step; arrays are not modified in place).

    Args:
        x: (N,3) node positions [m].
        theta: (E,) twist angles [rad].
        d1: (E,3) reference directors (unit, normal to the tangents ``t``).
        t: (E,3) unit edge tangents.
        ref_twist: (H,) reference twist [rad].
        body_pos: (B,3) body positions [m].
        body_rot: (B,3,3) rotation matrices (body -> world).
    """

    x: np.ndarray
    theta: np.ndarray
    d1: np.ndarray
    t: np.ndarray
    ref_twist: np.ndarray
    body_pos: np.ndarray
    body_rot: np.ndarray

    def replace(self, **kw) -> "RodState":
        """A copy with some fields replaced (:func:`dataclasses.replace`).

        Args:
            **kw: field name -> new value.

        Returns:
            A new :class:`RodState`.
        """
        return dataclasses.replace(self, **kw)

    def material_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """The material frames of the edges.

        Returns:
            A tuple (m1, m2) of (E,3) unit directors.
        """
        return fr.material_frames(self.d1, self.t, self.theta)


def _hinge_curvatures(te, tf, m1e, m2e, m1f, m2f) -> np.ndarray:
    """(H,2) material curvatures (kappa1, kappa2) from the tangents and material directors (H,3)
    of the incoming (e) and outgoing (f) edges of each hinge (same definition as bend.py)."""
    kb = 2.0 * np.cross(te, tf) / (1.0 + np.einsum("ij,ij->i", te, tf))[:, None]
    k1 = 0.5 * np.einsum("ij,ij->i", kb, m2e + m2f)
    k2 = -0.5 * np.einsum("ij,ij->i", kb, m1e + m1f)
    return np.stack([k1, k2], axis=1)


def material_curvatures(model: RodModel, state: RodState) -> np.ndarray:
    """(H,2) material curvatures (kappa1, kappa2) of ``state`` (same definition as bend.py)."""
    if model.n_hinges == 0:
        return np.zeros((0, 2))
    m1, m2 = state.material_frames()
    e, f = model.hinge_edges[:, 0], model.hinge_edges[:, 1]
    return _hinge_curvatures(state.t[e], state.t[f], m1[e], m2[e], m1[f], m2[f])


def synchronize(model: RodModel, prev: RodState, x: np.ndarray, theta: np.ndarray,
                body_pos: np.ndarray, body_rot: np.ndarray) -> RodState:
    """New state from ``prev`` with new unknowns: attached nodes follow their bodies, reference
    directors are time-parallel transported to the new tangents, clamped edges take the twist
    angle that aligns their material frame with the body, and the reference twist is updated
    continuously."""
    x = np.array(x, dtype=np.float64, copy=True)
    theta = np.array(theta, dtype=np.float64, copy=True)
    att = model.node_body >= 0
    if att.any():
        b = model.node_body[att]
        x[att] = body_pos[b] + np.einsum("kij,kj->ki", body_rot[b], model.node_offset[att])
    t = fr.tangents(x, model.edges)
    d1 = fr.transport_directors(prev.d1, prev.t, t)
    clamped = model.edge_body >= 0
    if clamped.any():
        b = model.edge_body[clamped]
        m1 = np.einsum("kij,kj->ki", body_rot[b], model.edge_m1_local[clamped])
        ang = fr.signed_angle(d1[clamped], m1 - np.einsum("ij,ij->i", m1, t[clamped])[:, None] * t[clamped], t[clamped])
        prev_th = prev.theta[clamped]
        theta[clamped] = prev_th + (ang - prev_th + np.pi) % (2.0 * np.pi) - np.pi
    ref = fr.reference_twist(d1, t, model.hinge_edges, prev.ref_twist) if model.n_hinges else prev.ref_twist
    return RodState(x=x, theta=theta, d1=d1, t=t, ref_twist=ref, body_pos=np.array(body_pos, dtype=np.float64),
                    body_rot=np.array(body_rot, dtype=np.float64))


# ----------------------------------------------------------------------------- builder
@dataclass
class _RodSpec:
    name: str
    points: np.ndarray
    rest_points: np.ndarray
    section: Section
    material: RodMaterial
    director: np.ndarray
    stretch_stiffness: float | None


@dataclass
class NetworkBuilder:
    """Assemble a :class:`RodModel` and its initial :class:`RodState`.

    Example::

        nb = NetworkBuilder()
        ins = nb.add_body("insert", pos=[0.1, 0, 0], driven=True)
        r = nb.add_rod("beam", pts, section=Section(width=5e-3, thickness=1e-3), material=RodMaterial(young=2e9),
                       director=[0, 0, 1])
        nb.clamp("beam", "end", "insert")
        nb.fix("beam", nodes=[0, 1], thetas=[0])
        model, state = nb.build()

    Args:
        rods, bodies, clamps, pins, fixed_nodes, fixed_thetas: what was added so far (filled by the
            methods below; start empty).
    """

    rods: list = field(default_factory=list)
    bodies: list = field(default_factory=list)  # (name, pos (3,), rot (3,3), driven)
    clamps: list = field(default_factory=list)  # (rod, end, body)
    pins: list = field(default_factory=list)
    fixed_nodes: list = field(default_factory=list)  # (rod, local node, comps)
    fixed_thetas: list = field(default_factory=list)  # (rod, local edge)

    def add_body(self, name: str, *, pos=(0.0, 0.0, 0.0), rot=None, driven: bool = False) -> str:
        """Add a rigid body (insert or junction frame).

        Args:
            name: the body's name (unique).
            pos: (3,) its position [m].
            rot: (3,3) its rotation (body -> world); None for the identity.
            driven: its pose is prescribed by the driver.

        Returns:
            ``name``.

        Raises:
            InputError: a duplicate name.
        """
        if any(b[0] == name for b in self.bodies):
            raise InputError(f"duplicate body name {name!r}")
        R = np.eye(3) if rot is None else np.asarray(rot, dtype=np.float64)
        self.bodies.append((name, np.asarray(pos, dtype=np.float64), R, bool(driven)))
        return name

    def add_rod(self, name: str, points, *, section: Section, material: RodMaterial, director=(0.0, 0.0, 1.0),
                rest_points=None, stretch_stiffness: float | None = None) -> str:
        """Add a rod.

        Args:
            name: the rod's name (unique).
            points: (k+1,3) its node positions [m], k >= 1.
            section: its cross-section.
            material: its material.
            director: (3,) the initial m1 of the first edge (the sheet normal for laser-cut beams).
            rest_points: (k+1,3) the natural shape (curvature) [m]; None: ``points``.
            stretch_stiffness: overrides EA [N] (e.g. to approach the inextensible limit).

        Returns:
            ``name``.

        Raises:
            InputError: bad points (shape, non-finite, repeated) or a duplicate name.
        """
        P = np.asarray(points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2:
            raise InputError(f"rod {name!r}: points must be (k+1, 3) with k >= 1, got {P.shape}")
        Q = P if rest_points is None else np.asarray(rest_points, dtype=np.float64)
        if Q.shape != P.shape:
            raise InputError(f"rod {name!r}: rest_points shape {Q.shape} differs from points {P.shape}")
        for arr, what in ((P, "points"), (Q, "rest_points")):
            if not np.all(np.isfinite(arr)) or np.any(np.linalg.norm(np.diff(arr, axis=0), axis=1) <= 0):
                raise InputError(f"rod {name!r}: {what} must be finite with no repeated consecutive points")
        if any(r.name == name for r in self.rods):
            raise InputError(f"duplicate rod name {name!r}")
        self.rods.append(_RodSpec(name, P, Q, section, material, np.asarray(director, dtype=np.float64),
                                  stretch_stiffness))
        return name

    def clamp(self, rod: str, end: str, body: str) -> None:
        """Clamp an end edge of a rod to a body (position and frame).

        Args:
            rod: the rod's name.
            end: "start" or "end".
            body: the body's name.
        """
        self.clamps.append((rod, _end(end), body))

    def pin(self, rod: str, end: str, body: str) -> None:
        """Pin an end node of a rod to a body (position only).

        Args:
            rod: the rod's name.
            end: "start" or "end".
            body: the body's name.
        """
        self.pins.append((rod, _end(end), body))

    def fix(self, rod: str, *, nodes=(), thetas=(), comps=(0, 1, 2)) -> None:
        """Prescribe coordinates of nodes and twist angles of edges of a rod.

        Args:
            rod: the rod's name.
            nodes: local node indices (Python indexing) whose coordinates are held.
            thetas: local edge indices whose angles are held.
            comps: the coordinates held (0, 1, 2 for x, y, z).
        """
        for n in nodes:
            self.fixed_nodes.append((rod, int(n), tuple(comps)))
        for e in thetas:
            self.fixed_thetas.append((rod, int(e)))

    def build(self) -> tuple[RodModel, RodState]:
        """Assemble the network.

        Returns:
            A tuple (the immutable :class:`RodModel`, its initial :class:`RodState`).

        Raises:
            InputError: no rod, or an attachment or fixed index naming an unknown rod, body, node or edge.
        """
        if not self.rods:
            raise InputError("a rod network needs at least one rod")
        body_idx = {b[0]: i for i, b in enumerate(self.bodies)}
        rod_idx = {r.name: i for i, r in enumerate(self.rods)}
        X, Xr, edges, rest_len, EA, d1, infos = [], [], [], [], [], [], []
        hn, he, B, GJ, kb_rest, vor = [], [], [], [], [], []
        n0 = e0 = 0
        for r in self.rods:
            k = len(r.points) - 1
            nodes = np.arange(n0, n0 + k + 1)
            eds = np.arange(e0, e0 + k)
            stiff = r.section.stiffness(r.material)
            X.append(r.points)
            Xr.append(r.rest_points)
            edges.append(np.stack([nodes[:-1], nodes[1:]], axis=1))
            L = np.linalg.norm(np.diff(r.rest_points, axis=0), axis=1)
            rest_len.append(L)
            EA.append(np.full(k, stiff["EA"] if r.stretch_stiffness is None else r.stretch_stiffness))
            try:
                d1.append(fr.space_parallel_frames(fr.normalize(np.diff(r.points, axis=0)), r.director))
            except ValueError:
                raise InputError(f"rod {r.name!r}: director {r.director.tolist()} "
                                 "is parallel to the first edge") from None
            if k >= 2:
                hn.append(np.stack([nodes[:-2], nodes[1:-1], nodes[2:]], axis=1))
                he.append(np.stack([eds[:-1], eds[1:]], axis=1))
                B.append(np.tile([stiff["B1"], stiff["B2"]], (k - 1, 1)))
                GJ.append(np.full(k - 1, stiff["GJ"]))
                vor.append(0.5 * (L[:-1] + L[1:]))
                # rest curvature measured in the rest shape's own space-parallel frames
                tr = fr.normalize(np.diff(r.rest_points, axis=0))
                dr = fr.space_parallel_frames(tr, r.director)
                m1, m2 = fr.material_frames(dr, tr, np.zeros(k))
                kb_rest.append(_hinge_curvatures(tr[:-1], tr[1:], m1[:-1], m2[:-1], m1[1:], m2[1:]))
            infos.append(RodInfo(r.name, nodes, eds, r.section))
            n0 += k + 1
            e0 += k
        N, E = n0, e0
        x = np.concatenate(X)
        edges = np.concatenate(edges).astype(np.int32)
        d1 = np.concatenate(d1)
        t = fr.tangents(x, edges)
        cat = lambda a, shape: np.concatenate(a) if a else np.zeros(shape)  # noqa: E731
        hinge_nodes = cat(hn, (0, 3)).astype(np.int32)
        hinge_edges = cat(he, (0, 2)).astype(np.int32)
        nb = len(self.bodies)
        body_pos = np.array([b[1] for b in self.bodies]).reshape(nb, 3)
        body_rot = np.array([b[2] for b in self.bodies]).reshape(nb, 3, 3)
        node_body = np.full(N, -1, dtype=np.int32)
        node_offset = np.zeros((N, 3))
        edge_body = np.full(E, -1, dtype=np.int32)
        edge_m1 = np.zeros((E, 3))
        m1_all, _ = fr.material_frames(d1, t, np.zeros(E))

        def attach_node(n, b):
            if node_body[n] >= 0 and node_body[n] != b:
                raise InputError(f"node {n} is attached to two bodies")
            node_body[n] = b
            node_offset[n] = body_rot[b].T @ (x[n] - body_pos[b])

        def rod_info(rod):
            if rod not in rod_idx:
                raise InputError(f"a clamp, pin or fix names unknown rod {rod!r}")
            return infos[rod_idx[rod]]

        def local(items, i, rod, what):  # global index of local node/edge i (Python indexing) of a rod
            if not -len(items) <= i < len(items):
                raise InputError(f"rod {rod!r} has no {what} {i} (it has {len(items)})")
            return items[i]

        def lookup(rod, body):
            info = rod_info(rod)
            if body not in body_idx:
                raise InputError(f"attachment names unknown body {body!r}")
            return info, body_idx[body]

        for rod, end, body in self.clamps:
            info, b = lookup(rod, body)
            e = info.edges[0] if end == "start" else info.edges[-1]
            for n in edges[e]:
                attach_node(n, b)
            edge_body[e] = b
            edge_m1[e] = body_rot[b].T @ m1_all[e]
        for rod, end, body in self.pins:
            info, b = lookup(rod, body)
            attach_node(info.nodes[0] if end == "start" else info.nodes[-1], b)
        node_fixed = np.zeros((N, 3), dtype=bool)
        theta_fixed = np.zeros(E, dtype=bool)
        for rod, n, comps in self.fixed_nodes:
            node_fixed[local(rod_info(rod).nodes, n, rod, "node"), list(comps)] = True
        for rod, e in self.fixed_thetas:
            theta_fixed[local(rod_info(rod).edges, e, rod, "edge")] = True
        if np.any(node_fixed[node_body >= 0]) or np.any(theta_fixed[edge_body >= 0]):
            raise InputError("a node or edge is both fixed and attached to a body")
        lengths = [np.sum(np.linalg.norm(np.diff(r.rest_points, axis=0), axis=1)) for r in self.rods]
        Bmax = max((float(np.max(b)) for b in B), default=max(r.section.stiffness(r.material)["B1"] for r in self.rods))
        model = RodModel(
            n_nodes=N, edges=edges, rest_len=np.concatenate(rest_len), stretch_stiff=np.concatenate(EA),
            hinge_nodes=hinge_nodes, hinge_edges=hinge_edges, vor_len=cat(vor, (0,)), kappa_bar=cat(kb_rest, (0, 2)),
            bend_stiff=cat(B, (0, 2)), twist_stiff=cat(GJ, (0,)), twist_bar=np.zeros(len(hinge_nodes)),
            rods=tuple(infos), body_names=tuple(b[0] for b in self.bodies),
            body_driven=np.array([b[3] for b in self.bodies], dtype=bool),
            node_body=node_body, node_offset=node_offset, edge_body=edge_body, edge_m1_local=edge_m1,
            node_fixed=node_fixed, theta_fixed=theta_fixed,
            length_scale=float(np.mean(np.concatenate(rest_len))), force_scale=Bmax / max(lengths) ** 2,
        )
        # the initial reference twist of the initial frames (zero when points == rest_points)
        ref0 = fr.reference_twist(d1, t, hinge_edges, np.zeros(len(hinge_nodes))) if len(hinge_nodes) else np.zeros(0)
        state = RodState(x=x, theta=np.zeros(E), d1=d1, t=t, ref_twist=ref0, body_pos=body_pos, body_rot=body_rot)
        return model, state


def _end(end: str) -> str:
    if end not in ("start", "end"):
        raise InputError(f"rod end must be 'start' or 'end' (got {end!r})")
    return end
