"""``simfab validate <validation>``: simulators checked against analytic mechanics.

Validations are registered in :data:`VALIDATIONS` (name -> module path); each module defines
``HELP``, optional ``DESCRIPTION``, ``add_args(parser)`` and ``run(args) -> dict``, like a
subcommand. A module is imported only when its validation is invoked (its ``--help`` too): the
listing reads ``HELP`` and ``DESCRIPTION`` from the module's source, so ``simfab --help`` and
``simfab validate --help`` load no simulator.
"""

from __future__ import annotations

import importlib

HELP = "validate simulators against analytic mechanics (buckling, ...)"
DESCRIPTION = "Run a validation against closed-form mechanics; see 'simfab validate VALIDATION --help'."

#: validation name -> implementing module (other areas add theirs here)
VALIDATIONS = {
    "buckling": "simfab.deploy.validation",
}


def add_args(p) -> None:
    sub = p.add_subparsers(dest="validation", metavar="VALIDATION", parser_class=_lazy_parser_class(type(p)))
    for name, modname in VALIDATIONS.items():
        text = _module_strings(modname)
        sub.add_parser(name, help=text["HELP"], description=text.get("DESCRIPTION", text["HELP"]), module=modname)


def _module_strings(modname: str) -> dict:
    """The module's top-level string literals (HELP, and DESCRIPTION unless it is computed), read
    from its source without importing it."""
    import ast
    import importlib.util

    origin = importlib.util.find_spec(modname).origin
    with open(origin, encoding="utf-8") as fh:
        tree = ast.parse(fh.read())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            try:
                value = ast.literal_eval(node.value)
            except ValueError:
                continue
            if isinstance(value, str):
                out[node.targets[0].id] = value
    return out


def _lazy_parser_class(base):
    """A parser class that imports its validation module and adds its arguments the first time it
    parses or prints help."""

    class LazyParser(base):
        def __init__(self, *a, module: str | None = None, **kw):
            super().__init__(*a, **kw)
            self._module_name = module

        def _load(self):
            if self._module_name is not None:
                from simfab.cli import add_common_args

                mod = importlib.import_module(self._module_name)
                self._module_name = None
                self.description = getattr(mod, "DESCRIPTION", mod.HELP)  # (may be computed: an f-string)
                add_common_args(self)
                mod.add_args(self)
                self.set_defaults(_validation=mod)

        def parse_known_args(self, *a, **kw):
            self._load()
            return super().parse_known_args(*a, **kw)

        def format_help(self):
            self._load()
            return super().format_help()

        def format_usage(self):
            self._load()
            return super().format_usage()

    return LazyParser


def run(args) -> dict:
    from simfab.errors import InputError

    mod = getattr(args, "_validation", None)
    if mod is None:
        raise InputError(f"choose a validation: {', '.join(VALIDATIONS)}", where="simfab validate")
    return mod.run(args)


def demo(ctx) -> dict:
    """The buckling validation on a small table (n = 20, 40, 80; g/L = 0.9, 0.6; both supports,
    direct and through the insert): a table small enough for a demo."""
    import argparse

    mod = importlib.import_module(VALIDATIONS["buckling"])
    args = argparse.Namespace(out=ctx.out, seed=ctx.seed, device=ctx.device, quiet=ctx.quiet, json=True,
                              g_over_L=[0.9, 0.6], n=[20, 40, 80], support="both", path="both", scene=None)
    res = mod.run(args)
    return {"buckling": {k: res[k] for k in ("passed", "convergence_order", "critical_load", "outputs")}}
