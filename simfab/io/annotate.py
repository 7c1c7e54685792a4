"""Annotations that make a rendered PNG read on its own: title, scale bar (valid at the camera's
look-at depth), legend and colour bar, drawn with Pillow onto the image."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simfab.io.atomic import atomic_path


def _nice_length(x: float) -> float:
    """The largest 1, 2 or 5 x 10^k not above x."""
    k = np.floor(np.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= x:
            return float(m * 10**k)
    return float(10**k)


def annotate_png(png, camera: dict, *, title: str = "", legend: list | None = None,
                 colorbar: dict | None = None) -> Path:
    """Add a title (top left), a scale bar valid at the look-at depth (bottom left), an
    optional legend ``[(label, rgb), ...]`` (top right) and an optional colour bar
    ``{"label", "cmap", "min", "max"}`` (right edge; with ``"clipped"`` true its top reads ">= max":
    larger values share the top colour) to a PNG rendered with ``camera`` (see
    :func:`render_model`). The image is rewritten in place."""
    from PIL import Image, ImageDraw, ImageFont

    png = Path(png)
    img = Image.open(png).convert("RGB")
    W, H = img.size
    d = ImageDraw.Draw(img, "RGBA")
    fs = max(12, H // 32)
    try:
        font = ImageFont.load_default(size=fs)
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    if title:
        d.rectangle([0, 0, W, int(1.8 * fs)], fill=(255, 255, 255, 190))
        d.text((int(0.5 * fs), int(0.35 * fs)), title, fill=(20, 20, 20), font=font)
    depth = float(np.linalg.norm(np.subtract(camera["target"], camera["eye"])))
    px_per_m = H / (2.0 * depth * np.tan(np.radians(camera["fovy_deg"]) / 2.0))
    L = _nice_length(0.25 * W / px_per_m)
    n = int(round(L * px_per_m))
    x0, y0 = int(0.5 * fs), H - int(1.2 * fs)
    label = (f"{L * 1e3:g} mm" if L < 1 else f"{L:g} m") + " (at the look-at point)"
    tw = int(d.textlength(label, font=font))
    d.rectangle([x0 - 4, y0 - int(1.6 * fs), x0 + max(n, tw) + 8, H - 2], fill=(255, 255, 255, 190))
    d.rectangle([x0, y0, x0 + n, y0 + max(3, fs // 4)], fill=(20, 20, 20))
    d.text((x0, y0 - int(1.3 * fs)), label, fill=(20, 20, 20), font=font)
    for i, (lab, rgb) in enumerate(legend or []):
        y = int((2.2 + 1.4 * i) * fs)
        c = tuple(int(255 * float(v)) for v in rgb[:3])
        w = int(d.textlength(lab, font=font)) + 2 * fs
        d.rectangle([W - w - fs, y - 4, W - 4, y + fs + 4], fill=(255, 255, 255, 190))
        d.rectangle([W - w - int(0.5 * fs), y, W - w + int(0.3 * fs), y + fs], fill=c)
        d.text((W - w + fs // 2 + 4, y), lab, fill=(20, 20, 20), font=font)
    if colorbar:
        import matplotlib

        cm = matplotlib.colormaps[colorbar.get("cmap", "viridis")]
        bh, bw = int(0.5 * H), max(10, W // 40)
        labels = [(">= " if colorbar.get("clipped") else "") + f"{colorbar['max']:.3g}", f"{colorbar['min']:.3g}"]
        tw = max(int(d.textlength(t, font=font)) for t in labels)
        box_w = max(bw + tw + 14, int(d.textlength(colorbar["label"], font=font)) + 10)
        x1, y1 = W - box_w - 4, int(0.25 * H)
        d.rectangle([x1 - 6, y1 - int(1.8 * fs), W - 2, y1 + bh + 6], fill=(255, 255, 255, 190))
        for j in range(bh):
            c = cm(1.0 - j / max(bh - 1, 1))
            d.line([(x1, y1 + j), (x1 + bw, y1 + j)], fill=tuple(int(255 * x) for x in c[:3]))
        d.text((x1 + bw + 4, y1 - fs // 2), labels[0], fill=(20, 20, 20), font=font)
        d.text((x1 + bw + 4, y1 + bh - fs // 2), labels[1], fill=(20, 20, 20), font=font)
        d.text((x1 - 2, y1 - int(1.5 * fs)), colorbar["label"], fill=(20, 20, 20), font=font)
    with atomic_path(png) as tmp:
        img.save(tmp, format="PNG")
    return png
