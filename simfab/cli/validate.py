"""``simfab validate``: not built yet (placeholder until its issue lands; exits 2)."""

from simfab.cli._pending import not_built

HELP = "validate (not built yet)"


def add_args(p):
    p.add_argument("rest", nargs="*", help="arguments of the future pipeline")


def run(args):
    raise not_built("validate")
