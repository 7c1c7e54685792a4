"""The rest-shape optimization loop on the bundled 2D C-clamp (simfab.design.optimize)."""

import json
from pathlib import Path

import numpy as np
import pytest

from simfab.coupling.scene import load_coupling_scene
from simfab.design.brief import DesignConfig
from simfab.design.optimize import optimize_anneal
from simfab.design.problem import element_quality, evaluate, make_problem
from simfab.errors import ConvergenceError

STEPS = 12  # a coarse insertion keeps the loop fast; the physics is the bundled scene's


@pytest.fixture(scope="module")
def scene():
    from simfab.coupling.scene import load_coupling_scene

    return load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": STEPS}})


def test_element_quality():
    tri = np.array([[0, 0], [1, 0], [0.5, np.sqrt(3) / 2]])
    assert np.isclose(element_quality(tri, np.array([[0, 1, 2]]))[0], 1.0)
    assert element_quality(tri, np.array([[0, 2, 1]]))[0] < 0  # inverted
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    assert np.isclose(element_quality(tet, np.array([[0, 1, 2, 3]]))[0], 1.0) or np.isclose(
        element_quality(tet, np.array([[0, 2, 1, 3]]))[0], 1.0)


def test_invalid_and_failing_candidates_are_rejected_not_raised(scene, monkeypatch):
    P = make_problem(scene, DesignConfig(grip="tight", insertion_force=(0.0, 12.0), handles=3, placement="spatial"))
    h = P.handles.identity()
    t, s = P.handles.split(h)
    bad = h.copy().reshape(P.handles.n_active, -1)
    bad[0, :2] = [0.0, -0.03]  # drag one handle 30 mm across the part: folds elements over
    ev = evaluate(P, bad.ravel())
    assert ev.status == "rejected" and ev.reason in ("inverted element", "degenerate element")
    assert ev.objective == np.inf

    import simfab.design.problem as design_problem  # the simulator as the design problem calls it

    real = design_problem.simulate_insertion
    calls = {"n": 0}

    def flaky(cm, **kw):  # every second simulation does not converge
        calls["n"] += 1
        if calls["n"] % 2 == 0:
            raise ConvergenceError("step 7: Newton did not converge (test)")
        return real(cm, **kw)

    monkeypatch.setattr(design_problem, "simulate_insertion", flaky)
    res = optimize_anneal(P, iterations=6, seed=1)
    reasons = [r["evaluation"].reason for r in res.history]
    assert any(r.startswith("simulation did not converge") for r in reasons)
    assert res.rejected.get("simulation did not converge", 0) >= 2
    assert all(r["evaluation"].objective == np.inf for r in res.history if r["evaluation"].status == "rejected")
    assert res.best.status == "ok"


def test_small_design_problem_meets_every_constraint(scene):
    """The building block's socket exceeds PLA's 60 MPa yield stress; ask for a tight grip with
    an insertion force <= 12 N and no yielding, and check by re-simulating the optimized shape."""
    from simfab.coupling.simulate import simulate_insertion
    from simfab.design.problem import candidate_model, profile_figures

    brief = DesignConfig(grip="tight", insertion_force=(0.0, 12.0), handles=4, iterations=60, patience=15)
    P = make_problem(scene, brief)
    init = evaluate(P, P.handles.identity())
    assert not init.feasible  # the start violates the brief (yield)
    res = optimize_anneal(P, seed=0)
    assert res.iterations <= 60
    assert res.best.feasible, [c for c in res.best.constraints if not c.satisfied]
    assert res.best.E_L > 0
    cm, why = candidate_model(P, res.best.rest)
    fig = profile_figures(simulate_insertion(cm))
    assert fig["category"] == "tight"
    assert fig["von_mises"] < 60e6 and fig["insertion_force"] <= 12.0
    # reproducible: the same seed gives the same design
    res2 = optimize_anneal(P, seed=0)
    assert np.array_equal(res2.best.h, res.best.h)


def test_cli_optimize_writes_a_scene_that_simulates_to_the_same_profile(tmp_path):
    import subprocess
    import sys

    from simfab.io.usd import check_compliance

    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "simfab", "couple", "optimize", "block2d_tight", "--method", "anneal",
                        "--iterations", "4",
                        "--steps", "8", "--handles", "3", "--placement", "spatial", "--revolve-axis", "x",
                        "--workers", "1", "--correction-rounds", "1", "--check-refinements", "0", "--revolve-arms", "2",
                        "--out", str(out), "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    for k, p in s["outputs"].items():
        assert (out / p.split("/")[-1]).is_file(), k
    assert s["simulations"] >= 1
    # the (quick: --check-refinements 0) mesh check ran (linear, then P2 on the same mesh) and,
    # if the brief was missed there, one correction round optimized again (half the iterations)
    # with the check's factors
    mc = s["mesh_check"]
    n = [(lv["element_order"], lv["elements"]) for lv in mc["levels"]]
    assert n == [(1, n[0][1]), (2, n[0][1])]
    rounds = s["correction_rounds"]
    assert len(rounds) <= 1 and s["iterations_total"] == 4 + sum(r["iterations"] for r in rounds)
    if rounds and rounds[0]["kept"]:  # the round's design was better on the refined meshes
        assert s["iterations"] == 2 and s["corrections"] == rounds[0]["factors"]
        assert s["objective_fine"] == rounds[0]["objective_fine"]
    else:
        assert s["iterations"] == 4 and s["corrections"] == {}
        assert all(s["objective_fine"] <= r["objective_fine"] for r in rounds)
    assert check_compliance(s["outputs"]["usd"]) == []
    from simfab.io.usd_read import open_stage, read_scalar_at

    # the stress field carries its unit, so a rendered colour bar reads "von_mises [Pa]"
    sc = read_scalar_at(open_stage(s["outputs"]["usd"]))
    assert (sc.name, sc.units) == ("von_mises", "Pa") and 0.0 == sc.range[0] < sc.range[1]
    import trimesh

    for k in ("part_stl", "revolved_stl"):
        m = trimesh.load(s["outputs"][k])
        assert m.is_watertight and m.volume > 0, k
    # the 3D synthesis (base revolved, 2 arms) was simulated and checked against the brief, and the
    # summary file on disk has it too
    rev = s["revolved"]
    assert rev["elements"] > 100 and rev["category"] in ("tight", "loose", "ejects")
    assert {c["name"] for c in rev["constraints"]} == set(s["constraints"])
    assert json.loads(Path(s["outputs"]["summary_json"]).read_text())["revolved"]["elements"] == rev["elements"]
    assert all(Path(s["outputs"][k]).is_file() for k in ("revolved_scene_xml", "revolved_scene_toml", "revolved_mesh"))
    # the optimized scene runs unchanged and reproduces the optimizer's figures
    r2 = subprocess.run([sys.executable, "-m", "simfab", "couple", "simulate", s["outputs"]["scene_xml"], "--out",
                         str(tmp_path / "sim"), "--json"], capture_output=True, text=True)
    assert r2.returncode == 0, r2.stderr
    d = json.loads(r2.stdout)
    p = s["profile"]
    assert np.isclose(d["max_von_mises"], p["max_von_mises_Pa"], rtol=1e-9)
    assert np.isclose(d["F_in"], p["F_in_N"], rtol=1e-9)
    assert np.isclose(d["coupling_ratio"], p["coupling_ratio_pct"], rtol=1e-9)
    assert d["category"] == p["category"]
    # the optimized part is stored beside its boundary loops (the outline CSV), so a convergence study
    # meshes it again (run_levels checks the part's table before its first level: none asked here), and
    # the outline meshes to the stored part's area
    from simfab.coupling.converge import run_levels
    from simfab.coupling.scene import read_outline, read_scene_toml
    from simfab.fem.meshing import triangulate_polygon

    comp = read_scene_toml(s["outputs"]["scene_toml"])["compliant"]
    assert comp["outline"] == Path(s["outputs"]["outline_csv"]).name and comp["units"] == "mm"
    stored = np.load(s["outputs"]["scene_mesh"])
    assert comp["target_elements"] == len(stored["elements"])
    assert run_levels(s["outputs"]["scene_xml"], ()) == []
    outline, holes = read_outline(Path(s["outputs"]["outline_csv"]), 1e-3)
    V, F = triangulate_polygon(outline, holes=holes)
    P, T = stored["points"], stored["elements"]
    area = lambda P, T: 0.5 * np.abs(np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]])).sum()  # noqa: E731
    assert np.isclose(area(V, F), area(P, T), rtol=1e-9)


def test_parallel_workers_make_the_same_decisions_as_one_process():
    """Two processes evaluating speculative proposals (simfab.design.parallel): the worker rebuilds
    the problem from its scene file, and every decision - hence the design - is the serial one."""
    from simfab.design.problem import ProblemSource
    from simfab.design.scene import load_design_scene

    ds = load_design_scene("block2d_tight", design={"handles": 3, "placement": "spatial"}, simulation={"steps": 8})
    src = ProblemSource(scene=str(ds.xml), design={"handles": 3, "placement": "spatial"}, simulation={"steps": 8})
    P = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, source=src)
    assert P.source.handle_vertices == tuple(int(v) for v in P.handles.vertex[P.handles.active])
    one = optimize_anneal(P, iterations=10, seed=2)
    two = optimize_anneal(P, iterations=10, seed=2, workers=2)
    assert two.workers == 2 and one.workers == 1
    assert [r["value"] for r in two.history] == [r["value"] for r in one.history]
    assert [r["accepted"] for r in two.history] == [r["accepted"] for r in one.history]
    assert np.array_equal(two.best.h, one.best.h)
    assert two.best.result is not None  # evaluated on a worker or here, the best keeps its insertion
    assert sum(r["accepted"] for r in one.history[1:]) >= 1  # the run did move


def test_workers_started_early_serve_several_problems():
    """Worker processes started before the problem is known (simfab.design.parallel.Workers, as
    `couple optimize` starts them) build each problem on its first task and score it with the
    settings that travel with every task (a correction round's factors): every decision is still
    the serial one."""
    from simfab.design.parallel import Workers
    from simfab.design.problem import ProblemSource
    from simfab.design.scene import load_design_scene

    design, simulation = {"handles": 3, "placement": "spatial"}, {"steps": 8}
    with Workers(2) as w:
        ds = load_design_scene("block2d_tight", design=design, simulation=simulation)
        src = ProblemSource(scene=str(ds.xml), design=design, simulation=simulation)
        P = make_problem(ds.cm, ds.brief, kept_regions=ds.kept_regions, source=src)
        corr = {"von_mises": 0.5, "insertion_force": 0.5}
        Pc = P.with_settings(corrections=corr)
        runs = [optimize_anneal(p, iterations=8, seed=5, workers=w) for p in (P, Pc)]
    for p, two in zip((P, Pc), runs):
        one = optimize_anneal(p, iterations=8, seed=5)
        assert two.workers == 2
        assert [r["value"] for r in two.history] == [r["value"] for r in one.history]
        assert [r["accepted"] for r in two.history] == [r["accepted"] for r in one.history]
    # the corrections changed the figures the constraints read: the runs differ
    assert [r["value"] for r in runs[0].history] != [r["value"] for r in runs[1].history]


def test_objective_bounds_along_the_insertion_are_lower_bounds_that_bite(scene):
    """The per-step lower bounds of the objective (yield, insertion and removal force upper bounds:
    what stops a candidate's insertion early) never exceed the finished objective, and the force
    bounds (the yield bound set out of reach here) prove a large part of the penalty by the energy's
    peak (the block needs ~14 N on the way in, ~18 N at its seat: asked for <= 4 N)."""
    P = make_problem(scene, DesignConfig(grip="tight", insertion_force=(0.0, 4.0), removal_force=(0.0, 4.0),
                                        yield_stress=1e12, handles=3, placement="spatial"))  # force terms only
    h = P.handles.identity()
    rng = np.random.default_rng(3)
    for hh in (h, np.clip(h + 0.3 * P.sigma0 * rng.standard_normal(h.shape), P.lower, P.upper)):
        ev = evaluate(P, hh, threshold=1e300, keep_result=True)  # finite: the bounds are traced, nothing stops
        assert ev.status == "ok" and len(ev.bounds) == len(ev.result.steps)
        assert max(ev.bounds) <= ev.objective * (1 + 1e-12)
        assert all(b1 >= b0 for b0, b1 in zip(ev.bounds, ev.bounds[1:]))  # running maxima
        peak = int(np.argmax(ev.result.column("energy")))
        assert ev.bounds[peak] - ev.E_L > 0.25 * (ev.objective - ev.E_L) > 1e4
        # stopped by a threshold just below a step's bound: rejected there, as the full run would be
        k = peak
        stopped = evaluate(P, hh, threshold=ev.bounds[k] * (1 - 1e-9))
        assert stopped.status == "stopped" and stopped.objective == ev.bounds[k]
        assert ev.objective > ev.bounds[k] * (1 - 1e-9)


def test_initial_insertion_run_for_the_placement_is_scored_not_run_again(scene):
    """The unmodified shape's insertion, run before the optimization (displacement placement), is the
    optimizer's initial evaluation: scored as evaluate() would score that shape (identity handles
    reproduce the mesh), not simulated again; a run of another model is not taken for it."""
    from simfab.coupling.simulate import simulate_insertion
    from simfab.design.problem import initial_evaluation

    brief = DesignConfig(grip="tight", insertion_force=(0.0, 12.0), handles=3, placement="displacement")
    run = simulate_insertion(scene)
    P = make_problem(scene, brief, initial=run)
    assert P.initial is run
    ev = initial_evaluation(P)
    fresh = evaluate(P, P.handles.identity())
    assert ev.status == fresh.status == "ok" and ev.result is run
    # the rest search's secant trials follow the forces, so a re-simulation of the same shape (the
    # mesh reproduced up to round-off) stops at another point within the search's own tolerance
    # (REST_ENERGY_REL): the figures read there agree to that, the rest to round-off; the objective
    # reads the grip (this brief's tight grip), so it agrees to the search's tolerance too
    from simfab.coupling.settle import REST_ENERGY_REL

    assert ev.objective == pytest.approx(fresh.objective, rel=REST_ENERGY_REL)

    at_rest = {"E_ss", "grip_force", "coupling_ratio"}  # read at the seat
    assert all(ev.figures[k] == pytest.approx(fresh.figures[k], rel=REST_ENERGY_REL if k in at_rest else 1e-9,
                                              abs=1e-12)
               for k in fresh.figures if k not in ("category", "seat_clearance"))
    # the seat's clearance is a gap of a few um read at the rest point, which the search knows to
    # its bracket (a fraction of d_hat): compared to a tenth of d_hat, not relative to itself
    dhat = float(np.max(run.model.dhat))
    assert abs(ev.figures["seat_clearance"] - fresh.figures["seat_clearance"]) < 0.1 * dhat
    other = simulate_insertion(load_coupling_scene("block2d_tight", overrides={"simulation": {"steps": STEPS}}))
    assert make_problem(scene, brief, initial=other).initial is None  # not this problem's model


def test_target_matching_starts_from_the_initial_shapes_mesh_correction(tmp_path):
    """Matching a force profile, the coarse mesh's bias on the whole profile is measured on the
    initial shape before the first iteration and the run starts corrected by it (a coarse linear
    mesh is too stiff: factor < 1); without the mesh check nothing is corrected."""
    import subprocess
    import sys

    base = [sys.executable, "-m", "simfab", "couple", "optimize", "profile2d", "--method", "anneal",
            "--iterations", "3", "--steps", "8",
            "--handles", "2", "--placement", "spatial", "--workers", "1", "--correction-rounds", "0", "--json"]
    r = subprocess.run(base + ["--check-refinements", "0", "--out", str(tmp_path / "a")], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert 0.3 < s["corrections"]["force_profile"] < 0.95 and s["correction_rounds"] == []
    r = subprocess.run(base + ["--no-mesh-check", "--out", str(tmp_path / "b")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["corrections"] == {}
