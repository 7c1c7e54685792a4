"""One run of a sweep, executed on a Dask worker: write the run's scene, call the subcommand
in-process (its ``run(args) -> dict``, no shell), pick the figures out of its summary.

:func:`run_task` builds the picklable arguments on the client; :func:`execute_run` is the
task itself. The base scene travels as text (the worker need not see the client's files);
file references inside it (meshes, outlines) are made absolute against the client's scene
folder, so they must be reachable there on the workers (the bundled scenes always are when
client and workers share the installation path; otherwise use a shared file system).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

from simfab.cli.sweep_spec import SweepSpec, scene_files
from simfab.errors import InputError

_PARSER = None  # one argparse tree per worker process (building it imports every subcommand)


def _parser():
    global _PARSER
    if _PARSER is None:
        from simfab.cli import build_parser

        _PARSER = build_parser()
    return _PARSER


def _flag_args(flag: str, v) -> list[str]:
    if isinstance(v, bool):
        return [flag] if v else []
    if isinstance(v, (list, tuple)):
        return [flag, *map(str, v)]
    return [flag, str(v)]


def run_task(spec: SweepSpec, point: dict, *, run_dir: str) -> dict:
    """Keyword arguments of :func:`execute_run` for the run with parameter values ``point``."""
    settings = list(spec.fixed) + [(p.address, point[p.name]) for p in spec.parameters]
    argv = list(spec.command)
    scene = None
    for a, v in settings:
        if a.kind == "flag":
            argv += _flag_args(a.text, v)
    if not any(a.kind == "flag" and a.text == "--seed" for a, _ in settings):
        argv += ["--seed", str(spec.seed)]
    edits = [(a, v) for a, v in settings if a.kind != "flag"]
    if spec.scene is not None:
        if edits:
            scene = {
                "main": spec.scene.name,
                "base": str(spec.scene.parent),
                "files": {f.name: f.read_text(encoding="utf-8") for f in scene_files(spec.scene)},
                "toml": [(a.path, v) for a, v in edits if a.kind == "toml"],
                "mjcf": [(a.tag, a.name, a.attr, a.index, v) for a, v in edits if a.kind == "mjcf"],
            }
        else:
            argv = [s.replace("{scene}", str(spec.scene)) for s in argv]
    return {"argv": argv, "figures": [(g.name, g.path) for g in spec.figures], "run_dir": run_dir,
            "keep": spec.keep_outputs, "scene": scene}


def execute_run(*, argv: list[str], figures: list[tuple[str, str]], run_dir: str, keep: bool,
                scene: dict | None) -> dict:
    """Run ``simfab ARGV --out RUN_DIR --quiet`` in this process; return {figure: value}.

    With ``scene``, first writes the edited base scene into RUN_DIR/scene and puts its path
    where the command line says ``{scene}``. ``keep=False`` runs in a temporary folder that is
    removed afterwards. Raises what the subcommand raises (the task wrapper turns it into a row).
    """
    from simfab.cli import DEFAULTS
    from simfab.io.atomic import to_jsonable

    with contextlib.ExitStack() as stack:
        d = Path(run_dir) if keep else Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="simfab-run-")))
        d.mkdir(parents=True, exist_ok=True)
        if scene is not None:
            main = write_scene(scene, d / "scene")
            argv = [s.replace("{scene}", str(main)) for s in argv]
        args = _parser().parse_args(list(argv) + ["--out", str(d), "--quiet"])
        for k, v in DEFAULTS.items():
            if not hasattr(args, k):
                setattr(args, k, v)
        args.quiet, args.json = True, False
        summary = to_jsonable(args._module.run(args) or {})
    return {name: cell(lookup(summary, path)) for name, path in figures}


def lookup(summary: dict, path: str):
    """The value at dotted ``path`` (dict keys; integers index lists); KeyError naming the
    missing part and the keys that are there."""
    cur = summary
    for i, part in enumerate(path.split(".")):
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and part.lstrip("-").isdigit() and -len(cur) <= int(part) < len(cur):
            cur = cur[int(part)]
        else:
            here = ".".join(path.split(".")[:i]) or "the summary"
            have = ", ".join(list(cur)[:12]) if isinstance(cur, dict) else f"a {type(cur).__name__}"
            raise KeyError(f"{here} has no {part!r} (has: {have})")
    return cur


def cell(v):
    """A table cell: scalars as they are, anything nested as compact JSON."""
    if isinstance(v, (dict, list)):
        return json.dumps(v, separators=(",", ":"))
    return v


def write_scene(scene: dict, folder: Path) -> Path:
    """Write the base scene's files with the edits applied into ``folder``; returns the main
    file's path. File references relative to the base folder become absolute."""
    folder.mkdir(parents=True, exist_ok=True)
    base = Path(scene["base"])
    for name, text in scene["files"].items():
        if name.endswith(".toml"):
            text = _edit_toml(text, scene["toml"], base, where=name)
        else:
            text = _edit_mjcf(text, scene["mjcf"], base, where=name)
        (folder / name).write_text(text, encoding="utf-8")
    return folder / scene["main"]


def _edit_toml(text: str, edits, base: Path, *, where: str) -> str:
    import tomllib

    import tomli_w

    d = tomllib.loads(text)

    def absolute(x):  # relative file names (outline, mesh, mesh_file) keep pointing at the base folder
        if isinstance(x, dict):
            return {k: absolute(v) for k, v in x.items()}
        if isinstance(x, str) and x and not os.path.isabs(x) and (base / x).is_file():
            return str(base / x)
        return x

    d = absolute(d)
    for path, v in edits:
        cur = d
        for k in path[:-1]:
            cur = cur.setdefault(k, {})
            if not isinstance(cur, dict):
                raise InputError(f"{'.'.join(path)}: {k!r} is not a table", where=where)
        cur[path[-1]] = v
    return tomli_w.dumps(d)


def _edit_mjcf(text: str, edits, base: Path, *, where: str) -> str:
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise InputError(f"not valid XML: {e}", where=where) from None
    for el in root.iter():  # file references stay valid from the run folder
        for attr in ("file", "meshdir", "texturedir", "assetdir"):
            v = el.get(attr)
            if v and not os.path.isabs(v) and (base / v).exists():
                el.set(attr, str(base / v))
    for tag, name, attr, index, v in edits:
        hits = [el for el in root.iter(tag) if el.get("name") == name]
        if not hits:
            raise InputError(f"no <{tag} name={name!r}> in the MJCF scene", where=where)
        for el in hits:
            if index:
                old = el.get(attr)
                if old is None:
                    raise InputError(f"<{tag} name={name!r}> has no {attr!r} to set components of", where=where)
                comps = old.split()
                if max(index) >= len(comps):
                    raise InputError(f"<{tag} name={name!r}> {attr}={old!r} has no component {max(index)}", where=where)
                for i in index:
                    comps[i] = repr(float(v)) if isinstance(v, float) else str(v)
                el.set(attr, " ".join(comps))
            else:
                text = " ".join(map(str, v)) if isinstance(v, (list, tuple)) else (
                    repr(v) if isinstance(v, float) else str(v))
                el.set(attr, text)
    return ET.tostring(root, encoding="unicode")
