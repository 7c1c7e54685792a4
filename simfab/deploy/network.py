"""Deployment of a flat pattern as a network of discrete elastic rods with rigid inserts.

Network (:func:`build_network`, from a :class:`simfab.deploy.pattern.Pattern`, flat in z = 0):
free rigid bodies for the inserts (``I<id>``), the boundary junctions (``B<v>``) and the edge
midpoints (``J<e>``); two half-beam rods per edge (midpoint junction to the vertex's insert at the
gap g, or to the boundary junction); one rod per spring arc (rest shape: the flat, cut shape);
optional seam ties across the wedges of a cut pattern (:func:`simfab.deploy.cuts.seam_ties`); a
statically determinate 3-2-1 support on three spring arcs' middle nodes.

Deployment (:func:`deploy`, quasi-static as in :mod:`simfab.deploy.unitcell`): the beam ends'
attachment points move from the gap (g_i) to the insert's edge (r) in ``increments`` steps, each
solved to equilibrium from the last.

Branch selection: (1) each increment starts from the tangent continuation of the last equilibrium,
dq = -H^{-1} (dg/dlambda) / increments, the first also moved by 1/increments of the out-of-plane
part of the displacement to the target (a Newton start only); (2) while drawing in, each insert
carries a small out-of-plane load f_i = perturbation B1 / h^2 s_i (s_i: the target's normalised
height there, no resultant force or moment), removed for the final solve, so the reported state is
an unloaded equilibrium whose stability is reported. In full: docs/methods.md, "simfab.deploy.network".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simfab.deploy._config import require_positive
from simfab.deploy.compare import kabsch
from simfab.errors import ConvergenceError, InputError
from simfab.progress import progress
from simfab.rods.model import NetworkBuilder, RodMaterial, Section, synchronize
from simfab.rods.statics import StaticsConfig, StaticSolver

#: Newton step cap of the deployment's solves [longest rod] (StaticsConfig.max_step): the tangent
#: predictor starts each increment near its equilibrium, so the cap only binds in the first
#: increment's buckling (the measurements: docs/validation/deploy.md, "simfab.deploy.network").
MAX_STEP = 0.2
#: rod segments of a seam tie per ``beam_segments``: a tie spans up to 1.5 spacings (three half
#: beams), so it gets three half beams' segments and, like them, short clamped end edges
#: (``clamp_edge``): it bends and twists over its whole length
TIE_SEGMENTS_PER_BEAM_SEGMENT = 3


@dataclass(frozen=True, kw_only=True)
class DeployConfig:
    """Material and simulation parameters (scene ``[material]`` and ``[deploy]`` tables).

    Args:
        young: the sheet's Young's modulus [Pa] (``[material]``).
        poisson: its Poisson ratio [-] (``[material]``).
        density: its density [kg/m^3] (``[material]``).
        beam_segments: rod segments per half beam.
        spring_segments: rod segments per Bezier spring arc (a zigzag arc has its own, per piece:
            :data:`simfab.deploy.springs.ZIGZAG_SEGMENTS`).
        clamp_edge: length of a rod's two clamped end edges relative to its other edges [-] (a
            clamped edge is rigid within its body, so uniform edges would stiffen a 3-segment beam by
            leaving only its middle third free).
        increments: quasi-static steps.
        perturbation: branch-selection load factor [-] (see the module doc).
    """

    young: float = 2.5e9
    poisson: float = 0.35
    density: float = 1200.0
    beam_segments: int = 3
    spring_segments: int = 6
    clamp_edge: float = 0.2
    increments: int = 8
    perturbation: float = 0.05

    def __post_init__(self):
        require_positive(self, lambda f: f"material.{f}" if f in ("young", "poisson", "density") else f"deploy.{f}")
        if not -1.0 < self.poisson < 0.5:
            raise InputError(f"must be in (-1, 0.5) (got {self.poisson})", where="material.poisson")
        if not self.clamp_edge <= 1.0:
            raise InputError(f"must be in (0, 1] (got {self.clamp_edge})", where="deploy.clamp_edge")
        for f in ("beam_segments", "spring_segments", "increments"):
            if int(getattr(self, f)) != getattr(self, f) or getattr(self, f) < 1:
                raise InputError(f"must be a positive integer (got {getattr(self, f)})", where=f"deploy.{f}")


@dataclass
class Network:
    """The rod network of a pattern (:func:`build_network`).

    Args:
        model: the :class:`simfab.rods.model.RodModel`.
        state: its flat state.
        vertex_body: (n,) body index of each pattern vertex (insert or boundary junction).
        edge_body: (e,) the edge midpoint junctions' body indices.
        pull_nodes: (k,) the insert-clamped rod nodes.
        pull_dir: (k,3) their unit direction from the insert centre.
        pull_grow: (k,) [m] their grow distance r - g.
        pull_vertex: (k,) their pattern vertex.
        held_node: the fully supported node (the predictor's origin).
        tie_offset: (N,3) [m] the seam ties' clamp-offset change at full deployment (None: no ties).
    """

    model: object
    state: object
    vertex_body: np.ndarray
    edge_body: np.ndarray
    pull_nodes: np.ndarray
    pull_dir: np.ndarray
    pull_grow: np.ndarray
    pull_vertex: np.ndarray  # (k,) the pattern vertex (insert) of each insert-clamped node
    held_node: int  # the fully supported node (predictor origin)
    tie_offset: np.ndarray | None = None  # (N,3) [m] seam ties' clamp-offset change at full deployment


def rod_parameters(n: int, clamp_edge: float) -> np.ndarray:
    """Node parameters of a rod whose two end edges are ``clamp_edge`` times as long as the n - 2
    uniform inner ones (n = 1, 2: uniform).

    Args:
        n: segments.
        clamp_edge: the end edges' relative length [-].

    Returns:
        (n+1,) parameters in [0, 1].
    """
    if n <= 2:
        return np.linspace(0.0, 1.0, n + 1)
    d = clamp_edge / (n - 2 + 2 * clamp_edge)
    return np.concatenate([[0.0], np.linspace(d, 1.0 - d, n - 1), [1.0]])


def build_network(pat, cfg: DeployConfig, *, ties=None) -> Network:
    """The rod network of a pattern (see the module doc).

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        cfg: the :class:`DeployConfig`.
        ties: the :class:`simfab.deploy.cuts.SeamTies` (seam vertex pairs and their target distances)
            or None (seams free).

    Returns:
        The :class:`Network`.
    """

    pc = pat.config
    sec = Section(width=pc.beam_width, thickness=pc.beam_thickness)
    sec_spring = Section(width=pc.spring_width, thickness=pc.beam_thickness)
    mat = RodMaterial(young=cfg.young, poisson=cfg.poisson)
    nb = NetworkBuilder()
    P3 = np.column_stack([pat.P, np.zeros(len(pat.P))])
    mids = np.column_stack([pat.midpoints(), np.zeros(len(pat.edges))])
    vname = []
    for v in range(len(pat.P)):
        vname.append(nb.add_body(f"I{pat.insert_ids[v]}" if pat.interior[v] else f"B{v}", pos=P3[v]))
    for e in range(len(pat.edges)):
        nb.add_body(f"J{e}", pos=mids[e])
    nbeam, nspring = int(cfg.beam_segments), int(cfg.spring_segments)
    sb, ss = rod_parameters(nbeam, cfg.clamp_edge), rod_parameters(nspring, cfg.clamp_edge)
    lin = lambda p, q: p + sb[:, None] * (q - p)  # noqa: E731
    pulls = []  # (rod name, direction (3,), grow)
    for k, (e, v, start, end) in enumerate(pat.beam_halves()):
        name = f"beam{e}_{v}"
        s3, e3 = np.append(start, 0.0), np.append(end, 0.0)
        nb.add_rod(name, lin(s3, e3), section=sec, material=mat)
        nb.clamp(name, "start", f"J{e}")
        nb.clamp(name, "end", vname[v])
        if pat.interior[v]:
            d = s3 - P3[v]
            pulls.append((name, d / np.linalg.norm(d), pat.insert_size[v] - pat.gap[v], v))
    springs = []
    for i, (q, e0, e1, pts) in enumerate(pat.spring_rods(ss)):
        name = f"spring{q}_{i % 4}"
        nb.add_rod(name, np.column_stack([pts, np.zeros(len(pts))]), section=sec_spring, material=mat)
        nb.clamp(name, "start", f"J{e0}")
        nb.clamp(name, "end", f"J{e1}")
        springs.append((name, pts[(len(pts) - 1) // 2], (len(pts) - 1) // 2))  # (rod, middle node, its index)
    if len(springs) < 3:
        raise InputError("the pattern needs at least one quad with a spring (make pattern.spacing smaller)",
                         where="pattern.spacing")
    tie_rods = []
    st = rod_parameters(TIE_SEGMENTS_PER_BEAM_SEGMENT * nbeam, cfg.clamp_edge)
    for k, ((a, b), L) in enumerate(zip(np.zeros((0, 2), int) if ties is None else ties.pairs,
                                        () if ties is None else ties.length)):
        name = f"tie{k}"
        nb.add_rod(name, P3[a] + st[:, None] * (P3[b] - P3[a]), section=sec, material=mat)
        nb.clamp(name, "start", vname[a])
        nb.clamp(name, "end", vname[b])
        Lf = float(np.linalg.norm(P3[b] - P3[a]))
        tie_rods.append((name, (P3[a] - P3[b]) / Lf, 0.5 * max(Lf - float(L), 0.0)))
    mid = np.array([p for _, p, _ in springs])
    c = pat.P.mean(axis=0)
    span = np.ptp(pat.P, axis=0)
    picks = []
    for aim, comps in ((c, (0, 1, 2)), (c + [0.5 * span[0], 0.0], (1, 2)), (c + [0.0, 0.5 * span[1]], (2,))):
        order = np.argsort(np.linalg.norm(mid - aim, axis=1))
        k = next(int(j) for j in order if int(j) not in picks)
        picks.append(k)
        nb.fix(springs[k][0], nodes=[springs[k][2]], comps=comps)
    model, state = nb.build()
    nodes, dirs, grow, pv = [], [], [], []
    for name, d, g, v in pulls:
        r = model.rod(name)
        for n in r.nodes[-2:]:  # the clamped end edge's two nodes
            nodes.append(int(n))
            dirs.append(d)
            grow.append(g)
            pv.append(v)
    vb = np.array([model.body_index(n) for n in vname])
    eb = np.array([model.body_index(f"J{e}") for e in range(len(pat.edges))])
    held = int(model.rod(springs[picks[0]][0]).nodes[springs[picks[0]][2]])
    tie_offset = None
    if tie_rods:
        tie_offset = np.zeros((model.n_nodes, 3))
        for name, d, s in tie_rods:  # start end (at a) moves away from b, the end end away from a
            nd = model.rod(name).nodes
            tie_offset[nd[:2]] = d * s
            tie_offset[nd[-2:]] = -d * s
    return Network(model=model, state=state, vertex_body=vb, edge_body=eb, pull_nodes=np.array(nodes),
                   pull_dir=np.array(dirs), pull_grow=np.array(grow), pull_vertex=np.array(pv, dtype=np.int64),
                   held_node=held, tie_offset=tie_offset)


@dataclass
class Deployment:
    """A deployed network (:func:`deploy`).

    Args:
        network: the :class:`Network`.
        states: the state per increment (0: flat; the last: the unloaded final state).
        stable: the final state's reduced Hessian is positive definite.
        iterations: Newton iterations per increment.
        energy: elastic energy of the final state [J].
        seconds: wall time [s].
    """

    network: Network
    states: list
    stable: bool
    iterations: list
    energy: float
    seconds: float

    @property
    def final(self):
        """The final (unloaded) state."""
        return self.states[-1]

    def vertex_positions(self, state=None) -> np.ndarray:
        """Positions of the pattern vertices (insert centres / boundary junctions).

        Args:
            state: a state of the network (None: the final one).

        Returns:
            (n,3) [m].
        """
        st = self.final if state is None else state
        return st.body_pos[self.network.vertex_body]


def target_heights(pat, target_points: np.ndarray) -> np.ndarray:
    """Branch-selection signs: the target points' height above their best-fit plane, normalised (the
    plane normal +z-ish: positive towards the target's +z side).

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        target_points: (n,3) [m] the pattern vertices' target points.

    Returns:
        s (n,) in [-1, 1].
    """
    c = target_points.mean(axis=0)
    normal = np.linalg.svd(target_points - c)[2][2]
    if normal[2] < 0:
        normal = -normal
    h = (target_points - c) @ normal
    h -= np.mean(h[pat.interior]) if pat.interior.any() else 0.0
    m = float(np.max(np.abs(h))) or 1.0
    return h / m


def target_displacement(net: Network, flat_to_target) -> tuple[np.ndarray, np.ndarray]:
    """The predictor field D (see the module doc): each node and body from its flat position to the
    target point its flat position maps to (the target rigidly aligned to the flat pattern, D = 0 at
    the fully supported node).

    Args:
        net: the :class:`Network`.
        flat_to_target: function (k,2) flat points [m] -> (k,3) target points [m].

    Returns:
        (nodes (N,3) [m], bodies (B,3) [m]).
    """

    X0 = np.vstack([net.state.x, net.state.body_pos])
    T = flat_to_target(X0[:, :2])
    R, t = kabsch(T, X0)  # the target rigidly moved onto the flat pattern
    D = T @ R.T + t - X0
    D -= D[net.held_node]
    return D[: len(net.state.x)], D[len(net.state.x):]


def deploy(pat, net: Network, cfg: DeployConfig, heights: np.ndarray, *, device: str = "cpu", quiet: bool = True,
           callback=None, predictor=None) -> Deployment:
    """Draw the beam ends onto the inserts in ``cfg.increments`` steps (see the module doc).

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        net: its :class:`Network`.
        cfg: the :class:`DeployConfig`.
        heights: (n,) [-] branch-selection signs per pattern vertex (:func:`target_heights`).
        device: Warp device.
        quiet: no progress bar.
        callback: called as callback(increment, state) after each increment's equilibrium (None: none).
        predictor: (nodes (N,3), bodies (B,3)) [m] displacement towards the target
            (:func:`target_displacement`), or None.

    Returns:
        The :class:`Deployment`; ConvergenceError when an increment does not converge.
    """
    import time


    t0 = time.perf_counter()
    model = net.model
    solver = StaticSolver(model, device=device, options=StaticsConfig(max_step=MAX_STEP))
    offset0 = model.node_offset.copy()
    direction = np.zeros_like(offset0)
    direction[net.pull_nodes] = net.pull_dir * net.pull_grow[:, None]
    if net.tie_offset is not None:
        direction += net.tie_offset
    B1 = float(np.min(model.bend_stiff[:, 0]))
    f = cfg.perturbation * B1 / pat.config.spacing**2
    body_forces = np.zeros((model.n_bodies, 3))
    ins = np.flatnonzero(pat.interior)
    # self-equilibrated: remove the least-squares plane a + b x + c y from the signs so that the
    # loads have no resultant force or moment (they would tilt the network about the held body)
    M = np.column_stack([np.ones(len(ins)), pat.P[ins]])
    s_i = heights[ins] - M @ np.linalg.lstsq(M, heights[ins], rcond=None)[0]
    s_i /= float(np.max(np.abs(s_i))) or 1.0
    body_forces[net.vertex_body[ins], 2] = f * s_i
    state = net.state
    states, iters = [state], []
    n = int(cfg.increments)
    res = None
    for i in progress(range(1, n + 1), total=n, desc="deploy pattern", quiet=quiet):
        lam = i / n
        # tangent continuation from the last equilibrium (implicit function theorem; the flat state
        # is the unloaded equilibrium of increment 0)
        dq = solver.offset_sensitivity(state, direction / n, body_forces=body_forces if i > 1 else None)
        solver.set_attachment_offsets(offset0 + lam * direction)
        st = solver.red.apply(state, dq)
        if i == 1 and predictor is not None:  # the out-of-plane branch towards the target
            free = ~model.node_fixed.any(axis=1)
            x = st.x + (free[:, None] * predictor[0] * [0, 0, 1]) / n
            pos = st.body_pos + (~model.body_driven[:, None] * predictor[1] * [0, 0, 1]) / n
            st = synchronize(solver.model, st, x, st.theta, pos, st.body_rot)
        try:
            res = solver.solve(st, body_forces=body_forces)
            its = res.iterations
            if i == n:  # remove the branch-selection load
                res = solver.solve(res.state)
                its += res.iterations
        except ConvergenceError as e:
            raise ConvergenceError(f"deploying the pattern: increment {i}/{n}: {e}") from None
        state = res.state
        states.append(state)
        iters.append(its)
        if callback is not None:
            callback(i, state)
    stable = solver.is_stable(state)
    return Deployment(network=net, states=states, stable=bool(stable), iterations=iters, energy=float(res.energy),
                      seconds=time.perf_counter() - t0)


def discrete_gaussian_curvature(P: np.ndarray, quads: np.ndarray, interior: np.ndarray) -> np.ndarray:
    """Angle defect 2 pi - the sum of the quad corner angles at each interior vertex of a quad mesh
    (positive: dome, negative: saddle).

    Args:
        P: (n,3) [m] vertex positions.
        quads: (q,4) the quads.
        interior: (n,) bool, the interior vertices.

    Returns:
        (n,) [rad] (NaN on the boundary).
    """
    n = len(P)
    s = np.zeros(n)
    for k in range(4):
        v = quads[:, k]
        a = P[quads[:, (k + 1) % 4]] - P[v]
        b = P[quads[:, (k + 3) % 4]] - P[v]
        cosang = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        np.add.at(s, v, np.arccos(np.clip(cosang, -1.0, 1.0)))
    out = np.full(n, np.nan)
    out[interior] = 2 * np.pi - s[interior]
    return out
