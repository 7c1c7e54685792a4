"""``simfab inspect FILE``: summarize a mesh, MJCF scene or USD stage (and validate it)."""

HELP = "summarize and validate a mesh, MJCF scene or USD stage"


def add_args(p):
    p.add_argument("file", help="mesh (.stl/.obj/.ply), MJCF (.xml) or USD (.usda/.usdc/.usd)")
    p.add_argument("--units", choices=["m", "mm"], default="m", help="units of a mesh file (default m)")


def run(args):
    from simfab.io import inspect_file

    return inspect_file(args.file, units=args.units)
