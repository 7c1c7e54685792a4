"""Coupling scenes: an MJCF file plus a companion TOML file with the same stem.

The **MJCF** (``NAME.xml``, opens in the MuJoCo viewer) holds the rigid object O (a mocap body,
default ``object``; in 2D its cross-section with z = 0), O's path (keyframes of the mocap body,
:class:`simfab.io.trajectory.Trajectory`), the fixed region of A (a box site, default ``fixed``,
``size`` along its own axes: a ``quat`` turns it, in 2D about z only) and A's rest shape as a display mesh.

The **TOML** (``NAME.toml``) defines A and the run (SI units)::

    name = "cclamp2d"
    dim = 2                              # 2 (plane strain) or 3
    [material]  name = "PLA"             # or youngs_modulus [Pa], poisson_ratio, yield_stress [Pa]
    [compliant] generator = "c_clamp", target_elements = 450, thickness = 0.005 (2D), ...
                # c_clamp | extruded_clamp | cross_claw | outline = "part.csv" (x,y rows, or loop,x,y with
                # holes) | mesh = "part.stl"; mesh_file = "part.npz": a ready mesh (points, elements)
    [object]    body, samples, sigma, seed, rot_length_scale   (ObjectConfig)
    [fixed]     site = "fixed"
    [simulation] steps = 35 (or h_in [m]), L_max [m], element_order = 1 | 2, ...  (InsertionConfig)
    [contact]   friction, friction_eps_rel, lag_tol, max_lag_iterations  (ContactConfig)
    [design]    the design brief (simfab.design.brief.DesignConfig; read by ``couple optimize``)

Every table and key is checked against :data:`SCENE_TABLES` before anything is built; the config
tables load through :func:`simfab.io.tables.load_table`, so an error names the file, table and key,
or the flag (:class:`simfab.io.tables.Override`) a value came from. The full format:
docs/methods.md, "simfab.coupling.scene".
"""

from __future__ import annotations

import inspect
from dataclasses import fields
from pathlib import Path

import numpy as np

from simfab._bundled import scenes_dir
from simfab.contact.imls import build_imls
from simfab.contact.sdf import build_primitive_field, primitives_of_body, section_primitives
from simfab.coupling import geometry
from simfab.coupling.config import ContactConfig, InsertionConfig, ObjectConfig
from simfab.coupling.simulate import make_coupling_model
from simfab.errors import InputError
from simfab.fem.materials import Material, material_by_name
from simfab.fem.meshing import extrude_triangles, tetrahedralize, triangulate_polygon
from simfab.fem.model import make_model
from simfab.fem.p2 import to_p2
from simfab.io import tables
from simfab.io.companion import read_csv_numbers, read_npz
from simfab.io.mesh import load_mesh
from simfab.io.mjcf_load import load_mjcf
from simfab.io.trajectory import Trajectory
from simfab.progress import log as progress_log
from simfab.rotations import quat_to_matrix

GENERATORS_2D = ("c_clamp", "outline")
GENERATORS_3D = ("extruded_clamp", "cross_claw", "mesh")


def _names(cls) -> frozenset:
    return frozenset(f.name for f in fields(cls))


def _compliant_keys(table: dict, dim: int) -> frozenset | None:
    """The keys [compliant] may hold: the common ones and those of its generator (its function's
    keyword parameters); None for an unknown generator (build_compliant names it)."""
    gen = table.get("generator")
    if gen is None:  # the generator inferred from the part's source (outline / mesh file)
        gen = "outline" if "outline" in table else "mesh" if "mesh" in table else None
    common = {"generator", "target_elements", "units", "mesh_file"} | ({"thickness"} if dim == 2 else set())
    own = {None: set(), "outline": {"outline"}, "mesh": {"mesh"},
           "c_clamp": _kwargs(geometry.c_clamp_outline),
           "extruded_clamp": {"layers", "height"} | _kwargs(geometry.c_clamp_outline),
           "cross_claw": {"height"} | _kwargs(geometry.c_clamp_outline)}.get(gen)
    return None if own is None else frozenset(common | own)


def _kwargs(fn) -> set:
    return {n for n, p in inspect.signature(fn).parameters.items() if p.kind == p.KEYWORD_ONLY}


#: Top-level keys of a coupling scene's TOML that are not tables.
TOP_LEVEL_KEYS = frozenset({"name", "dim"})
#: Every table a coupling scene's TOML may hold and the keys allowed in it: a set of names, or a
#: function (table, dim) -> names when they depend on the table's values ([compliant]: its
#: generator's parameters; None there leaves the error to the generator check). The table's own
#: configuration (e.g. InsertionConfig) validates the values. A new table is one line here.
SCENE_TABLES: dict = {
    "material": frozenset({"name", "youngs_modulus", "poisson_ratio", "yield_stress", "density"}),
    "compliant": _compliant_keys,
    "object": _names(ObjectConfig),
    "fixed": frozenset({"site"}),
    "simulation": _names(InsertionConfig),
    "contact": _names(ContactConfig),
    "design": None,  # keys and values checked by simfab.design.brief.DesignConfig where the brief is read
}


def check_tables(cfg: dict, where: str) -> None:
    """Check every table and key of a coupling scene's TOML against :data:`SCENE_TABLES`.

    Args:
        cfg: the TOML document.
        where: the TOML file, for messages.

    Raises:
        InputError: naming ``where``, the table and the key of the first unknown table, unknown key,
            or table given as a plain value.
    """
    dim = cfg.get("dim", 2)
    for key, value in cfg.items():
        if key in TOP_LEVEL_KEYS:
            continue
        if key not in SCENE_TABLES:
            what = "table" if isinstance(value, dict) else "key"
            known = ", ".join([f"[{t}]" for t in SCENE_TABLES] + sorted(TOP_LEVEL_KEYS))
            raise InputError(f"unknown {what} {f'[{key}]' if what == 'table' else repr(key)} (a coupling scene "
                             f"has {known})", where=where)
        if not isinstance(value, dict):
            raise InputError(f"[{key}] must be a table, got {value!r}", where=where)
        allowed = SCENE_TABLES[key]
        if callable(allowed):
            allowed = allowed(value, dim)
        if allowed is None:
            continue
        extra = sorted(k for k in value if k not in allowed)
        if extra:
            raise InputError(f"[{key}]: unknown key {extra[0]!r} (known: {', '.join(sorted(allowed))})", where=where)


def read_scene_toml(path: Path) -> dict:
    """A coupling scene's TOML document (InputError naming the file when missing or not TOML).

    Args:
        path: the scene's ``NAME.toml``.

    Returns:
        Its tables.
    """
    return tables.read_toml(path, missing="companion TOML file not found (a coupling scene is NAME.xml + NAME.toml)")


def scene_paths(scene) -> tuple[Path, Path]:
    """The two files of a coupling scene.

    Args:
        scene: NAME.xml, NAME.toml or NAME (a bundled scene: scenes/coupling/NAME, unless a file of
            that name exists).

    Returns:
        (xml, toml) paths.
    """
    p = Path(scene)
    if p.suffix in (".xml", ".toml"):
        return p.with_suffix(".xml"), p.with_suffix(".toml")
    # a folder of that name (e.g. the --out folder of an earlier run) does not hide a bundled scene
    if not p.is_file() and not p.with_suffix(".xml").is_file():
        bundled = bundled_dir() / p.name
        if bundled.with_suffix(".xml").exists():
            p = bundled
    return p.with_suffix(".xml"), p.with_suffix(".toml")


def bundled_dir() -> Path:
    """The folder of the bundled coupling scenes.

    Returns:
        scenes/coupling inside the installed package.
    """
    return scenes_dir("coupling")


def _section(cfg: dict, name: str, where: str) -> dict:
    v = cfg.get(name, {})
    if not isinstance(v, dict):
        raise InputError(f"[{name}] must be a table", where=where)
    return dict(v)


#: The tables read into config classes (:func:`simfab.io.tables.load_table`): their overrides may carry
#: their source (a command-line flag, :class:`simfab.io.tables.Override`).
CONFIG_TABLES = {"simulation": InsertionConfig, "contact": ContactConfig, "object": ObjectConfig}


def load_coupling_scene(scene, *, overrides: dict | None = None, device: str = "cpu", quiet: bool = True):
    """Build a :class:`simfab.coupling.model.CouplingModel` from a scene (see the module docstring).

    Args:
        scene: ``NAME.xml``, ``NAME.toml`` or a bundled scene's name.
        overrides: {table: {key: value}} replacing the TOML's values (e.g. ``{"simulation": {"steps": 5}}``);
            a value may be a :class:`simfab.io.tables.Override` naming its source (``--friction``), which
            an error then names instead of the file; ``None`` removes a key.
        device: the Warp device.
        quiet: do not log the flags that replace a value of the scene file.

    Returns:
        The coupling model.
    """

    xml, toml = scene_paths(scene)
    if not xml.is_file():
        raise InputError("scene file not found", where=str(xml))
    cfg = read_scene_toml(toml)
    overrides = dict(overrides or {})
    config_overrides = {t: overrides.pop(t) or {} for t in CONFIG_TABLES if t in overrides}
    for k, v in overrides.items():
        if isinstance(v, dict):
            cfg.setdefault(k, {}).update(v)
        else:
            cfg[k] = v
    where = str(toml)
    dim = cfg.get("dim", 2)
    if isinstance(dim, bool) or dim not in (2, 3):
        raise InputError(f"dim must be 2 or 3, got {dim!r}", where=where)
    check_tables({k: ({kk: vv for kk, vv in v.items() if vv is not None} if isinstance(v, dict) else v)
                  for k, v in cfg.items()}, where)  # None: an override that removes a key
    name = str(cfg.get("name", xml.stem))

    mat = _section(cfg, "material", where)
    if "youngs_modulus" in mat:
        vals = {}
        for key, default in (("youngs_modulus", None), ("poisson_ratio", 0.35), ("yield_stress", 60e6),
                             ("density", 1200.0)):
            try:
                vals[key] = float(mat.get(key, default))
            except (TypeError, ValueError):
                raise InputError(f"[material] {key} must be a number, got {mat.get(key)!r}", where=where) from None
        try:
            material = Material(name=str(mat.get("name", "custom")), **vals)
        except (TypeError, ValueError) as e:
            raise InputError(f"[material]: {e}", where=where) from None
    else:
        try:
            material = material_by_name(mat.get("name", "PLA"))
        except InputError as e:
            raise InputError(f"[material] name: {e.message}", where=where) from None

    comp = _section(cfg, "compliant", where)
    fixed_cfg = _section(cfg, "fixed", where)
    notes = []  # flags that replace values of the file: logged once the scene is built (an error stays one line)
    options, contact, obj_opts = (
        tables.load_table(cls, cfg.get(t), table_name=t, file=where, overrides=config_overrides.get(t),
                          log=notes.append)
        for t, cls in CONFIG_TABLES.items())

    points, elements, thickness = build_compliant(comp, dim, base=toml.parent, where=f"{where} [compliant]")
    fem = make_model(points, elements, material, thickness=thickness, device=device)
    if options.element_order == 2:

        fem = to_p2(fem)  # the fixed region below then holds the midpoints inside it as well

    sc = load_mjcf(xml)
    body = obj_opts.body
    rho = obj_opts.rot_length_scale
    path = Trajectory.from_scene(sc, body=body, **({} if rho is None else {"rot_length_scale": float(rho)}))
    if dim == 2:
        check_planar_path(path, where=str(xml))
    n_samples = obj_opts.samples if obj_opts.samples is not None else (50 if dim == 2 else 2000)
    fld = primitive_field(sc, body, dim, n_samples) if obj_opts.sigma is None else None
    # O's mesh: sampled for its IMLS field, or displayed in 3D (a 2D primitive shows its exact samples)
    mesh = object_mesh_body_frame(sc, body) if fld is None or dim == 3 else None
    if fld is not None:  # exact signed distance of primitive geoms (simfab.contact.sdf)
        disp_v, disp_f = (fld.vertices, None) if dim == 2 else (np.asarray(mesh.vertices), np.asarray(mesh.faces))
    elif dim == 2:
        ov, on = geometry.section_samples(mesh, n_samples)
        spacing = float(np.linalg.norm(np.diff(np.vstack([ov, ov[:1]]), axis=0), axis=1).mean())
        disp_v, disp_f = ov, None
    else:
        ov, on = geometry.mesh_surface_samples(mesh, n_samples, seed=obj_opts.seed)
        spacing = None
        disp_v, disp_f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if fld is None:

        sigma = obj_opts.sigma
        fld = build_imls(ov, on, sigma=None if sigma is None else float(sigma), spacing=spacing, device=device,
                         area=None if dim == 2 else float(mesh.area))

    site = str(fixed_cfg.get("site", "fixed"))
    if site not in sc.sites:
        raise InputError(f"no site named {site!r} (the fixed region of the compliant part)", where=str(xml))
    if dim == 2:
        check_turned_about_z(sc, site, where=str(xml))
    fixed = np.flatnonzero(sc.in_box(site, fem.rest))
    cm = make_coupling_model(name=name, fem=fem, field=fld, path=path, fixed_vertices=fixed, options=options,
                             object_vertices=disp_v, object_faces=disp_f, contact=contact)
    for note in notes:
        progress_log(note, quiet=quiet)
    return cm


def primitive_field(sc, body: str, dim: int, samples: int):
    """Exact signed-distance field of O when all its geoms are primitives.

    Spheres, capsules, cylinders, boxes or tori (in 2D: whose z = 0 section is a circle or an aligned
    rectangle); the geoms' poses are taken relative to the mocap body.

    Args:
        sc: the loaded scene.
        body: O's mocap body.
        dim: 2 or 3.
        samples: display samples of the field.

    Returns:
        :class:`simfab.contact.sdf.PrimitiveField`, or None (O is then sampled and its IMLS field used).
    """
    import mujoco


    bid = mujoco.mj_name2id(sc.model, mujoco.mjtObj.mjOBJ_BODY, body)
    prims = primitives_of_body(sc.model, bid, sc.sdf_plugins) if bid >= 0 else None
    if prims is not None and dim == 2:
        prims = section_primitives(prims)
    return None if prims is None else build_primitive_field(prims, dim, samples)


def object_mesh_body_frame(sc, body: str):
    """O's geoms as one mesh in O's body frame (the mocap body's pose at qpos0 undone).

    Args:
        sc: the loaded scene.
        body: O's mocap body.

    Returns:
        ``trimesh.Trimesh``; InputError naming the MJCF when the body has no geometry.
    """
    import mujoco

    meshes = sc.body_meshes()
    if body not in meshes:
        raise InputError(f"body {body!r} has no geometry to build the object from", where=str(sc.path))
    m = meshes[body].copy()
    bid = mujoco.mj_name2id(sc.model, mujoco.mjtObj.mjOBJ_BODY, body)

    R = quat_to_matrix(sc.model.body_quat[bid])
    p = np.asarray(sc.model.body_pos[bid])
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = -R.T @ p
    m.apply_transform(T)
    return m


def part_surface(scene):
    """The surface a 3D scene's part is meshed from (``[compliant] mesh``, in the scene's frame) [m], or
    None (a 2D scene, a generator's part).

    Args:
        scene: NAME.xml, NAME.toml or a bundled scene's name.

    Returns:
        A trimesh, or None.
    """
    toml = scene_paths(scene)[1]
    doc = read_scene_toml(toml)
    comp = doc.get("compliant") or {}
    if doc.get("dim") != 3 or "mesh" not in comp:
        return None
    return load_mesh(toml.parent / str(comp["mesh"]), units=comp.get("units", "m"), require_watertight=True)


def stored_part_table(mesh_file: str, surface: str, units: str, tets: int) -> dict:
    """The ``[compliant]`` table of a 3D part stored as tets beside the surface they were meshed from: the
    tets (``mesh_file``) are what every run meshes, the surface (``generator = "mesh"``) is what a
    convergence study meshes again at multiples of their count (:mod:`simfab.coupling.converge`).

    Args:
        mesh_file: the tets' file (.npz: points, elements), relative to the scene.
        surface: the surface mesh file, relative to the scene.
        units: the surface file's unit ("m" or "mm").
        tets: the stored tets' count.

    Returns:
        The table.
    """
    return {"generator": "mesh", "mesh": surface, "units": units, "target_elements": int(tets),
            "mesh_file": mesh_file}


def build_compliant(comp: dict, dim: int, *, base: Path, where: str):
    """A's mesh from the ``[compliant]`` table.

    Args:
        comp: the table (its keys are consumed).
        dim: 2 or 3.
        base: the folder relative paths (outline, mesh, mesh_file) are read from.
        where: the file and table, for messages.

    Returns:
        (points (n, dim) [m], elements (m, dim + 1), thickness [m]; 1 in 3D).
    """

    gen = comp.pop("generator", None)
    cached = comp.pop("mesh_file", None)
    if cached is not None:
        return load_mesh_file(base / str(cached), dim) + ((float(comp.get("thickness", 1.0)) if dim == 2 else 1.0),)
    target = comp.pop("target_elements", None)
    if target is not None and (isinstance(target, bool) or not isinstance(target, int) or target < 1):
        raise InputError(f"target_elements must be an integer >= 1, got {target!r}", where=where)
    thickness = float(comp.pop("thickness", 1.0)) if dim == 2 else 1.0
    units = comp.pop("units", "m")
    scale = {"m": 1.0, "mm": 1e-3}.get(units)
    if scale is None:
        raise InputError(f"units must be 'm' or 'mm', got {units!r}", where=where)
    if dim == 2:
        if gen == "c_clamp":
            outline, holes = _call(geometry.c_clamp_outline, comp, where), []
        elif gen == "outline" or "outline" in comp:
            outline, holes = read_outline(base / str(comp.pop("outline")), scale)
        else:
            raise InputError(f"2D generator must be one of {GENERATORS_2D}, got {gen!r}", where=where)
        if not (np.isfinite(thickness) and thickness > 0):
            raise InputError(f"thickness must be a positive length [m], got {thickness}", where=where)
        try:
            return _triangulate_to_target(outline, target, holes) + (thickness,)
        except InputError as e:
            raise e.in_file(where) from None
    if gen == "extruded_clamp":
        # an extrusion meshed as one: the clamp's outline triangulated to target / (3 layers)
        # triangles, extruded in prisms of 3 tets (in-plane bending resolved like the 2D mesh; an
        # isotropic fTetWild mesh of the same part was 150% too stiff at 1,070 tets, 18% at 11k)

        layers = comp.pop("layers", 1)
        if isinstance(layers, bool) or not isinstance(layers, int) or not 1 <= layers <= 64:
            raise InputError(f"layers must be an integer in [1, 64], got {layers!r}", where=where)
        height = comp.pop("height", None)
        if not (isinstance(height, (int, float)) and height > 0):
            raise InputError(f"height must be a positive length [m], got {height!r}", where=where)
        outline = _call(geometry.c_clamp_outline, comp, where)
        tris = None if target is None else max(1, int(round(target / (3 * layers))))
        try:
            P2, F2 = _triangulate_to_target(outline, tris)
        except InputError as e:
            raise e.in_file(where) from None
        V, T = extrude_triangles(P2, F2, -0.5 * height, 0.5 * height, layers)
        return V, T, 1.0
    elif gen == "cross_claw":
        surf = _call(geometry.cross_claw, comp, where)
    elif gen == "mesh" or "mesh" in comp:

        surf = load_mesh(base / str(comp.pop("mesh")), units=units, require_watertight=True)
    else:
        raise InputError(f"3D generator must be one of {GENERATORS_3D}, got {gen!r}", where=where)
    try:
        V, T = tetrahedralize(np.asarray(surf.vertices), np.asarray(surf.faces), target_tets=target)
    except InputError as e:
        raise e.in_file(where) from None
    return V, T, 1.0


#: A 2D scene's keyframes lie in the plane z = 0 within this distance [m] and turn about z within this
#: sine of the tilt.
PLANE_TOL = 1e-9


def check_turned_about_z(sc, site: str, *, where: str) -> None:
    """Raise an InputError unless the box site ``site`` of a 2D scene is turned about z only (its section
    with the plane z = 0 is then a rectangle: the region it holds).

    Args:
        sc: the loaded MJCF scene.
        site: the site's name.
        where: the scene file, for the message.
    """
    axes = sc.site_axes.get(site, np.eye(3))
    if abs(abs(axes[2, 2]) - 1.0) > PLANE_TOL:
        raise InputError(f"site {site!r} is turned about an axis other than z; a 2D scene's box sites turn "
                         "about z only (their section with the plane z = 0 is the region)", where=where)


def check_planar_path(path: Trajectory, *, where: str) -> None:
    """Raise an InputError unless every keyframe of a 2D scene's path puts O in the plane z = 0 and turns
    it about z only: the 2D model meets O's section with that plane (its body frame's z = 0 section carried
    by the poses), and a keyframe off the plane leaves every point of the part beyond O's field (the barrier
    never acts, and the first contact is an infeasible step).

    Args:
        path: O's path.
        where: the scene file, for the message.
    """
    z = path.positions[:, 2]
    k = np.flatnonzero(np.abs(z) > PLANE_TOL)
    if k.size:
        raise InputError(f"keyframe {int(k[0])} puts the object at z = {z[k[0]]:.6g} m; a 2D scene's object moves "
                         "in the plane z = 0 (set the keyframes' mpos z, and the body's pos, to 0)", where=where)
    tilt = np.hypot(path.quats[:, 1], path.quats[:, 2])
    k = np.flatnonzero(tilt > PLANE_TOL)
    if k.size:
        raise InputError(f"keyframe {int(k[0])} turns the object about an axis other than z (mquat "
                         f"{tuple(np.round(path.quats[k[0]], 6).tolist())}); a 2D scene's object turns in the plane",
                         where=where)


def load_mesh_file(path: Path, dim: int):
    """A ready simplicial mesh from an ``.npz`` with arrays ``points`` and ``elements``.

    Bundled 3D scenes ship their tetrahedral mesh this way (the mesh generated once by
    ``scenes/coupling/make_scenes.py`` is stored with the scene, so its figures stay fixed).

    Args:
        path: the ``.npz`` file.
        dim: 2 or 3.

    Returns:
        (points (n, dim) [m] float64, elements (m, dim + 1) int64); InputError naming the file when
        the arrays are missing, of the wrong shape, not finite or out of range.
    """
    z = read_npz(path, ("points", "elements"), what="mesh file (.npz with points and elements)")
    P, T = z["points"], z["elements"]
    if P.dtype.kind not in "iuf" or T.dtype.kind not in "iuf":
        raise InputError(f"points and elements must be numeric arrays, got {P.dtype} and {T.dtype}", where=str(path))
    if P.ndim != 2 or P.shape[1] != dim or T.ndim != 2 or T.shape[1] != dim + 1:
        raise InputError(f"mesh arrays have shapes {P.shape}, {T.shape}; expected (n, {dim}), (m, {dim + 1})",
                         where=str(path))
    if not np.all(np.isfinite(P)):
        raise InputError("points contain NaN or infinity", where=str(path))
    if len(T) == 0 or not np.all(np.isfinite(T)) or np.any(T != np.round(T)) or T.min() < 0 or T.max() >= len(P):
        raise InputError(f"elements must be {dim + 1} whole-number indices into the {len(P)} points per row",
                         where=str(path))
    return P.astype(np.float64), T.astype(np.int64)


def _call(fn, kw: dict, where: str):
    try:
        return fn(**kw)
    except TypeError as e:
        raise InputError(f"bad generator parameters: {e}", where=where) from None
    except InputError as e:
        raise e.in_file(where) from None


def read_outline(path: Path, scale: float) -> tuple[np.ndarray, list]:
    """A 2D part's outline CSV: rows ``x, y`` (one loop), or ``loop, x, y`` (loops numbered, as
    ``simfab couple optimize`` writes NAME_optimized_outline.csv): the loop of largest area is the
    part's outline, the others its holes.

    Args:
        path: the CSV file.
        scale: metres per unit of its coordinates.

    Returns:
        (outline (k, 2) [m], holes: a list of (k_i, 2) [m]); InputError naming the file for a loop
        number that is not an integer or a loop of fewer than 3 points.
    """
    a = read_csv_numbers(path, (2, 3), what="outline CSV (x,y or loop,x,y per row)", min_rows=3)
    if a.shape[1] == 2:
        return a * scale, []
    ids = a[:, 0]
    if not np.all(ids == np.round(ids)):
        bad = a[np.flatnonzero(ids != np.round(ids))[0], 0]
        raise InputError(f"loop numbers must be integers, got {bad:g}", where=str(path))
    loops = []
    for k in dict.fromkeys(ids.tolist()):  # (in order of first appearance)
        loop = a[ids == k, 1:] * scale
        if len(loop) < 3:
            raise InputError(f"loop {k:g} has {len(loop)} point(s), a loop needs at least 3", where=str(path))
        loops.append(loop)
    outer = int(np.argmax([abs(geometry.signed_area(loop)) for loop in loops]))
    return loops[outer], loops[:outer] + loops[outer + 1:]


def _triangulate_to_target(outline: np.ndarray, target: int | None, holes=()):
    """Triangle mesh of the outline (less its holes) with about ``target`` triangles (area bound tuned
    in 3 passes)."""

    if target is None:
        return triangulate_polygon(outline, holes=holes)
    area = abs(geometry.signed_area(outline)) - sum(abs(geometry.signed_area(h)) for h in holes)
    max_area = area / target
    best = None
    for _ in range(4):
        V, F = triangulate_polygon(outline, holes=holes, max_area=max_area)
        if best is None or abs(len(F) - target) < abs(len(best[1]) - target):
            best = (V, F)
        if abs(len(F) - target) <= 0.05 * target:
            break
        max_area *= len(F) / target
    return best
