"""Pattern layout, gap rule and laser-cut export (simfab.deploy.pattern, simfab.deploy.lasercut)."""

import numpy as np
import pytest

from simfab.deploy import flatten, lasercut, pattern, scene


@pytest.fixture(scope="module", params=scene.BUNDLED)
def laid_out(request):
    sc = scene.load_scene(scene.bundled_path(request.param))
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
    return pattern._interpolate(f.uv, F, K, points)


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
    assert len(pat.unreachable) == 0


def test_layout_structure(laid_out):
    _, sc, _, pat = laid_out
    # interior vertices have four beams; quads are CCW and not smaller than a quarter cell
    val = np.bincount(pat.edges.ravel(), minlength=len(pat.P))
    assert np.all(val[pat.interior] == 4)
    Q = pat.P[pat.quads]
    area = 0.5 * np.sum(Q[:, :, 0] * np.roll(Q[:, :, 1], -1, axis=1) - np.roll(Q[:, :, 0], -1, axis=1) * Q[:, :, 1], axis=1)
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

    sc = scene.load_scene(scene.bundled_path("dome"))
    f = flatten.flatten(sc.target.V, sc.target.F)
    pat = pattern.layout(f.uv, f.boundary, sc.target.F, f.u, sc.pattern)
    cut = lasercut.layout(pat)
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
