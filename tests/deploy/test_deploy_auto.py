"""The defaults decided from the target (simfab.deploy.auto): spacing, cuts, catalogue, layout, tuning."""

import json

import numpy as np
import pytest
import trimesh

from simfab.deploy import auto, families, flatten, surface
from simfab.deploy.pattern import PatternConfig
from simfab.deploy.scene import load_deploy_scene


def _bare(tmp_path, t):
    p = tmp_path / "t.obj"
    trimesh.Trimesh(t.V, t.F, process=False).export(p)
    return load_deploy_scene(p)


@pytest.mark.parametrize("h", [0.02, 0.03])
def test_catalogue_gives_every_growth_an_achievable_gap(h):
    """Every growth d gets a size r with min_gap + MARGIN <= r - d <= h/2 - min_beam - MARGIN (the gap
    rule's achievable range with the margin), in at most MAX_SIZES sizes, each a plate that fits the
    cell (r < h/2 - beam_width); a spread wider than the sizes can span is reported, not hidden."""
    pc = PatternConfig(spacing=h)
    rng = np.random.default_rng(0)
    for lo, hi in ((-0.004, 0.0), (0.0, 0.004), (-0.002, 0.006)):
        d = rng.uniform(lo, hi, 400)
        sizes, left = auto.catalogue(d, h, pc)
        r = np.asarray(sizes)[None, :]
        g = r - d[:, None]
        lo_g, hi_g = pc.min_gap + auto.MARGIN - 1e-12, h / 2 - pc.min_beam - auto.MARGIN + 1e-12
        ok = np.any((g >= lo_g) & (g <= hi_g), axis=1)
        assert left == np.sum(~ok) and len(sizes) <= auto.MAX_SIZES and len(set(sizes)) == len(sizes)
        if not sizes:  # the largest growth needs a plate wider than the cell allows
            assert left == len(d) and d.max() + pc.min_gap + auto.MARGIN > h / 2 - pc.beam_width - auto.SIZE_STEP
            continue
        assert max(sizes) < h / 2 - pc.beam_width and min(sizes) >= auto.MIN_INSERT
        if h == 0.03:  # a 4 mm spread fits the 30 mm cell's 10.5 mm of gap range with 3 mm inserts or more
            assert left == 0
    sizes, left = auto.catalogue(np.array([0.02]), 0.03, pc)  # a growth beyond any plate the cell allows
    assert sizes == [] and left == 1


def test_gentle_dome_needs_no_cuts_and_steep_cap_does(tmp_path):
    """The bundled dome's cap (50 deg): one insert size, no cuts, the conforming layout (>= 99 %
    covered), tuning on; an 80 deg cap: its uncut growth e^{-u} (1.7) is beyond the springs' reach
    (max_growth 1.25), so cones and tied seams, the mesh layout."""
    s = _bare(tmp_path, surface.spherical_cap(0.15, np.radians(50), 16))
    d = s.decisions
    assert not d.needs_cuts and s.cuts.max_cones == 0 and s.pattern.layout == "conforming"
    assert len(s.pattern.sizes) == 1 and s.tune.iterations > 0 and "pattern.spacing" in d.decided
    assert 0.02 <= s.pattern.spacing <= 0.035
    s = _bare(tmp_path, surface.spherical_cap(0.15, np.radians(80), 16))
    assert s.decisions.needs_cuts and s.decisions.uncut_growth_max > 1.5
    assert s.cuts.max_cones > 0 and s.cuts.join_seams and s.pattern.layout == "mesh"


def test_saddle_catalogue_pulls(tmp_path):
    """A saddle grows (u > 0): its growths are <= 0, so one size reaches all of them (g >= r: the inserts
    pull), the smallest (in SIZE_STEP) that keeps the tuning's room (TUNE_ROOM of the gap range, and the
    margin) below the smallest gap, r - max d >= min_gap + m."""
    t = surface.saddle(0.1, 0.1, 16)
    s = _bare(tmp_path, t)
    f = flatten.flatten(t.V, t.F)
    assert f.u.min() >= -1e-9 and not s.decisions.needs_cuts
    pc, h = s.pattern, s.pattern.spacing
    interior = np.ones(len(t.V), dtype=bool)
    interior[f.boundary] = False
    d = 0.5 * h * np.expm1(-f.u[interior])
    lo = pc.min_gap + auto.MARGIN + auto.TUNE_ROOM * (h / 2 - pc.min_beam - pc.min_gap)
    (r,) = s.pattern.sizes
    assert r >= auto.MIN_INSERT and lo - 1e-12 <= r - d.max() < lo + auto.SIZE_STEP or r == auto.MIN_INSERT


def test_given_fields_are_kept(tmp_path):
    """What a scene file (or a flag) sets is not decided: a steep cap's file keeps its catalogue,
    spacing, layout and cuts; a flag's tuning steps stay, and the tuning's other settings (point
    weight, stops) are still decided; ``--tune 0`` turns the tuning off."""
    from simfab.deploy.scene import bundled_path

    p = tmp_path / "cap.toml"
    p.write_text('[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 80\nrings = 12\n'
                 '[pattern]\nspacing = 0.03\ninsert_half_sizes = [0.004, 0.007, 0.010]\nlayout = "grid"\n'
                 '[cuts]\nmax_cones = 4\n')
    s = load_deploy_scene(p, overrides={"tune": {"iterations": 2}})
    assert s.pattern.sizes == (0.004, 0.007, 0.01) and s.pattern.spacing == 0.03 and s.cuts.max_cones == 4
    assert s.pattern.layout == "grid" and s.tune.iterations == 2
    assert "pattern.insert_half_sizes" not in s.decisions.decided and "tune.iterations" not in s.decisions.decided
    assert s.tune.point_weight == auto.AUTO_TUNE["point_weight"] and s.tune.target_rms > 0
    assert load_deploy_scene(p, overrides={"tune": {"iterations": 0}}).tune.point_weight == 0
    assert load_deploy_scene(bundled_path("dome"), auto=False).tune.iterations == 0


def test_spacing_follows_size_and_curvature():
    """Larger targets get larger cells; the spacing is at most sqrt(area / CELLS) and, on a curved
    target, CURVATURE_SPACING / sqrt(median |K|) (a sphere: K = 1/R^2), within SPACING_RANGE."""
    small, big = (auto.spacing(surface.saddle(a, 4 * a, 12)) for a in (0.08, 0.16))
    assert small < big
    for R in (0.1, 0.2):
        t = surface.spherical_cap(R, np.radians(80), 12)
        h = auto.spacing(t)
        assert h <= max(auto.CURVATURE_SPACING * R, auto.SPACING_RANGE[0]) + 1e-12
        assert h <= max(np.sqrt(np.sum(flatten.face_areas(t.V, t.F)) / auto.CELLS), auto.SPACING_RANGE[0]) + 1e-12
    for n in families.names((12,)):
        assert auto.SPACING_RANGE[0] <= auto.spacing(families.member(n)) <= auto.SPACING_RANGE[1]


@pytest.mark.parametrize("name", ["cap70-R100@12", "saddle-c110-a90@16"])
def test_bare_mesh_deploys_within_the_bounds_on_the_defaults(name, tmp_path):
    """A steep spherical cap (70 deg, R = 100 mm: cones and tied seams decided by the defaults) and a
    strong saddle (curvature radius 110 mm over a 90 mm disk, 39 deg slopes at the rim), each read as a
    bare mesh - no scene file, no flag - deploy within the bounds: RMS <= 1 % of the diameter, height
    within 3 %, no gap unreachable. The saddle's height is held by the tuning's height row: without it
    (w = 0 on saddles) it deployed 6.6 % too high. Measured (docs/validation/deploy.md): the cap 0.523 % /
    +2.38 % (bench deploy --family), the saddle 0.647 % / -2.44 % (in-process)."""
    from simfab.deploy import pipeline

    s = _bare(tmp_path, families.member(name))
    r = pipeline.run(s, mujoco_check=False)
    b = pipeline.bounds(r)
    assert r.deployment.stable and r.tuning is not None
    assert b["rms"] <= pipeline.BOUND_RMS and abs(b["height_error"]) <= pipeline.BOUND_HEIGHT
    assert b["unreachable_gaps"] == 0
    assert pipeline.flat_area_covered(r) >= 0.99


def test_bundled_saddle_deploys_within_the_bounds_with_trials_rejected_early():
    """The bundled saddle on the defaults, its tuning rejecting trials early by their fit check: within
    the bounds. With the height row read as the bounds read it, its first step's longer trials were
    rejected early, the short step accepted gained too little and the tuning stopped as stalled at
    -3.12 % height; a stall is now confirmed on trials solved to equilibrium. Measured
    (docs/validation/deploy.md): 0.378 %, -0.76 %, bound met in 2 steps, 4 trials rejected early."""
    from simfab.deploy import pipeline
    from simfab.deploy.scene import bundled_path

    r = pipeline.run(load_deploy_scene(bundled_path("saddle")), mujoco_check=False)
    b = pipeline.bounds(r)
    assert r.tuning["rejected_early_trials"] > 0  # the check acted
    assert b["rms"] <= pipeline.BOUND_RMS and abs(b["height_error"]) <= pipeline.BOUND_HEIGHT


def test_cap_in_millimetres_deploys_within_the_bounds_on_the_defaults(tmp_path):
    """A user's 55 deg cap of a 90 mm sphere, an STL in millimetres (631 vertices in 14 rings), no scene
    file: within the bounds on the defaults (RMS <= 1 % of the diameter, height within 3 %, no gap
    unreachable). Its untuned deployment is +4.1 % high; the tuning's height row read it as +3.0 % while
    each extreme was smoothed by log-sum-exp (the rim's tied vertices shifted the target's), and the
    tuning stalled at +3.8 %. Measured (docs/validation/deploy.md): 0.435 %, +1.85 %, bound met in 1 step."""
    from simfab.deploy import pipeline

    t = surface.spherical_cap(0.09, np.radians(55), 14)
    p = tmp_path / "cap55_mm.stl"
    trimesh.Trimesh(1e3 * t.V, t.F, process=False).export(p)
    s = load_deploy_scene(p, units="mm")
    assert s.target.diameter == pytest.approx(t.diameter, rel=1e-6)  # (STL: float32)
    r = pipeline.run(s, mujoco_check=False)
    b = pipeline.bounds(r)
    assert r.deployment.stable and r.tuning is not None
    assert b["rms"] <= pipeline.BOUND_RMS and abs(b["height_error"]) <= pipeline.BOUND_HEIGHT
    assert b["unreachable_gaps"] == 0


def test_a_missed_bound_is_said_with_what_would_help(tmp_path, capsys, monkeypatch):
    """The summary's ``bounds`` and a warning state each missed bound with the key or flag that would
    help (the bounds tightened here so that a small, quick saddle misses them)."""
    from simfab.cli import main
    from simfab.deploy import pipeline

    monkeypatch.setattr(pipeline, "BOUND_RMS", 1e-6)
    monkeypatch.setattr(pipeline, "BOUND_HEIGHT", 1e-6)
    scene = tmp_path / "tiny.toml"
    scene.write_text('[target]\nkind = "saddle"\ndisk_radius = 0.06\ncurvature_radius = 0.1\nrings = 8\n'
                     '[pattern]\nspacing = 0.03\n[deploy]\nincrements = 4\nperturbation = 0.5\n')
    out = tmp_path / "o"
    assert main(["deploy", "surface", str(scene), "--out", str(out), "--json", "--quiet", "--tune", "0",
                 "--no-mujoco-check"]) == 0
    cap = capsys.readouterr()
    b = json.loads(cap.out)["bounds"]
    assert b["rms"] > b["rms_bound"] and len(b["missed"]) >= 2
    assert "--tune N" in b["missed"][0] and "point_weight" in b["missed"][1]
    assert "deployment bound missed" in cap.err and "tiny.toml" in cap.err
    assert json.loads((out / "surface.json").read_text())["bounds"]["missed"] == b["missed"]


def test_run_api_writes_only_with_out_and_keeps_the_json_keys(tmp_path):
    """``simfab.deploy.run`` (issue 40's shape): a frozen result, nothing written without ``out``; with
    it, every output file, and ``to_json()`` is the CLI's ``--json`` summary (same keys); ``import
    simfab.deploy`` loads neither Warp nor MuJoCo."""
    import dataclasses
    import subprocess
    import sys

    import simfab.deploy
    from simfab.deploy import outputs

    code = "import sys, simfab.deploy; simfab.deploy.run; print('warp' in sys.modules, 'mujoco' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.split() == ["False", "False"]
    scene = tmp_path / "tiny.toml"
    scene.write_text('[target]\nkind = "saddle"\ndisk_radius = 0.06\ncurvature_radius = 0.1\nrings = 8\n'
                     '[pattern]\nspacing = 0.03\n[deploy]\nincrements = 4\nperturbation = 0.5\n')
    r = simfab.deploy.run(str(scene), tune=0, mujoco_check=False)
    assert r.outputs == {} and not list(tmp_path.glob("*/*")) and 0 < r.rms < 0.05
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.rms = 0.0
    r2 = simfab.deploy.run(str(scene), out=str(tmp_path / "o"), tune=0, mujoco_check=False)
    assert set(r2.outputs) == set(outputs.NAMES) and all((tmp_path / "o" / n).is_file() for n in outputs.NAMES.values())
    j = r2.to_json()
    assert j["outputs"] == r2.outputs and j["deviation"]["rms"] == r2.rms == r.rms
    assert json.loads((tmp_path / "o" / "surface.json").read_text()).keys() == j.keys()


#: the bundled scenes whose pattern and tuning are left to the defaults (their files: target, sheet, material, deploy)
ON_DEFAULTS = ("dome", "saddle", "mixed", "saddle_steep", "cap80", "petal")
KNOBS = {"spacing", "insert_half_size", "insert_half_sizes", "layout", "conforming_core", "growth_fit", "spring_width"}


def test_bundled_scene_files_leave_the_pattern_to_the_defaults():
    """The bundled scene files of ``ON_DEFAULTS`` set no pattern knob, no [tune] and no [cuts]: the
    spacing, catalogue, layout and tuning are decided from the target (``defaults.decided``)."""
    import tomllib

    from simfab.deploy.scene import bundled_path

    for name in ON_DEFAULTS:
        doc = tomllib.loads(open(bundled_path(name), encoding="utf-8").read())
        assert not {"tune", "cuts"} & set(doc) and not KNOBS & set(doc.get("pattern", {})), name
        d = load_deploy_scene(bundled_path(name)).decisions.decided
        assert {"pattern.spacing", "pattern.insert_half_sizes", "pattern.layout", "tune.iterations"} <= set(d), name


@pytest.mark.parametrize("name", ["dome", "saddle_steep"])
def test_bundled_scene_meets_the_bounds_on_the_defaults(name):
    """The bundled dome and steep saddle (K = -156 1/m^2 at the centre) on the defaults deploy within the
    bounds: RMS <= 1 % of the diameter, height within 3 %, no gap unreachable; the dome's MuJoCo scene
    comes to rest. Measured (docs/validation/deploy.md): the dome 0.310 %, -1.5 % untuned (the bound met),
    the steep saddle 0.463 %, -1.94 % after 3 tuning steps (w = 0)."""
    from simfab.deploy import pipeline
    from simfab.deploy.scene import bundled_path

    r = pipeline.run(load_deploy_scene(bundled_path(name)), mujoco_check=name == "dome")
    b = pipeline.bounds(r)
    assert r.deployment.stable and b["rms"] <= pipeline.BOUND_RMS and abs(b["height_error"]) <= pipeline.BOUND_HEIGHT
    assert b["unreachable_gaps"] == 0 and pipeline.flat_area_covered(r) >= 0.99
    if name == "dome":
        assert r.sim_check["stability"]["settled"]


def test_strongly_curved_target_gets_smaller_cells_with_scaled_features(tmp_path):
    """An 85 deg cap on a 60 mm sphere: the curvature rule asks for cells below SPACING_RANGE[0] (0.25 R =
    15 mm), where the default features (3 mm beams, 4 mm beam ends, 1.5 mm gaps) leave no gap range; the
    defaults then take the smaller cell and scale those features with it, and every catalogue size is a
    plate the cell allows. Given beams (a scene's sheet) keep the cell at SPACING_RANGE[0]."""
    t = families.member("cap85-R60@12")
    s = _bare(tmp_path, t)
    h, pc = s.pattern.spacing, s.pattern
    assert auto.SPACING_RANGE[0] * auto.FEATURE_SCALE_MIN <= h < auto.SPACING_RANGE[0]
    scale = h / auto.SPACING_RANGE[0]
    base = PatternConfig()
    for k in ("beam_width", "min_beam", "min_gap"):
        assert getattr(pc, k) == pytest.approx(scale * getattr(base, k), abs=1e-6), k
        assert f"pattern.{k}" in s.decisions.decided
    assert s.cuts.max_cones > 0 and all(scale * auto.MIN_INSERT - auto.SIZE_STEP <= r < h / 2 - pc.beam_width
                                        for r in pc.sizes)
    given = tmp_path / "given.toml"
    trimesh.Trimesh(t.V, t.F, process=False).export(tmp_path / "c.obj")
    given.write_text('[target]\nmesh = "c.obj"\n[pattern]\nbeam_width = 0.003\n')
    s2 = load_deploy_scene(given)
    assert s2.pattern.spacing == auto.SPACING_RANGE[0] and s2.pattern.beam_width == 0.003
    assert s2.pattern.min_beam == base.min_beam


def test_point_weight_follows_the_saddle_shaped_area():
    """The tuning's point weight: the full AUTO_TUNE weight on a cap (K > 0 everywhere: the shape could
    turn within its sphere) and on a cylinder (K = 0 up to the triangulation's noise: it could slide
    along and around its axis), none on a saddle (K < 0 everywhere), in between on the mixed patch (a
    bump on a saddle: saddle-shaped over about four fifths of it)."""
    w = auto.AUTO_TUNE["point_weight"]
    assert auto.point_weight(surface.spherical_cap(0.15, np.radians(50), 12)) == w
    assert auto.point_weight(families.member("cylinder-R100@12")) == w
    assert auto.point_weight(surface.saddle(0.1, 0.1, 12)) == 0.0
    assert 0.0 < auto.point_weight(families.member("mixed@12")) < 0.5 * w


def test_inserts_on_short_edges_keep_beam_ends_scaled_with_them(tmp_path):
    """The 85 deg cap of a 60 mm sphere (14 mm cells, 100 inserts): valence-3 vertices of the mesh layout
    next to the seams have edges of ~0.6 h, where half an edge less the beam end (min_beam) leaves less
    than the gap the smallest insert needs; those inserts keep beam ends scaled with their edges (min_beam
    x e / h, at least pattern.SHORT_BEAM_MIN of it) and become reachable: 6 unreachable before, 2 now
    (each 0.1 mm short: no catalogue size is small enough). No other insert changes (the bundled targets'
    patterns are bit-identical)."""
    from simfab.deploy import cuts, pattern

    s = _bare(tmp_path, families.member("cap85-R60@12"))
    pc = s.pattern
    cf = cuts.flatten_with_cuts(s.target.V, s.target.F, s.cuts, pc)
    pat = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, pc,
                         seams=[p for _, p in cuts.seam_lines(cf)], cone_tips=cuts.cone_points(cf))
    assert len(pat.unreachable) <= 2
    elen = np.linalg.norm(pat.P[pat.edges[:, 0]] - pat.P[pat.edges[:, 1]], axis=1)
    val = np.bincount(pat.edges.ravel(), minlength=len(pat.P))
    hv = np.bincount(pat.edges.ravel(), weights=np.repeat(elen, 2), minlength=len(pat.P)) / np.maximum(val, 1)
    ok = pat.interior.copy()
    ok[pat.unreachable] = False
    end = 0.5 * hv - pat.gap  # the beam end each insert leaves on its mean half edge
    assert np.sum(ok & (end < pc.min_beam - 1e-9)) >= 3  # inserts that fit only with scaled beam ends
    assert np.all(end[ok] >= pattern.SHORT_BEAM_MIN * pc.min_beam - 1e-9)



def test_a_size_is_added_for_gaps_the_layout_leaves_out_of_reach(tmp_path):
    """cap85-R60@12's decided catalogue (3, 3.5, 4 mm, sized before the layout) leaves 1-2 inserts next to
    the seams with no achievable gap (required 2.67 mm where their edges hold 2.30 mm with a 3 mm insert);
    the defaults add the size that serves them (the decided smallest insert, 2 mm) and lay out again:
    none is out of reach. A catalogue the scene gives is kept as given."""
    from simfab.deploy import cuts, pattern

    s = _bare(tmp_path, families.member("cap85-R60@12"))
    cf = cuts.flatten_with_cuts(s.target.V, s.target.F, s.cuts, s.pattern)
    seams, tips = [p for _, p in cuts.seam_lines(cf)], cuts.cone_points(cf)
    pat = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, s.pattern, seams=seams, cone_tips=tips)
    assert len(pat.unreachable) >= 1 and len(s.pattern.sizes) == auto.MAX_SIZES
    r = auto.unreachable_size(pat, s.decisions)
    assert r is not None and r not in s.pattern.sizes and r >= s.decisions.min_insert - 1e-12
    more = pattern.PatternConfig(**{**s.pattern.__dict__, "insert_half_sizes": (*s.pattern.sizes, r)})
    pat2 = pattern.layout(cf.flat.uv, cf.flat.boundary, cf.F, cf.flat.u, more, seams=seams, cone_tips=tips)
    assert len(pat2.unreachable) == 0
    assert np.any(pat2.insert_size[pat.unreachable] == r)  # the inserts out of reach took the new size
    given = auto.Decisions(**{**s.decisions.__dict__, "decided": tuple(
        d for d in s.decisions.decided if d != "pattern.insert_half_sizes")})
    assert auto.unreachable_size(pat, given) is None


def test_a_conforming_layout_leaving_the_outline_uncovered_becomes_the_mesh_layout(tmp_path):
    """The curled petal's narrow outline: the decided conforming layout (no cuts: K = 0) covers 94 % of the
    flat domain, below auto.MIN_COVERED; the run lays it out again with the mesh layout (>= 99 %). A layout
    the scene gives is kept."""
    import simfab.deploy as D

    p = tmp_path / "t.obj"
    t = families.member("petal-curled@12")
    trimesh.Trimesh(t.V, t.F, process=False).export(p)
    res = D.run(str(p), mujoco_check=False, tune=0)
    assert res.summary["layout"] == "mesh" and res.covered >= auto.MIN_COVERED
    assert "pattern.layout" in res.summary["defaults"]["decided"]
    (tmp_path / "s.toml").write_text('[target]\nmesh = "t.obj"\n\n[pattern]\nlayout = "conforming"\n')
    kept = D.run(str(tmp_path / "s.toml"), mujoco_check=False, tune=0)
    assert kept.summary["layout"] == "conforming"


def test_a_mesh_with_a_spike_is_refused_before_the_deployment(tmp_path):
    """A dome whose apex vertex is pulled down to the base plane (a spike: the flattening grows its cells
    thousands of times) is refused on load naming the file and the vertex, instead of failing in the
    deployment's Newton solve; the same dome without the spike loads."""
    from simfab.errors import InputError

    t = families.member("cap50-R150@12")
    V = t.V.copy()
    top = int(np.argmax(V[:, 2]))
    trimesh.Trimesh(V, t.F, process=False).export(tmp_path / "ok.obj")
    assert load_deploy_scene(tmp_path / "ok.obj").decisions.uncut_growth_max < auto.MAX_PLAUSIBLE_GROWTH
    V[top, 2] = V[:, 2].min()
    trimesh.Trimesh(V, t.F, process=False).export(tmp_path / "spike.obj")
    with pytest.raises(InputError, match=f"spike.obj.*vertex {top} .*spike or fold"):
        load_deploy_scene(tmp_path / "spike.obj")

@pytest.mark.parametrize("name", ["bogus@12", "cap70-R100", "cap70-R100@x"])
def test_an_unknown_family_member_is_named_with_the_known_shapes(name):
    """A member name that is not shape@rings of a known shape is refused with the shapes named."""
    with pytest.raises(ValueError, match="cap70-R100, cap85-R60") as e:
        families.member(name)
    assert repr(name) in str(e.value)


def test_every_half_beam_at_an_insert_keeps_its_shortest_length(tmp_path):
    # a shallow cap (22 deg of a 240 mm sphere, 180 mm across) on the defaults: the mesh layout's cells
    # clipped by the outline leave inserts with one edge much shorter than their mean edge, and a gap
    # sized by the mean edge left a half beam of tens of micrometres there (0.45 mm here before; 64 um on a
    # similar cap, whose deployment's Newton then could not factor its Hessian); every half beam keeps
    # HALF_BEAM_FLOOR x the sheet's thickness
    import dataclasses

    from simfab.deploy import pattern

    s = trimesh.creation.icosphere(subdivisions=5, radius=240.0)
    cap = s.submesh([np.flatnonzero(s.triangles_center[:, 2] > 240.0 * np.cos(np.radians(22)))], append=True)
    cap.export(tmp_path / "cap.stl")
    sc = load_deploy_scene(tmp_path / "cap.stl", units="mm")
    flat = flatten.flatten(sc.target.V, sc.target.F)
    pc = dataclasses.replace(sc.pattern, layout="mesh")  # (the layout the pipeline falls back to here)
    pat = pattern.layout(flat.uv, flat.boundary, sc.target.F, flat.u, pc)
    halves = [np.linalg.norm(end - start) for _, v, start, end in pat.beam_halves() if pat.interior[v]]
    assert len(halves) > 100 and min(halves) >= pattern.HALF_BEAM_FLOOR * pc.beam_thickness - 1e-12
