"""``simfab inspect FILE``: summarize a mesh, MJCF scene or USD stage (and validate it)."""

HELP = "summarize and validate a mesh, MJCF scene or USD stage"
DESCRIPTION = """Summarize and validate a file. Writes nothing. A mesh whose size is implausible for
--units (e.g. a millimetre file read as metres: a 64 m part) gets a warning on stderr.

--json keys by kind:
  mesh: kind, file, units, vertices, faces, degenerate_faces, duplicate_faces, unreferenced_vertices,
        watertight, winding_consistent, volume [file units^3], bodies, extents [file units],
        repaired (what loading repaired), problems, interior_faces (faces inside the solid:
        overlaps / self-intersection; null when open), usable_after_repair, extents_m [m], warnings
  mjcf: kind, file, bodies, geoms, meshes, sites, keyframes, flexes, custom_numeric, custom_text,
        trajectories {mocap body: {length_m}}
  usd:  kind, file, default_prim, up_axis, meters_per_unit, time_codes_per_second,
        start_time_code, end_time_code, prims {path: type}, compliance_errors"""

UNITS = {"volume": "file units³", "extents": "file units", "extents_m": "m"}


def add_args(p):
    p.add_argument("file", help="mesh (.stl/.obj/.ply/.off/.glb), MJCF (.xml) or USD (.usda/.usdc/.usd)")
    p.add_argument("--units", choices=["m", "mm", "cm"], default="m", help="units of a mesh file (default m)")


def output_roots(args) -> list:
    """inspect writes no file."""
    return []


def run(args):
    from simfab.io import inspect_file
    from simfab.progress import log

    res = inspect_file(args.file, units=args.units)
    for w in res.get("warnings", []):  # shown even with --quiet
        log(f"simfab: warning: {args.file}: {w}")
    return res
