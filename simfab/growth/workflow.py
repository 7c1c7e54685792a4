"""The ``simfab grow`` workflow as library calls: :func:`run` (grow, skin, check, write),
:func:`check` (the structural check of a skeleton) and :func:`edit` (a sketch edit of a
skeleton chain), returning the frozen results of
:mod:`simfab.growth.results`. Files are written only when ``out`` is given; a check runs before
any file of its run is written, so a failed check writes nothing.
"""

from __future__ import annotations

import os

import numpy as np

import simfab.growth.tolerances as tol
from simfab.errors import InputError
from simfab.growth.pipeline import as_scene, grow, skin_result
from simfab.growth.scene import GrowthScene
from simfab.growth.skeleton import Skeleton
from simfab.io.tables import Override

#: GrowthSceneConfig field -> the command-line option that sets it (errors name the option the value came from)
FLAGS = {"branch_length": "--branch-length", "kill": "--kill", "influence": "--influence",
         "attractors": "--attractors", "max_steps": "--max-steps"}


def _say(progress, msg: str) -> None:
    if progress is not None:
        progress(msg)


def _check_device(device: str) -> None:
    if device != "cpu":
        raise InputError(f"the growth check runs on the CPU only, got device {device!r}", where="device")


def _check_result(c, *, extra: dict, files: dict | None, skeleton=None, scene=None, buckling=None,
                  strengthened=None):
    """A :class:`simfab.growth.results.CheckResult` (or StrengthenedResult with ``extra``) of a StructureCheck."""
    from simfab.growth.results import CheckResult, StrengthenedResult

    kw = dict(c.summary())
    kw.update({k: (str(v) if v is not None else None) for k, v in (files or {}).items()})
    kw.update(extra)
    cls = StrengthenedResult if "target_safety_factor" in extra else CheckResult
    return cls(structure=c, skeleton=skeleton, scene=scene, buckling_factor=buckling, strengthened=strengthened,
               outputs={k: str(v) for k, v in (files or {}).items() if v is not None}, **kw)


def _reached_loads(skeleton, scene, loads: dict) -> None:
    """InputError naming where a load on a target the support does not reach came from: ``loads``
    (the ``--load`` flag) or the scene TOML's ``[loads]`` table; before any meshing."""
    from simfab.growth.structure import load_points

    points = load_points(skeleton)
    reached = ", ".join(sorted(n for n in scene.target_names if n in points)) or "none"
    toml = f"{scene.path.with_suffix('.toml')}: [loads]" if scene.path else "scene: [loads]"
    for where, names in (("--load", list(loads)), (toml, [n for n, _ in scene.structure.loads if n not in loads])):
        missing = [n for n in names if n not in points]
        if missing:
            raise InputError(f"target(s) {', '.join(missing)} not reached by the support, so nothing carries "
                             f"the load (reached: {reached}); grow until it reaches them or load a reached one",
                             where=where)


def _check(skeleton, scene, *, stem, loads, strengthen, thin, buckling, best_effort, progress,
           skeleton_path=None, scene_path=None):
    """Compute the check of ``skeleton`` in ``scene`` (see :func:`check`) and return its writer,
    ``write(out_dir or None) -> CheckResult``, so that :func:`run` checks before writing the growth's files."""
    from simfab.growth.structure import buckling_factor, check_structure
    from simfab.growth.structure import strengthen as strengthen_support
    from simfab.progress import log

    unknown = [n for n in loads if n not in scene.target_names]
    if unknown:
        raise InputError(f"unknown target site(s) {', '.join(unknown)} (targets: {', '.join(scene.target_names)})",
                         where="--load")
    if strengthen is not None and not (0 < strengthen < float("inf")):
        raise InputError(f"must be a positive finite number, got {strengthen}", where="--strengthen")
    if thin and strengthen is None:
        raise InputError("--thin goes with --strengthen SF", where="--thin")
    _reached_loads(skeleton, scene, loads)
    merged = {**dict(scene.structure.loads), **loads}
    _say(progress, f"simfab grow check: {stem}: meshing and solving")
    c = check_structure(skeleton, scene, loads=merged, best_effort=best_effort)
    if c.mesher != "gmsh":  # shown always: the figures will differ from run to run
        log(f"simfab grow check: warning: meshed by {c.mesher}")
    for o, d in c.dropped.items():  # shown always: the figures leave this weight out
        log(f"simfab grow check: warning: the support carries none of {o}'s weight ({d.weight_N:.3g} N; targets "
            f"{', '.join(d.targets) or 'none'} do not touch it): the figures leave it out")
    bf = buckling_factor(c) if buckling else None
    res = None
    if strengthen is not None:
        _say(progress, f"simfab grow check: {stem}: strengthening to safety factor {strengthen:g}")
        res = strengthen_support(skeleton, scene, strengthen, loads=merged, thin=thin, check=c,
                                 best_effort=best_effort)

    def write(out_dir):
        from simfab.growth.outputs import write_check_outputs

        files = write_check_outputs(c, res, scene, out_dir, stem=stem) if out_dir is not None else \
            {"check": {"check_usd": None, "check_png": None},
             "strengthened": {"skeleton_json": None, "skin_stl": None, "check_usd": None, "check_png": None}}
        st = None
        if res is not None:
            st = _check_result(res.check, extra={**res.summary(), "skeleton_strengthened": res.skeleton},
                               files=files["strengthened"])
        return _check_result(c, extra={}, files=files["check"], skeleton=skeleton_path, scene=scene_path,
                             buckling=bf, strengthened=st)

    return write


def check(skeleton, *, scene=None, out=None, loads: dict | None = None, strengthen: float | None = None,
          thin: bool = False, buckling: bool = False, best_effort: bool = False, device: str = "cpu",
          progress=None, stem: str | None = None):
    """Structural check of a grown support (``simfab grow check``).

    Args:
        skeleton: a skeleton JSON path written by ``simfab grow`` (its scene is the one it names)
            or a :class:`Skeleton` (then ``scene`` is required).
        scene: the :class:`GrowthScene` or MJCF path (None: the skeleton file's).
        out: folder for the USD/PNG (and strengthened files); None writes nothing.
        loads: extra forces target name -> (3,) [N] replacing the scene's ``[loads]`` entries.
        strengthen: target safety factor to thicken the support to; thin: also thin over-strong branches.
        buckling: also the linearized buckling factor. best_effort: check a support that leaves a
            supported object's weight without a load path (warn) instead of failing.
        device: "cpu" (the only one). progress: callable taking a status line, or None.
        stem: output file stem (default: the skeleton file's or the scene's name).

    Returns:
        :class:`simfab.growth.results.CheckResult`. InputError on unusable input (nothing written),
        ConvergenceError when a weight has no load path (unless ``best_effort``).
    """
    from pathlib import Path

    from simfab.growth.contact import require_ground
    from simfab.growth.skeleton import load_skeleton_json
    from simfab.growth.structure import validate_loads

    _check_device(device)
    skeleton_path = scene_path = None
    if isinstance(skeleton, (str, os.PathLike)):
        skeleton_path = str(skeleton)
        sk, doc = load_skeleton_json(skeleton)
        stem = stem or Path(skeleton).stem.removesuffix("_skeleton")
        if scene is None:
            scene_path = doc.get("scene")
            if not scene_path or not Path(scene_path).is_file():
                raise InputError(f"the skeleton names no readable scene ({scene_path!r})",
                                 where=f"{skeleton}: scene")
    elif isinstance(skeleton, Skeleton):
        sk = skeleton
        if scene is None:
            raise InputError("a Skeleton needs its scene", where="scene")
    else:
        raise InputError(f"expected a skeleton JSON path or a Skeleton, got {type(skeleton).__name__}",
                         where="skeleton")
    where = skeleton_path or "skeleton"
    sc = as_scene(scene if scene is not None else scene_path)
    if scene_path is None and sc.path is not None:
        scene_path = str(sc.path)
    names = set(sc.target_names)
    foreign = [n for n in sk.target_names if n not in names]
    if foreign:
        raise InputError(f"target(s) {', '.join(foreign)} are not sites of its scene {sc.name} (its targets: "
                         f"{', '.join(sc.target_names) or 'none'})", where=f"{where}: target_names")
    if not np.any(sk.parent >= 0):
        raise InputError(f"the skeleton has no segments ({len(sk.nodes)} node(s)): nothing to check",
                         where=f"{where}: parent")
    validate_loads(sc)
    require_ground(sc)
    write = _check(sk, sc, stem=stem or sc.name, loads=dict(loads or {}), strengthen=strengthen, thin=thin,
                   buckling=buckling, best_effort=best_effort, progress=progress, skeleton_path=skeleton_path,
                   scene_path=scene_path)
    return write(out)


def run(scene, *, out=None, seed: int = 0, device: str = "cpu", progress=None, check: bool = False,
        best_effort: bool = False, loads: dict | None = None, strengthen: float | None = None, thin: bool = False,
        buckling: bool = False, stem: str | None = None, **overrides):
    """Grow, skin, (optionally) check and write a support for one scene (``simfab grow``).

    Args:
        scene: MJCF path or :class:`GrowthScene`.
        out: output folder (skin STL/PLY, skeleton JSON, USD, MJCF, PNG; with ``check`` the check's
            files); None writes nothing.
        seed: growth seed. device: "cpu". progress: callable taking a status line, or None.
        check: run the structural check (also implied by ``loads``, ``strengthen``, ``buckling``);
            it runs before any file is written, so a failed check writes nothing.
        best_effort: keep a growth that leaves targets unreached, and check a support that leaves a
            weight without a load path (both warn instead of failing).
        loads, strengthen, thin, buckling: as :func:`check`. stem: output file stem (default: the scene's name).
        **overrides: :class:`simfab.growth.config.GrowthSceneConfig` flat names (``attractors``, ``kill``,
            ``symmetric``, ...; None = keep the scene's), a value or a :class:`simfab.io.tables.Override`
            (an error then names its flag; a note that it replaced a value of the scene file goes to
            ``progress`` once the growth stands).

    Returns:
        :class:`simfab.growth.results.GrowthResult`.
    """
    from pathlib import Path

    from simfab.errors import ConvergenceError
    from simfab.growth.contact import require_ground
    from simfab.growth.outputs import SKIN_FILE_UNITS, write_all
    from simfab.growth.results import GrowthResult
    from simfab.growth.structure import validate_loads
    from simfab.progress import log

    _check_device(device)
    structural = check or bool(loads) or strengthen is not None or thin or buckling
    if structural:
        sc0 = as_scene(scene)
        validate_loads(sc0)
        require_ground(sc0)  # before growing: the check clamps the support to what a root stands on
        unknown = [n for n in (loads or {}) if n not in sc0.target_names]
        if unknown:
            raise InputError(f"unknown target site(s) {', '.join(unknown)} (targets: {', '.join(sc0.target_names)})",
                             where="--load")
        if thin and strengthen is None:
            raise InputError("--thin goes with --strengthen SF", where="--thin")
    symmetric = overrides.pop("symmetric", None)
    try:
        result = grow(scene, seed=seed, symmetric=symmetric, **overrides)
    except InputError as e:  # name the scene's file with the field (its TOML holds the growth parameters)
        if (e.where or "").startswith("--") or isinstance(scene, GrowthScene):
            raise
        toml = Path(scene).with_suffix(".toml")
        key = (e.where or "").removeprefix("growth.")
        given = overrides.get(key)
        if isinstance(given, Override) and given.value is not None:  # the value came from a flag
            raise InputError(e.message, where=given.source) from None
        if key in FLAGS and given is not None:  # the value came from the command line
            raise InputError(e.message, where=FLAGS[key]) from None
        raise e.in_file(toml if toml.is_file() else scene) from None
    s = result.summary()
    if s["segments"] == 0:
        raise ConvergenceError(f"{scene}: growth produced no structure ({'; '.join(s['stop_reasons'])}); "
                               f"unreached targets: {', '.join(s['targets_unreached']) or 'none'}")
    if s["targets_unreached"]:
        msg = (f"{scene}: {len(s['targets_unreached'])} of {s['targets_total']} targets unreached "
               f"({', '.join(s['targets_unreached'])}; {'; '.join(s['stop_reasons'])})")
        if not best_effort:
            raise ConvergenceError(f"{msg}; change the growth parameters (e.g. --branch-length, --influence, "
                                   "--max-steps) or pass --best-effort to keep the partial structure")
        log(f"simfab grow: warning: {msg}")  # shown always: the result is partial
    mesh, rep, seconds_skin = skin_result(result)
    tol_pen = result.scene.params.skin_tolerance
    if rep.penetration > tol_pen + tol.PENETRATION_ROUNDOFF * result.resolved.diag:
        raise ConvergenceError(f"the skin penetrates the objects by {rep.penetration:.3g} m, more than the "
                               f"tolerance {tol_pen:.3g} m (enable skin.subtract_objects or raise skin.tolerance)")
    name = stem or result.scene.name
    write_check = None
    if structural:  # before any file is written: a failed check leaves out untouched
        write_check = _check(result.skeleton, result.scene, stem=name, loads=dict(loads or {}),
                             strengthen=strengthen, thin=thin, buckling=buckling, best_effort=best_effort,
                             progress=progress)
    for note in result.scene.notes:  # flags that replaced values of the scene file, once the run stands
        _say(progress, note)
    paths = write_all(result, mesh, Path(out), stem=name) if out is not None else {}
    c = write_check(out) if write_check is not None else None
    s.update({
        "watertight": rep.watertight, "is_volume": rep.is_volume, "bodies": rep.bodies, "volume": rep.volume,
        "nodes_in_skin": rep.nodes_contained, "overlap_volume": rep.overlap_volume,
        "penetration": rep.penetration, "skin_attempts": rep.attempts,
        "objects_subtracted": rep.objects_subtracted, "objects_not_manifold": rep.objects_not_manifold,
        "seconds_skin": seconds_skin,
    })
    outputs = dict(paths)
    if c is not None:
        outputs.update({f"check_{k}" if not k.startswith("check_") else k: v for k, v in c.outputs.items()})
    return GrowthResult(**s, **paths, skin_units=SKIN_FILE_UNITS, check=c, growth=result, mesh=mesh,
                        outputs=outputs)


def edit(skeleton, *, stroke, camera, chain: int | None = None, scene=None, out=None, progress=None,
         stem: str | None = None):
    """Sketch edit (``simfab grow edit``): move one skeleton chain onto the surface of rays through
    a 2D stroke (objects of the scene avoided) and re-skin the result.

    Args:
        skeleton: a skeleton JSON path written by ``simfab grow`` (its scene, when readable, gives the
            objects to avoid and to carve out) or a :class:`Skeleton`.
        stroke: the stroke in the camera's pixels: a JSON/CSV file path or an (m, 2) array.
        camera: the camera the stroke was drawn in: a JSON file path, an inline JSON object or a
            :class:`simfab.growth.sketch.Camera` (``simfab grow`` writes its preview's).
        chain: index of the chain to move (None: the one nearest the stroke on screen).
        scene: the :class:`GrowthScene` or MJCF path (None: the skeleton file's, if readable).
        out: folder for the edited skeleton JSON, skin STL/PLY and preview PNG; None writes nothing.
        progress: callable taking a status line (warnings of a colliding edit), or None.
        stem: output file stem (default: the skeleton file's name, ``_edited`` appended).

    Returns:
        :class:`simfab.growth.results.EditResult`. InputError on unusable input (nothing written).
    """
    from pathlib import Path

    from simfab.growth.obstacles import Obstacles
    from simfab.growth.outputs import SKIN_FILE_UNITS, edit_paths, write_edit
    from simfab.growth.results import EditResult
    from simfab.growth.skeleton import load_skeleton_json
    from simfab.growth.sketch import Camera, edit_chain, load_camera, load_stroke
    from simfab.growth.skinning import skin_skeleton

    doc = {}
    if isinstance(skeleton, (str, os.PathLike)):
        sk, doc = load_skeleton_json(skeleton)
        stem = stem or Path(skeleton).stem.removesuffix("_skeleton") + "_edited"
    elif isinstance(skeleton, Skeleton):
        sk = skeleton
        stem = stem or "skeleton_edited"
    else:
        raise InputError(f"expected a skeleton JSON path or a Skeleton, got {type(skeleton).__name__}",
                         where="skeleton")
    cam = camera if isinstance(camera, Camera) else load_camera(str(camera))
    strk = load_stroke(str(stroke)) if isinstance(stroke, (str, os.PathLike)) else np.asarray(stroke, np.float64)
    objects, obstacles, scene_path = {}, None, None
    if scene is not None:
        sc = as_scene(scene)
        scene_path = str(sc.path) if sc.path is not None else None
    else:
        scene_path = doc.get("scene")
        sc = as_scene(scene_path) if scene_path and Path(scene_path).is_file() else None
    if sc is not None:
        objects = sc.objects
        diag = float(np.linalg.norm(np.ptp(sc.objects_bbox(), axis=0)))
        obstacles = Obstacles.of_scene(sc, diag)
    edited, rep = edit_chain(sk, cam, strk, chain=chain, obstacles=obstacles)
    mesh, srep = skin_skeleton(edited.nodes, edited.parent, edited.radius, objects)
    if rep.get("segments_colliding") or srep.bodies != 1:
        _say(progress, f"simfab grow edit: warning: the edited chain crosses objects in "
                       f"{rep.get('segments_colliding', 0)} segment(s); the skin has {srep.bodies} bodies")
    files = {}
    if out is not None:
        files = write_edit(edited, mesh, objects, cam, strk, edit_paths(Path(out), stem),
                           skeleton_extra=dict(scene=scene_path, seed=doc.get("seed"), edit=rep),
                           title=f"{stem}: chain {rep.get('chain')} moved onto the stroke (red)")
    return EditResult(**rep, nodes=len(edited.nodes), segments=int((edited.parent >= 0).sum()),
                      watertight=srep.watertight, bodies=srep.bodies, volume=srep.volume,
                      skin_units=SKIN_FILE_UNITS, **files, skeleton=edited, mesh=mesh, outputs=dict(files))
