"""A sweep spec's runs as library calls: :func:`run_task` turns a run's command line into the
area function it names (:class:`simfab.sweep.runs.ApiCall`, through the subcommand module's
``api_call(args)``) and the task's arguments; the task itself is the library's
:func:`simfab.sweep.runs.execute_run`. A command whose module has no ``api_call`` (or whose line is
bad input, reported by its run) runs as :class:`ArgvCall`: the subcommand in-process.

The base scene travels as text (the worker need not see the client's files); file references
inside it (meshes, outlines) are made absolute against the client's scene folder, so they must be
reachable there on the workers (the bundled scenes always are when client and workers share the
installation path; otherwise use a shared file system).
"""

from __future__ import annotations

import dataclasses

from simfab.cli.sweep_spec import SweepConfig, scene_files
from simfab.errors import InputError
from simfab.sweep.runs import ApiCall, execute_run, lookup, table_cell, write_scene

__all__ = ["ArgvCall", "command_call", "run_task", "execute_run", "lookup", "table_cell", "write_scene"]

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


def run_task(spec: SweepConfig, point: dict, *, run_dir: str) -> dict:
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
    return {"call": command_call(argv), "figures": [(g.name, g.path) for g in spec.figures], "run_dir": run_dir,
            "keep": spec.keep_outputs, "scene": scene}


def _parse(argv: list[str]):
    from simfab.cli import DEFAULTS

    args = _parser().parse_args(list(argv))
    for k, v in DEFAULTS.items():
        if not hasattr(args, k):
            setattr(args, k, v)
    args.quiet, args.json = True, False
    return args


def command_call(argv: list[str]):
    """The call a run's command line makes: an :class:`ApiCall` when its module offers ``api_call``
    and the line is good, else an :class:`ArgvCall` (which reports bad input when the run runs)."""
    try:
        args = _parse(argv)
        hook = getattr(args._module, "api_call", None)
        call = hook(args) if hook is not None else None
    except InputError:
        call = None
    return call if isinstance(call, ApiCall) else ArgvCall(argv=tuple(argv))


@dataclasses.dataclass(frozen=True)
class ArgvCall:
    """A run as ``simfab ARGV --out OUT --quiet`` in this process (for subcommands without an area
    function yet); the protocol of :class:`simfab.sweep.runs.ApiCall`."""

    argv: tuple

    def __call__(self, *, scene_path: str | None, out: str) -> dict:
        from simfab.io.atomic import to_jsonable

        argv = [s.replace("{scene}", scene_path) for s in self.argv] if scene_path else list(self.argv)
        args = _parse([*argv, "--out", out, "--quiet"])
        return to_jsonable(args._module.run(args) or {})


