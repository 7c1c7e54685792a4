"""Sweep specs: expansion, seeded random values, run keys, errors; scene edits; summary paths."""

import json

import mujoco
import numpy as np
import pytest

from simfab.cli import main
from simfab.cli.sweep_runner import execute_run, lookup, run_task, write_scene
from simfab.cli.sweep_spec import load_spec
from simfab.errors import InputError


def _spec(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_grid_zip_range_and_random(tmp_path):
    p = _spec(tmp_path, """
[sweep]
command = ["crowd", "simulate", "--scale", "1", "10"]
seed = 7
[parameters.a]
set = "--tasks"
values = [2, 3]
[parameters.b]
set = "--public"
range = [10, 30]
num = 3
""")
    s = load_spec(p)
    pts = s.points()
    assert len(pts) == 6 and pts[0] == {"a": 2, "b": 10.0} and pts[-1] == {"a": 3, "b": 30.0}
    assert [p.name for p in s.swept] == ["a", "b"]
    r = _spec(tmp_path, """
[sweep]
command = ["crowd", "simulate", "--scale", "1", "10"]
combine = "zip"
seed = 7
[parameters.difficulty]
set = "--difficulty"
random = "loguniform"
low = 0.5
high = 2.0
samples = 5
[parameters.public]
set = "--public"
random = "integers"
low = 1
high = 20
samples = 5
""", "r.toml")
    a, b = load_spec(r), load_spec(r)
    assert len(a.points()) == 5 and a.points() == b.points()  # seeded: the same values every time
    d = np.array([p["difficulty"] for p in a.points()])
    assert np.all((d >= 0.5) & (d <= 2.0)) and len(set(d)) == 5
    other = load_spec(_spec(tmp_path, r.read_text().replace("seed = 7", "seed = 8"), "r8.toml"))
    assert [p["difficulty"] for p in other.points()] != list(d)


def test_run_keys(tiny_spec):
    s = load_spec(tiny_spec)
    pts = s.points()
    keys = [s.run_key(p, "0.1.0") for p in pts]
    assert len(set(keys)) == len(pts)
    assert keys == [s.run_key(p, "0.1.0") for p in pts]  # stable
    assert s.run_key(pts[0], "0.2.0") != keys[0]  # another simfab version is another run


@pytest.mark.parametrize("text, field", [
    ("[sweep]\ncommand = ['crowd', 'simulate']\nbogus = 1\n", "[sweep]"),
    ("[sweep]\ncommand = ['nope']\n", "[sweep] command"),
    ("[sweep]\ncommand = ['crowd', 'simulate', '--out', 'x']\n", "[sweep] command"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\n[parameters.x]\nset = '--tasks'\nrange = [1, 2]\n", "[parameters.x]"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\n[parameters.x]\nset = 'material.youngs_modulus'\nvalues = [1]\n",
     "[parameters.x]"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\n[collect]\n'bad name' = 'raters'\n", "[collect] bad name"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\n[plot]\nx = 'nothing'\n", "[plot]"),
    # typed by the loader (simfab.io.tables): a value of the wrong type names its table and key
    ("[sweep]\ncommand = ['crowd', 'simulate']\nkeep_outputs = 'yes'\n", "[sweep]: keep_outputs='yes'"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\nseed = 1.5\n", "[sweep]: seed must be an integer"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\n[parameters.x]\nvalus = [1]\n", "[parameters.x]: unknown key 'valus'"),
    ("[sweep]\ncommand = ['crowd', 'simulate']\n[plot]\nfigures = 'F_in'\n", "[plot]: figures="),
])
def test_bad_spec_names_file_and_field(tmp_path, capsys, text, field):
    p = _spec(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_spec(p)
    assert str(p) in str(e.value) and field in str(e.value)
    assert main(["sweep", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err
    assert not (tmp_path / "o").exists()  # no output folder for a spec that does not load


def test_derived_expression_checked_before_running(tmp_path, capsys):
    p = _spec(tmp_path, "[sweep]\ncommand = ['crowd', 'simulate', '--scale', '1', '10', '--tasks', '2']\n"
                        "[collect]\nraters = 'raters'\n[derived]\nz = 'raters / nonexistent'\n")
    assert main(["sweep", str(p), "--out", str(tmp_path / "o"), "--scheduler", "serial"]) == 2
    assert "[derived] z" in capsys.readouterr().err


def test_lookup_nested_paths():
    d = {"inserts": {"a": {"k": 1.5}}, "sizes": [{"bias": 0.1}, {"bias": 0.2}]}
    assert lookup(d, "inserts.a.k") == 1.5 and lookup(d, "sizes.1.bias") == 0.2 and lookup(d, "sizes.-1.bias") == 0.2
    with pytest.raises(KeyError, match="inserts.a has no 'x'.*has: k"):
        lookup(d, "inserts.a.x")


def test_scene_edits_toml_and_mjcf(tmp_path):
    """The edited copies load with the new values; relative file references stay valid."""
    from simfab.coupling.scene import read_scene_toml

    p = _spec(tmp_path, """
[sweep]
command = ["couple", "simulate", "{scene}"]
scene = "coupling/claw3d.toml"
[set]
"simulation.steps" = 3
[parameters.E]
set = "material.youngs_modulus"
values = [1.0e9]
""")
    s = load_spec(p)
    kw = run_task(s, s.points()[0], run_dir=str(tmp_path / "run"))
    main_file = write_scene(kw["scene"], tmp_path / "copy")
    cfg = read_scene_toml(main_file)
    assert cfg["material"]["youngs_modulus"] == 1.0e9 and cfg["simulation"]["steps"] == 3
    assert (main_file.parent / cfg["compliant"]["mesh_file"]).is_file()  # npz reference made absolute
    assert main_file.with_suffix(".xml").is_file()

    c = _spec(tmp_path, """
[sweep]
command = ["deploy", "--scene", "{scene}"]
scene = "deploy/unit_cell.xml"
[set]
"numeric:cell_gap" = 0.012
[parameters.r]
set = "geom:insert_large_plate.size[0,1]"
values = [0.0123]
""", "c.toml")
    s = load_spec(c)
    kw = run_task(s, s.points()[0], run_dir=str(tmp_path / "run2"))
    m = mujoco.MjModel.from_xml_path(str(write_scene(kw["scene"], tmp_path / "copy2")))
    size = m.geom(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "insert_large_plate")).size
    np.testing.assert_allclose(size, [0.0123, 0.0123, 0.0015])
    assert m.numeric("cell_gap").data[0] == 0.012


def test_couple_run_in_process_scales_with_youngs_modulus(tmp_path):
    """Two runs of the coupling scene through the sweep's worker function: Neo-Hookean with a
    fixed Poisson ratio under prescribed motion has E-independent deformed shapes, so F_in
    and E_max scale exactly with E -- the edited scene copy really sets the material. The
    tolerance is the Newton solver's relative tolerance scale (its stopping test is relative)."""
    p = _spec(tmp_path, """
[sweep]
command = ["couple", "simulate", "{scene}", "--steps", "6"]
scene = "coupling/cclamp2d.toml"
[set]
"material.poisson_ratio" = 0.36
[parameters.E]
set = "material.youngs_modulus"
values = [1.0e9, 2.0e9]
[collect]
F_in = "F_in"
E_max = "E_max"
profile = "profile_csv"
""")
    s = load_spec(p)
    runs = [execute_run(**run_task(s, pt, run_dir=str(tmp_path / f"r{i}"))) for i, pt in enumerate(s.points())]
    assert runs[0]["F_in"] > 0
    assert runs[1]["F_in"] == pytest.approx(2 * runs[0]["F_in"], rel=1e-4)
    assert runs[1]["E_max"] == pytest.approx(2 * runs[0]["E_max"], rel=1e-4)
    assert runs[0]["profile"].startswith(str(tmp_path / "r0"))  # the run wrote into its own folder


def test_bundled_specs_load(tmp_path):
    """Every bundled spec parses, names existing scenes and edits addresses they have."""
    from simfab._bundled import scenes_dir

    specs = {p.stem: load_spec(p) for p in scenes_dir("sweeps").glob("*.toml")}
    assert set(specs) == {"cclamp2d_chart", "cclamp2d_friction", "unit_cell_inserts"}
    chart = specs["cclamp2d_chart"]
    assert len(chart.points()) == 20 and [p.name for p in chart.swept] == ["youngs_modulus", "arm_width"]
    cell = specs["unit_cell_inserts"]
    sizes = [p["insert_half_size"] for p in cell.points()]
    assert min(sizes) < 0.015 < max(sizes) and 0.015 in [round(s, 12) for s in sizes]  # saddle, flat and dome
    assert [p["friction"] for p in specs["cclamp2d_friction"].points()] == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    for name, s in specs.items():  # the edited scenes are written and parse
        kw = run_task(s, s.points()[-1], run_dir=str(tmp_path / name))
        f = write_scene(kw["scene"], tmp_path / name)
        assert f.is_file() and f.name == s.scene.name


def test_serial_sweep_without_kept_outputs(tmp_path, tiny_spec):
    import pandas as pd

    from simfab.cli.sweep_study import run_sweep

    p = _spec(tmp_path, tiny_spec.read_text().replace("seed = 3", "seed = 3\nkeep_outputs = false"), "nokeep.toml")
    s = run_sweep(load_spec(p), tmp_path / "o", scheduler="serial", quiet=True)
    df = pd.read_parquet(s["outputs"]["table_parquet"])
    assert (s["runs"], s["ran"], s["ok"], s["failed"]) == (6, 6, 5, {"bad_input": 1})
    assert set(df["worker"]) == {"serial"} and (df["outputs"].fillna("") == "").all()
    assert not (tmp_path / "o" / "runs").exists()  # the runs wrote into temporary folders
    assert set(s["outputs"]["plots"]) == {"raters", "malicious", "first_task", "malicious_share"}
    assert json.loads((tmp_path / "o" / "tiny.json").read_text())["ok"] == 5
