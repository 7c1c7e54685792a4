"""Helpers shared by the gallery's examples (not an example itself: no ``plot_`` prefix)."""

import json
import tempfile
from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt


def workdir(name: str) -> Path:
    """A fresh temporary folder for one example's files."""
    return Path(tempfile.mkdtemp(prefix=f"simfab-{name}-"))


def simfab(*argv) -> dict:
    """Run ``simfab ARGV... --json`` in-process and return its JSON summary (raises on a non-zero exit)."""
    import contextlib
    import io

    from simfab.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main([str(a) for a in argv] + ["--json"])
    plt.close("all")  # figures the pipeline drew for its PNGs: the gallery shows what the example shows
    if code != 0:
        raise RuntimeError(f"simfab {' '.join(map(str, argv))} exited with {code}")
    return json.loads(buf.getvalue())


def show_png(path, title: str | None = None):
    """Show a PNG simfab wrote (its own title, units and legend) as a gallery figure."""
    img = mpimg.imread(str(path))
    h, w = img.shape[:2]
    fig, ax = plt.subplots(figsize=(w / 100, h / 100), dpi=100)
    ax.imshow(img)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig
