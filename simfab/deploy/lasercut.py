"""Laser-cut export of a flat pattern: closed outlines (SVG and DXF, millimetres).

Geometry: every beam half and spring arc is a centre-line offset by half its width
(flat caps at the gaps, round joins), united into closed outlines (shapely); each outline
ring (outer boundary and holes) is one closed polyline on the **cut** layer. The inserts (each a
square plate of half-side r_i + beam_width, so the clamped beam ends rest on it) are laid out
in rows below the pattern as separate parts, by size class. The **engrave** layer carries the
insert numbers with their size class (``12 B``; the number alone with a one-size catalogue) at
each gap of the pattern and on each insert part, and a 50 mm scale bar. A pattern flattened with
cuts (:mod:`simfab.deploy.cuts`) also has a **seam** layer: both sides of every cut path as open
polylines, labelled ``S<k>`` at their middles (the two edges that meet on the target; the sheet
is already cut there, the pattern's outline follows them).

Files: SVG with ``width``/``height`` in mm and the viewBox ``0 0 W H`` in mm (y down: x_svg =
x - x0, y_svg = y1 - y with (x0, y1) the sheet's top-left corner, :func:`svg_origin`), layers as
Inkscape layer groups ``cut`` (red hairline) and ``engrave`` (blue); DXF (R2010, $INSUNITS = mm)
with layers ``CUT`` (closed LWPOLYLINEs), ``ENGRAVE`` (TEXT, LINE) and ``SEAM`` (open LWPOLYLINEs,
TEXT). Summary: part count, total cut length [mm], sheet extent [mm] (the seams included), seams.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MM = 1e3  # metres -> millimetres
SCALE_BAR_MM = 50.0


@dataclass(frozen=True)
class CutLayout:
    """Everything drawn, in mm (y up; :func:`layout`).

    Args:
        rings: cut rings [(k,2) closed, first != last] [mm].
        labels: [(text, (x, y), height)] [mm].
        scale_bar: segments [((x0, y0), (x1, y1))] [mm].
        parts: separate parts (the pattern and the inserts).
        inserts: insert parts.
        cut_length: total cut length [mm].
        extent: (xmin, ymin, xmax, ymax) [mm].
        seams: [(label, (k,2) open polyline [mm])] (empty without cuts).
    """

    rings: list
    labels: list
    scale_bar: list
    parts: int
    inserts: int
    cut_length: float
    extent: tuple
    seams: tuple = ()


def cut_layout(pat, *, arc_points: int = 12, seams=()) -> CutLayout:
    """Outlines of a pattern and its inserts (see the module doc).

    Args:
        pat: the :class:`simfab.deploy.pattern.Pattern`.
        arc_points: points per spring arc.
        seams: [(label, (k,2) polyline [m])] for the seam layer.

    Returns:
        The :class:`CutLayout`.
    """
    import shapely

    w = pat.config.beam_width * MM
    ws = pat.config.spring_width * MM
    lines = [(shapely.LineString(np.array([a, b]) * MM), w) for _, _, a, b in pat.beam_halves()]
    lines += [(shapely.LineString(pts * MM), ws) for *_, pts in pat.spring_curves(arc_points)]
    beams = shapely.unary_union([ln.buffer(0.5 * wd, cap_style="flat", join_style="round", quad_segs=4)
                                 for ln, wd in lines])
    # junctions: a round pad where beams and springs meet (midpoints, boundary vertices)
    pads = [shapely.Point(p * MM).buffer(0.5 * w, quad_segs=4) for p in pat.midpoints()]
    pads += [shapely.Point(pat.P[v] * MM).buffer(0.5 * w, quad_segs=4) for v in np.flatnonzero(~pat.interior)]
    shape = shapely.unary_union([beams, *pads]).simplify(1e-3)
    polys = list(shape.geoms) if hasattr(shape, "geoms") else [shape]
    rings = []
    for poly in polys:
        for ring in [poly.exterior, *poly.interiors]:
            rings.append(np.asarray(ring.coords)[:-1])
    labels = []
    ids = np.flatnonzero(pat.interior)
    name = lambda v: f"{pat.insert_ids[v]} {pat.class_label(v)}".strip()  # noqa: E731  number + size class
    for v in ids:
        labels.append((name(v), tuple(pat.P[v] * MM), 1.2))
    minx, miny, maxx, maxy = shape.bounds
    seam_lines = tuple((lab, np.asarray(pts, dtype=np.float64) * MM) for lab, pts in seams)
    if seam_lines:  # the seams run on to the rim where the grid left notches
        allp = np.vstack([pts for _, pts in seam_lines])
        minx, miny = min(minx, allp[:, 0].min()), min(miny, allp[:, 1].min())
        maxx, maxy = max(maxx, allp[:, 0].max()), max(maxy, allp[:, 1].max())
    # insert parts: rows below the pattern, by size class then number, on the largest size's pitch
    half = (pat.insert_size + pat.config.beam_width) * MM  # plate half-side per vertex
    s = float(half[ids].max()) if len(ids) else 0.0
    pitch = 2 * s + 3.0
    per_row = max(1, int((maxx - minx) // pitch))
    y0 = miny - 10.0 - s
    for k, v in enumerate(ids[np.lexsort((pat.insert_ids[ids], pat.insert_class[ids]))]):
        cx = minx + s + (k % per_row) * pitch
        cy = y0 - (k // per_row) * pitch
        a = half[v]
        rings.append(np.array([[cx - a, cy - a], [cx + a, cy - a], [cx + a, cy + a], [cx - a, cy + a]]))
        labels.append((name(v), (cx, cy), 1.2))
    nrows = (len(ids) + per_row - 1) // per_row if len(ids) else 0
    ybar = y0 - max(nrows - 1, 0) * pitch - s - 8.0
    bar = [((minx, ybar), (minx + SCALE_BAR_MM, ybar))]
    bar += [((minx + x, ybar), (minx + x, ybar + (2.0 if x % 50 == 0 else 1.0))) for x in np.arange(0.0, 51.0, 10.0)]
    labels.append((f"{SCALE_BAR_MM:.0f} mm", (minx + SCALE_BAR_MM / 2, ybar - 3.0), 2.5))
    cut_length = float(sum(np.sum(np.linalg.norm(np.roll(r, -1, axis=0) - r, axis=1)) for r in rings))
    extent = (minx, ybar - 6.0, maxx, maxy)
    return CutLayout(rings=rings, labels=labels, scale_bar=bar, parts=len(polys) + len(ids), inserts=len(ids),
                     cut_length=cut_length, extent=extent, seams=seam_lines)


SVG_MARGIN = 5.0  # mm around the drawing


def svg_origin(cut: CutLayout) -> tuple[float, float, float, float]:
    """The SVG sheet's frame.

    Args:
        cut: the :class:`CutLayout`.

    Returns:
        (x0, y1, W, H) [mm]: the sheet's top-left corner in drawing coordinates and its size.
    """
    x0, y0, x1, y1 = cut.extent
    return x0 - SVG_MARGIN, y1 + SVG_MARGIN, x1 - x0 + 2 * SVG_MARGIN, y1 - y0 + 2 * SVG_MARGIN


def write_svg(path, cut: CutLayout) -> None:
    """SVG in millimetres (see the module doc).

    Args:
        path: the file, written as given (pass an atomic temporary path).
        cut: the :class:`CutLayout`.
    """
    X0, Y1, W, H = svg_origin(cut)
    f = lambda v: f"{v:.4f}"  # noqa: E731
    fx = lambda x: f(x - X0)  # noqa: E731
    fy = lambda y: f(Y1 - y)  # noqa: E731
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape" '
           f'width="{f(W)}mm" height="{f(H)}mm" viewBox="0 0 {f(W)} {f(H)}">',
           '<g id="cut" inkscape:label="cut" inkscape:groupmode="layer" fill="none" stroke="#ff0000" '
           'stroke-width="0.05">']
    for k, r in enumerate(cut.rings):
        d = "M " + " L ".join(f"{fx(x)},{fy(y)}" for x, y in r) + " Z"
        out.append(f'<path id="cut{k}" d="{d}"/>')
    out.append("</g>")
    out.append('<g id="engrave" inkscape:label="engrave" inkscape:groupmode="layer" fill="none" stroke="#0000ff" '
               'stroke-width="0.1">')
    for (a, b) in cut.scale_bar:
        out.append(f'<line x1="{fx(a[0])}" y1="{fy(a[1])}" x2="{fx(b[0])}" y2="{fy(b[1])}"/>')
    for text, (x, y), h in cut.labels:
        out.append(f'<text x="{fx(x)}" y="{fy(y)}" font-size="{f(h)}" font-family="sans-serif" text-anchor="middle" '
                   f'dominant-baseline="central" fill="#0000ff" stroke="none">{text}</text>')
    out.append("</g>")
    if cut.seams:
        out.append('<g id="seam" inkscape:label="seam" inkscape:groupmode="layer" fill="none" stroke="#00a000" '
                   'stroke-width="0.1">')
        for k, (lab, pts) in enumerate(cut.seams):
            d = "M " + " L ".join(f"{fx(x)},{fy(y)}" for x, y in pts)
            out.append(f'<path id="seam{k}" d="{d}"/>')
            x, y = pts[len(pts) // 2]
            out.append(f'<text x="{fx(x)}" y="{fy(y)}" font-size="3" font-family="sans-serif" text-anchor="middle" '
                       f'dominant-baseline="central" fill="#00a000" stroke="none">{lab}</text>')
        out.append("</g>")
    out.append("</svg>")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(out) + "\n")


def write_dxf(path, cut: CutLayout) -> None:
    """DXF R2010 in millimetres, layers CUT / ENGRAVE (see the module doc).

    Args:
        path: the file.
        cut: the :class:`CutLayout`.
    """
    import ezdxf
    from ezdxf.enums import TextEntityAlignment

    doc = ezdxf.new("R2010", setup=True)
    doc.units = ezdxf.units.MM
    doc.header["$MEASUREMENT"] = 1
    doc.layers.add("CUT", color=1)
    doc.layers.add("ENGRAVE", color=5)
    if cut.seams:
        doc.layers.add("SEAM", color=3)
    msp = doc.modelspace()
    for r in cut.rings:
        msp.add_lwpolyline([tuple(p) for p in r], close=True, dxfattribs={"layer": "CUT"})
    for a, b in cut.scale_bar:
        msp.add_line(a, b, dxfattribs={"layer": "ENGRAVE"})
    for text, (x, y), h in cut.labels:
        msp.add_text(text, height=h, dxfattribs={"layer": "ENGRAVE"}).set_placement(
            (x, y), align=TextEntityAlignment.MIDDLE_CENTER)
    for lab, pts in cut.seams:
        msp.add_lwpolyline([tuple(p) for p in pts], close=False, dxfattribs={"layer": "SEAM"})
        msp.add_text(lab, height=3.0, dxfattribs={"layer": "SEAM"}).set_placement(
            tuple(pts[len(pts) // 2]), align=TextEntityAlignment.MIDDLE_CENTER)
    doc.saveas(path)


def cut_summary(cut: CutLayout) -> dict:
    """The cut layout's figures for the JSON summary.

    Args:
        cut: the :class:`CutLayout`.

    Returns:
        {parts, inserts, cut_outlines, cut_length_mm, sheet_mm [w, h], seams}.
    """
    x0, y0, x1, y1 = cut.extent
    return dict(parts=cut.parts, inserts=cut.inserts, cut_outlines=len(cut.rings), cut_length_mm=cut.cut_length,
                sheet_mm=[x1 - x0, y1 - y0], seams=len({lab for lab, _ in cut.seams}))
