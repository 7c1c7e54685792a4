"""``simfab render FILE -o out.png``: offscreen PNG of an MJCF scene, a USD stage or a mesh."""

HELP = "render an MJCF scene, a USD stage (at a time code) or a mesh file to a PNG"
DESCRIPTION = """Render an MJCF scene (.xml), a USD stage (.usd/.usda/.usdc: its visible meshes with their
displayColor, basis curves as tubes of their widths and points as spheres, at --time, default
the last time code) or a mesh file (.stl/.obj/.ply/.off/.glb) to a PNG, offscreen (MuJoCo with
EGL; matplotlib when no OpenGL is available).

-o/--output is a .png file or an existing folder (the PNG is then FOLDER/<file stem>.png);
without it the PNG goes to --out/<file stem>.png.

The picture is titled with the file name (and time code), carries a scale bar and, for a stage
with a scalar field written by simfab (e.g. von Mises stress), a colour bar.

--json keys: png (path of the image), source (the rendered file), time (USD time code drawn,
USD only), colorbar {label, cmap, min, max, clipped} (USD with a scalar field only; clipped: some
values of the timeline lie above max, and share its colour)."""


def add_args(p):
    p.add_argument("file", help="MJCF (.xml), USD (.usda/.usdc/.usd) or mesh (.stl/.obj/.ply/.off/.glb) file")
    p.add_argument("-o", "--output", metavar="PNG|DIR",
                   help="PNG path, or an existing folder (default: <out>/<file stem>.png)")
    p.add_argument("--time", type=float, default=None, metavar="T",
                   help="USD time code to draw (default: the stage's last); outside the stage's range it is "
                        "clamped with a warning")
    p.add_argument("--width", type=int, default=640, metavar="PX", help="image width in pixels (default 640)")
    p.add_argument("--height", type=int, default=480, metavar="PX", help="image height in pixels (default 480)")


def _target(args):
    from pathlib import Path

    src = Path(args.file)
    if args.output:
        o = Path(args.output)
        return o / (src.stem + ".png") if o.is_dir() else o
    return Path(args.out) / (src.stem + ".png")


def output_roots(args) -> list:
    """The PNG's folder (checked before rendering)."""
    from simfab.io.outpaths import check_out_file, require_nonempty

    if args.output is not None:  # -o "$UNSET" would otherwise fall back to --out unnoticed
        require_nonempty(args.output, "-o/--output")
    t = check_out_file(_target(args), where="-o/--output" if args.output else "--out", suffixes=(".png",))
    return [str(t.parent) if str(t.parent) else "."]


def run(args):
    import os
    from pathlib import Path

    from simfab.io import render

    src = Path(args.file)
    out = _target(args)
    info: dict = {}
    path = render.render_file(src, out, time=args.time, width=args.width, height=args.height, info=info)
    return {"png": str(path), "source": os.fspath(src), **info}
