"""Pattern layout, gap rule and laser-cut export (simfab.deploy.pattern, simfab.deploy.lasercut)."""

import numpy as np
import pytest

from simfab._bundled import scenes_dir
from simfab.deploy import flatten, lasercut, pattern, scene
from simfab.errors import InputError

#: the patterns these layout tests were written on: the bundled targets with the spacing, insert size and layout
#: their scene files set by hand before the files were left to the defaults (simfab.deploy.auto)
PINNED = {"dome": dict(spacing=0.03, insert_half_size=0.005, layout="conforming", conforming_core="regular",
                       growth_fit="edges"),
          "saddle": dict(spacing=0.025, insert_half_size=0.005, layout="conforming"),
          "mixed": dict(spacing=0.025, insert_half_size=0.005, layout="conforming")}


def _pinned(name, **pattern_):
    """A bundled target with the pattern of ``PINNED`` (and ``pattern_`` over it)."""
    return scene.load_deploy_scene(scene.bundled_path(name), overrides={"pattern": {**PINNED[name], **pattern_}})


@pytest.fixture(scope="module", params=scene.BUNDLED)
def laid_out(request):
    """Each bundled target flattened without cuts and laid out on the clipped grid (the layouts the
    scenes choose have their own tests)."""
    sc = _pinned(request.param, layout="grid")
    f = flatten.flatten(sc.target.V, sc.target.F)
    pat = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, sc.pattern)
    return request.param, sc, f, pat


def _gaussian_curvature_at(sc, f, points):
    """Angle defect per unit area (Voronoi-free: defect / (area/3)) of the target, interpolated at
    flat points (k,2) [1/m^2]."""
    V, F = sc.target.V, sc.target.F
    ang = flatten.corner_angles(V, F)
    n = len(V)
    defect = 2 * np.pi - np.bincount(F.ravel(), weights=ang.ravel(), minlength=n)
    area = np.bincount(F.ravel(), weights=np.repeat(flatten.face_areas(V, F) / 3, 3), minlength=n)
    K = defect / area
    K[f.boundary] = K[f.boundary] * 0  # boundary vertices carry geodesic, not Gaussian, curvature
    return pattern.interpolate(f.uv, F, K, points)


def test_interpolate_inside_and_outside_the_flat_mesh():
    """Inside: the piecewise-linear interpolant (matplotlib's as the reference); outside (a
    conforming layout's boundary vertices): the value at the nearest boundary point, here of a
    linear field on the unit square, evaluated 1 mm beyond an edge."""
    import matplotlib.tri as mtri

    rng = np.random.default_rng(3)
    uv = np.vstack([[[0, 0], [1, 0], [1, 1], [0, 1]], rng.uniform(0.1, 0.9, (30, 2))])
    faces = mtri.Triangulation(uv[:, 0], uv[:, 1]).triangles
    vals = np.column_stack([2 * uv[:, 0] - uv[:, 1], np.sin(3 * uv[:, 0])])
    P = rng.uniform(0.0, 1.0, (50, 2))
    ref = mtri.LinearTriInterpolator(mtri.Triangulation(uv[:, 0], uv[:, 1], faces), vals[:, 1])(P[:, 0], P[:, 1])
    assert np.allclose(pattern.interpolate(uv, faces, vals, P)[:, 1], ref, atol=1e-12)
    out = np.array([[0.3, -0.001], [1.001, 0.6], [0.5, 1.001]])
    near = np.array([[0.3, 0.0], [1.0, 0.6], [0.5, 1.0]])
    got = pattern.interpolate(uv, faces, vals[:, 0], out)
    assert np.allclose(got, 2 * near[:, 0] - near[:, 1], atol=1e-12)


def test_gap_rule_formula():
    u = np.array([-0.2, 0.0, 0.1])
    g = pattern.gap_rule(u, np.full(3, 0.03), 0.005)
    # the insert must lengthen each half-edge from h/2 to h/2 e^{-u}
    assert np.allclose(0.005 - g, 0.015 * (np.exp(-u) - 1), rtol=1e-12)
    assert g[0] < 0.005 and g[1] == 0.005 and g[2] > 0.005


def test_gap_sign_follows_curvature(laid_out):
    name, sc, f, pat = laid_out
    r = sc.pattern.insert_half_size
    ins = np.flatnonzero(pat.interior)
    assert len(ins) >= 20
    push = r - pat.gap_required[ins]  # > 0: dome, < 0: saddle
    if name == "dome":
        assert np.all(push > 0)
    elif name == "saddle":
        assert np.all(push < 0)
    else:  # mixed: both signs; the most positively / negatively curved inserts push / pull
        assert np.any(push > 0) and np.any(push < 0)
        K = _gaussian_curvature_at(sc, f, pat.P[ins])
        order = np.argsort(K)
        assert K[order[0]] < 0 < K[order[-1]]
        assert np.all(push[order[-3:]] > 0), (K[order[-3:]], push[order[-3:]])
        assert np.all(push[order[:3]] < 0), (K[order[:3]], push[order[:3]])
    # every half beam at an insert runs from its edge's midpoint towards the insert, at least the floor long
    # (on the saddle's clipped cells, 8.5 mm edges of 25 mm cells, the gaps the saddle asks for reach past
    # the midpoint: they were laid out as half beams folded back over their neighbours, 0.84 mm "long")
    floor = pattern.HALF_BEAM_FLOOR * sc.pattern.beam_thickness
    elen = np.linalg.norm(pat.P[pat.edges[:, 0]] - pat.P[pat.edges[:, 1]], axis=1)
    for e, (a, b) in enumerate(pat.edges):
        for v in (a, b):
            if pat.interior[v]:
                assert 0.5 * elen[e] - pat.gap[v] >= floor - 1e-12, (e, v)
    # so the inserts of those clipped cells fall short of the gap they need, and only they (none elsewhere)
    emin = np.full(len(pat.P), np.inf)
    np.minimum.at(emin, pat.edges.ravel(), np.repeat(elen, 2))
    short = 0.5 * emin[pat.unreachable] - pat.gap_required[pat.unreachable] < floor
    assert np.all(short) and len(pat.unreachable) == (8 if name == "saddle" else 0)


def test_layout_structure(laid_out):
    _, sc, _, pat = laid_out
    # interior vertices have four beams; quads are CCW and not smaller than a quarter cell
    val = np.bincount(pat.edges.ravel(), minlength=len(pat.P))
    assert np.all(val[pat.interior] == 4)
    Q = pat.P[pat.quads]
    area = 0.5 * np.sum(Q[:, :, 0] * np.roll(Q[:, :, 1], -1, axis=1) - np.roll(Q[:, :, 0], -1, axis=1) * Q[:, :, 1],
                        axis=1)
    assert np.all(area > 0.2 * sc.pattern.spacing**2)
    # springs are missing only in boundary quads
    qb = np.unique(pat.edge_quads[pat.edge_quads[:, 1] < 0, 0])
    assert set(np.flatnonzero(~pat.spring)) <= set(qb.tolist())
    # beam halves stop at the gap: distance from an insert centre to its beam end = g
    for e, v, start, end in pat.beam_halves():
        assert np.isclose(np.linalg.norm(end - pat.P[v]), pat.gap[v], atol=1e-12)


def test_svg_and_dxf_reread_same_outlines_mm(tmp_path):
    import ezdxf
    from svgelements import SVG, Path

    sc = scene.load_deploy_scene(scene.bundled_path("dome"))
    f = flatten.flatten(sc.target.V, sc.target.F)
    pat = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, sc.pattern)
    cut = lasercut.cut_layout(pat)
    svg, dxf = tmp_path / "p.svg", tmp_path / "p.dxf"
    lasercut.write_svg(svg, cut)
    lasercut.write_dxf(dxf, cut)
    # every outline is closed and the pattern is one part plus one part per insert
    assert cut.parts == 1 + pat.n_inserts
    # SVG: parse with physical units (1 user unit = 1 mm at 25.4 ppi), undo the sheet offset
    X0, Y1, W, H = lasercut.svg_origin(cut)
    doc = SVG.parse(str(svg), ppi=25.4)
    assert np.isclose(doc.width, W, rtol=1e-6) and np.isclose(doc.height, H, rtol=1e-6)
    paths = [e for e in doc.elements() if isinstance(e, Path) and str(e.id).startswith("cut")]
    assert len(paths) == len(cut.rings)
    for pth, ring in zip(paths, cut.rings):
        pts = np.array([(s.end.x, s.end.y) for s in pth if s.end is not None])
        got = np.column_stack([pts[:, 0] + X0, Y1 - pts[:, 1]])
        assert str(pth.segments()[-1].__class__.__name__) == "Close"
        assert np.allclose(got[: len(ring)], ring, atol=1e-3)  # 4-decimal mm in the file
    # DXF: millimetres, closed polylines on CUT, labels on ENGRAVE
    d = ezdxf.readfile(dxf)
    assert d.units == ezdxf.units.MM
    polys = d.modelspace().query('LWPOLYLINE[layer=="CUT"]')
    assert len(polys) == len(cut.rings)
    for pl, ring in zip(polys, cut.rings):
        assert pl.closed
        assert np.allclose(np.array([p[:2] for p in pl.get_points()]), ring, atol=1e-9)
    texts = d.modelspace().query('TEXT[layer=="ENGRAVE"]')
    assert len(texts) == 2 * pat.n_inserts + 1  # gap labels, insert-part labels, scale bar
    # total cut length matches the outlines'
    per = sum(np.sum(np.linalg.norm(np.roll(r, -1, axis=0) - r, axis=1)) for r in cut.rings)
    assert np.isclose(per, cut.cut_length)


def test_spring_arc_length_closed_form():
    """b = 0 puts the handles on the chord: the arc is the straight chord (S/c = 1); the Bezier
    polyline converges to the arc length at second order in the sample spacing."""
    from simfab.deploy import springs

    M0, M1, c = np.array([[[0.5, 0.0]]]), np.array([[[1.0, 0.5]]]), np.array([[0.5, 0.5]])
    assert abs(springs.length_ratio(M0, M1, c, [0.0])[0] - 1.0) < 1e-12
    # the arc length grows with the bulge (the sizing's bisection relies on it)
    r = [springs.length_ratio(M0, M1, c, [b])[0] for b in (0.3, 0.6, 0.9, 1.2)]
    assert np.all(np.diff(r) > 0)


def test_springs_are_long_enough_for_the_growth(laid_out):
    """Every arc is at least (1 + slack) max(s, 1) times its chord (s: its chord's growth in
    deployment) unless its quad is reported short of slack, and even then longer than the
    deployed chord s c (an arc shorter than that would have to stretch: the beams buckle locally
    instead of the network growing - the bundled dome's failure mode before the sizing)."""
    name, sc, f, pat = laid_out
    slack = sc.pattern.spring_slack
    need = (1 + slack) * np.maximum(pat.growth, 1.0)
    short = np.zeros(len(pat.quads), dtype=bool)
    short[pat.tight_springs] = True
    ok = pat.spring & ~short
    assert np.all(pat.spring_ratio[ok] >= need[ok] - 1e-9)
    # (a quad at an insert that falls short of its gap - the saddle's clipped cells, above - grows as its
    # clamped gap makes it, which no spring of its short edges reaches: it is reported unreachable)
    at_short = np.isin(pat.quads, pat.unreachable).any(axis=1)
    assert np.all(pat.spring_ratio[pat.spring & ~at_short] > pat.growth[pat.spring & ~at_short])
    # the stored ratios are the drawn arcs' (independent re-measurement on the curves themselves)
    mids = pat.midpoints()
    for i, (q, e0, e1, pts) in enumerate(pat.spring_curves(200)):
        S = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
        assert S / np.linalg.norm(mids[e1] - mids[e0]) >= pat.spring_ratio[q][i % 4] - 1e-3
    # the arcs keep the spring width clear of the quad centre (the four arcs of a quad stay apart)
    for q, e0, e1, pts in pat.spring_curves(64):
        c = pat.P[pat.quads[q]].mean(axis=0)
        assert np.min(np.linalg.norm(pts - c, axis=1)) >= sc.pattern.spring_width * (1 - 1e-6)
    if name == "dome":  # all its quads grow (u < 0): up to 20 % at the centre; the boundary quads whose Bezier
        # arcs cannot get the slack (short half-edges of a clipped cell next to a full-size insert) take zigzags
        assert pat.growth.max() > 1.15
        assert len(pat.tight_springs) == 0 and np.any(pat.spring_legs > 0)
    # every quad still short of the slack is a boundary quad (a skinny clipped cell where no zigzag fits)
    assert np.all(~pat.interior[pat.quads[pat.tight_springs]].all(axis=1))


def test_steep_cap_springs_reach_their_slack():
    """The 80 deg cap's quads grow up to 1.57 x (Bezier arcs reach 1.2-1.5 x their chord inside a
    cell): zigzag arcs make every arc at least (1 + slack) x its chord's growth long, with the rod
    segments the zigzag's pieces need (the cap uncut, on the clipped grid)."""
    from simfab.deploy import network, springs

    sc = scene.load_deploy_scene(scenes_dir("deploy", "cap80.toml"), overrides={"pattern": {
        "layout": "grid", "spacing": 0.03, "insert_half_sizes": [0.004, 0.007, 0.010]}})
    f = flatten.flatten(sc.target.V, sc.target.F)
    pat = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, sc.pattern)
    need = (1 + sc.pattern.spring_slack) * np.maximum(pat.growth, 1.0)
    assert pat.growth.max() > 1.5 and len(pat.tight_springs) == 0
    assert np.all(pat.spring_ratio[pat.spring] >= need[pat.spring] - 1e-9)
    zz = pat.spring_legs > 0
    assert zz.sum() > 0.5 * zz.size  # most arcs need the zigzag
    ss = network.rod_parameters(sc.deploy.spring_segments, sc.deploy.clamp_edge)
    for (q, e0, e1, drawn), (_, _, _, rod) in zip(pat.spring_curves(), pat.spring_rods(ss)):
        assert np.allclose(drawn[[0, -1]], rod[[0, -1]])  # same ends: the two edge midpoints
    legs = pat.spring_legs[zz]
    n_rod = [len(r) - 1 for (q, _, _, r) in pat.spring_rods(ss)]
    flat_legs = pat.spring_legs[pat.spring].ravel()
    assert all(n == (springs.zigzag_segments(int(lg)) if lg else sc.deploy.spring_segments)
               for n, lg in zip(n_rod, flat_legs))
    assert legs.min() >= 2 and np.all(legs % 2 == 0)
    # springs = "bezier": no zigzag, the quads short of the slack reported (68 of 76: the arcs reach 1.2-1.5 x)
    bez = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, pattern.PatternConfig(
        **{**sc.pattern.__dict__, "springs": "bezier"}))
    assert not np.any(bez.spring_legs) and len(bez.tight_springs) > 0.8 * len(bez.quads)
    # of those, the taut ones (an arc shorter than its deployed chord: a missed bound) are the quads where
    # the cell grows beyond what a Bezier arc reaches; the others reach, with less than the slack margin
    from simfab.deploy.pipeline import taut_springs

    taut = taut_springs(bez)
    assert 0 < len(taut) < len(bez.tight_springs) and np.all(np.isin(taut, bez.tight_springs))
    reach = np.maximum(bez.growth, 1.0)
    assert np.all(np.any(bez.spring_ratio[taut] < reach[taut] - 1e-9, axis=1))
    rest = np.setdiff1d(bez.tight_springs, taut)
    assert np.all(bez.spring_ratio[rest] >= reach[rest] - 1e-9)
    assert np.all(bez.growth[taut].max(axis=1) > bez.spring_ratio[rest].min())  # the taut ones grow most
    with pytest.raises(InputError, match="pattern.springs"):
        pattern.PatternConfig(springs="meander")


def _zigzag_length(pieces) -> float:
    """Exact length of a zigzag: straight pieces plus rho |angle| of its circular turns."""
    return sum(float(np.linalg.norm(p[2] - p[1])) if p[0] == "line" else p[2] * abs(p[4] - p[3]) for p in pieces)


def test_zigzag_geometry_against_closed_form():
    """A zigzag in a quad's triangle (edge midpoints M0, M1, centre c): its drawn polyline converges
    to the exact length (lines + rho x turning angle) at second order in the turn sampling; it
    keeps ``clearance`` from the triangle's two sides through c except along its lead pieces on the
    chord; its length grows with the amplitude; size_zigzag meets the length asked for; the rod's
    nodes turn by at most 60 deg at every node (a half turn in three segments)."""
    from simfab.deploy import springs

    M0, M1, c = np.array([0.015, 0.0]), np.array([0.03, 0.015]), np.array([0.015, 0.016])
    clear = 0.001
    lay, rho = springs.zigzag_layout(M0, M1, c, 4, 1.0, clear)
    exact = _zigzag_length(lay)
    drawn = springs.zigzag_points(lay)
    err = abs(np.sum(np.linalg.norm(np.diff(drawn, axis=0), axis=1)) - exact) / exact
    # chords of a circular arc: relative shortfall (dtheta)^2 / 24 per turn sample; 16 samples per half turn
    assert 0 < err < (np.pi / 16) ** 2 / 24
    # clearance from the sides M0-c and M1-c (signed distance, inside positive), leads excluded
    pts = np.vstack([springs.piece_points(p, 64) for p in lay[1:-1]])
    for A in (M0, M1):
        d = c - A
        n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
        n = n if n @ (0.5 * (M0 + M1) - A) > 0 else -n
        assert np.min((pts - A) @ n) >= clear * (1 - 1e-9)
    assert np.min(np.linalg.norm(pts - c, axis=1)) >= clear
    lengths = [_zigzag_length(springs.zigzag_layout(M0, M1, c, 4, a, clear)[0]) for a in (0.0, 0.3, 0.6, 1.0)]
    assert np.all(np.diff(lengths) > 0)
    chord = np.linalg.norm(M1 - M0)
    for need in (1.3, 1.7, 2.0):
        legs, a, ratio = springs.size_zigzag(M0, M1, c, need, clear)
        assert legs >= 2 and ratio >= need - 1e-9
        pts = springs.zigzag_points(springs.zigzag_layout(M0, M1, c, legs, a, clear)[0])
        assert np.isclose(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)) / chord, ratio)
    rod = springs.zigzag_points(lay, rod=True)
    assert len(rod) - 1 == springs.zigzag_segments(4)
    t = np.diff(rod, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    turn = np.degrees(np.arccos(np.clip(np.sum(t[1:] * t[:-1], axis=1), -1, 1)))
    assert turn.max() <= 60 + 1e-6
    assert springs.zigzag_layout(M0, M1, c, 30, 1.0, clear) is None  # legs closer than the clearance: none


def test_rod_parameters_short_clamped_ends():
    from simfab.deploy.network import rod_parameters

    s = rod_parameters(5, 0.2)
    d = np.diff(s)
    assert s[0] == 0 and s[-1] == 1 and np.all(d > 0)
    assert np.allclose(d[1:-1], d[1]) and np.allclose(d[[0, -1]], 0.2 * d[1])
    assert np.allclose(rod_parameters(4, 1.0), np.linspace(0, 1, 5))


def test_catalogue_assignment_reaches_every_reachable_gap():
    """Each insert takes the size whose gap g = r - d lies in [min_gap, gmax], nearest the range's
    middle; where none does, the smallest shortfall (hand-worked cases)."""
    sizes = (0.004, 0.007, 0.010)
    gmax = np.full(5, 0.011)
    min_gap = 0.0015
    d = np.array([0.0, 0.006, 0.0095, 0.012, -0.009])  # growth r - g each insert needs [m]
    k = pattern.assign_sizes(d, gmax, sizes, min_gap)
    # d = 0: all sizes reachable (g = r); the middle 6.25 mm is nearest 7 mm
    # d = 6 mm: 7 -> g = 1 (short), 10 -> g = 4 (reachable; 4 is the only reachable one)
    # d = 9.5 mm: only 10 mm -> g = 0.5 (short by 1 mm, the least)
    # d = 12 mm: none; 10 mm short by 3.5 mm (the least)
    # d = -9 mm (shrinking): 4 -> g = 13 (over by 2 mm, the least), 7 -> 16, 10 -> 19
    assert k.tolist() == [1, 2, 2, 2, 0]


def test_catalogue_in_pattern_files_and_bill_of_materials(tmp_path):
    """A steep cap (80 deg) needs more growth than one insert size can give: the catalogue reaches
    gaps the single size cannot, the size class is engraved next to each number in the SVG and
    the bill of materials counts every insert once."""
    from simfab.deploy import surface

    tgt = surface.spherical_cap(0.15, np.radians(80), 16)
    f = flatten.flatten(tgt.V, tgt.F)
    one = pattern.layout(f.uv, f.boundary, tgt.F, f.u, pattern.PatternConfig(spacing=0.03))
    cat = pattern.layout(f.uv, f.boundary, tgt.F, f.u,
                         pattern.PatternConfig(spacing=0.03, insert_half_sizes=[0.004, 0.007, 0.010]))
    assert len(cat.unreachable) < len(one.unreachable) / 3
    ins = cat.interior
    d = cat.insert_size[ins] - cat.gap_required[ins]
    assert np.allclose(d, one.insert_size[ins] - one.gap_required[ins])  # the growth does not depend on r
    bom = cat.bill_of_materials()
    assert [b["size_class"] for b in bom] == ["A", "B", "C"][:len(cat.config.sizes)] and len(bom) >= 2
    assert sum(b["count"] for b in bom) == cat.n_inserts
    assert sorted(i for b in bom for i in b["inserts"]) == list(range(1, cat.n_inserts + 1))
    cut = lasercut.cut_layout(cat)
    texts = [t for t, _, _ in cut.labels]
    for v in np.flatnonzero(ins):
        label = f"{cat.insert_ids[v]} {'ABC'[cat.insert_class[v]]}"
        assert cat.class_label(v) == 'ABC'[cat.insert_class[v]]
        assert texts.count(label) == 2  # at the gap and on the insert part
    # insert parts: one square per insert, of side 2 (r_i + beam_width)
    squares = [r for r in cut.rings[-cat.n_inserts:]]  # the parts come last
    assert all(len(r) == 4 and np.isclose(np.ptp(r[:, 0]), np.ptp(r[:, 1])) for r in squares)
    sides = sorted(round(float(np.ptp(r[:, 0])), 6) for r in squares)
    want = sorted(round(2e3 * (float(cat.insert_size[v]) + 0.003), 6) for v in np.flatnonzero(ins))
    assert sides == want


def test_catalogue_size_no_insert_takes_leaves_the_bill():
    """A catalogue size no insert takes (1 and 4 mm on the steep cap, whose inserts grow 2-11 mm) is not
    in the pattern's catalogue, its bill of materials (no size of count 0), its size letters or its
    laser-cut labels; every insert keeps the size and gap it gets from the catalogue without that size."""
    from simfab.deploy import surface

    tgt = surface.spherical_cap(0.15, np.radians(80), 16)
    f = flatten.flatten(tgt.V, tgt.F)
    lay = lambda sizes: pattern.layout(f.uv, f.boundary, tgt.F, f.u,  # noqa: E731
                                       pattern.PatternConfig(spacing=0.03, insert_half_sizes=sizes))
    spare, used = lay([0.001, 0.004, 0.007, 0.010]), lay([0.007, 0.010])
    ins = spare.interior
    # 1 and 4 mm: for no insert the size whose gap is nearest the middle of its range (assign_sizes)
    assert spare.config.sizes == used.config.sizes == (0.007, 0.010)
    assert np.array_equal(spare.insert_size, used.insert_size) and np.array_equal(spare.gap, used.gap)
    assert np.array_equal(spare.insert_class, used.insert_class)
    bom = spare.bill_of_materials()
    assert all(b["count"] > 0 for b in bom) and sum(b["count"] for b in bom) == spare.n_inserts
    assert [(b["size_class"], b["half_size_mm"]) for b in bom] == [("A", 7.0), ("B", 10.0)]
    for b in bom:  # each size's inserts are the ones of that half-size
        k = np.isin(spare.insert_ids, b["inserts"])
        assert np.allclose(spare.insert_size[k] * 1e3, b["half_size_mm"])
    texts = {t for t, _, _ in lasercut.cut_layout(spare).labels}
    assert {f"{spare.insert_ids[v]} {spare.class_label(v)}" for v in np.flatnonzero(ins)} <= texts
    # with every size used, the catalogue is the pattern's as given
    assert pattern.used_sizes_only(used) is used


def test_catalogue_config_errors():
    from simfab.errors import InputError

    with pytest.raises(InputError, match="insert_half_sizes"):
        pattern.PatternConfig(insert_half_sizes=[0.004, -0.002])
    with pytest.raises(InputError, match="insert_half_sizes"):
        pattern.PatternConfig(insert_half_sizes=[0.004, 0.004])
    with pytest.raises(InputError, match="insert_half_sizes"):  # overlapping plates (checked once final)
        pattern.PatternConfig(spacing=0.03, insert_half_sizes=[0.004, 0.013]).check_plates()
    with pytest.raises(InputError, match="insert_half_sizes"):
        pattern.PatternConfig(insert_half_sizes="0.004")


def test_a_spacing_the_default_insert_does_not_fit_gets_a_decided_catalogue(tmp_path):
    """Setting only the spacing (--spacing 15 mm, where the fixed default 5 mm insert's plates would overlap)
    is not refused for the insert size the user never set: the catalogue is decided from the target and
    fits; a size the user sets that does not fit is refused naming its flag, and a cell no insert fits
    (12 mm with the dome's 3 mm beams) naming the spacing's."""
    from simfab.deploy.scene import load_deploy_scene
    from simfab.errors import InputError
    from simfab.io.tables import Override

    def load(**pattern):
        flags = {"spacing": "--spacing", "insert_half_size": "--insert-size"}
        return load_deploy_scene(scene.bundled_path("dome"), overrides={"pattern": {
            k: Override(v, flags[k]) for k, v in pattern.items()}})

    sc = load(spacing=0.015)
    assert sc.pattern.spacing == 0.015 and 0 < max(sc.pattern.sizes) < 0.0075 - sc.pattern.beam_width
    for kw, flag, what in (({"spacing": 0.015, "insert_half_size": 0.005}, "--insert-size", "overlap"),
                           ({"spacing": 0.012}, "--spacing", "no insert fits a 12 mm cell")):
        with pytest.raises(InputError) as e:
            load(**kw)
        assert e.value.where == flag and what in str(e.value)


@pytest.mark.parametrize("name", scene.BUNDLED)
def test_conforming_layout_covers_the_domain_without_degenerate_quads(name):
    """layout = "conforming" (grid core + pillow layer): at least 99 % of the flat domain covered
    (measured 99.74-99.77 % vs 95.2-97.9 % for the clipped grid on the bundled targets; the dome's
    unsmoothed core, conforming_core = "regular": 99.51 %), about as much outside as the chords'
    segments leave inside (<= 0.3 %; the dome 0.33 %, its pillow vertices on the bisectors), its
    boundary vertices within a sagitta h^2 / (8 R_min) of the flattened boundary, every quad convex
    with all angles well below the spring limit (so every quad has a spring) and no edge below half
    the spacing."""
    import shapely

    sc = _pinned(name)
    f = flatten.flatten(sc.target.V, sc.target.F)
    h = sc.pattern.spacing
    poly = shapely.Polygon(f.uv[f.boundary])
    cover = {}
    for lay in ("grid", "conforming"):
        cfg = pattern.PatternConfig(**{**sc.pattern.__dict__, "layout": lay})
        pat = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, cfg)
        quads = shapely.union_all([shapely.Polygon(pat.P[q]) for q in pat.quads])
        cover[lay] = quads.intersection(poly).area / poly.area
    outside = quads.difference(poly).area / poly.area
    assert cover["conforming"] >= 0.99 and cover["conforming"] > cover["grid"]
    assert outside < 0.004
    assert np.all(pat.spring)
    angles = np.array([pattern.max_angle(pat.P[q]) for q in pat.quads])
    assert np.degrees(angles.max()) < 140.0  # smoothed <= 135; the dome's regular core 136 (bisectors)
    Q = pat.P[pat.quads]
    edge = np.linalg.norm(np.roll(Q, -1, axis=1) - Q, axis=2)
    assert edge.min() > 0.5 * h
    bnd = ~pat.interior
    d = shapely.distance(poly.exterior, shapely.points(pat.P[bnd]))
    R_min = 0.5 * np.sqrt(poly.area / np.pi)  # the flat domains are near-round: half their mean radius
    assert 0 < np.max(d) < h**2 / (8 * R_min)
    val = np.bincount(pat.edges.ravel(), minlength=len(pat.P))[pat.interior]
    assert set(val.tolist()) <= {3, 4, 5}  # 3 / 5 at the core's staircase corners (54 % of the dome's 37)


def test_edge_fitted_growth_is_the_gap_rule_on_a_uniform_grid_and_fits_unequal_edges():
    """growth_fit = "edges": on a uniform grid (h = 30 mm, rigid outline, a smooth u) the fitted
    growths are the vertex rule's (h/2)(e^{-u} - 1) up to the trapezoid rule's O(h^2 u'') along
    the edges next to the rigid outline, i.e. every residual d_a + d_b - G_e is zero where both
    rules agree; on the same grid with its rows unevenly spaced (25 / 35 mm, as a smoothed
    outline leaves them) the edges' growths d_a + d_b match their targets
    (L_e/2)(e^{-u_a} + e^{-u_b} - 2) better (RMS, relative) than the vertex rule's with the mean
    edge length."""
    h = 0.03
    def grid(ys):
        X, Y = np.meshgrid(np.arange(5) * h, np.asarray(ys), indexing="ij")
        P = np.column_stack([X.ravel(), Y.ravel()])
        idx = np.arange(len(P)).reshape(5, len(ys))
        E = np.vstack([np.column_stack([idx[:-1].ravel(), idx[1:].ravel()]),
                       np.column_stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()])])
        free = np.zeros(idx.shape, dtype=bool)
        free[1:-1, 1:-1] = True
        return P, E, free.ravel()

    def target(P, E, u):
        L = np.linalg.norm(P[E[:, 0]] - P[E[:, 1]], axis=1)
        return L, 0.5 * L * (np.exp(-u[E[:, 0]]) + np.exp(-u[E[:, 1]]) - 2)

    P, E, free = grid(np.arange(5) * h)
    u = -0.2 + 0.1 * np.sum((P - 2 * h) ** 2, axis=1) / (2 * h) ** 2  # u = 0 .. -0.2, largest growth inside
    u[~free] = 0.0  # the outline keeps its length (BFF with u = 0 on the boundary)
    d = pattern.edge_fitted_growth(P, E, u, free)
    d0 = np.where(free, 0.5 * h * np.expm1(-u), 0.0)
    assert np.all(d[~free] == 0)
    both = free[E[:, 0]] & free[E[:, 1]]
    L, G = target(P, E, u)
    assert np.max(np.abs(d[E[both, 0]] + d[E[both, 1]] - G[both])) < 0.02 * np.max(np.abs(G))
    assert np.max(np.abs(d - d0)) < 0.05 * np.max(np.abs(d0))
    # unequal rows: the fit matches the edges' growth, the vertex rule misses it
    P, E, free = grid(np.cumsum([0, 0.025, 0.035, 0.035, 0.025]))
    u = np.where(free, -0.2, 0.0)
    L, G = target(P, E, u)
    d = pattern.edge_fitted_growth(P, E, u, free)
    hv = np.bincount(E.ravel(), weights=np.repeat(L, 2), minlength=len(P)) / np.bincount(E.ravel(), minlength=len(P))
    dv = np.where(free, 0.5 * hv * np.expm1(-u), 0.0)
    err = lambda dd: np.sqrt(np.mean(((dd[E[:, 0]] + dd[E[:, 1]] - G) / L) ** 2))  # noqa: E731
    assert err(d) < err(dv)  # the least-squares optimum of the sums (the differences' term aside)
    assert np.all(np.isfinite(d)) and np.all(d[free] > 0)


def test_conforming_core_regular_keeps_the_grid_and_options_are_checked():
    """conforming_core = "regular": the core's vertices stay on the grid (every core edge h long;
    the pillow quads alone follow the outline), the coverage is the smoothed layout's; bad choices
    name their field."""
    sc = scene.load_deploy_scene(scene.bundled_path("dome"), overrides={"pattern": {"layout": "conforming"}})
    f = flatten.flatten(sc.target.V, sc.target.F)
    h = sc.pattern.spacing
    pats = {}
    for core in ("regular", "smoothed"):
        cfg = pattern.PatternConfig(**{**sc.pattern.__dict__, "conforming_core": core})
        pats[core] = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, cfg)
    reg = pats["regular"]
    ins = np.flatnonzero(reg.interior)
    assert np.allclose(reg.P[ins] / h, np.round(reg.P[ins] / h), atol=1e-9)
    core = reg.interior[reg.edges].all(axis=1)
    L = np.linalg.norm(reg.P[reg.edges[core, 0]] - reg.P[reg.edges[core, 1]], axis=1)
    assert np.allclose(L, h)
    L = np.linalg.norm(pats["smoothed"].P[pats["smoothed"].edges[core, 0]]
                       - pats["smoothed"].P[pats["smoothed"].edges[core, 1]], axis=1)
    assert np.ptp(L) > 0.2 * h  # smoothed: the outline's edges range ~25-35 mm
    with pytest.raises(InputError, match="conforming_core"):
        pattern.PatternConfig(conforming_core="round")
    with pytest.raises(InputError, match="growth_fit"):
        pattern.PatternConfig(growth_fit="faces")


def test_cone_tip_growth_is_the_half_edge_integral():
    """cone_tip_growth: for a linear u = a . x (interpolated exactly on any triangulation) each half
    edge from the tip along unit e (length L/2) grows by int_0^{L/2} (e^{-beta s} - 1) ds
    = (1 - e^{-beta L/2}) / beta - L/2, beta = a . e; the growth is their mean (8-point
    Gauss-Legendre: exact to round-off for this smooth integrand)."""
    uv = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05], [0.0, 0.0]])
    faces = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    a = np.array([-6.0, 3.0])  # [1/m]: u from -0.45 to +0.45 over the square
    u = uv @ a
    P = np.array([[0.0, 0.0], [0.04, 0.0], [0.0, 0.03], [-0.02, -0.02]])
    edges = np.array([[0, 1], [2, 0], [0, 3]])
    exact = []
    for o in (1, 2, 3):
        L = np.linalg.norm(P[o]); beta = a @ (P[o] / L)  # noqa: E702
        exact.append((1 - np.exp(-beta * L / 2)) / beta - L / 2)
    assert pattern.cone_tip_growth(P, edges, 0, uv, faces, u) == pytest.approx(np.mean(exact), rel=1e-10)


def test_skewed_quad_springs_take_per_arc_pulls():
    """A skewed interior quad of the bundled mixed surface's conforming layout (edges 20-29 mm): at a
    common pull its two arcs round the short diagonal's corners reach 1.231 x their chord of the
    1.239 x they need before they come within one spring width w of the centre (no zigzag fits its
    7-9 mm triangles). Per-arc pulls (springs.size_arcs): the shallow arcs keep room for the deep one,
    every arc reaches its need, and the arcs stay apart as far as the cap keeps them in a regular
    quad: opposite arcs' polylines >= 2 w apart, adjacent arcs' nearest approaches to the centre
    at least sqrt(2) w apart."""
    from simfab.deploy import springs

    Q = np.array([[-53.49, 53.39], [-25.0, 50.0], [-25.36, 75.32], [-45.13, 72.88]]) * 1e-3
    need = np.array([[1.239, 1.157, 1.126, 1.142]])
    w = 0.0015
    M0 = 0.5 * (Q + np.roll(Q, -1, axis=0))[None]
    M1, c = np.roll(M0, -1, axis=1), Q.mean(axis=0)[None, None]
    b, ratio, tight = springs.size_bulges(Q, np.arange(4)[None], M0[0][None], need / 1.1, bulge_min=0.5,
                                          slack=0.1, width=w)
    assert tight[0] and ratio[0, 0] < need[0, 0]  # the common pull falls short
    bk, rk = springs.size_arcs(M0, M1, c, need, b, bulge_min=0.5, width=w)
    assert np.all(rk >= need - 1e-9) and bk[0, 0] > b[0] > bk[0, 2]
    arcs = [springs.bezier(M0[0, k], M1[0, k], c[0, 0], bk[0, k], 400) for k in range(4)]
    dist = lambda p, q: np.min(np.linalg.norm(p[:, None] - q[None], axis=2))  # noqa: E731
    assert min(dist(arcs[0], arcs[2]), dist(arcs[1], arcs[3])) >= 2 * w * (1 - 1e-3)
    apex = [a[np.argmin(np.linalg.norm(a - c[0, 0], axis=1))] for a in arcs]
    assert min(np.linalg.norm(apex[k] - apex[(k + 1) % 4]) for k in range(4)) >= np.sqrt(2) * w * (1 - 1e-3)


def test_bundled_mixed_layout_has_every_spring_at_its_slack():
    """The bundled mixed surface's 25 mm conforming layout (``PINNED``): a spring in every quad, none short
    of its slack (the skewed quad above among them)."""
    sc = _pinned("mixed")
    f = flatten.flatten(sc.target.V, sc.target.F)
    pat = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, sc.pattern)
    need = (1 + sc.pattern.spring_slack) * np.maximum(pat.growth, 1.0)
    assert np.all(pat.spring) and len(pat.tight_springs) == 0
    assert np.all(pat.spring_ratio >= need - 1e-9)
