"""Cuts with cone singularities (simfab.deploy.cuts): closed-form cone flattening, greedy placement,
the cut mesh and its seams, the pattern laid out around the cuts, the seam layer."""

import numpy as np
import pytest
import shapely

from simfab.deploy import cuts, flatten, lasercut, pattern, quadmesh, surface
from simfab.deploy.pattern import PatternConfig
from simfab.deploy.scene import load_deploy_scene
from simfab.errors import InputError


def pyramid(n: int, m: int, H: float):
    """A regular n-sided pyramid (base circumradius 1, apex height H) whose n planar facets are each
    split uniformly into m^2 triangles: every vertex but the apex is intrinsically flat (inside a
    facet, or on a pyramid edge whose two facets unfold into one plane), so its only curvature is
    the apex's angle defect 2 pi - n theta (theta: a facet's apex angle)."""
    key = {}
    V, F = [], []

    def vid(p):
        k = tuple(np.round(p, 12))
        if k not in key:
            key[k] = len(V)
            V.append(p)
        return key[k]

    apex = np.array([0.0, 0.0, H])
    for k in range(n):
        a = np.array([np.cos(2 * np.pi * k / n), np.sin(2 * np.pi * k / n), 0.0])
        b = np.array([np.cos(2 * np.pi * (k + 1) / n), np.sin(2 * np.pi * (k + 1) / n), 0.0])
        pt = lambda i, j: apex + (i / m) * (a - apex) + (j / m) * (b - apex)  # noqa: E731  i + j <= m
        for i in range(m):
            for j in range(m - i):
                F.append([vid(pt(i, j)), vid(pt(i + 1, j)), vid(pt(i, j + 1))])
                if i + j < m - 1:
                    F.append([vid(pt(i + 1, j)), vid(pt(i + 1, j + 1)), vid(pt(i, j + 1))])
    V = np.array(V)
    theta = 2 * np.arcsin(np.sin(np.pi / n) / np.sqrt(1 + H * H))
    return surface.validate(V, np.array(F), "pyramid"), key[tuple(np.round(apex, 12))], theta


@pytest.mark.parametrize("n,H", [(6, 0.8), (5, 1.5)])
def test_cone_at_pyramid_apex_flattens_isometrically(n, H):
    """Closed form: with the cone at the apex, u = 0 everywhere (no other vertex is curved), the
    cone's defect is 2 pi - n theta, and the cut mesh unfolds isometrically (every edge keeps its
    length, the flat angle at the cone tip is n theta)."""
    t, apex, theta = pyramid(n, 6, H)
    cfg = PatternConfig(spacing=0.2, insert_half_size=0.02, beam_width=0.01, min_gap=0.01, min_beam=0.02)
    cf = cuts.flatten_with_cuts(t.V, t.F, cuts.CutsConfig(max_cones=1), cfg, cones=[apex])
    assert cf.cone_defect[0] == pytest.approx(2 * np.pi - n * theta, abs=1e-12)
    assert np.max(np.abs(cf.u_uncut)) < 1e-12 and np.max(np.abs(cf.flat.u)) < 1e-12
    e = np.concatenate([cf.F[:, [0, 1]], cf.F[:, [1, 2]], cf.F[:, [2, 0]]])
    l3 = np.linalg.norm(cf.V[e[:, 0]] - cf.V[e[:, 1]], axis=1)
    l2 = np.linalg.norm(cf.flat.uv[e[:, 0]] - cf.flat.uv[e[:, 1]], axis=1)
    assert np.max(np.abs(l2 / l3 - 1)) < 1e-9
    assert cf.flat.closure_angle_correction < 1e-9
    tip = int(np.flatnonzero(cf.orig == apex)[0])
    ang = flatten.corner_angles(cf.flat.uv, cf.F)
    assert np.sum(ang[cf.F == tip]) == pytest.approx(n * theta, abs=1e-9)
    assert np.all(flatten.face_areas(cf.flat.uv, cf.F) > 0)


CAP80 = PatternConfig(spacing=0.03, insert_half_sizes=[0.004, 0.007, 0.010], spring_width=0.001)


def _cap80(rings=16):
    return surface.spherical_cap(0.15, np.radians(80), rings)


def test_greedy_cones_make_every_gap_reachable():
    t = _cap80()
    cfg = cuts.CutsConfig(max_cones=8)
    cf = cuts.flatten_with_cuts(t.V, t.F, cfg, CAP80)
    interior = np.ones(len(t.V), dtype=bool)
    interior[flatten.boundary_loop(t.F, len(t.V))] = False
    # without cones the flattening shrinks the centre beyond every catalogue size
    u0, _ = cuts.cone_metric(t.V, t.F, [])
    ok0 = cuts.reachable(u0, CAP80.spacing, CAP80.sizes, CAP80.min_gap, CAP80.min_beam)
    assert cf.unreachable_vertices["without_cones"] == int(np.sum(~ok0[interior])) > 50
    # with them every interior vertex is reachable and within the springs' growth
    ok = cuts.reachable(cf.u_uncut, CAP80.spacing, CAP80.sizes, CAP80.min_gap, CAP80.min_beam)
    assert np.all(ok[interior]) and cf.unreachable_vertices["with_cones"] == 0
    assert np.all(np.exp(-cf.u_uncut) <= cfg.max_growth + 1e-12)
    assert 1 <= len(cf.cones) <= cfg.max_cones
    assert np.all(cf.cone_defect > 0)  # positive cones only: their wedges open in the plane
    # Gauss-Bonnet of the cone metric: the cones carry part of the cap's total curvature 2 pi (1 - cos 80)
    assert np.sum(cf.cone_defect) < 2 * np.pi * (1 - np.cos(np.radians(80)))
    # cones keep their graph distance (along mesh edges) from the boundary and from each other
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    e = np.unique(np.sort(np.concatenate([t.F[:, [0, 1]], t.F[:, [1, 2]], t.F[:, [2, 0]]]), axis=1), axis=0)
    w = np.linalg.norm(t.V[e[:, 0]] - t.V[e[:, 1]], axis=1)
    G = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(t.V),) * 2)
    D = dijkstra(G, directed=False, indices=cf.cones)  # (c, n)
    assert np.all(D[:, flatten.boundary_loop(t.F, len(t.V))].min(axis=1) >= cfg.boundary_distance * CAP80.spacing)
    Dc = D[:, cf.cones] + np.diag(np.full(len(cf.cones), np.inf))
    assert np.all(Dc >= cfg.cone_distance * CAP80.spacing)


def test_cut_mesh_is_a_disk_with_isometric_seams():
    t = _cap80()
    cf = cuts.flatten_with_cuts(t.V, t.F, cuts.CutsConfig(max_cones=8), CAP80)
    surface.validate(cf.V, cf.F, "cut mesh")  # one boundary loop, Euler characteristic 1
    assert np.array_equal(cf.V, t.V[cf.orig])
    assert np.all(flatten.face_areas(cf.flat.uv, cf.F) > 0)  # no flipped triangle
    assert shapely.Polygon(cf.flat.uv[cf.flat.boundary]).is_valid  # the wedges do not overlap
    for s in cf.seams:
        assert s.path[0] == s.cone and np.all(s.sides >= 0)
        assert np.array_equal(cf.orig[s.sides[0]], s.path) and np.array_equal(cf.orig[s.sides[1]], s.path)
        la = np.linalg.norm(np.diff(cf.flat.uv[s.sides[0]], axis=0), axis=1)
        lb = np.linalg.norm(np.diff(cf.flat.uv[s.sides[1]], axis=0), axis=1)
        # both sides carry the same scale factors: equal lengths e^{(u_i+u_j)/2} l_ij (round-off)
        assert np.max(np.abs(la - lb)) < 1e-12
        u = cf.u_uncut[s.path]
        l3 = np.linalg.norm(np.diff(t.V[s.path], axis=0), axis=1)
        assert np.allclose(la, np.exp(0.5 * (u[1:] + u[:-1])) * l3, rtol=1e-10)
        # the cone's defect opens as the wedge between the two sides at the tip
        tip = int(np.flatnonzero(cf.orig == s.cone)[0])
        d0 = cf.flat.uv[s.sides[0][1]] - cf.flat.uv[tip]
        d1 = cf.flat.uv[s.sides[1][1]] - cf.flat.uv[tip]
        wedge = np.arccos(d0 @ d1 / np.linalg.norm(d0) / np.linalg.norm(d1))
        k = list(cf.cones).index(s.cone)
        assert wedge == pytest.approx(cf.cone_defect[k], abs=0.1 * cf.cone_defect[k])  # one mesh edge from the tip


def test_pattern_around_the_cuts():
    t = _cap80()
    cf = cuts.flatten_with_cuts(t.V, t.F, cuts.CutsConfig(max_cones=8), CAP80)
    lines = cuts.seam_lines(cf)
    pat = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, CAP80, seams=[p for _, p in lines])
    poly = shapely.Polygon(cf.flat.uv[cf.flat.boundary])
    cells = shapely.polygons(pat.P[pat.quads])
    # no quad bridges a wedge
    assert np.all(shapely.area(shapely.difference(cells, poly)) <= pattern.OUTSIDE_AREA * shapely.area(cells))
    # seam vertices (on the outline along a cut) with room for a gap hold inserts; rim vertices do not;
    # every beam half keeps at least min_beam between its gap and its midpoint
    bnd = np.zeros(len(pat.P), dtype=bool)
    bnd[pat.edges[pat.edge_quads[:, 1] < 0].ravel()] = True
    seam = bnd & pattern.near_seams(pat.P, poly, [p for _, p in lines], CAP80.spacing)
    assert np.sum(pat.interior[seam]) > 10 and not np.any(pat.interior[bnd & ~seam])
    # every insert inside the outline reaches its gap (the cones' purpose); a seam insert next to a
    # short clipped edge may not (it is listed, with its gap clamped)
    assert not np.any(~bnd[pat.unreachable]) and len(pat.unreachable) <= 2
    for _, v, start, end in pat.beam_halves():
        assert np.linalg.norm(end - start) >= CAP80.min_beam - 1e-12
    # the seam layer: both sides of every cut, in the SVG and the DXF
    cut = lasercut.cut_layout(pat, seams=lines)
    assert len(cut.seams) == 2 * len(cf.seams) and lasercut.cut_summary(cut)["seams"] == len(cf.seams)
    assert np.allclose(cut.seams[0][1], lines[0][1] * 1e3)


def test_mesh_layout_follows_the_cuts():
    """``layout = "mesh"`` (Triangle's triangulation of the cut flat domain paired into quads; the
    bundled 80 deg cap's layout) follows the seams: it covers >= 99 % of the cut flat domain (the
    clipped grid drops the cells a wedge crosses: measured 84 %, here checked below 95 %), its quads
    do not overlap or leave the domain by more than a chord's segment, all are convex. Its defects
    are few and all on the outline (on the defaults' 37 mm spacing and catalogue, with the smaller
    sizes for the seams' short edges: measured 99.3 % covered, no gap out of reach, 1 quad short of
    spring slack; with the earlier hand-set 30 mm and 4 / 7 / 10 mm: 99.7 %, 3 seam inserts whose
    shortest edge, 0.43 spacings, left their gap no room, 6 quads short; Gmsh's Blossom quads, the
    earlier mesher, had none but need X11/GLU system libraries)."""
    import dataclasses

    from simfab.deploy.scene import bundled_path, load_deploy_scene

    s = load_deploy_scene(bundled_path("cap80"))
    assert s.pattern.layout == "mesh"
    cf = cuts.flatten_with_cuts(s.target.V, s.target.F, s.cuts, s.pattern)
    lines = [p for _, p in cuts.seam_lines(cf)]
    poly = shapely.Polygon(cf.flat.uv[cf.flat.boundary])
    covered = {}
    for lay in ("grid", "mesh"):
        cfg = dataclasses.replace(s.pattern, layout=lay)
        pat = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, cfg, seams=lines)
        cells = shapely.polygons(pat.P[pat.quads])
        union = shapely.union_all(cells)
        covered[lay] = shapely.area(shapely.intersection(union, poly)) / poly.area
    assert covered["grid"] < 0.95 and covered["mesh"] >= 0.99
    assert np.sum(shapely.area(cells)) == pytest.approx(shapely.area(union), rel=1e-9)  # no overlaps
    assert shapely.area(shapely.difference(union, poly)) < 0.005 * poly.area
    Q = pat.P[pat.quads]  # (q,4,2) CCW
    a, b = np.roll(Q, 1, axis=1) - Q, np.roll(Q, -1, axis=1) - Q
    cos = np.einsum("qki,qki->qk", a, b) / (np.linalg.norm(a, axis=2) * np.linalg.norm(b, axis=2))
    cross = b[..., 0] * a[..., 1] - b[..., 1] * a[..., 0]  # > 0: a convex corner of a CCW quad
    assert np.all(cross > 0) and np.sum(np.degrees(np.arccos(cos)).max(axis=1) > s.pattern.degenerate_angle_deg) <= 1
    assert np.sum(~pat.spring) <= 1 and pat.n_inserts > 50
    bnd = np.zeros(len(pat.P), dtype=bool)
    bnd[pat.edges[pat.edge_quads[:, 1] < 0].ravel()] = True
    assert np.all(bnd[pat.unreachable]) and len(pat.unreachable) <= 3 and len(pat.tight_springs) <= 6


def test_seam_layer_files(tmp_path):
    import ezdxf

    t = _cap80(12)
    cf = cuts.flatten_with_cuts(t.V, t.F, cuts.CutsConfig(max_cones=8), CAP80)
    lines = cuts.seam_lines(cf)
    pat = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, CAP80, seams=[p for _, p in lines])
    cut = lasercut.cut_layout(pat, seams=lines)
    lasercut.write_svg(tmp_path / "p.svg", cut)
    lasercut.write_dxf(tmp_path / "p.dxf", cut)
    svg = (tmp_path / "p.svg").read_text()
    assert 'inkscape:label="seam"' in svg and svg.count('<path id="seam') == len(lines)
    doc = ezdxf.readfile(tmp_path / "p.dxf")
    seam = [e for e in doc.modelspace() if e.dxf.layer == "SEAM" and e.dxftype() == "LWPOLYLINE"]
    assert len(seam) == len(lines) and not any(e.closed for e in seam)


def test_cuts_table_is_validated(tmp_path):
    base = (tmp_path / "s.toml")
    base.write_text('[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 80\nrings = 8\n'
                    '[cuts]\nmax_cones = 2\n')
    assert load_deploy_scene(base).cuts.max_cones == 2
    for body, field in (("max_cones = -1", "cuts.max_cones"), ("max_growth = 0", "cuts.max_growth"),
                        ("join_seams = 1", "cuts.join_seams"), ("bogus = 1", "[cuts]")):
        p = tmp_path / "bad.toml"
        p.write_text('[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 80\nrings = 8\n'
                     f"[cuts]\n{body}\n")
        with pytest.raises(InputError) as e:
            load_deploy_scene(p)
        assert field in str(e.value) and str(p) in str(e.value)


def test_cut_cap_deploys_with_its_seams_closed():
    """A small 80 deg cap (R = 0.1 m) cut at its cones: with the seams free the flaps open into
    another shell of the same metric; with join_seams the ties draw facing seam vertices to their
    target distance and the deployed network follows the cap (measured: RMS 7.0 % free, 1.5 %
    joined, before tuning)."""
    from simfab.deploy import pipeline
    from simfab.deploy.mjcf_sim import SimConfig
    from simfab.deploy.network import DeployConfig
    from simfab.deploy.scene import SurfaceScene
    from simfab.deploy.tuning import TuneConfig

    t = surface.spherical_cap(0.1, np.radians(80), 12)
    pc = PatternConfig(spacing=0.025, insert_half_sizes=[0.003, 0.006, 0.009], spring_width=0.001)
    rms = {}
    for join in (False, True):
        s = SurfaceScene(target=t, pattern=pc, deploy=DeployConfig(perturbation=0.5), mujoco=SimConfig(),
                         path="small_cap80", tune=TuneConfig(iterations=0),
                         cuts=cuts.CutsConfig(max_cones=8, join_seams=join))
        r = pipeline.run(s, mujoco_check=False)
        assert r.deployment.stable and len(r.cuts.cones) >= 2 and len(r.pattern.unreachable) <= 2
        rms[join] = r.deviation.rms
    X = r.deployment.vertex_positions()
    a, b = r.ties.pairs.T
    assert len(a) >= 4
    # the ties close the seams to their target distance (within a tenth of a cell: the ties bend)
    assert np.max(np.abs(np.linalg.norm(X[a] - X[b], axis=1) - r.ties.length)) < 0.1 * pc.spacing
    assert rms[True] < 0.025 and rms[True] < 0.3 * rms[False]


def test_cut_cap_mujoco_scene_comes_to_rest():
    """The MuJoCo scene of a cut cap with its seams tied comes to rest within its check, at
    simfab's equilibrium. Each tie bends and twists by about the cone angle between its clamps; it
    needs its whole length for that (a tie whose outer thirds were rigid clamp edges took it in two
    10-27 deg hinges, and this scene crept for the whole 2 s: relaxed state 0.31 % RMS of the height
    from simfab's and still moving)."""
    from simfab.deploy import pipeline
    from simfab.deploy.mjcf_sim import SimConfig
    from simfab.deploy.network import DeployConfig
    from simfab.deploy.scene import SurfaceScene
    from simfab.deploy.tuning import TuneConfig

    t = surface.spherical_cap(0.1, np.radians(80), 12)
    pc = PatternConfig(spacing=0.025, insert_half_sizes=[0.003, 0.006, 0.009], spring_width=0.001)
    sc = SimConfig()
    s = SurfaceScene(target=t, pattern=pc, deploy=DeployConfig(perturbation=0.5), mujoco=sc, path="small_cap80",
                     tune=TuneConfig(iterations=0), cuts=cuts.CutsConfig(max_cones=8, join_seams=True))
    r = pipeline.run(s, mujoco_check=True)
    assert len(r.ties.pairs) >= 4
    st, rel = r.sim_check["stability"], r.sim_check["relaxation"]
    assert st["finite"] and st["settled"] and st["seconds"] < sc.stability_seconds
    # at rest within settle_tol x height of where it would be after the full check; simfab's equilibrium
    # is MuJoCo's to within the links' rigidity (simfab's rods stretch by up to ~0.1 mm)
    assert rel["rms_rel"] < sc.settle_tol and rel["max_rel"] < 2 * sc.settle_tol


def test_bundled_cap80_meets_the_deployment_bound():
    """The bundled 80 deg cap (scenes/deploy/cap80.toml: the target only) on the defaults - cut at
    its cones with the seams tied, laid out by quads along the seams (``layout = "mesh"``), the
    catalogue with the seams' smaller sizes - and its gaps tuned by 2 Gauss-Newton steps (of the
    default 8, for the test's time), deploys within the issue's bound: RMS <= 1 % of the diameter,
    out-of-plane height within 3 % of the target's, every gap reachable. Measured with the 8 steps
    (docs/validation/deploy.md): 0.543 %, -1.37 %. The tuning's point term makes the height: fitted
    to the surface alone the (grid-laid) cap ended on the sphere but 5.7 % too low."""
    from simfab.deploy import pipeline
    from simfab.deploy.scene import bundled_path, load_deploy_scene

    s = load_deploy_scene(bundled_path("cap80"), overrides={"tune": {"iterations": 2}})
    r = pipeline.run(s, mujoco_check=False)
    height = pipeline.out_of_plane_extent(r.deviation.aligned) / pipeline.out_of_plane_extent(r.target_points)
    assert r.deployment.stable and len(r.pattern.unreachable) == 0 and r.tuning["steps"] >= 1
    assert r.deviation.rms <= 0.01 and abs(height - 1.0) <= 0.03


def test_cone_tip_insert_grows_with_its_half_edges():
    """The bundled petal's mesh layout puts a vertex on its cone tip (an outline corner). u = 0 at a
    cone, so the gap rule gives it no growth, but its first ring shrank (u ~ -0.15): its half edges
    must grow by 1.1-1.9 mm to reach their target lengths (measured on the target, below). The tip
    holds an insert whose growth is the half edges' integral of e^{-u} - 1
    (pattern.cone_tip_growth): within 10 % of the mean target growth (the target polylines are
    sampled on the 24-ring triangulation that u is interpolated on)."""
    from simfab.deploy.scene import bundled_path, load_deploy_scene

    s = load_deploy_scene(bundled_path("petal"))
    assert s.pattern.layout == "mesh"
    cf = cuts.flatten_with_cuts(s.target.V, s.target.F, s.cuts, s.pattern)
    pat = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, s.pattern,
                         seams=[p for _, p in cuts.seam_lines(cf)], cone_tips=cuts.cone_points(cf))
    (v,) = np.flatnonzero(pat.cone_tip)
    assert np.linalg.norm(pat.P[v] - cuts.cone_points(cf)[0]) < 1e-9 and pat.interior[v] and abs(pat.u[v]) < 1e-9
    d = pat.insert_size[v] - pat.gap[v]
    assert d == pytest.approx(pattern.cone_tip_growth(pat.P, pat.edges, v, cf.flat.uv, cf.F, cf.flat.u), abs=1e-12)
    mids = pat.midpoints()[np.any(pat.edges == v, axis=1)]
    s_ = np.linspace(0.0, 1.0, 41)[:, None]
    grow = []
    for m in mids:
        T = pattern.map_to_surface(cf.flat.uv, cf.F, cf.V, pat.P[v] + s_ * (m - pat.P[v]))
        grow.append(np.sum(np.linalg.norm(np.diff(T, axis=0), axis=1)) - np.linalg.norm(m - pat.P[v]))
    assert min(grow) > 0.0003 and d == pytest.approx(np.mean(grow), rel=0.1)
    assert v not in pat.unreachable


def test_mesh_layout_needs_no_gmsh(monkeypatch):
    """The plain install runs every bundled target: the mesh layout imports no Gmsh (whose PyPI wheel
    links X11/GLU system libraries a bare Debian lacks). With ``import gmsh`` failing, a notched disk
    (a wedge cut out, as a cone's seams leave) is meshed into convex quads covering >= 99 % of it."""
    import sys

    monkeypatch.setitem(sys.modules, "gmsh", None)  # import gmsh -> ImportError
    t = np.linspace(0.3, 2 * np.pi - 0.3, 60)
    poly = shapely.Polygon(np.r_[[[0.0, 0.0]], 0.1 * np.column_stack([np.cos(t), np.sin(t)])])
    P, quads = quadmesh.mesh_quads(poly, 0.02)
    Q = P[quads]
    a, b = np.roll(Q, 1, axis=1) - Q, np.roll(Q, -1, axis=1) - Q
    assert np.all(b[..., 0] * a[..., 1] - b[..., 1] * a[..., 0] > 0)
    cells = shapely.polygons(Q)
    assert shapely.area(shapely.intersection(shapely.union_all(cells), poly)) >= 0.99 * poly.area
    assert np.sum(shapely.area(cells)) == pytest.approx(shapely.area(shapely.union_all(cells)), rel=1e-9)
    assert np.any(np.linalg.norm(P, axis=1) < 1e-12)  # a vertex on the notch's corner (a cone tip)
