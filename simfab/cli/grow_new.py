"""``simfab grow new OBJECT... --root POINT --target POINT... --out DIR``: a growth scene from the user's meshes.

Adds its flags to ``simfab grow`` (:func:`add_args`), parses them, calls
:func:`simfab.growth.author.new_scene` and returns its summary.
"""

from __future__ import annotations

DESCRIPTION = """'simfab grow new OBJECT... --root X,Y,Z --target X,Y,Z ... [--mass KG ...] --out DIR' writes a
growth scene (NAME.xml + NAME.toml) for your own object meshes: one body per mesh file (named after
it), root_* and target_* sites, a plate under the roots (--no-plate when one of the objects is the
ground), targets snapped onto the nearest object's surface. An object without --mass weighs MuJoCo's
default density (1000 kg/m^3) times its volume in 'grow --check' (the notes say how much)."""


def add_args(p) -> None:
    """The ``grow new`` flags and the extra OBJECT positional (the first object is SKELETON_JSON's slot)."""
    p.add_argument("more_objects", nargs="*", metavar="OBJECT", help="(new) further object meshes")
    g = p.add_argument_group("new (write a scene from your meshes)", DESCRIPTION)
    g.add_argument("--root", action="extend", nargs="+", metavar="X,Y,Z", help="(new) root point(s)")
    g.add_argument("--target", action="extend", nargs="+", metavar="X,Y,Z", help="(new) target point(s)")
    g.add_argument("--mass", action="extend", nargs="+", type=float, metavar="KG",
                   help="(new) object masses [kg], one per object or one for all")
    g.add_argument("--units", choices=["mm", "m"], default="mm", help="(new) units of meshes and points (default mm)")
    g.add_argument("--no-plate", action="store_true", help="(new) no plate under the roots")
    g.add_argument("--name", help="(new) scene name (default: the first object's stem)")


def run(args) -> dict:
    from simfab.growth.author import GrowthAuthorConfig, new_scene
    from simfab.progress import log
    from simfab.results import units

    objects = tuple(o for o in (args.skeleton, *args.more_objects) if o is not None)
    spec = GrowthAuthorConfig(objects=objects, roots=tuple(args.root or ()), targets=tuple(args.target or ()),
                           masses=tuple(args.mass or ()), name=args.name, units=args.units, plate=not args.no_plate)
    res = new_scene(spec, args.out)
    for n in res.notes:
        log(f"grow new: {n}", quiet=args.quiet)
    log(f"next: {res.next_commands[0]}", quiet=args.quiet)
    return {**res.to_json(), "units": units(res)}


def misused(args) -> bool:
    """True when ``grow new``'s flags are given to another grow action."""
    return bool(args.more_objects or args.root or args.target or args.mass or args.no_plate or args.name)
