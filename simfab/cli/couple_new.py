"""``simfab couple new PART OBJECT --into AXIS_OR_POINT --out DIR``: a coupling scene from the user's meshes.

Parses the flags, calls :func:`simfab.coupling.author.new_scene` and returns its summary (the files
written, the path's ends, notes on every correction, the command to run next).
"""

from __future__ import annotations

import argparse

HELP = "write a coupling scene (MJCF + TOML) from your own part and object meshes"
DESCRIPTION = """Write a coupling scene that 'simfab couple simulate' and 'couple optimize' run, from the
compliant part's and the rigid object's mesh files (STL/OBJ/PLY, watertight, in one common frame:
an assembly with the object in its seat is fine). The object moves in a straight line through its
centre along --into. The path starts just before the first contact (an object that starts inside the
part is moved back, and the notes say from where to where); it ends, unless --depth is given, just
before the seat (the first narrowing after the mouth), and the simulation continues from there to
the object's rest point. A --depth that ends past the seat, inside the part, is refused with the
seat's depth in the message.

Files under --out: NAME.xml (the mocap body 'object' with keyframes k0, k1, the box site 'fixed',
the part as a display mesh), NAME.toml, and NAME_outline.csv (2D: the part's section through the
object's centre, which is the scene's plane z = 0: the scene's frame is the files' moved along z, and
the notes say so) or NAME_part.npz (3D: the part's tetrahedral mesh, stored so runs are reproducible)
and NAME_part.ply (3D: the surface it was meshed from, in the scene's frame [m], which 'couple
converge' meshes again at its other refinement factors).

--json keys: scene, dim, start, end [m] (the object's centre at the path's ends), path_length [m],
  first_contact, seat [m] (along the path from its start; seat null if none), to_rest, notes,
  warnings (3D: where the tets' surface departs from the part's by more than a tenth of the object's
  overlap with it at the seat, the forces there depend on the mesh; the line says how many tets
  resolve it), next_commands, outputs {scene_xml, scene_toml, outline_csv | part_npz, part_ply}."""


def add_args(p) -> None:
    p.add_argument("part", metavar="PART", help="mesh file of the compliant part (STL/OBJ/PLY)")
    p.add_argument("object", metavar="OBJECT", help="mesh file of the rigid object, same frame as the part")
    p.add_argument("--into", required=True, metavar="AXIS_OR_POINT",
                   help="insertion direction: an axis (--into=-x, +y, z; write a leading minus with =) "
                        "or a point X,Y,Z the object's centre moves towards")
    p.add_argument("--fixed", default="back", metavar="REGION",
                   help="region of the part held fixed: back (default: the part's face farthest along --into, in "
                        "the part's own axes: the files' axes, or its smallest turned bounding box's where the part is "
                        "turned in the assembly), a face of the files' axes (-x, +y, ...) or a box X0,Y0,Z0,X1,Y1,Z1")
    end = p.add_mutually_exclusive_group()
    end.add_argument("--depth", type=float, metavar="D", help="insertion depth past the first contact (in --units)")
    end.add_argument("--to-rest", action="store_true",
                     help="end just before the seat and let the simulation run to the rest point (the default)")
    p.add_argument("--friction", type=float, default=0.0, metavar="MU", help="Coulomb coefficient (default 0)")
    p.add_argument("--brief", action="append", metavar="KEY=VALUE",
                   help="a [design] key for 'couple optimize', e.g. --brief grip=tight "
                        "--brief 'insertion_force=[0, 20]' (repeat)")
    p.add_argument("--units", choices=["mm", "m"], default="mm", help="units of the meshes and lengths (default mm)")
    p.add_argument("--dim", type=int, choices=(2, 3), default=3,
                   help="3 (default) or 2: plane strain on the section through the object's centre (fast)")
    p.add_argument("--name", help="scene name (default: the part file's stem)")
    p.add_argument("--material", default="PLA", help="material name (default PLA)")
    p.add_argument("--elements", type=int, metavar="N", help="target triangles (2D, default 1500) / tets (3D, 3000)")
    p.add_argument("--steps", type=int, default=40, metavar="N", help="insertion steps (default 40)")


def register(sub, add_common_args) -> argparse.ArgumentParser:
    """Add ``new`` to the ``simfab couple`` actions."""
    q = sub.add_parser("new", help="write a coupling scene from your part and object meshes", description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    add_args(q)
    add_common_args(q)
    return q


def run(args) -> dict:
    from pathlib import Path

    from simfab.coupling.author import CouplingAuthorConfig, new_scene, parse_brief
    from simfab.progress import log

    spec = CouplingAuthorConfig(part=Path(args.part), object=Path(args.object), into=args.into, name=args.name,
                             dim=args.dim, units=args.units, fixed=args.fixed, depth=args.depth,
                             friction=args.friction, brief=parse_brief(args.brief), material=args.material,
                             elements=args.elements, steps=args.steps)
    res = new_scene(spec, args.out)
    for n in res.notes:
        log(f"couple new: {n}", quiet=args.quiet)
    for w in res.warnings:
        log(f"simfab: warning: couple new: {w}")
    log(f"next: {res.next_commands[0]}", quiet=args.quiet)
    from simfab.results import units

    return {**res.to_json(), "units": units(res)}
