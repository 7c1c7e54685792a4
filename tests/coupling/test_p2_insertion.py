"""Insertion on quadratic (P2) elements (``[simulation] element_order = 2``): less bending locking
than linear elements on the same mesh, forces consistent with the energy profile, valid outputs;
the default (linear) path unchanged in structure.

The C-clamp's arms are 2-4 linear triangles wide at ``target_elements = 450``: linear triangles
lock there (E_max and F_in ~30% above the mesh-converged values), 6-node triangles on the same
mesh represent the arms' linear strain variation exactly. The reference is the bundled ~4,800
triangle linear mesh (itself ~3.6% stiff, scenes/coupling/README.md). 12 steps keep the runs short
(the same steps for every run, so the comparison is between meshes only)."""

import json
import shutil

import numpy as np
import pytest
from _coupling_checks import check_every_step

from simfab.coupling.config import InsertionConfig
from simfab.coupling.outputs import summarize
from simfab.coupling.scene import load_coupling_scene
from simfab.coupling.settle import work_energy_mismatch
from simfab.coupling.simulate import simulate_insertion
from simfab.errors import InputError
from simfab.fem.model import FemModel
from simfab.fem.p2 import P2Model

STEPS = 12


def _run(order: int, elements: int | None):
    ov = {"simulation": {"element_order": order, "steps": STEPS, "h_in": None}}
    if elements is not None:
        ov["compliant"] = {"target_elements": elements}
    return simulate_insertion(load_coupling_scene("cclamp2d", overrides=ov))


@pytest.fixture(scope="module")
def runs():
    return {"p1": _run(1, 450), "p2": _run(2, 450), "fine": _run(1, None)}


def test_p2_runs_on_the_lifted_mesh(runs):
    res = runs["p2"]
    cm = res.model
    assert isinstance(cm.fem, P2Model) and cm.fem.n_elements == runs["p1"].model.fem.n_elements
    check_every_step(res)  # no penetration beyond the tolerance, no inverted element, finite figures
    # contact acts at every boundary node (corners and edge midpoints) and on the sub-facets
    assert len(cm.fem.boundary_vertices) == 2 * len(runs["p1"].model.fem.boundary_vertices)
    assert cm.contact_facets.shape == (2 * len(cm.fem.boundary_facets), 2)
    # the fixed region holds the midpoints inside it as well
    assert np.any(cm.fixed_vertices >= cm.fem.n_corners)
    assert summarize(res)[0].category == "tight"


def test_p2_locks_less_than_linear_on_the_same_mesh(runs):
    # the property that matters: at the coarse mesh P2 is much closer to the fine linear mesh
    # than linear elements are (measured: E_max +31% linear vs -2.7% P2, F_in +31% vs -2.7%)
    ref, p1, p2 = (summarize(runs[k])[1] for k in ("fine", "p1", "p2"))
    for key in ("E_max", "F_in", "F_grip"):
        e1 = abs(p1[key] - ref[key]) / ref[key]
        e2 = abs(p2[key] - ref[key]) / ref[key]
        assert e1 > 0.2, (key, e1)  # linear elements lock at this mesh (the test's premise)
        assert e2 < 0.06 and e2 < 0.25 * e1, (key, e1, e2)


def test_p2_work_matches_energy(runs):
    res = runs["p2"]
    n = len(res.model.s_steps)
    F, P = res.column("force")[:n], res.column("path_force")[:n]
    # equilibrium of A: the support reactions along O's translation equal the work-conjugate force
    # from the contact forces on O (to the Newton force tolerance)
    assert np.allclose(P, F, atol=1e-3 * np.abs(F).max())
    # the work of the force over each step is the change of stored energy (trapezoidal rule over
    # 12 steps: the linear run on the same mesh misses by 1.0% of E_max, P2 by 1.1%)
    we = work_energy_mismatch(res.steps, n)
    assert we["work"] < 0.02, we
    assert we["work"] < 1.5 * work_energy_mismatch(runs["p1"].steps, n)["work"] + 1e-3


def test_default_order_is_linear_and_unchanged(runs):
    assert InsertionConfig().element_order == 1
    cm = load_coupling_scene("cclamp2d", overrides={"compliant": {"target_elements": 450}})
    assert type(cm.fem) is FemModel and cm.options.element_order == 1
    # contact and output geometry are the linear mesh's own arrays
    assert np.array_equal(cm.contact_facets, cm.fem.boundary_facets)
    assert np.array_equal(cm.display_elements, cm.fem.elements)
    assert np.array_equal(runs["p1"].model.fem.rest, cm.fem.rest)


@pytest.mark.parametrize("bad", [0, 3, 1.5, "2", True])
def test_element_order_is_validated(bad):
    with pytest.raises(InputError, match="element_order") as e:
        load_coupling_scene("cclamp2d", overrides={"simulation": {"element_order": bad}})
    # a value given as an override is blamed on the override, not on the scene file that does not hold it
    assert "[simulation] element_order (override)" in e.value.where and "cclamp2d.toml" not in str(e.value)


def test_cli_p2_writes_valid_outputs(tmp_path, capsys):
    # the bundled cclamp2d at 450 triangles (a copy of the scene), run by the CLI with --element-order 2
    import mujoco

    from simfab.cli import main
    from simfab.coupling.scene import bundled_dir
    from simfab.io.usd import check_compliance, read_mesh_at

    for ext in (".xml", ".toml"):
        shutil.copy(bundled_dir() / f"cclamp2d{ext}", tmp_path / f"cclamp2d{ext}")
    toml = tmp_path / "cclamp2d.toml"
    toml.write_text(toml.read_text().replace("target_elements = 4800", "target_elements = 450"))
    out = tmp_path / "out"
    assert main(["couple", "simulate", str(toml), "--element-order", "2", "--steps", "3", "--out", str(out),
                 "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["element_order"] == 2 and d["elements"] < 500 and d["nodes"] > 2 * d["elements"]
    assert check_compliance(d["usd"]) == []
    # A's USD mesh: the 4 sub-triangles of every element over all P2 nodes, at every step
    (V, F), = [(V, F) for name, V, F, rgb in read_mesh_at(d["usd"], 3) if "part" in name]
    assert len(V) == d["nodes"] and len(F) == 4 * d["elements"]
    assert mujoco.MjModel.from_xml_path(d["mjcf"]).nkey == len(np.genfromtxt(d["profile_csv"], delimiter=",",
                                                                            names=True))


def test_rest_shape_optimizer_takes_p2_parts_with_handles_on_the_linear_mesh():
    # the handles, E_L and the quality bound act on the P2 part's linear mesh (its vertices); candidates
    # are the P2 part with its edge nodes at the moved edges' midpoints
    from simfab.design.brief import DesignConfig
    from simfab.design.problem import make_problem

    cm = load_coupling_scene("cclamp2d", overrides={"compliant": {"target_elements": 450},
                                                     "simulation": {"element_order": 2}})
    P = make_problem(cm, DesignConfig(placement="spatial"))
    assert P.mesh.elements.shape[1] == 3 and cm.fem.elements.shape[1] == 6
    assert P.handles.apply(P.handles.identity()).shape[0] == int(P.mesh.elements.max()) + 1
