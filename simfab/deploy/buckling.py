"""Elastica buckling validation of the rod solver (``simfab validate buckling``).

A straight beam of length L (rectangular section, sheet normal +z) lies on the x axis from the
anchor (origin) to its moving end at x = L. The moving end is pushed towards the anchor in
quasi-static increments of the gap g; every increment is solved to equilibrium from the
last. The beam buckles out of the sheet (weak axis, B1 = E w t^3 / 12) and is compared with
the exact elastica (:mod:`simfab.deploy.elastica`).

Supports: *pinned* = end node held, edge free to turn about the pin axis (y), twist held;
*clamped* = end edge held (both nodes and its material frame).
Paths: *direct* = end nodes displaced directly; *insert* = the moving end is attached (pinned
or clamped) to the rigid insert body of the MJCF scene, whose pose is driven.

Buckling perturbation: the initial configuration carries a small first-mode imperfection
(amplitude ``imperfection * L``; half sine for pinned, 1 - cos for clamped). The rest shape
is exactly straight, so the equilibria found are those of the perfect beam; the imperfection
only selects the upward branch instead of the unstable straight one.
Planarity: all y coordinates are held (the problem is planar; this removes the zero-energy
rotation of a pinned beam about its chord).
Inextensible limit: EA is set to ``axial_ratio * B1 / L^2`` (1e8 by default); each increment
is first relaxed with EA / 100 (stiffness homotopy) and then solved with the real EA.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from simfab._bundled import scenes_dir
from simfab.deploy import elastica
from simfab.deploy import tolerances as tol
from simfab.deploy._config import require_positive
from simfab.errors import ConvergenceError, InputError
from simfab.io.mjcf import load_mjcf, numeric_config
from simfab.io.tables import load_table
from simfab.rods.model import NetworkBuilder, RodMaterial, Section, synchronize
from simfab.rods.statics import StaticsConfig, StaticSolver

DEFAULT_RATIOS = (0.99, 0.95, 0.90, 0.80, 0.60)
DEFAULT_N = (20, 40, 80, 160)
PATHS = ("direct", "insert")


@dataclass(frozen=True, kw_only=True)
class BeamConfig:
    """Beam of the buckling validation (``<numeric name="beam_<field>">`` of ``scenes/deploy/elastica.xml``).

    Args:
        length: [m].
        width: [m].
        thickness: [m].
        young: Young's modulus [Pa].
        poisson: Poisson ratio [-].
        axial_ratio: EA L^2 / B1 [-] (nearly inextensible).
        imperfection: initial first-mode amplitude / L [-].
        max_increment: largest change of g/L per quasi-static increment [-].
    """

    length: float = 0.1
    width: float = 5e-3
    thickness: float = 5e-4
    young: float = 2.0e9
    poisson: float = 0.35
    axial_ratio: float = 1e8
    imperfection: float = 1e-3
    max_increment: float = 0.1

    def __post_init__(self):
        require_positive(self, "beam_")

    @property
    def B(self) -> float:
        """Weak-axis bending stiffness B1 = E w t^3 / 12 [N m^2]."""
        return self.young * self.width * self.thickness**3 / 12.0


@dataclass(frozen=True)
class InsertScene:
    """What the insert path takes from the MJCF scene (:func:`load_insert_scene`).

    Args:
        path: the scene file.
        insert_pos: (3,) [m] the insert body's start position (the beam's moving end).
        setup: the :class:`BeamConfig`.
        mesh: the insert's mesh (for outputs).
    """

    path: str
    insert_pos: np.ndarray
    setup: BeamConfig
    mesh: object


def load_insert_scene(path) -> InsertScene:
    """Read the elastica scene: body ``insert`` (start pose: the beam's moving end), site ``anchor``
    (the fixed end, origin), the beam's parameters as ``<numeric name="beam_<field>">`` (through
    :func:`simfab.io.tables.load_table`).

    Args:
        path: the MJCF scene.

    Returns:
        The :class:`InsertScene`; InputError naming the file and what is missing or wrong.
    """

    sc = load_mjcf(path)
    setup = load_table(BeamConfig, numeric_config(sc, "beam_", BeamConfig), table_name="custom", file=str(path))
    if "anchor" not in sc.sites:
        raise InputError("the scene needs a site named 'anchor' at the fixed beam end", where=str(path))
    meshes = sc.body_meshes(include_world=False)
    if "insert" not in meshes:
        raise InputError("the scene needs a body named 'insert' with geometry", where=str(path))
    import mujoco  # after simfab.io (headless GL set-up)

    d = mujoco.MjData(sc.model)
    mujoco.mj_forward(sc.model, d)
    bid = mujoco.mj_name2id(sc.model, mujoco.mjtObj.mjOBJ_BODY, "insert")
    pos = np.array(d.xpos[bid]) - sc.sites["anchor"]
    if abs(np.linalg.norm(pos) - setup.length) > 1e-9 * setup.length or abs(pos[1]) + abs(pos[2]) > 1e-9:
        raise InputError(f"body 'insert' must sit at beam_length = {setup.length} m along +x from 'anchor' "
                         f"(found offset {pos.tolist()})", where=str(path))
    return InsertScene(path=str(path), insert_pos=pos, setup=setup, mesh=meshes["insert"])


def elastica_scene_path() -> str:
    """The bundled elastica scene.

    Returns:
        The path of ``scenes/deploy/elastica.xml``.
    """
    return str(scenes_dir("deploy", "elastica.xml"))


# ----------------------------------------------------------------------------- the beam
@dataclass
class Beam:
    """A beam of the buckling validation (:func:`build_beam`).

    Args:
        model: the :class:`simfab.rods.model.RodModel`.
        state: its start state (with the imperfection).
        support: "pinned" or "clamped".
        path: "direct" (the end moved) or "insert" (drawn by an insert body).
        n: segments.
        moving_nodes: the nodes at the moving end.
        span: the flat span L [m].
    """
    model: object
    state: object
    support: str
    path: str
    n: int
    moving_nodes: np.ndarray  # nodes whose x-reaction is the axial force
    span: float  # support-to-support length L [m]

    def rise(self, state) -> float:
        """Midspan rise. Pinned: the midspan node. Clamped (nodes straddle midspan at +-h/2, +-3h/2): the
        symmetric quadratic through them, (9 z_1 - z_3) / 8.

        Args:
            state: a state of the beam.

        Returns:
            The rise [m].
        """
        z = state.x[:, 2]
        if self.support == "pinned":
            return float(z[self.n // 2])
        m = self.n // 2
        z1 = 0.5 * (z[m] + z[m + 1])
        z3 = 0.5 * (z[m - 1] + z[m + 2])
        return float((9.0 * z1 - z3) / 8.0)


def check_segments(n) -> int:
    """A segment count checked.

    Args:
        n: the count.

    Returns:
        ``n`` as an int; InputError unless it is an even count >= 4 (the midspan is a node).
    """
    if int(n) != n or int(n) < 4 or int(n) % 2:
        raise InputError(f"segment count must be an even integer >= 4 (got {n})", where="--n")
    return int(n)


def build_beam(setup: BeamConfig, n: int, support: str, path: str = "direct", *, free_end: bool = False) -> Beam:
    """The beam with ``n`` segments, its start state carrying the first-mode imperfection.

    Args:
        setup: the :class:`BeamConfig`.
        n: segments (:func:`check_segments`).
        support: "pinned" or "clamped".
        path: "direct" or "insert".
        free_end: the moving end's x is an unknown, loaded by a force (the critical load).

    Returns:
        The :class:`Beam`.
    """

    if support not in elastica.SUPPORTS:
        raise InputError(f"support must be one of {elastica.SUPPORTS} (got {support!r})", where="--support")
    if path not in PATHS:
        raise InputError(f"path must be one of {PATHS} (got {path!r})")
    n = check_segments(n)
    L = setup.length
    h = L / n
    a = setup.imperfection * L
    if support == "pinned":
        s = np.linspace(0.0, L, n + 1)
        z = a * np.sin(np.pi * s / L)
        ends = [0, n]
    else:
        # clamp = end edge held rigid and centred on the support point (half-edge ghost clamp):
        # the support is the midpoint of the clamped edge, which keeps second-order accuracy.
        s = -0.5 * h + h * np.arange(n + 2)
        z = 0.5 * a * (1.0 - np.cos(2.0 * np.pi * s / L))
        ends = [0, 1, n, n + 1]
        z[ends] = 0.0
    if free_end:
        z[:] = 0.0
    last = len(s) - 1
    pts = np.stack([s, np.zeros_like(s), z], axis=1)
    rest = np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1)
    nb = NetworkBuilder()
    nb.add_rod("beam", pts, rest_points=rest, section=Section(width=setup.width, thickness=setup.thickness),
               material=RodMaterial(young=setup.young, poisson=setup.poisson), director=(0.0, 0.0, 1.0),
               stretch_stiffness=setup.axial_ratio * setup.B / L**2)
    start, moving = ends[: len(ends) // 2], ends[len(ends) // 2:]
    attached = moving if path == "insert" else []  # these follow the insert, which stays in the plane
    nb.fix("beam", nodes=[i for i in range(last + 1) if i not in attached], comps=(1,))  # planar problem
    nb.fix("beam", nodes=start, comps=(0, 1, 2))
    nb.fix("beam", thetas=[0])
    if path == "insert":
        nb.add_body("insert", pos=(L, 0.0, 0.0), driven=True)
        if support == "pinned":
            nb.pin("beam", "end", "insert")
            nb.fix("beam", thetas=[last - 1])
        else:
            nb.clamp("beam", "end", "insert")
    else:
        comps = (1, 2) if free_end else (0, 1, 2)
        nb.fix("beam", nodes=moving, comps=comps)
        nb.fix("beam", thetas=[last - 1])
    model, state = nb.build()
    return Beam(model, state, support, path, n, np.asarray(moving), L)


def _prescribe_gap(beam: Beam, state, g_old: float, g: float):
    """State for the next increment: prescribed end at gap ``g`` plus a length-preserving predictor.

    Predictor (continuation, not part of the equilibrium): the previous shape is scaled by
    g/g_old along x and its rise is rescaled so the centreline keeps its length. Without it
    the first Newton iterate would be a beam compressed by EA * (shortening) >> the Euler
    load, far from the buckled branch.
    """
    from scipy.optimize import brentq

    L = beam.span
    x0 = beam.state.x
    x = state.x.copy()
    x[:, 0] *= g / g_old
    length = float(np.sum(np.linalg.norm(np.diff(state.x, axis=0), axis=1)))

    def excess(c):
        y = x.copy()
        y[:, 2] *= c
        return float(np.sum(np.linalg.norm(np.diff(y, axis=0), axis=1))) - length

    if excess(1.0) < 0.0:
        hi = 2.0
        while excess(hi) < 0.0 and hi < 1e6:
            hi *= 2.0
        if excess(hi) >= 0.0:
            x[:, 2] *= brentq(excess, 1.0, hi, xtol=1e-12)
    # redistribute the nodes to equal arc length so no edge starts stretched
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
    target = np.linspace(0.0, arc[-1], len(x))
    x = np.stack([np.interp(target, arc, x[:, c]) for c in range(3)], axis=1)
    shift = L - g
    fixed = beam.model.node_fixed[:, 0]
    x[fixed, 0] = x0[fixed, 0]
    x[fixed, 2] = x0[fixed, 2]
    if beam.path == "insert":
        pos = state.body_pos.copy()
        pos[0, 0] = L - shift
        return _sync(beam, state, x, pos)
    x[beam.moving_nodes, 0] = x0[beam.moving_nodes, 0] - shift
    x[beam.moving_nodes, 2] = 0.0
    return _sync(beam, state, x, state.body_pos)


def _sync(beam: Beam, prev, x, body_pos):

    return synchronize(beam.model, prev, x, prev.theta, body_pos, prev.body_rot)


def run_continuation(setup: BeamConfig, support: str, n: int, ratios, *, path: str = "direct", device: str = "cpu",
                     keep_states: bool = False) -> list[dict]:
    """Push the beam through the gap ratios (sorted descending) and measure each equilibrium.

    Args:
        setup: the :class:`BeamConfig`.
        support: "pinned" or "clamped".
        n: segments.
        ratios: the gap ratios g/L [-].
        path: "direct" or "insert".
        device: Warp device.
        keep_states: add each equilibrium's shape.

    Returns:
        One dict per ratio: support, path, g_over_L, n, delta_over_L (simulated and exact, rel_err),
        force [N] (simulated and exact, force_rel_err), seconds (wall time of the increments since
        the flat start), newton_iterations and increments since the flat start, and shape (x, z) [m]
        with ``keep_states``.
    """

    beam = build_beam(setup, n, support, path)
    # nearly inextensible beam: relax each increment with EA / 100 first (see StaticsConfig)
    solver = StaticSolver(beam.model, device=device, options=StaticsConfig(stretch_homotopy=1e-2))
    L = setup.length
    targets = sorted({float(r) for r in ratios}, reverse=True)
    state = beam.state
    rows = []
    r = 1.0
    t0 = time.perf_counter()
    iters = increments = 0
    for target in targets:
        while r > target + 1e-12:
            r_old, r = r, max(target, r - setup.max_increment)
            state = _prescribe_gap(beam, state, r_old * L, r * L)
            try:
                res = solver.solve(state)
            except ConvergenceError as e:
                raise ConvergenceError(f"elastica {support} n={n} {path}: g/L={r:.4f}: {e}") from None
            state = res.state
            iters += res.iterations
            increments += 1
        seconds = time.perf_counter() - t0
        ex = elastica.solve_elastica(target, support)
        delta = beam.rise(state) / L
        g = solver.reactions(state)
        force = -float(np.sum(g[3 * beam.moving_nodes]))
        force_ex = ex.force_factor * setup.B / L**2
        row = dict(support=support, path=path, g_over_L=target, n=n, delta_over_L=delta,
                   delta_over_L_exact=ex.delta_over_L, rel_err=abs(delta - ex.delta_over_L) / ex.delta_over_L,
                   force=force, force_exact=force_ex, force_rel_err=abs(force - force_ex) / force_ex,
                   seconds=seconds, newton_iterations=iters, increments=increments)
        if keep_states:
            row["shape"] = state.x[:, [0, 2]].copy()
        rows.append(row)
    return rows


def critical_load(setup: BeamConfig, n: int, support: str = "pinned", *, device: str = "cpu") -> dict:
    """Smallest compressive end load at which the straight beam's Hessian stops being positive definite.

    The straight beam under end load P is uniformly compressed (EA eps = -P); its elastic Hessian (the
    load is linear, so it adds nothing) is factorized by Cholesky; bisection on P brackets the loss of
    definiteness to ``CRITICAL_LOAD_BISECTION_RTOL``. Compare with pi^2 B / L^2 (pinned) and
    4 pi^2 B / L^2 (clamped).

    Args:
        setup: the :class:`BeamConfig`.
        n: segments.
        support: "pinned" or "clamped".
        device: Warp device.

    Returns:
        {support, n, critical_load [N], euler_load [N], rel_err}.
    """

    beam = build_beam(setup, n, support, "direct", free_end=True)
    model = beam.model
    solver = StaticSolver(model, device=device)
    EA = float(model.stretch_stiff[0])
    s0 = beam.state.x[:, 0].copy()
    P_e = elastica.euler_load_factor(support) * setup.B / setup.length**2

    def stable(P):
        # the straight equilibrium under P: every edge shortened by the axial strain -P / EA
        x = beam.state.x.copy()
        x[:, 0] = s0 * (1.0 - P / EA)
        st = synchronize(model, beam.state, x, beam.state.theta, beam.state.body_pos, beam.state.body_rot)
        return solver.is_stable(st)

    lo, hi = 0.5 * P_e, 1.5 * P_e
    if not stable(lo) or stable(hi):
        raise ConvergenceError(f"critical load of the {support} beam (n={n}) is not within [0.5, 1.5] x Euler")
    while hi - lo > tol.CRITICAL_LOAD_BISECTION_RTOL * P_e:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    P = 0.5 * (lo + hi)
    return dict(support=support, n=n, critical_load=P, euler_load=P_e, rel_err=abs(P - P_e) / P_e)
