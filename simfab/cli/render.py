"""``simfab render FILE -o out.png``: offscreen PNG of an MJCF scene or a USD stage's mesh."""

HELP = "render an MJCF scene or a USD stage (at a time code) to a PNG"
DESCRIPTION = """Render an MJCF scene (.xml), a USD stage (.usd/.usda/.usdc, its visible meshes with their
displayColor at --time, default the last time code) or a mesh file to a PNG, offscreen
(MuJoCo with EGL; matplotlib when no OpenGL is available).

--json keys: png (path of the image), source (the rendered file)."""


def add_args(p):
    p.add_argument("file", help="MJCF (.xml) or USD (.usda/.usdc/.usd) file")
    p.add_argument("-o", "--output", help="PNG path (default: <out>/<file stem>.png)")
    p.add_argument("--time", type=float, default=None, help="USD time code (default: last)")
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)


def run(args):
    import os
    from pathlib import Path

    from simfab.io import render

    src = Path(args.file)
    out = Path(args.output) if args.output else Path(args.out) / (src.stem + ".png")
    path = render.render_file(src, out, time=args.time, width=args.width, height=args.height)
    return {"png": str(path), "source": os.fspath(src)}
