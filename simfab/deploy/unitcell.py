"""Unit-cell deployment: four spokes around a gap, side beams, torsional-spring corners, an insert.

The cell (:func:`build_cell`, flat, centred at the origin; u_k = +x, +y, -x, -y): spoke k from
``gap u_k`` to ``size/2 u_k``; side k through ``size/2 u_k`` in two halves joined with the spoke at
a rigid T-junction; corner k a cubic Bezier torsional spring; the insert a free rigid body whose
half-size r (its MuJoCo box geom) is where the spokes' inner ends are clamped; a statically
determinate 3-2-1 support on three corner-spring midpoints.

Deployment (:func:`deploy`, quasi-static): the spokes' clamp points are drawn from ``gap`` to r in
``increments`` steps. A small out-of-plane load f = perturbation B1 / spoke_length^2 selects the
branch (4 f up on an insert larger than the gap: a dome; f alternating on the T-junctions for a
smaller one: a saddle) and is removed for the final solve (an unloaded equilibrium, its stability
reported).

Shape (:func:`gaussian_curvature`): the insert rise and the ring's cos/sin 2 phi saddle amplitude in
the ring's best-fit plane; the discrete Gaussian curvature, the angle deficit of the fan from the
insert centre to the eight ring points over a third of its area [1/m^2] (> 0: dome). In full:
docs/methods.md, "simfab.deploy.unitcell".
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from simfab._bundled import scenes_dir
from simfab.deploy._config import require_positive
from simfab.errors import ConvergenceError, InputError
from simfab.io.mjcf import geom_mesh, load_mjcf, numeric_config
from simfab.io.tables import load_table
from simfab.progress import progress
from simfab.rods.model import NetworkBuilder, RodMaterial, Section, synchronize
from simfab.rods.statics import StaticSolver

U = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0]])


#: Allowed range of the unit cell's counts: rod segments per beam piece (16 pieces per cell) and
#: quasi-static increments; beyond the upper bounds a run takes minutes without changing the result.
COUNT_RANGES = {"segments": (2, 200), "increments": (1, 1000)}


@dataclass(frozen=True, kw_only=True)
class CellConfig:
    """Unit-cell parameters (``<numeric name="cell_<field>">`` in the scene).

    Args:
        size: side of the cell [m].
        gap: half-size of the central gap [m].
        corner_gap: where the sides stop before a corner [m].
        spring_bulge: Bezier handle length of the corner springs [m].
        beam_width: in-plane beam width [m].
        beam_thickness: sheet thickness [m].
        young: Young's modulus [Pa].
        poisson: Poisson ratio [-].
        segments: rod segments per beam piece (a whole number, :data:`COUNT_RANGES`).
        increments: quasi-static steps (a whole number, :data:`COUNT_RANGES`).
        perturbation: out-of-plane load factor [-] (see the module doc).
    """

    size: float = 0.08
    gap: float = 0.015
    corner_gap: float = 0.008
    spring_bulge: float = 0.012
    beam_width: float = 0.004
    beam_thickness: float = 0.001
    young: float = 2.5e9
    poisson: float = 0.35
    segments: int = 10
    increments: int = 8
    perturbation: float = 0.05

    def __post_init__(self):
        for name, (lo, hi) in COUNT_RANGES.items():  # counts first: whole numbers in their range
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise InputError(f"must be a whole number in [{lo}, {hi}], got {v!r}", where=f"cell_{name}")
        require_positive(self, "cell_")
        if not self.gap < self.size / 2 - 2 * self.beam_width:
            raise InputError(f"{self.gap} leaves no room for the spokes in a cell of size {self.size} (need gap < "
                             f"size/2 - 2 beam_width = {self.size / 2 - 2 * self.beam_width:.4g} m)", where="cell_gap")
        if not self.corner_gap < self.size / 2:
            raise InputError(f"{self.corner_gap} must be smaller than half the cell size ({self.size / 2:.4g} m)",
                             where="cell_corner_gap")


@dataclass(frozen=True)
class Insert:
    """A rigid insert from the MJCF scene.

    Args:
        name: the body's name.
        r: half-size [m] (its box geom along x): where the spokes are clamped.
        mesh: its mesh in its own frame (trimesh).
        pos: (3,) [m] parking position.
        quat: (4,) parking orientation (w, x, y, z).
        mass: [kg].
    """

    name: str
    r: float
    mesh: object
    pos: np.ndarray
    quat: np.ndarray
    mass: float


def load_cell_scene(path) -> tuple[CellConfig, dict]:
    """Read a unit-cell scene.

    The ``<numeric name="cell_...">`` parameters load through :func:`simfab.io.tables.load_table`
    (an unknown name, a bad count or value: InputError naming the file and the parameter).

    Args:
        path: the MJCF scene.

    Returns:
        (:class:`CellConfig`, {name: :class:`Insert`} of every body whose name starts with ``insert``).
    """
    import mujoco  # (simfab.io, imported above, set up headless GL before MuJoCo loads)

    sc = load_mjcf(path)
    cfg = load_table(CellConfig, numeric_config(sc, "cell_", CellConfig), table_name="custom", file=str(path))
    m = sc.model
    inserts = {}
    for b in range(1, m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if not name.startswith("insert"):
            continue
        geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == b]
        boxes = [g for g in geoms if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX]
        if not boxes:
            raise InputError(f"insert body {name!r} needs a box geom (its x half-size is the attachment radius)",
                             where=str(path))
        g = boxes[0]
        mesh = geom_mesh(m, g)
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, m.geom_quat[g])
        T = np.eye(4)
        T[:3, :3] = R.reshape(3, 3)
        T[:3, 3] = m.geom_pos[g]
        mesh.apply_transform(T)
        inserts[name] = Insert(name=name, r=float(m.geom_size[g][0]), mesh=mesh, pos=np.array(m.body_pos[b]),
                               quat=np.array(m.body_quat[b]), mass=float(m.body_mass[b]))
    if not inserts:
        raise InputError("the scene has no insert body (name starting with 'insert')", where=str(path))
    return cfg, inserts


def default_scene_path() -> str:
    """The bundled unit-cell scene.

    Returns:
        The path of ``scenes/deploy/unit_cell.xml``.
    """
    return str(scenes_dir("deploy", "unit_cell.xml"))


def _bezier(P0, P1, P2, P3, n):
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    return (1 - t) ** 3 * P0 + 3 * (1 - t) ** 2 * t * P1 + 3 * (1 - t) * t**2 * P2 + t**3 * P3


@dataclass
class Cell:
    """The unit cell's rod network (:func:`build_cell`).

    Args:
        model: the :class:`simfab.rods.model.RodModel`.
        state: its flat state.
        spokes: the spoke rods' names.
        t_bodies: the T-junction body indices.
        spring_mid_nodes: the middle node of each corner spring.
        insert_body: the insert's body index.
        spoke_len: a spoke's length [m].
    """
    model: object
    state: object
    spokes: list  # rod names
    t_bodies: list  # T-junction body indices
    spring_mid_nodes: list  # middle node of each corner spring
    insert_body: int
    spoke_len: float


def build_cell(cfg: CellConfig, insert_name: str = "insert") -> Cell:
    """The flat unit cell (see the module doc): spokes, sides, corner springs, the insert body, the support.

    Args:
        cfg: the :class:`CellConfig`.
        insert_name: the insert body's name.

    Returns:
        The :class:`Cell`.
    """
    a2 = cfg.size / 2
    c = cfg.corner_gap
    n = int(cfg.segments)
    sec = Section(width=cfg.beam_width, thickness=cfg.beam_thickness)
    mat = RodMaterial(young=cfg.young, poisson=cfg.poisson)
    nb = NetworkBuilder()
    nb.add_body(insert_name, pos=(0, 0, 0))  # a free 6-DOF rigid body
    line = lambda p, q: p + np.linspace(0, 1, n + 1)[:, None] * (q - p)  # noqa: E731
    spokes = []
    for k in range(4):
        u, v = U[k], U[(k + 1) % 4]
        nb.add_body(f"T{k}", pos=a2 * u)
        nb.add_body(f"J{k}a", pos=a2 * u + (a2 - c) * v)
        nb.add_body(f"J{k}b", pos=(a2 - c) * u + a2 * v)
    for k in range(4):
        u, v = U[k], U[(k + 1) % 4]
        name = f"spoke{k}"
        nb.add_rod(name, line(cfg.gap * u, a2 * u), section=sec, material=mat)
        nb.clamp(name, "start", insert_name)
        nb.clamp(name, "end", f"T{k}")
        spokes.append(name)
        # side k: from junction J{k-1}b (start of this side) through T{k} to J{k}a
        p_start = a2 * u - (a2 - c) * v
        nb.add_rod(f"side{k}a", line(p_start, a2 * u), section=sec, material=mat)
        nb.add_rod(f"side{k}b", line(a2 * u, a2 * u + (a2 - c) * v), section=sec, material=mat)
        nb.clamp(f"side{k}a", "start", f"J{(k - 1) % 4}b")
        nb.clamp(f"side{k}a", "end", f"T{k}")
        nb.clamp(f"side{k}b", "start", f"T{k}")
        nb.clamp(f"side{k}b", "end", f"J{k}a")
        P0 = a2 * u + (a2 - c) * v
        P3 = (a2 - c) * u + a2 * v
        b = cfg.spring_bulge
        pts = _bezier(P0, P0 + b * v, P3 + b * u, P3, n)
        nb.add_rod(f"spring{k}", pts, section=sec, material=mat)
        nb.clamp(f"spring{k}", "start", f"J{k}a")
        nb.clamp(f"spring{k}", "end", f"J{k}b")
    # 3-2-1 support on three corner-spring midpoints: removes the six rigid motions of the
    # free-floating cell without constraining its deformation (statically determinate)
    m = n // 2
    nb.fix("spring0", nodes=[m], comps=(0, 1, 2))
    nb.fix("spring1", nodes=[m], comps=(2,))
    nb.fix("spring2", nodes=[m], comps=(1, 2))
    model, state = nb.build()
    t_bodies = [model.body_index(f"T{k}") for k in range(4)]
    mids = [int(model.rod(f"spring{k}").nodes[n // 2]) for k in range(4)]
    return Cell(model, state, spokes, t_bodies, mids, model.body_index(insert_name), a2 - cfg.gap)


def gaussian_curvature(cell: Cell, state) -> dict:
    """Shape of a deployed cell at its insert (see the module doc).

    Args:
        cell: the :class:`Cell`.
        state: its state.

    Returns:
        {angle_deficit [rad], gaussian_curvature [1/m^2], kind ("dome" or "saddle"), insert_rise [m],
        saddle_amplitude [m]}.
    """
    C = state.body_pos[cell.insert_body]
    ring = []
    for k in range(4):
        ring.append(state.body_pos[cell.t_bodies[k]])
        ring.append(state.x[cell.spring_mid_nodes[k]])
    ring = np.array(ring)
    d = ring - C
    nxt = np.roll(d, -1, axis=0)
    cosang = np.einsum("ij,ij->i", d, nxt) / (np.linalg.norm(d, axis=1) * np.linalg.norm(nxt, axis=1))
    angles = np.arccos(np.clip(cosang, -1.0, 1.0))
    area = 0.5 * np.sum(np.linalg.norm(np.cross(d, nxt), axis=1))
    deficit = 2.0 * np.pi - float(np.sum(angles))
    # out-of-plane shape in the ring's best-fit plane (invariant to rigid motion of the cell):
    # heights h ~ -rise + A cos 2phi + B sin 2phi about the insert centre
    ctr = ring.mean(axis=0)
    normal = np.linalg.svd(ring - ctr)[2][2]
    if normal[2] < 0:
        normal = -normal
    e1 = np.cross([0.0, 1.0, 0.0], normal)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    h = d @ normal
    phi = np.arctan2(d @ e2, d @ e1)
    M = np.stack([np.ones_like(phi), np.cos(2 * phi), np.sin(2 * phi)], axis=1)
    coef = np.linalg.lstsq(M, h, rcond=None)[0]
    return dict(angle_deficit=deficit, gaussian_curvature=float(deficit / (area / 3.0)),
                kind="dome" if deficit > 0 else "saddle",
                insert_rise=float(-coef[0]), saddle_amplitude=float(np.hypot(coef[1], coef[2])))


@dataclass
class CellDeployment:
    """One deployment of the cell by an insert (:func:`deploy`).

    Args:
        cell: the :class:`Cell`.
        insert: the :class:`Insert`.
        states: the state per increment (index 0: flat).
        curvature: :func:`gaussian_curvature` of the final state.
        stable: the final (unloaded) equilibrium is stable.
        iterations: Newton iterations per increment.
        energy: elastic energy of the final state [J].
        materials: rod name -> (young [Pa], poisson [-]) for the exports.
        curvature_history: discrete Gaussian curvature per increment [1/m^2] (0: flat).
    """

    cell: Cell
    insert: Insert
    states: list
    curvature: dict
    stable: bool
    iterations: list
    energy: float
    materials: dict  # rod name -> (young [Pa], poisson [-]) for exports
    curvature_history: list  # discrete Gaussian curvature [1/m^2] per increment (0 = flat)


def deploy_cell(cfg: CellConfig, insert: Insert, *, device: str = "cpu", quiet: bool = True) -> CellDeployment:
    """Draw the spokes onto an insert in ``cfg.increments`` steps (see the module doc).

    Args:
        cfg: the :class:`CellConfig`.
        insert: the :class:`Insert`.
        device: Warp device.
        quiet: no progress bar.

    Returns:
        The :class:`CellDeployment`; ConvergenceError when an increment's solve does not converge.
    """

    cell = build_cell(cfg, insert.name)
    model = cell.model
    solver = StaticSolver(model, device=device)
    offset0 = model.node_offset.copy()
    grow = insert.r - cfg.gap
    direction = np.zeros_like(offset0)
    spoke_nodes = []
    for k, name in enumerate(cell.spokes):
        rod = model.rod(name)
        att = rod.nodes[:2]
        direction[att] = U[k]
        spoke_nodes.append((rod.nodes, U[k]))
    B1 = float(np.min(model.bend_stiff[:, 0]))
    f = cfg.perturbation * B1 / cell.spoke_len**2
    body_forces = np.zeros((model.n_bodies, 3))
    if grow > 0:  # dome mode: lift the insert
        body_forces[cell.insert_body, 2] = 4.0 * f
    else:  # saddle mode: alternate the T-junctions
        for k, b in enumerate(cell.t_bodies):
            body_forces[b, 2] = f * (1.0 if k % 2 == 0 else -1.0)
    state = cell.state
    states, iters = [state], []
    ninc = int(cfg.increments)
    for i in progress(range(1, ninc + 1), total=ninc, desc=f"deploy {insert.name}", quiet=quiet):
        lam = i / ninc
        solver.set_attachment_offsets(offset0 + lam * grow * direction)
        # predictor: slide each spoke's nodes towards the new clamp point (linearly along the spoke)
        x = state.x.copy()
        step = grow / ninc
        for nodes, u in spoke_nodes:
            w = np.linspace(1.0, 0.0, len(nodes))[:, None]
            x[nodes] += w * step * u
        st = synchronize(solver.model, state, x, state.theta, state.body_pos, state.body_rot)
        try:
            res = solver.solve(st, body_forces=body_forces)
            if i == ninc:  # remove the perturbation
                unloaded = solver.solve(res.state)
                res = replace(unloaded, iterations=res.iterations + unloaded.iterations)
        except ConvergenceError as e:
            raise ConvergenceError(f"deploying {insert.name}: increment {i}/{ninc}: {e}") from None
        state = res.state
        states.append(state)
        iters.append(res.iterations)
    curvatures = [gaussian_curvature(cell, st) for st in states]
    curv = curvatures[-1]
    history = [c["gaussian_curvature"] for c in curvatures]
    mats = {r.name: (cfg.young, cfg.poisson) for r in model.rods}
    return CellDeployment(cell=cell, insert=insert, states=states, curvature=curv, stable=solver.is_stable(state),
                      iterations=iters, energy=res.energy, materials=mats, curvature_history=history)
