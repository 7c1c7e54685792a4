"""Growth parameters: keyword-only dataclasses nested like a scene's companion TOML.

One config per TOML table (every table and key optional; the full layout with defaults is in
``scenes/growth/README.md``): ``[growth]`` :class:`GrowthConfig` (mode, attractors, influence,
kill, branch_length, box, ...), ``[radius]`` :class:`RadiusConfig` (r = r_min + (r_max - r_min)
exp(-decay age)), ``[smoothing]`` :class:`SmoothingConfig` (v += lambda1 Lap(v) + lambda2
Lap(Lap(v))), ``[symmetry]`` :class:`SymmetryConfig`, ``[profile]`` :class:`ProfileConfig`,
``[stages]`` :class:`StagesConfig`, ``[skin]`` :class:`SkinConfig`; together :class:`GrowthSceneConfig`
(whose old flat names, e.g. ``p.attractors``, still read). ``[material]`` :class:`MaterialConfig`
and ``[loads]`` (target site -> force [N]) make the structural check's :class:`StructureConfig`.

Each table loads through :func:`simfab.io.tables.load_table`: an unknown table or key is refused
naming the file, table and key; a refused value names ``FILE: table.key`` or, when it came from a
flag (:class:`simfab.io.tables.Override`), the flag. Every length is in metres. Parameters left at
``None`` are derived from the design space by :func:`resolve` (see :class:`Resolved`), which also
checks lengths against the box and influence > kill across keys.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

import numpy as np

import simfab.growth.tolerances as tol
from simfab.errors import InputError
from simfab.fem.materials import PLA, Material, material_by_name
from simfab.io.tables import FieldError, Override, load_table

MODES = ("volume", "surface", "profile")
AGES = ("front", "since_birth")


# --------------------------------------------------------------------------- value checks
def _fail(table: str, key: str, message: str):
    raise FieldError(message, key=key, where=f"{table}.{key}")


def _number(obj, table: str, key: str, *, integer=False, positive=True, allow_inf=False) -> None:
    """Check the number ``obj.<key>`` (None: left to its default) and store it as int/float;
    FieldError naming ``table.key``. ``allow_inf``: +inf is accepted too."""
    x = getattr(obj, key)
    if x is None:
        return
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        _fail(table, key, f"expected a number, got {x!r}")
    if integer and not float(x).is_integer():
        _fail(table, key, f"expected an integer, got {x!r}")
    if not math.isfinite(float(x)) and not (allow_inf and x == math.inf):
        _fail(table, key, f"expected a finite number, got {x!r}")
    if positive and not x > 0:
        _fail(table, key, f"must be positive, got {x!r}")
    object.__setattr__(obj, key, int(x) if integer else float(x))


def _vec(x, n, where: str, *, key: str | None = None) -> tuple:
    """``n`` finite numbers as a tuple; FieldError (key ``key``) located at ``where`` otherwise."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise FieldError(f"expected {n} numbers, got {x!r}", key=key or where, where=where) from None
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise FieldError(f"expected {n} finite numbers, got {x!r}", key=key or where, where=where)
    return tuple(float(v) for v in a)


def _integral(v, where):
    """A TOML float with an integer value (``2000.0``) read as the int it is (a parser of :func:`load_table`)."""
    return int(v) if isinstance(v, float) and v.is_integer() else v


# --------------------------------------------------------------------------- one dataclass per TOML table
@dataclasses.dataclass(frozen=True, kw_only=True)
class GrowthConfig:
    """The ``[growth]`` table: attractors and distances of space colonization (``None``: derived
    from the design space by :func:`resolve`).

    Args:
        mode: "volume" (attractors in the design box), "surface" (on the objects' surfaces) or
            "profile" (in a 2D profile swept along its normal).
        attractors: random attractors per growth (per stage).
        influence: attractor influence distance [m] (None: 4 s, s the attractor spacing; 8 s in
            surface and profile modes).
        kill: attractor kill distance [m] (None: 1 s; 3 s in surface and profile modes).
        branch_length: growth step L [m] (None: 0.5 s; 1.5 s in surface and profile modes).
        box: design box ((x0, y0, z0), (x1, y1, z1)) [m] (None: the bounding box of objects, roots, targets).
        surface_objects: surface mode: the bodies to sample (None: all).
        target_influence: influence distance of target attractors [m]; infinite by default so that
            a target keeps pulling its nearest node after every ordinary attractor has died.
        max_steps: growth step cap (None: 12 x the steps needed to cross the design box).
        max_nodes: growth stops at this many nodes.
        max_trials: random directions tried when a branch hits an obstacle.
        seed: seed of grow() when none is given.
    """

    mode: str = "volume"
    attractors: int = 2000
    influence: float | None = None
    kill: float | None = None
    branch_length: float | None = None
    box: tuple | None = None
    surface_objects: tuple | None = None
    target_influence: float = math.inf
    max_steps: int | None = None
    max_nodes: int = 50000
    max_trials: int = 32
    seed: int = 0

    def __post_init__(self):
        t = "growth"
        if self.mode not in MODES:
            _fail(t, "mode", f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        for key in ("attractors", "max_steps", "max_nodes", "max_trials"):
            _number(self, t, key, integer=True)
        _number(self, t, "seed", integer=True, positive=False)
        for key in ("influence", "kill", "branch_length", "target_influence"):
            _number(self, t, key, allow_inf=key == "target_influence")
        if self.box is not None:
            b = self.box
            if not (isinstance(b, (list, tuple)) and len(b) == 2):
                _fail(t, "box", "expected [[x0, y0, z0], [x1, y1, z1]]")
            lo, hi = _vec(b[0], 3, "growth.box", key="box"), _vec(b[1], 3, "growth.box", key="box")
            if not all(h > l for l, h in zip(lo, hi)):
                _fail(t, "box", "box max corner must exceed the min corner on every axis")
            object.__setattr__(self, "box", (lo, hi))
        if self.surface_objects is not None:
            so = self.surface_objects
            if not (isinstance(so, (list, tuple)) and so and all(isinstance(s, str) for s in so)):
                _fail(t, "surface_objects", "expected a non-empty list of body names")
            object.__setattr__(self, "surface_objects", tuple(so))


def _exceed(influence: float, kill: float) -> str:
    return f"influence distance ({influence:.4g} m) must exceed kill distance ({kill:.4g} m)"


@dataclasses.dataclass(frozen=True, kw_only=True)
class RadiusConfig:
    """The ``[radius]`` table: branch radius r = r_min + (r_max - r_min) exp(-decay age).

    Args:
        r_min, r_max: thinnest and thickest radius [m] (None: derived). decay: k [1/step] (None: derived).
        age: how a node's age is counted: "front" (its birth step, so the root is oldest in
            growth-front terms and gets r_max) or "since_birth" (steps from its birth to the end of
            growth, the literal reading; the root then gets r_min).
    """

    r_min: float | None = None
    r_max: float | None = None
    decay: float | None = None
    age: str = "front"

    def __post_init__(self):
        if self.age not in AGES:
            _fail("radius", "age", f"expected 'front' or 'since_birth', got {self.age!r}")
        _number(self, "radius", "r_min")
        _number(self, "radius", "r_max")
        _number(self, "radius", "decay", positive=False)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SmoothingConfig:
    """The ``[smoothing]`` table: v += lambda1 Lap(v) + lambda2 Lap(Lap(v)), roots, targets and leaves fixed.

    Args:
        iterations: smoothing passes (0: none).
        lambda1: weight of the Laplacian term [-].
        lambda2: weight of the bi-Laplacian term [-].
    """

    iterations: int = 10
    lambda1: float = 0.2
    lambda2: float = 0.1

    def __post_init__(self):
        _number(self, "smoothing", "iterations", integer=True, positive=False)
        _number(self, "smoothing", "lambda1", positive=False)
        _number(self, "smoothing", "lambda2", positive=False)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SymmetryConfig:
    """The ``[symmetry]`` table: mirror-symmetric growth (also ``--symmetric``).

    Args:
        enabled: grow mirror-symmetrically (``false`` turns the table off).
        point: a point of the mirror plane, (3,) [m].
        normal: the mirror plane's normal, (3,) (stored unit length).
    """

    enabled: bool = True
    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (1.0, 0.0, 0.0)

    def __post_init__(self):
        n = np.array(_vec(self.normal, 3, "symmetry.normal", key="normal"))
        if not np.linalg.norm(n) > 0:
            _fail("symmetry", "normal", "normal must be non-zero")
        object.__setattr__(self, "normal", tuple(float(x) for x in n / np.linalg.norm(n)))
        object.__setattr__(self, "point", _vec(self.point, 3, "symmetry.point", key="point"))


@dataclasses.dataclass(frozen=True, kw_only=True)
class ProfileConfig:
    """The ``[profile]`` table (mode "profile"): a closed 2D profile swept along ``u x v``. Every key
    is required.

    Args:
        origin: the profile plane's origin, (3,) [m].
        u: the plane's first in-plane direction, (3,) (stored unit length).
        v: the plane's second in-plane direction, (3,) (stored unit length).
        points: the closed profile, (k, 2) [m] in the plane origin + a u + b v.
        depth: (d0, d1) [m]: the sweep's extent along u x v.
    """

    origin: tuple | None = None
    u: tuple | None = None
    v: tuple | None = None
    points: tuple | None = None
    depth: tuple | None = None

    def __post_init__(self):
        for key in ("origin", "u", "v", "points", "depth"):
            if getattr(self, key) is None:
                raise FieldError(f"missing key {key!r}", key=key, where="profile")
        u = np.array(_vec(self.u, 3, "profile.u", key="u"))
        v = np.array(_vec(self.v, 3, "profile.v", key="v"))
        if np.linalg.norm(np.cross(u, v)) < 1e-9 * max(np.linalg.norm(u) * np.linalg.norm(v), 1e-300):
            raise FieldError("u and v must be non-zero and not parallel", key="v", where="profile")
        pts = self.points
        if not isinstance(pts, (list, tuple)) or len(pts) < 3:
            _fail("profile", "points", "a closed profile needs at least 3 points")
        d = _vec(self.depth, 2, "profile.depth", key="depth")
        if not d[1] >= d[0]:
            _fail("profile", "depth", "depth must be [d0, d1] with d1 >= d0")
        object.__setattr__(self, "points", tuple(_vec(q, 2, "profile.points", key="points") for q in pts))
        object.__setattr__(self, "depth", d)
        object.__setattr__(self, "origin", _vec(self.origin, 3, "profile.origin", key="origin"))
        object.__setattr__(self, "u", tuple(float(x) for x in u / np.linalg.norm(u)))
        object.__setattr__(self, "v", tuple(float(x) for x in v / np.linalg.norm(v)))


@dataclasses.dataclass(frozen=True, kw_only=True)
class StagesConfig:
    """The ``[stages]`` table: guided progressive growth.

    Args:
        targets: target site names per stage, ``[[names], ...]``; targets not listed grow in a last stage.
    """

    targets: tuple | None = None

    def __post_init__(self):
        t = self.targets
        if not (isinstance(t, (list, tuple)) and t
                and all(isinstance(x, (list, tuple)) and x and all(isinstance(n, str) for n in x) for x in t)):
            _fail("stages", "targets", "expected a list of non-empty lists of target site names")
        object.__setattr__(self, "targets", tuple(tuple(x) for x in t))


@dataclasses.dataclass(frozen=True, kw_only=True)
class SkinConfig:
    """The ``[skin]`` table.

    Args:
        segments: circular resolution of joint spheres (>= 6). subtract_objects: carve the objects out.
        tolerance: largest penetration depth [m] of the skin into an object that is accepted (with
            carving it is 0 up to round-off; without, the run fails above it).
    """

    segments: int = 12
    subtract_objects: bool = True
    tolerance: float = 0.0

    def __post_init__(self):
        _number(self, "skin", "tolerance", positive=False)
        if self.tolerance < 0:
            _fail("skin", "tolerance", "must be >= 0")
        _number(self, "skin", "segments", integer=True)
        if self.segments < 6:
            _fail("skin", "segments", "need at least 6 segments")
        if not isinstance(self.subtract_objects, bool):
            _fail("skin", "subtract_objects", "expected true or false")


#: the tables of :class:`GrowthSceneConfig` and their config types (None: the table is optional, absent = off)
TABLES = {"growth": GrowthConfig, "radius": RadiusConfig, "smoothing": SmoothingConfig, "symmetry": SymmetryConfig,
          "profile": ProfileConfig, "stages": StagesConfig, "skin": SkinConfig}
#: the old flat names of the growth parameters -> (table, key)
FLAT = {**{k: ("growth", k) for k in ("mode", "attractors", "influence", "kill", "branch_length", "box",
                                       "surface_objects", "target_influence", "max_steps", "max_nodes",
                                       "max_trials", "seed")},
        "r_min": ("radius", "r_min"), "r_max": ("radius", "r_max"), "radius_decay": ("radius", "decay"),
        "radius_age": ("radius", "age"), "smoothing_iterations": ("smoothing", "iterations"),
        "lambda1": ("smoothing", "lambda1"), "lambda2": ("smoothing", "lambda2"),
        "skin_segments": ("skin", "segments"), "subtract_objects": ("skin", "subtract_objects"),
        "skin_tolerance": ("skin", "tolerance")}
_PARSERS = {"growth": dict.fromkeys(("attractors", "max_steps", "max_nodes", "max_trials", "seed"), _integral),
            "smoothing": {"iterations": _integral}, "skin": {"segments": _integral}}


@dataclasses.dataclass(frozen=True, kw_only=True)
class GrowthSceneConfig:
    """Growth parameters nested like the scene's TOML tables (see the module docstring).

    Args:
        growth, radius, smoothing, skin: the tables' configs (defaults when the table is absent).
        symmetry, profile, stages: the optional tables (None: absent, or ``[symmetry] enabled = false``).
        from_file: the ``"table.key"`` s the scene file set (so that a flag replacing one is noted).

    The old flat names (``p.attractors``, ``p.radius_decay``, ``p.skin_tolerance``, ...; :data:`FLAT`)
    read the nested values; :meth:`of` and :meth:`replace` take them.
    """

    growth: GrowthConfig = dataclasses.field(default_factory=GrowthConfig)
    radius: RadiusConfig = dataclasses.field(default_factory=RadiusConfig)
    smoothing: SmoothingConfig = dataclasses.field(default_factory=SmoothingConfig)
    symmetry: SymmetryConfig | None = None
    profile: ProfileConfig | None = None
    stages: StagesConfig | None = None
    skin: SkinConfig = dataclasses.field(default_factory=SkinConfig)
    from_file: frozenset = dataclasses.field(default=frozenset(), compare=False, repr=False)

    @classmethod
    def of(cls, **values) -> "GrowthSceneConfig":
        """Parameters from flat names (``GrowthSceneConfig.of(mode="surface", kill=0.01)``), checked.

        Args:
            **values: :data:`FLAT` names, or ``symmetry`` / ``profile`` / ``stages`` configs.

        Returns:
            The parameters; InputError naming the key of a refused value.
        """
        return cls().replace(**values)

    def replace(self, *, file: str | None = None, log: Callable[[str], None] | None = None,
                **values) -> "GrowthSceneConfig":
        """A copy with some values replaced, each table re-checked through :func:`simfab.io.tables.load_table`.

        Args:
            file: the scene TOML the current values came from (a refused one of its values is
                located there; a note names it).
            log: called once per :class:`Override` that replaces a value differing from the default.
            **values: :data:`FLAT` names -> value or :class:`Override` (its source names the flag in
                an error); ``symmetry`` / ``profile`` / ``stages``: a config or None (absent).

        Returns:
            The new parameters; InputError naming the flag or the file, table and key.
        """
        unknown = sorted(set(values) - set(FLAT) - {"symmetry", "profile", "stages"})
        if unknown:
            raise InputError(f"unknown growth parameter(s) {', '.join(unknown)}")
        kw = {k: values.pop(k) for k in ("symmetry", "profile", "stages") if k in values}
        per_table: dict[str, dict] = {}
        for name, v in values.items():
            table, key = FLAT[name]
            per_table.setdefault(table, {})[key] = v
        if "growth" in per_table:
            _blame_exceed(self.growth, per_table["growth"])
        for table, ov in per_table.items():
            kw[table] = load_table(TABLES[table], self._given(table), table_name=table, file=file,
                                   overrides=ov, parsers=_PARSERS.get(table), log=log)
        return dataclasses.replace(self, **kw)

    def _given(self, table: str) -> dict:
        """The values of a table the scene file set or that differ from their defaults."""
        cfg = getattr(self, table)
        return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)
                if getattr(cfg, f.name) != f.default or f"{table}.{f.name}" in self.from_file}


def _blame_exceed(g: GrowthConfig, ov: Mapping) -> None:
    """The check influence > kill across two keys, blamed on the flag that gave one of them
    (:func:`resolve` checks it again with derived values, blaming the key given)."""
    val = {k: (ov[k].value if isinstance(ov[k], Override) else ov[k]) if k in ov else getattr(g, k)
           for k in ("influence", "kill")}
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < math.inf for v in val.values()):
        return  # each key's own check speaks first
    if not val["influence"] > val["kill"]:
        src = next((ov[k].source for k in ("kill", "influence") if isinstance(ov.get(k), Override)), None)
        if src is not None:
            raise InputError(_exceed(val["influence"], val["kill"]), where=src)


def _flat_property(table: str, key: str):
    return property(lambda self: getattr(getattr(self, table), key), doc=f"``[{table}] {key}``")


for _name, (_table, _key) in FLAT.items():
    setattr(GrowthSceneConfig, _name, _flat_property(_table, _key))

# the former names (simfab.growth exports them)


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


def resolve(p: GrowthSceneConfig, box: np.ndarray, *, area: float | None = None) -> Resolved:
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
    if not infl > kill:  # blamed on kill, or on influence when only it was given (flags: GrowthSceneConfig.replace)
        key = "kill" if p.kill is not None else "influence" if p.influence is not None else None
        raise FieldError(_exceed(infl, kill), key=f"growth.{key}" if key else "growth",
                         where=f"growth.{key}" if key else "growth")
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


def check_scale(p: GrowthSceneConfig, box: np.ndarray) -> None:
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
@dataclasses.dataclass(frozen=True, kw_only=True)
class MaterialConfig:
    """The ``[material]`` table: the printed material of the structural check.

    Args:
        name: a built-in base material (PLA, VeroWhite; None: PLA); the keys below override it.
        youngs_modulus: Young's modulus [Pa] (None keeps the base material's).
        poisson_ratio: Poisson's ratio [-] in (-1, 0.5) (None keeps the base material's).
        yield_stress: von Mises yield stress [Pa] (None keeps the base material's).
        density: density [kg/m^3] (None keeps the base material's).
        critical_distance: radius [m] the von Mises stress is averaged over (0: the largest point value).
    """

    name: str | None = None
    youngs_modulus: float | None = None
    poisson_ratio: float | None = None
    yield_stress: float | None = None
    density: float | None = None
    critical_distance: float = tol.CRITICAL_DISTANCE

    def __post_init__(self):
        if self.name is not None:
            if not isinstance(self.name, str):
                _fail("material", "name", f"expected a material name, got {self.name!r}")
            try:
                material_by_name(self.name)
            except InputError as e:
                _fail("material", "name", e.message)
        for key in ("youngs_modulus", "yield_stress", "density"):
            _number(self, "material", key)
        _number(self, "material", "poisson_ratio", positive=False)
        if self.poisson_ratio is not None and not -1.0 < self.poisson_ratio < 0.5:
            _fail("material", "poisson_ratio", f"must lie in (-1, 0.5), got {self.poisson_ratio}")
        _number(self, "material", "critical_distance", positive=False)
        if self.critical_distance < 0:
            _fail("material", "critical_distance", f"must be >= 0, got {self.critical_distance}")

    def material(self) -> Material:
        """The :class:`simfab.fem.materials.Material` (the base material with the given keys replaced)."""
        base = material_by_name(self.name) if self.name is not None else PLA
        over = {k: getattr(self, k) for k in ("youngs_modulus", "poisson_ratio", "yield_stress", "density")
                if getattr(self, k) is not None}
        return dataclasses.replace(base, name=self.name or base.name, **over) if over else base


@dataclasses.dataclass(frozen=True, kw_only=True)
class StructureConfig:
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



#: every table of a growth scene's TOML ([loads] is free-form: target site name -> force)
SCENE_TABLES = (*TABLES, "material", "loads")


def check_growth_tables(doc: Mapping, file: str | None) -> None:
    """Refuse a top-level entry of a growth TOML that is not one of :data:`SCENE_TABLES`.

    Args:
        doc: the parsed TOML. file: its path.

    Raises:
        InputError: ``FILE: unknown table [t] (known: [growth], ...)``.
    """
    for k, v in doc.items():
        if k not in SCENE_TABLES:
            what = f"table [{k}]" if isinstance(v, Mapping) else f"key {k!r}"
            raise InputError(f"unknown {what} (known: {', '.join(f'[{t}]' for t in sorted(SCENE_TABLES))})",
                             where=file)


def structure_from_toml(doc: dict, where: str) -> StructureConfig:
    """:class:`StructureConfig` from a parsed scene TOML (``[material]``, ``[loads]``).

    Args:
        doc: the parsed TOML. where: its path.

    Returns:
        The config; InputError names the file, table and key. Target names in ``[loads]`` are checked
        against the scene's sites by :func:`simfab.growth.scene.load_growth_scene`.
    """
    m = load_table(MaterialConfig, doc.get("material"), table_name="material", file=where)
    ld = doc.get("loads", {})
    if not isinstance(ld, dict):
        raise InputError("expected a table", where=f"{where}: [loads]")
    try:
        loads = tuple((str(k), _vec(v, 3, f"loads.{k}")) for k, v in ld.items())
    except InputError as e:
        raise e.in_file(where) from None
    return StructureConfig(material=m.material(), critical_distance=m.critical_distance, loads=loads)


def params_from_toml(doc: dict, where: str, *, overrides: Mapping | None = None,
                     log: Callable[[str], None] | None = None) -> GrowthSceneConfig:
    """:class:`GrowthSceneConfig` from a parsed scene TOML, each table through :func:`simfab.io.tables.load_table`.

    Args:
        doc: the parsed TOML. where: its path.
        overrides: :data:`FLAT` names -> value or :class:`Override` (e.g. command-line flags).
        log: called once per flag that replaces a value of the file.

    Returns:
        The parameters; InputError naming the file, table and key (or the flag a value came from).
    """
    check_growth_tables(doc, where)
    kw = {}
    for table, cls in TABLES.items():
        if table in ("symmetry", "profile", "stages") and doc.get(table) is None:
            continue
        kw[table] = load_table(cls, doc.get(table), table_name=table, file=where, parsers=_PARSERS.get(table))
    if "symmetry" in kw and not kw["symmetry"].enabled:
        kw["symmetry"] = None
    given = frozenset(f"{t}.{k}" for t in TABLES if isinstance(doc.get(t), Mapping) for k in doc[t])
    p = GrowthSceneConfig(**kw, from_file=given)
    return p.replace(file=where, log=log, **overrides) if overrides else p
