"""A MuJoCo scene of a rod network with rigid bodies that MuJoCo can simulate (not a picture).

Built from a :class:`simfab.rods.model.RodModel`, its flat state and a deployed state
(:func:`build`):

- every simfab body (insert, junction) is a free MuJoCo body (three slides and a ball joint, so that
  translations and rotations get their own damping); a driven body is attached to the world;
- every rod is a chain of rigid links, one per edge, each hanging from the previous one by three
  hinges (twist GJ / l, in-plane bending B2 / l, out-of-plane bending B1 / l; l the Voronoi
  length): the discrete elastic rod's energy 1/2 (B / l) phi^2, stretch-free; its first link is a
  geom of the body it starts clamped to, its last welded to the body its end is clamped to;
- the body tree is in the **deployed** state (``qpos0``, keyframe ``deployed``); every hinge's
  ``springref`` is its angle in the **flat** state (keyframe ``flat``): the cut pattern at rest.

Stability: each hinge gets an armature a = k (dt / omega_dt)^2 (its own mode at omega dt <=
``omega_dt``) and damping zeta 2 sqrt(k a); welds ``solref = (2 dt, 1)``, no gravity. Both change
the dynamics, not the equilibria. :func:`step_from_key` relaxes from the deployed key and compares
with simfab's equilibrium. The model's details and the time-step measurements: docs/methods.md
and docs/validation/deploy.md, "simfab.deploy.mjcf_sim".
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

    Args:
        timestep: the step dt [s].
        omega_dt: target hinge frequency x dt [-] (sets each hinge's armature).
        damping_ratio: zeta of every hinge [-].
        body_mass: mass of each junction body [kg].
        insert_mass: mass of each insert [kg].
        stability_seconds: simulated time of the stability check [s]: a damped relaxation from the
            deployed key whose end state is compared with simfab's equilibrium.
        settle_tol: the relaxation stops early once its bodies' speed, kept up for
            ``stability_seconds``, would move none of them by more than settle_tol x the deployment's
            out-of-plane height [-] (:func:`step_from_key`).
        impedance: the welds' solimp [-].
        body_inertia_factor: free bodies' rotational inertia / the stiffest hinge's armature [-].
        solver: MuJoCo's constraint solver, "PGS", "CG" or "Newton".
        mass_scale: factor on the links' density and the bodies' masses [-] (mass scaling: with the
            real strip density the links' own modes make the motion spurious; equilibria do not
            depend on it).
        iterations: the constraint solver's iterations per step (fewer let the welds slip).
        body_damping: mass-proportional damping of the free bodies [1/s] (c = body_damping x mass on
            their translations, x rotational inertia on their rotations: it damps the network's slow,
            nearly rigid modes, which the hinges' stiffness-proportional damping leaves oscillating).

    The measurements behind the defaults: docs/validation/deploy.md, "simfab.deploy.mjcf_sim".
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
    """What :func:`build` returns.

    Args:
        xml: the MJCF text (keys ``deployed`` and ``flat`` in it).
        key_values: the flat key's values per joint name.
        body_names: the simfab body names.
        key_qpos: the deployed key's full qpos.
        model: the compiled ``mujoco.MjModel`` (its ``qpos0`` is the deployed key).
    """

    xml: str
    key_values: dict
    body_names: list
    key_qpos: np.ndarray | None = None
    model: object = None

    def save(self, path):
        """Write the MJCF (compiled by MuJoCo in :func:`build` already) atomically.

        Args:
            path: the file.

        Returns:
            The path.
        """
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
    """The MuJoCo scene of a rod network (see the module doc).

    Args:
        model: the :class:`simfab.rods.model.RodModel`.
        flat: its flat (rest) state.
        deployed: its deployed state (the body tree's and ``qpos0``'s).
        density: the rods' density [kg/m^3].
        cfg: the :class:`SimConfig`.
        name: the model's name.
        body_geoms: simfab body name -> dict(mesh=(V,F) or box=half sizes (3,) [m], mass [kg], rgba)
            for inserts; other bodies get a small sphere.

    Returns:
        The :class:`SimScene`.
    """
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
    q_link0, q_link1, q_weld = _rod_end_quats(model, deployed, Rd, Qh, hinge_of)
    for ri, r in enumerate(model.rods):
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
        _link_geom(b, mb[sb], L[0], w, t, None, pos=rel_p, R=rel_R, quat=q_link0[ri])
        parent = mb[sb]
        for k in range(1, len(r.edges)):
            h = hinge_of[int(r.edges[k - 1]), int(r.edges[k])]
            B1, B2 = model.bend_stiff[h]
            GJ = model.twist_stiff[h]
            lv = model.vor_len[h]
            if k == 1:
                pos, quat = rel_p + L[0] * rel_R[:, 0], q_link1[ri]
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
            relq = q_weld[ri]
            last = f"{r.name}_{len(r.edges) - 1}"
        else:
            relpos = Re.T @ (deployed.body_pos[sb] - deployed.body_pos[eb])
            relq = q_weld[ri]
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
    """The ``mujoco.MjModel`` of an MJCF document, compiled from parts.

    The same model as ``MjModel.from_xml_string(xml)``: the document without its top-level bodies
    (options, assets, equalities, keys) and groups of ``part_bodies`` top-level bodies, each parsed on
    its own and attached (``MjSpec.attach``, no name prefix). MuJoCo's parser rebuilds its tree lists
    after every added element, so one parse of the whole network grows with the square of its links;
    the parts keep that quadratic cost per part. Documents with mesh assets or few bodies are compiled
    whole.

    Args:
        root: the MJCF document (ElementTree).
        xml: its text.
        part_bodies: top-level bodies per part.

    Returns:
        The compiled model.
    """
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


def _rod_end_quats(model, deployed, Rd: np.ndarray, Qh: np.ndarray, hinge_of: dict):
    """Per rod of :func:`build` (one batch each): the quaternion of its first link in its start body,
    of its second link's body in the start body (zeros for a one-edge rod) and of its weld's relative
    pose (the last link, or the start body, in the end body's frame)."""
    R0, R1, RW = [], [], []
    for r in model.rods:
        e0, e1 = int(r.edges[0]), int(r.edges[-1])
        sb, eb = int(model.edge_body[e0]), int(model.edge_body[e1])
        Rb, Re = deployed.body_rot[sb], deployed.body_rot[eb]
        rel_R = Rb.T @ Rd[e0]
        R0.append(rel_R)
        R1.append(rel_R @ Qh[hinge_of[e0, int(r.edges[1])]] if len(r.edges) > 1 else np.eye(3))
        RW.append(Re.T @ Rd[e1] if len(r.edges) > 1 else Re.T @ Rb)
    if not R0:
        return np.zeros((0, 4)), np.zeros((0, 4)), np.zeros((0, 4))
    return _quat(np.array(R0)), _quat(np.array(R1)), _quat(np.array(RW))


def _link_geom(b, body, length, w, t, density, *, pos=None, R=None, quat=None):
    """Box geom of a link of the given length along the frame's x axis from ``pos`` (default: the
    body's origin), frame ``R`` (default: the body's; ``quat``: its quaternion when known); ``density``
    None: massless (the geom sits in a simfab body, whose inertial is its own)."""
    p0 = np.zeros(3) if pos is None else np.asarray(pos, dtype=np.float64)
    ax = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
    extra = dict(mass=0) if density is None else dict(density=density)
    if R is not None and quat is None:
        quat = _quat(ax)
    b.geom(body, type="box", size=[0.5 * length, 0.5 * t, 0.5 * w], pos=p0 + 0.5 * length * ax[:, 0],
           quat=None if R is None else quat, contype=0, conaffinity=0, rgba=[0.95, 0.9, 0.75, 1], **extra)


@dataclass(frozen=True)
class Stability:
    """Stepping from the key (:func:`step_from_key`).

    Args:
        finite: finite throughout.
        seconds: simulated time [s].
        timestep: the step [s].
        max_speed: max |qvel| [m/s or rad/s].
        final_kinetic: kinetic energy at the end [J].
        max_drift: max body displacement from the key after the best rigid alignment (the scene
            floats freely) [m].
        wall: wall time [s].
        settled: the relaxation met its convergence test before ``seconds`` (None: not asked for).
        steps: steps taken.
    """

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
    """Largest distance between points rigidly aligned onto reference points and those points.

    Args:
        X0: (n,3) [m] the reference.
        X1: (n,3) [m] the points.

    Returns:
        The distance [m].
    """

    R, t = kabsch(X1, X0)
    return float(np.max(np.linalg.norm(X1 @ R.T + t - X0, axis=1)))


def step_from_key(m, seconds: float, key: str | None = "deployed", *, settle: float | None = None,
                  window: float = 0.05, bodies=None) -> tuple[Stability, object]:
    """Reset to a key and step up to ``seconds``.

    ``settle`` (optional convergence test of a damped relaxation): over windows of simulated time
    alternating between ``window`` and 0.6 ``window`` (incommensurate, so that an oscillation cannot
    return to the same place at both ends of two consecutive windows), the bodies' largest
    displacement over the window (after the best rigid alignment) gives their speed; stepping stops
    once, in two consecutive windows, that speed kept up for the whole ``seconds`` would move no body
    by more than ``settle``. The end state is then within about ``settle`` of the one stepping the full
    ``seconds`` would reach, as long as the motion only slows down (the hinges' damping is
    stiffness-proportional, so slow modes oscillate rather than creep).

    Args:
        m: the ``mujoco.MjModel``.
        seconds: simulated time at most [s].
        key: the keyframe (None: ``qpos0``, the deployed key of :func:`build`'s scenes).
        settle: the convergence test's distance [m] (None: step the full ``seconds``).
        window: the test's window [s].
        bodies: MuJoCo body ids the test watches (default: all but the world; the pipeline watches
            the bodies it compares, not the rods' links, whose small vibration would otherwise keep
            the test from ever passing).

    Returns:
        (:class:`Stability`, the final MjData).
    """
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

