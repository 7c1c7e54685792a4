"""``simfab validate <validation>``: simulators checked against analytic mechanics.

Validations are registered in :data:`VALIDATIONS` (name -> module path); each module defines
``HELP``, optional ``DESCRIPTION``, ``add_args(parser)`` and ``run(args) -> dict``, like a
subcommand. Modules are imported when the parser is built, so they must keep heavy imports
(Warp, MuJoCo) inside ``run``.
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
    from simfab.cli import add_common_args

    sub = p.add_subparsers(dest="validation", metavar="VALIDATION", parser_class=type(p))
    for name, modname in VALIDATIONS.items():
        mod = importlib.import_module(modname)
        sp = sub.add_parser(name, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        add_common_args(sp)
        mod.add_args(sp)
        sp.set_defaults(_validation=mod)


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
