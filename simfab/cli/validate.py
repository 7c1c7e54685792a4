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
