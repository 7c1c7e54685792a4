"""Growth parameters: keyword-only dataclasses, read from a scene's companion TOML.

Every length is in metres. Parameters left at ``None`` are derived from the design space
by :func:`resolve` (see :class:`Resolved`), so that a typical scene needs no tuning.

TOML layout (all tables and keys optional; see ``scenes/growth/README.md``)::

    [growth]
    mode = "volume"            # "volume" | "surface" | "profile"
    attractors = 2000
    influence = 0.05           # [m] attractor influence distance
    kill = 0.012               # [m] attractor kill distance
    branch_length = 0.006      # [m] L
    box = [[x0, y0, z0], [x1, y1, z1]]   # design box (default: bounding box of the objects)
    surface_objects = ["egg"]  # surface mode: bodies to sample (default: all)
    max_steps = 400
    max_nodes = 50000
    max_trials = 32            # random directions tried when a branch hits an obstacle
    seed = 0                   # seed of grow() when none is given (the CLI always passes --seed, default 0)

    [radius]                   # r = r_min + (r_max - r_min) exp(-k age)
    r_min = 0.0015
    r_max = 0.004
    decay = 0.05               # k [1/step]
    age = "front"              # "front": age = birth step (roots thickest);
                               # "since_birth": age = steps lived until the end (tips thickest)

    [smoothing]                # v += l1 Lap(v) + l2 Lap(Lap(v))
    iterations = 10
    lambda1 = 0.2
    lambda2 = 0.1

    [symmetry]                 # mirror-symmetric growth (also enabled by --symmetric)
    enabled = true
    point = [0, 0, 0]
    normal = [1, 0, 0]

    [profile]                  # mode = "profile": closed 2D profile swept along u x v
    origin = [0, 0, 0]
    u = [1, 0, 0]
    v = [0, 0, 1]
    points = [[u0, v0], [u1, v1], ...]
    depth = [-0.01, 0.01]      # sweep range along the view direction u x v [m]

    [stages]                   # guided progressive growth: target site names per stage
    targets = [["target_0", "target_1"], ["target_2"]]

    [skin]
    segments = 12              # circular resolution of joint spheres (rounded up to a multiple of 4)
    subtract_objects = true    # carve the objects out of the skin
    tolerance = 0.0            # [m] largest allowed penetration of the skin into an object

    [material]                 # structural check (simfab grow check): the printed material
    name = "PLA"               # built-in base material (PLA, VeroWhite); the keys below override it
    youngs_modulus = 3.5e9     # [Pa]
    poisson_ratio = 0.36       # [-]
    yield_stress = 60e6        # [Pa] von Mises yield stress
    density = 1240.0           # [kg/m^3]
    critical_distance = 5e-4   # [m] radius the von Mises stress is averaged over (0: the largest point value)

    [loads]                    # structural check: extra force per target site [N], world frame
    target_0 = [0.0, 0.0, -2.0]
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

import simfab.growth.tolerances as tol
from simfab.errors import InputError
from simfab.fem.materials import PLA, Material, material_by_name

MODES = ("volume", "surface", "profile")


@dataclasses.dataclass(frozen=True, kw_only=True)
class SymmetrySpec:
    """Mirror plane through ``point`` (3,) [m] with unit ``normal`` (3,)."""

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (1.0, 0.0, 0.0)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ProfileSpec:
    """Closed 2D profile ``points`` (k, 2) [m] in the plane ``origin + a u + b v``, swept along
    the view direction ``u x v`` over ``depth`` = (d0, d1) [m]."""

    origin: tuple
    u: tuple
    v: tuple
    points: tuple
    depth: tuple


@dataclasses.dataclass(frozen=True, kw_only=True)
class GrowthParams:
    """User-facing growth parameters (``None`` = derived from the scene, see :func:`resolve`)."""

    mode: str = "volume"
    attractors: int = 2000
    influence: float | None = None
    kill: float | None = None
    branch_length: float | None = None
    box: tuple | None = None
    surface_objects: tuple | None = None
    #: Influence distance of target attractors [m]; infinite by default so that a target
    #: keeps pulling its nearest node after every ordinary attractor has died.
    target_influence: float = math.inf
    max_steps: int | None = None
    max_nodes: int = 50000
    max_trials: int = 32
    r_min: float | None = None
    r_max: float | None = None
    radius_decay: float | None = None
    #: How a node's age α is counted: "front" (α = its birth step, so the root is oldest in
    #: growth-front terms and gets r_max) or "since_birth" (α = steps from its birth to the
    #: end of growth, the literal reading; the root then gets r_min).
    radius_age: str = "front"
    smoothing_iterations: int = 10
    lambda1: float = 0.2
    lambda2: float = 0.1
    symmetry: SymmetrySpec | None = None
    profile: ProfileSpec | None = None
    stages: tuple | None = None
    skin_segments: int = 12
    subtract_objects: bool = True
    #: Largest penetration depth [m] of the skin into an object that is accepted (with
    #: carving it is 0 up to round-off; without, the run fails above it).
    skin_tolerance: float = 0.0
    seed: int = 0


@dataclasses.dataclass(frozen=True, kw_only=True)
class Resolved:
    """Concrete numbers used by one run (all lengths in metres).

    box : (2, 3) design box corners. diag : its diagonal D. spacing : mean attractor
    spacing s (volume: (V/N)^(1/3); surface/profile: sqrt(A/N)).
    """

    box: np.ndarray
    diag: float
    spacing: float
    influence: float
    kill: float
    branch_length: float
    max_steps: int
    r_min: float
    r_max: float
    radius_decay: float


# Default scalings (multiples of the attractor spacing s or of the diagonal D).
#: (influence, kill, branch length) per attractor spacing s. Volume growth is pruned down
#: to the paths to the targets; surface and profile growth keeps the branches that cover
#: the surface, so there the kill distance is larger to give an open lattice rather than a
#: dense mat (node count ~ N s² / (kill L)).
SCALE_PER_SPACING = {"volume": (4.0, 1.0, 0.5), "surface": (8.0, 3.0, 1.5), "profile": (8.0, 3.0, 1.5)}
R_MAX_PER_DIAG = 1.0 / 60.0
R_MIN_PER_R_MAX = 0.4
#: radius decay k such that exp(-k * steps_to_cross_D) = exp(-DECAY_E_FOLDS)
DECAY_E_FOLDS = 3.0
#: step cap as a multiple of the number of steps needed to cross the design box
STEPS_PER_CROSSING = 12.0


def resolve(p: GrowthParams, box: np.ndarray, *, area: float | None = None) -> Resolved:
    """Fill derived defaults from the design box (2, 3) [m] (``area`` [m²] for surface modes)."""
    box = np.asarray(box, dtype=np.float64)
    ext = box[1] - box[0]
    diag = float(np.linalg.norm(ext))
    if not diag > 0:
        raise InputError("the design space is empty (zero-size bounding box)", where="growth.box")
    if area is not None:
        spacing = math.sqrt(area / p.attractors)
    else:
        spacing = float(np.prod(np.maximum(ext, 1e-3 * diag)) / p.attractors) ** (1.0 / 3.0)
    f_infl, f_kill, f_L = SCALE_PER_SPACING[p.mode]
    L = p.branch_length if p.branch_length is not None else f_L * spacing
    kill = p.kill if p.kill is not None else f_kill * spacing
    infl = p.influence if p.influence is not None else f_infl * spacing
    if not (L > 0 and kill > 0 and infl > 0):
        raise InputError(f"branch length, kill and influence distances must be positive (got {L}, {kill}, {infl})",
                         where="growth")
    check_scale(p, box)
    if not infl > kill:
        raise InputError(f"influence distance ({infl:.4g} m) must exceed kill distance ({kill:.4g} m)", where="growth")
    r_max = p.r_max if p.r_max is not None else R_MAX_PER_DIAG * diag
    r_min = p.r_min if p.r_min is not None else R_MIN_PER_R_MAX * r_max
    if not (0 < r_min <= r_max):
        raise InputError(f"need 0 < r_min <= r_max (got {r_min}, {r_max})", where="radius")
    decay = p.radius_decay if p.radius_decay is not None else DECAY_E_FOLDS * L / diag
    if decay < 0:
        raise InputError(f"radius decay must be >= 0, got {decay}", where="radius.decay")
    max_steps = p.max_steps if p.max_steps is not None else int(math.ceil(STEPS_PER_CROSSING * diag / L))
    return Resolved(box=box, diag=diag, spacing=spacing, influence=float(infl), kill=float(kill),
                    branch_length=float(L), max_steps=int(max_steps), r_min=float(r_min), r_max=float(r_max),
                    radius_decay=float(decay))


def check_scale(p: GrowthParams, box: np.ndarray) -> None:
    """InputError for a given length that cannot make sense in the design box (2, 3) [m]: a
    growth step longer than the box's longest side, a kill or influence distance or a maximum
    branch radius larger than its diagonal D (every attractor would be killed or seen at once,
    one step would leave the box). The error names the parameter (``growth.<key>`` or
    ``radius.r_max``) and the box size it was compared with. Derived (None) values scale with
    the box and are not checked."""
    ext = np.asarray(box[1], np.float64) - np.asarray(box[0], np.float64)
    side, diag = float(ext.max()), float(np.linalg.norm(ext))
    size = f"the design box is {' x '.join(f'{e:.4g}' for e in ext)} m, diagonal {diag:.4g} m"
    if p.branch_length is not None and p.branch_length > side:
        raise InputError(f"{p.branch_length:.4g} m is longer than the design box's longest side ({size})",
                         where="growth.branch_length")
    for key, v in (("kill", p.kill), ("influence", p.influence)):
        if v is not None and v > diag:
            raise InputError(f"{v:.4g} m is larger than the design box's diagonal ({size})", where=f"growth.{key}")
    if p.r_max is not None and p.r_max > diag:
        raise InputError(f"{p.r_max:.4g} m is larger than the design box's diagonal ({size})", where="radius.r_max")


# --------------------------------------------------------------------------- TOML
_GROWTH_KEYS = {"mode", "attractors", "influence", "kill", "branch_length", "box", "surface_objects",
                "target_influence", "max_steps", "max_nodes", "max_trials", "seed"}
_TABLES = {"growth", "radius", "smoothing", "symmetry", "profile", "stages", "skin", "material", "loads"}


def _vec(x, n, where):
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"expected {n} numbers, got {x!r}", where=where) from None
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise InputError(f"expected {n} finite numbers, got {x!r}", where=where)
    return tuple(float(v) for v in a)


def _num(x, where, *, integer=False, positive=True, allow_inf=False):
    """A number from the TOML (``allow_inf``: +inf is accepted too); InputError naming ``where``."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise InputError(f"expected a number, got {x!r}", where=where)
    if integer and not float(x).is_integer():
        raise InputError(f"expected an integer, got {x!r}", where=where)
    if not math.isfinite(float(x)) and not (allow_inf and x == math.inf):
        raise InputError(f"expected a finite number, got {x!r}", where=where)
    if positive and not x > 0:
        raise InputError(f"must be positive, got {x!r}", where=where)
    return int(x) if integer else float(x)


@dataclasses.dataclass(frozen=True, kw_only=True)
class StructureSpec:
    """The structural check's inputs from the ``[material]`` and ``[loads]`` tables.

    material : the printed material (:class:`simfab.fem.materials.Material`; PLA by default).
    critical_distance : radius [m] of the ball the von Mises stress is averaged over before it
        is compared with the yield stress (Theory of Critical Distances, as the coupling's
        yield check: :mod:`simfab.design.stress`); 0 compares the largest element-corner value.
    loads : ((target name, (fx, fy, fz)), ...) extra forces [N] on target sites, world frame,
        added to the supported objects' weights.
    """

    material: Material = PLA
    critical_distance: float = tol.CRITICAL_DISTANCE
    loads: tuple = ()


_MATERIAL_KEYS = {"name", "youngs_modulus", "poisson_ratio", "yield_stress", "density", "critical_distance"}


def structure_from_toml(doc: dict, where: str) -> StructureSpec:
    """:class:`StructureSpec` from a parsed scene TOML (``[material]``, ``[loads]``); InputError
    names the file, table and key. Target names in ``[loads]`` are checked against the scene's
    sites by :func:`simfab.growth.scene.load_growth_scene`."""
    m = doc.get("material", {})
    if not isinstance(m, dict):
        raise InputError("expected a table", where=f"{where}: [material]")
    _check_unknown(m, _MATERIAL_KEYS, f"{where}: [material]")
    base = PLA
    if "name" in m:
        if not isinstance(m["name"], str):
            raise InputError(f"expected a material name, got {m['name']!r}", where=f"{where}: material.name")
        try:
            base = material_by_name(m["name"])
        except InputError as e:
            raise InputError(e.message, where=f"{where}: material.name") from None
    over = {}
    for key in ("youngs_modulus", "yield_stress", "density"):
        if key in m:
            over[key] = _num(m[key], f"{where}: material.{key}")
    if "poisson_ratio" in m:
        nu = _num(m["poisson_ratio"], f"{where}: material.poisson_ratio", positive=False)
        if not -1.0 < nu < 0.5:
            raise InputError(f"must lie in (-1, 0.5), got {nu}", where=f"{where}: material.poisson_ratio")
        over["poisson_ratio"] = nu
    material = dataclasses.replace(base, name=str(m.get("name", base.name)), **over) if over else base
    radius = tol.CRITICAL_DISTANCE
    if "critical_distance" in m:
        radius = _num(m["critical_distance"], f"{where}: material.critical_distance", positive=False)
        if radius < 0:
            raise InputError(f"must be >= 0, got {radius}", where=f"{where}: material.critical_distance")
    ld = doc.get("loads", {})
    if not isinstance(ld, dict):
        raise InputError("expected a table", where=f"{where}: [loads]")
    loads = tuple((str(k), _vec(v, 3, f"{where}: loads.{k}")) for k, v in ld.items())
    return StructureSpec(material=material, critical_distance=radius, loads=loads)


def _check_unknown(d: dict, allowed: set, where: str):
    extra = sorted(set(d) - allowed)
    if extra:
        raise InputError(f"unknown key(s) {', '.join(extra)} (allowed: {', '.join(sorted(allowed))})", where=where)


def params_from_toml(doc: dict, where: str) -> GrowthParams:
    """Build :class:`GrowthParams` from a parsed TOML document; InputError names the bad key."""
    _check_unknown(doc, _TABLES, where)
    kw: dict = {}
    g = doc.get("growth", {})
    _check_unknown(g, _GROWTH_KEYS, f"{where}: [growth]")
    w = f"{where}: growth."
    if "mode" in g:
        if g["mode"] not in MODES:
            raise InputError(f"mode must be one of {', '.join(MODES)}, got {g['mode']!r}", where=w + "mode")
        kw["mode"] = g["mode"]
    for key in ("attractors", "max_steps", "max_nodes", "max_trials"):
        if key in g:
            kw[key] = _num(g[key], w + key, integer=True)
    if "seed" in g:
        kw["seed"] = _num(g["seed"], w + "seed", integer=True, positive=False)
    for key in ("influence", "kill", "branch_length", "target_influence"):
        if key in g:
            # an infinite target influence is the default: a target pulls from anywhere
            kw[key] = _num(g[key], w + key, allow_inf=key == "target_influence")
    if "box" in g:
        b = g["box"]
        if not (isinstance(b, list) and len(b) == 2):
            raise InputError("expected [[x0, y0, z0], [x1, y1, z1]]", where=w + "box")
        lo, hi = _vec(b[0], 3, w + "box"), _vec(b[1], 3, w + "box")
        if not all(h > l for l, h in zip(lo, hi)):
            raise InputError("box max corner must exceed the min corner on every axis", where=w + "box")
        kw["box"] = (lo, hi)
    if "surface_objects" in g:
        so = g["surface_objects"]
        if not (isinstance(so, list) and so and all(isinstance(s, str) for s in so)):
            raise InputError("expected a non-empty list of body names", where=w + "surface_objects")
        kw["surface_objects"] = tuple(so)

    r = doc.get("radius", {})
    _check_unknown(r, {"r_min", "r_max", "decay", "age"}, f"{where}: [radius]")
    if "age" in r:
        if r["age"] not in ("front", "since_birth"):
            raise InputError(f"expected 'front' or 'since_birth', got {r['age']!r}", where=f"{where}: radius.age")
        kw["radius_age"] = r["age"]
    for key, name in (("r_min", "r_min"), ("r_max", "r_max")):
        if key in r:
            kw[name] = _num(r[key], f"{where}: radius.{key}")
    if "decay" in r:
        kw["radius_decay"] = _num(r["decay"], f"{where}: radius.decay", positive=False)

    s = doc.get("smoothing", {})
    _check_unknown(s, {"iterations", "lambda1", "lambda2"}, f"{where}: [smoothing]")
    if "iterations" in s:
        kw["smoothing_iterations"] = _num(s["iterations"], f"{where}: smoothing.iterations", integer=True,
                                          positive=False)
    for key in ("lambda1", "lambda2"):
        if key in s:
            kw[key] = _num(s[key], f"{where}: smoothing.{key}", positive=False)

    sym = doc.get("symmetry")
    if sym is not None:
        _check_unknown(sym, {"enabled", "point", "normal"}, f"{where}: [symmetry]")
        if sym.get("enabled", True):
            n = np.array(_vec(sym.get("normal", [1, 0, 0]), 3, f"{where}: symmetry.normal"))
            if not np.linalg.norm(n) > 0:
                raise InputError("normal must be non-zero", where=f"{where}: symmetry.normal")
            kw["symmetry"] = SymmetrySpec(point=_vec(sym.get("point", [0, 0, 0]), 3, f"{where}: symmetry.point"),
                                          normal=tuple(n / np.linalg.norm(n)))

    pr = doc.get("profile")
    if pr is not None:
        kw["profile"] = _profile(pr, f"{where}: profile")

    st = doc.get("stages")
    if st is not None:
        _check_unknown(st, {"targets"}, f"{where}: [stages]")
        t = st.get("targets")
        if not (isinstance(t, list) and t
                and all(isinstance(x, list) and x and all(isinstance(n, str) for n in x) for x in t)):
            raise InputError("expected a list of non-empty lists of target site names",
                             where=f"{where}: stages.targets")
        kw["stages"] = tuple(tuple(x) for x in t)

    sk = doc.get("skin", {})
    _check_unknown(sk, {"segments", "subtract_objects", "tolerance"}, f"{where}: [skin]")
    if "tolerance" in sk:
        kw["skin_tolerance"] = _num(sk["tolerance"], f"{where}: skin.tolerance", positive=False)
        if kw["skin_tolerance"] < 0:
            raise InputError("must be >= 0", where=f"{where}: skin.tolerance")
    if "segments" in sk:
        kw["skin_segments"] = _num(sk["segments"], f"{where}: skin.segments", integer=True)
        if kw["skin_segments"] < 6:
            raise InputError("need at least 6 segments", where=f"{where}: skin.segments")
    if "subtract_objects" in sk:
        if not isinstance(sk["subtract_objects"], bool):
            raise InputError("expected true or false", where=f"{where}: skin.subtract_objects")
        kw["subtract_objects"] = sk["subtract_objects"]
    return GrowthParams(**kw)


def _profile(pr: dict, where: str) -> ProfileSpec:
    _check_unknown(pr, {"origin", "u", "v", "points", "depth"}, where)
    for key in ("origin", "u", "v", "points", "depth"):
        if key not in pr:
            raise InputError(f"missing key {key!r}", where=where)
    u = np.array(_vec(pr["u"], 3, where + ".u"))
    v = np.array(_vec(pr["v"], 3, where + ".v"))
    if np.linalg.norm(np.cross(u, v)) < 1e-9 * max(np.linalg.norm(u) * np.linalg.norm(v), 1e-300):
        raise InputError("u and v must be non-zero and not parallel", where=where)
    pts = pr["points"]
    if not isinstance(pts, list) or len(pts) < 3:
        raise InputError("a closed profile needs at least 3 points", where=where + ".points")
    P = tuple(_vec(q, 2, where + ".points") for q in pts)
    d = _vec(pr["depth"], 2, where + ".depth")
    if not d[1] >= d[0]:
        raise InputError("depth must be [d0, d1] with d1 >= d0", where=where + ".depth")
    return ProfileSpec(origin=_vec(pr["origin"], 3, where + ".origin"), u=tuple(u / np.linalg.norm(u)),
                       v=tuple(v / np.linalg.norm(v)), points=P, depth=d)
