"""``simfab inspect FILE``: summarize a mesh, MJCF scene or USD stage (and validate it)."""

HELP = "summarize and validate a mesh, MJCF scene or USD stage"
DESCRIPTION = """Summarize and validate a file.

--json keys by kind:
  mesh: kind, file, vertices, faces, degenerate_faces, duplicate_faces, unreferenced_vertices,
        watertight, winding_consistent, volume [m^3 in file units^3], bodies, extents, problems,
        usable_after_repair, extents_m
  mjcf: kind, file, bodies, geoms, meshes, sites, keyframes, flexes, custom_numeric, custom_text,
        trajectories {mocap body: {length_m}}
  usd:  kind, file, default_prim, up_axis, meters_per_unit, time_codes_per_second,
        start_time_code, end_time_code, prims {path: type}, compliance_errors"""


def add_args(p):
    p.add_argument("file", help="mesh (.stl/.obj/.ply), MJCF (.xml) or USD (.usda/.usdc/.usd)")
    p.add_argument("--units", choices=["m", "mm"], default="m", help="units of a mesh file (default m)")


def run(args):
    from simfab.io import inspect_file

    return inspect_file(args.file, units=args.units)


def output_roots(args) -> list:
    """inspect writes no file."""
    return []
