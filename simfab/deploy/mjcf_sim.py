"""A MuJoCo scene of a rod network with rigid bodies that MuJoCo can simulate (not a picture).

Model (built from a :class:`simfab.rods.model.RodModel`, its flat state and a deployed state):

- every simfab body (insert, junction) is a free MuJoCo body (pose: see below) - three slide
  joints along the world axes and a ball joint, so that translations and rotations get their own
  damping (``SimConfig.body_damping``); a *driven* (held) body is attached to the world instead;
- every rod is a chain of rigid links, one per rod edge (box geom: edge length x thickness x
  width, no contacts). Link frame: origin at the edge's first node, axes (t, m1, m2) = (tangent,
  sheet normal, in-plane width direction). The first link is rigidly part of the body the rod
  starts clamped to (a geom of that body, not a body of its own: MuJoCo's compile time grows
  with the square of the body count); each further link hangs from the previous one by three
  hinges at the node:
  twist about t (stiffness GJ / l), in-plane bending about m1 (B2 / l) and out-of-plane bending
  about m2 (B1 / l), l = the Voronoi length (l_{k-1} + l_k) / 2: the discrete elastic rod's
  bending/twist energy 1/2 (B / l) phi^2 for a hinge angle phi, stretch-free (links are rigid);
- the rod's last link is welded (``<equality weld>``) to the body its end is clamped to, with the
  relative pose of the *deployed* state (the inserts' clamp offsets are those after insertion).

The body tree is defined in simfab's **deployed** state, so ``qpos0`` (what the viewer opens
on) is the deployed state, also stored as keyframe ``deployed``; the **flat**, stress-free cut
pattern is the springs' rest configuration: every hinge's ``springref`` is its angle in the
flat state (intrinsic x-y-z angles of the flat relation R_{k-1}^T R_k relative to the deployed
one), and keyframe ``flat`` holds the flat pattern (free bodies at their flat poses, hinges at
their springref; the welds at the inserts are then violated by r - g: the inserts are not yet
pushed in).

Stability (explicit spring forces, implicit damping with ``implicitfast``): every hinge gets an
armature ``a = k (dt / omega_dt)^2`` so that its own mode has omega dt <= ``omega_dt`` whatever the
link's tiny inertia, and damping ``zeta * 2 sqrt(k a)`` (critical for zeta = 1). Both change the
dynamics, not the equilibria (quasi-static inspection). Welds use ``solref = (2 dt, 1)`` and a
stiff ``solimp``; gravity is off (simfab's deployment is unloaded).

Measured (tests/deploy small saddle, 2 s from the key, default settings, mass_scale 100):
dt = 2 ms keeps the elastic energy to -3 % and the shape to 2 % of the out-of-plane height
(kinetic energy 5e-6 J at the end); 5 ms stays finite but releases 36 % of the energy, 10-20 ms
stay finite and release ~90 % (the motion is then not a relaxation). Hence ``timestep = 2e-3``.
The bodies' damping (``body_damping``) lets the relaxation check come to rest in 0.1-0.25 s of
simulated time on the bundled surfaces instead of oscillating for seconds; with it, dt = 4 ms
still lets the welds slip (PGS at its iteration cap: the saddle's relaxed state ends 0.33 mm from
simfab's instead of 0.01 mm), so dt stays 2 ms.
"""

from __future__ import annotations

import dataclasses
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from simfab.deploy.compare import kabsch
from simfab.errors import InputError
from simfab.io.atomic import atomic_path
from simfab.io.mjcf import MJCFBuilder, mujoco_module


@dataclass(frozen=True, kw_only=True)
class SimConfig:
    """MuJoCo scene settings (scene ``[mujoco]`` table).

    timestep [s]; omega_dt [-]: target hinge frequency x dt; damping_ratio [-] (zeta of every
    hinge); body_mass [kg] (each junction; inserts get ``insert_mass``); insert_mass [kg];
    stability_seconds [s]: simulated time of the stability check, a damped relaxation from the
    deployed key whose end state is compared with simfab's equilibrium; settle_tol [-]: the
    relaxation stops early once its bodies' speed, kept up for ``stability_seconds``, would move
    none of them by more than settle_tol x the deployment's out-of-plane height (see
    :func:`step_from_key`); impedance [-]: weld solimp;
    body_inertia_factor [-]: free bodies' rotational inertia / the stiffest hinge's armature;
    mass_scale [-]: factor on the links' density and the bodies' masses (mass scaling: with the real
    strip density the links' own modes make the motion spurious at dt >= 1e-3 - a relaxation
    then released 95 % of the elastic energy into motion - while equilibria do not depend on it);
    solver, iterations: MuJoCo constraint solver and its iterations per step (PGS is 2x faster per
    step than Newton on these weld-heavy scenes; 20 iterations would be 4x faster again but let
    the welds slip: the unit cell then drifts by 26 mm in 2 s instead of 2 mm);
    body_damping [1/s]: mass-proportional damping of the free bodies, c = body_damping x mass on
    their translations and x rotational inertia on their rotations (absolute velocities: the
    scene floats freely, so this damps the network's slow, nearly rigid modes, which the hinges'
    stiffness-proportional damping leaves oscillating; equilibria do not depend on it).
    """

    timestep: float = 2e-3
    omega_dt: float = 0.3
    damping_ratio: float = 1.0
    body_mass: float = 2e-4
    insert_mass: float = 1e-3
    stability_seconds: float = 2.0
    settle_tol: float = 5e-3
    impedance: float = 0.999
    body_inertia_factor: float = 10.0
    solver: str = "PGS"
    mass_scale: float = 100.0
    iterations: int = 100
    body_damping: float = 200.0

    def __post_init__(self):

        if self.solver not in ("PGS", "CG", "Newton"):
            raise InputError(f"must be PGS, CG or Newton (got {self.solver!r})", where="mujoco.solver")
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name != "solver" and not (np.isfinite(v) and v > 0):
                raise InputError(f"must be a positive number (got {v})", where=f"mujoco.{f.name}")


def _frames(state) -> np.ndarray:
    """(E,3,3) link frames [t m1 m2] (columns) of every edge."""
    m1, m2 = state.material_frames()
    return np.stack([state.t, m1, m2], axis=2)


def _quat(R) -> np.ndarray:
    """(w, x, y, z) unit quaternions (w >= 0) of rotation matrices (3,3) or (k,3,3)."""
    from scipy.spatial.transform import Rotation

    q = np.roll(Rotation.from_matrix(R).as_quat(), 1, axis=-1)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


@dataclass
class SimScene:
    """What :func:`build` returns: the MJCF text (keys ``deployed`` and ``flat`` in it; ``save``
    writes it), the flat key's values per joint name, the body names, the deployed key's full
    qpos and the compiled ``mujoco.MjModel`` (its ``qpos0`` is the deployed key)."""

    xml: str
    key_values: dict
    body_names: list
    key_qpos: np.ndarray | None = None
    model: object = None

    def save(self, path):
        """Write the MJCF (compiled by MuJoCo in :func:`build` already) atomically; returns the path."""
        from pathlib import Path


        path = Path(path)
        with atomic_path(path) as tmp:
            tmp.write_text(self.xml, encoding="utf-8")
        return path


_QPOS_SIZE = {"free": 7, "ball": 4, "slide": 1, "hinge": 1}


def _key_qpos(root, values: dict) -> np.ndarray:
    """qpos of a key from per-joint values (joint name -> (size,) array; missing joints: their
    qpos0, 0 or the identity quaternion), in MuJoCo's order: joints in depth-first body order."""
    out = []
    for el in root.iter():
        if el.tag in ("joint", "freejoint"):
            kind = "free" if el.tag == "freejoint" else el.get("type", "hinge")
            v = values.get(el.get("name"))
            if v is None:
                v = np.zeros(_QPOS_SIZE[kind])
                if kind in ("free", "ball"):
                    v[-4] = 1.0
            out.append(np.asarray(v, dtype=np.float64))
    return np.concatenate(out) if out else np.zeros(0)


def build(model, flat, deployed, *, density: float, cfg: SimConfig, name: str = "deployed",
          body_geoms: dict | None = None) -> SimScene:
    """MJCF of the network (see module doc). ``body_geoms``: simfab body name -> dict(mesh=(V,F) or
    box=half sizes (3,), mass, rgba) for inserts; other bodies get a small sphere."""
    from scipy.spatial.transform import Rotation


    dt = cfg.timestep
    b = MJCFBuilder(name, timestep=dt, gravity=[0, 0, 0])
    b.add(b.root.find("option"), "flag", energy="enable")
    b.root.find("option").set("integrator", "implicitfast")
    b.root.find("option").set("solver", cfg.solver)
    b.root.find("option").set("iterations", str(int(cfg.iterations)))
    body_geoms = body_geoms or {}
    Rf, Rd = _frames(flat), _frames(deployed)
    # rotational inertia of the free bodies: at least that of the stiffest hinge's armature x
    # ``body_inertia_factor`` (light inserts would otherwise let the welds' rotations go soft)
    kmax = float(np.max(model.bend_stiff / model.vor_len[:, None])) if model.n_hinges else 0.0
    I_body = cfg.body_inertia_factor * kmax * (dt / cfg.omega_dt) ** 2
    mb = {}
    key = {}  # joint name -> qpos values of the flat key
    qb_d, qb_rel = _quat(deployed.body_rot), _quat(np.transpose(deployed.body_rot, (0, 2, 1)) @ flat.body_rot)
    for i, bn in enumerate(model.body_names):
        el = b.body(bn, pos=deployed.body_pos[i], quat=qb_d[i])
        g = body_geoms.get(bn)
        mass = (g.get("mass", cfg.insert_mass) if g else cfg.body_mass) * cfg.mass_scale
        if not model.body_driven[i]:
            # free body as three slides along the world axes (axis in the body frame: R_d^T e_k) and a
            # ball, so that translation and rotation get their own damping (see SimConfig.body_damping)
            for k, ax in enumerate("xyz"):
                b.add(el, "joint", name=f"{bn}_{ax}", type="slide", axis=deployed.body_rot[i][k],
                      damping=cfg.body_damping * mass)
                key[f"{bn}_{ax}"] = np.array([flat.body_pos[i][k] - deployed.body_pos[i][k]])
            b.add(el, "joint", name=f"{bn}_rot", type="ball", damping=cfg.body_damping * I_body)
            key[f"{bn}_rot"] = qb_rel[i]
        b.add(el, "inertial", pos=[0, 0, 0], mass=mass, diaginertia=[I_body] * 3)
        if g and "mesh" in g:
            V, F = g["mesh"]
            b.mesh_asset(f"{bn}_mesh", V, F)
            b.geom(el, type="mesh", mesh=f"{bn}_mesh", mass=0, contype=0, conaffinity=0,
                   rgba=g.get("rgba", [0.85, 0.45, 0.2, 1]))
        elif g and "box" in g:
            b.geom(el, type="box", size=g["box"], mass=0, contype=0, conaffinity=0,
                   rgba=g.get("rgba", [0.85, 0.45, 0.2, 1]))
        else:
            rad = 0.5 * float(np.max([r.section.draw_width() for r in model.rods]))
            b.geom(el, type="sphere", size=[rad], mass=0, contype=0, conaffinity=0, rgba=[0.3, 0.3, 0.35, 1])
        mb[i] = el
    # per hinge (all rods at once): the deployed relation Q of link k to link k-1 (qpos0) and the
    # flat one, J = Q^T (Rf_a^T Rf_b), whose intrinsic x-y-z angles are the springs' rest angles
    ha, hb = model.hinge_edges[:, 0], model.hinge_edges[:, 1]
    RdT = np.transpose(Rd, (0, 2, 1))
    Qh = RdT[ha] @ Rd[hb]
    Jh = np.transpose(Qh, (0, 2, 1)) @ (np.transpose(Rf, (0, 2, 1))[ha] @ Rf[hb])
    ang_h = Rotation.from_matrix(Jh).as_euler("XYZ") if len(Jh) else np.zeros((0, 3))
    quat_h = _quat(Qh) if len(Qh) else np.zeros((0, 4))
    hinge_of = {(int(a), int(c)): h for h, (a, c) in enumerate(model.hinge_edges)}
    for r in model.rods:
        e0, e1 = int(r.edges[0]), int(r.edges[-1])
        sb, eb = int(model.edge_body[e0]), int(model.edge_body[e1])
        if sb < 0 or eb < 0:
            raise ValueError(f"rod {r.name!r}: both end edges must be clamped to bodies for the MuJoCo scene")
        w, t = r.section.width, r.section.thickness
        L = model.rest_len[r.edges]
        # link 0 is rigidly part of the start body: its geom sits in that body (pose relative to the
        # body from the deployed state; the body keeps its own inertial) and link 1 hangs from the body
        n0 = int(r.nodes[0])
        Rb = deployed.body_rot[sb]
        rel_p = Rb.T @ (deployed.x[n0] - deployed.body_pos[sb])
        rel_R = Rb.T @ Rd[e0]
        _link_geom(b, mb[sb], L[0], w, t, None, pos=rel_p, R=rel_R)
        parent = mb[sb]
        for k in range(1, len(r.edges)):
            h = hinge_of[int(r.edges[k - 1]), int(r.edges[k])]
            B1, B2 = model.bend_stiff[h]
            GJ = model.twist_stiff[h]
            lv = model.vor_len[h]
            if k == 1:
                pos, quat = rel_p + L[0] * rel_R[:, 0], _quat(rel_R @ Qh[h])
            else:
                pos, quat = [L[k - 1], 0.0, 0.0], quat_h[h]
            child = b.add(parent, "body", name=f"{r.name}_{k}", pos=pos, quat=quat)
            ang = ang_h[h]
            for ax, axis, kk, a in (("x", "1 0 0", GJ / lv, ang[0]), ("y", "0 1 0", B2 / lv, ang[1]),
                                    ("z", "0 0 1", B1 / lv, ang[2])):
                arm = kk * (dt / cfg.omega_dt) ** 2
                jn = f"{r.name}_{k}_{ax}"
                b.add(child, "joint", name=jn, type="hinge", axis=axis, stiffness=kk, springref=a, armature=arm,
                      damping=cfg.damping_ratio * 2.0 * np.sqrt(kk * arm))
                key[jn] = np.array([a])
            _link_geom(b, child, L[k], w, t, density * cfg.mass_scale)
            parent = child
        # weld the last link (the start body itself for a one-edge rod) to the end body (deployed
        # relative pose)
        Re = deployed.body_rot[eb]
        if len(r.edges) > 1:
            n_last = int(model.edges[e1][0])
            relpos = Re.T @ (deployed.x[n_last] - deployed.body_pos[eb])
            relq = _quat(Re.T @ Rd[e1])
            last = f"{r.name}_{len(r.edges) - 1}"
        else:
            relpos = Re.T @ (deployed.body_pos[sb] - deployed.body_pos[eb])
            relq = _quat(Re.T @ Rb)
            last = model.body_names[sb]
        # relpose: pose of body2 (the link) in body1's (the end body's) frame
        b.equality("weld", body1=model.body_names[eb], body2=last,
                   relpose=np.concatenate([relpos, relq]), solref=[2 * dt, 1.0],
                   solimp=[cfg.impedance, cfg.impedance, 0.001, 0.5, 2])
    qpos_deployed = _key_qpos(b.worldbody, {})
    b.key("deployed", qpos=qpos_deployed)
    b.key("flat", qpos=_key_qpos(b.worldbody, key))
    xml = b.to_xml()
    m = compile_in_parts(b.root, xml)
    return SimScene(xml=xml, key_values=key, body_names=list(model.body_names), key_qpos=qpos_deployed, model=m)


#: top-level bodies (with their subtrees) per part in :func:`compile_in_parts`
PART_BODIES = 50
_EMPTY_PREFIX = "empty prefix"  # MuJoCo's warning on attach(prefix=""): about saving the spec, which simfab never does


def compile_in_parts(root, xml: str, *, part_bodies: int = PART_BODIES):
    """``mujoco.MjModel`` of the MJCF document ``root`` (ElementTree; ``xml`` is its text), the same
    model as ``MjModel.from_xml_string(xml)``, compiled from parts: the document without its
    top-level bodies (options, assets, equalities, keys) and groups of ``part_bodies`` top-level
    bodies, each parsed on its own and attached (``MjSpec.attach``, no name prefix). MuJoCo's
    parser rebuilds its tree lists after every added element, so one parse of the whole network
    grows with the square of its links (more than half of the MJCF compile of a 165-insert
    network); the parts keep that quadratic cost per part. Documents with mesh assets or few
    bodies are compiled whole."""
    mj = mujoco_module()
    wb = root.find("worldbody")
    tops = [el for el in wb if el.tag == "body"]
    if root.find("asset/mesh") is not None or len(tops) <= part_bodies:
        return mj.MjModel.from_xml_string(xml)
    for el in tops:
        wb.remove(el)
    try:
        spec = mj.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    finally:
        wb.extend(tops)
    compiler = root.find("compiler")
    prev = mj.get_mju_user_warning()
    mj.set_mju_user_warning(lambda msg: None if _EMPTY_PREFIX in str(msg) else prev(msg))
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=f".*{_EMPTY_PREFIX}")
            for i in range(0, len(tops), part_bodies):
                part = ET.Element("mujoco")
                part.append(compiler)
                ET.SubElement(part, "worldbody").extend(tops[i:i + part_bodies])
                spec.attach(mj.MjSpec.from_string(ET.tostring(part, encoding="unicode")),
                            frame=spec.worldbody.add_frame(), prefix="")
            return spec.compile()
    finally:
        mj.set_mju_user_warning(prev)


def _link_geom(b, body, length, w, t, density, *, pos=None, R=None):
    """Box geom of a link of the given length along the frame's x axis from ``pos`` (default: the
    body's origin), frame ``R`` (default: the body's); ``density`` None: massless (the geom sits in
    a simfab body, whose inertial is its own)."""
    p0 = np.zeros(3) if pos is None else np.asarray(pos, dtype=np.float64)
    ax = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
    extra = dict(mass=0) if density is None else dict(density=density)
    b.geom(body, type="box", size=[0.5 * length, 0.5 * t, 0.5 * w], pos=p0 + 0.5 * length * ax[:, 0],
           quat=None if R is None else _quat(ax), contype=0, conaffinity=0, rgba=[0.95, 0.9, 0.75, 1], **extra)


@dataclass(frozen=True)
class Stability:
    """Stepping from the key: finite throughout, seconds simulated, timestep [s], max |qvel| [m/s or
    rad/s], kinetic energy at the end [J], drift (max body displacement from the key after the
    best rigid alignment: the scene floats freely) [m], wall time [s], settled (the relaxation met
    its convergence test before ``seconds``; None when not asked for), steps taken."""

    finite: bool
    seconds: float
    timestep: float
    max_speed: float
    final_kinetic: float
    max_drift: float
    wall: float
    settled: bool | None = None
    steps: int = 0


def aligned_drift(X0: np.ndarray, X1: np.ndarray) -> float:
    """Largest distance [m] between points X1 (n,3) rigidly aligned onto X0 (n,3) and X0."""

    R, t = kabsch(X1, X0)
    return float(np.max(np.linalg.norm(X1 @ R.T + t - X0, axis=1)))


def step_from_key(m, seconds: float, key: str | None = "deployed", *, settle: float | None = None,
                  window: float = 0.05, bodies=None) -> tuple[Stability, object]:
    """Reset to ``key`` (None: ``qpos0``, which is the deployed key of :func:`build`'s scenes) and
    step up to ``seconds``; returns the measures and the final MjData.

    ``settle`` [m] (optional convergence test of a damped relaxation): over windows of simulated
    time alternating between ``window`` and 0.6 ``window`` [s] (incommensurate, so that an
    oscillation cannot return to the same place at both ends of two consecutive windows), the
    bodies' largest displacement over the window (after the best rigid alignment) gives their
    speed; stepping stops once, in two consecutive windows, that speed kept up for the whole
    ``seconds`` would move no body by more than ``settle``. The end state is then within about
    ``settle`` of the one stepping the full ``seconds`` would reach, as long as the motion only
    slows down (the hinges' damping is stiffness-proportional, so slow modes oscillate rather
    than creep: a state still moving keeps stepping). ``bodies``: MuJoCo body ids the test
    watches (default: all but the world; the pipeline watches the bodies it compares, not the
    rods' links, whose small vibration would otherwise keep the test from ever passing)."""
    import time

    import mujoco

    d = mujoco.MjData(m)
    if key is None:
        mujoco.mj_resetData(m, d)
    else:
        mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, key))
    mujoco.mj_forward(m, d)
    x0 = d.xpos.copy()
    dt = float(m.opt.timestep)
    n = int(round(seconds / dt))
    every = max(1, int(round(window / dt)))
    vmax = 0.0
    finite = True
    settled = None if settle is None else False
    watch = np.arange(1, m.nbody) if bodies is None else np.asarray(bodies, dtype=int)
    prev = x0[watch].copy()
    calm = 0
    steps = 0
    short = max(1, int(round(0.6 * every)))
    span, next_check = every, every
    t0 = time.perf_counter()
    for i in range(n):
        mujoco.mj_step(m, d)
        steps = i + 1
        if i % 10 == 9 or i == n - 1:
            if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
                finite = False
                break
            vmax = max(vmax, float(np.max(np.abs(d.qvel[:]))) if m.nv else 0.0)
        if settle is not None and steps == next_check:
            X = d.xpos[watch].copy()
            speed = aligned_drift(prev, X) / (span * dt)
            prev = X
            calm = calm + 1 if speed * seconds <= settle else 0
            if calm >= 2:
                settled = True
                break
            span = every if span != every else short  # alternate window lengths (no aliasing)
            next_check = steps + span
    wall = time.perf_counter() - t0
    drift = aligned_drift(x0[1:], d.xpos[1:]) if finite else float("inf")
    return Stability(finite=finite, seconds=steps * dt, timestep=dt, max_speed=vmax,
                     final_kinetic=float(d.energy[1]) if finite else float("inf"), max_drift=drift, wall=wall,
                     settled=settled, steps=steps), d

