"""Surface and unit-cell scenes load through the one scene-table loader (simfab.io.tables): an unknown
table or key is refused naming the file, the table and the key; a bad value names the file and
``table.key``, or the flag that gave it; a flag over a value of the file is said once."""

import re
from pathlib import Path

import pytest

from simfab.deploy import unitcell
from simfab.deploy.scene import bundled_path, load_deploy_scene
from simfab.errors import InputError
from simfab.io.tables import Override

TARGET = '[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 50\nrings = 8\n\n'


def _scene(tmp_path, text: str) -> Path:
    p = tmp_path / "s.toml"
    if text.startswith("[target]"):  # the test's own target
        p.write_text(text)
    else:  # a top-level key before the tables
        p.write_text(TARGET + text if text.startswith("[") else text + TARGET)
    return p


@pytest.mark.parametrize("text, message", [
    ("[pattern]\nspacing = 0.03\nspcing = 0.02\n", "[pattern]: unknown key 'spcing' (known: beam_thickness"),
    ("[patern]\nspacing = 0.03\n", "unknown table [patern] (known: [cuts], [deploy], [material]"),
    ("name = 'x'\n", "unknown key 'name' (known: [cuts]"),
    ("[material]\nincrements = 3\n", "[material]: unknown key 'increments' (known: density, poisson, young)"),
    ("[deploy]\nyoung = 1e9\n", "[deploy]: unknown key 'young' (known: beam_segments"),
    ("[mujoco]\ntimestep = 0.001\nsolvr = 'PGS'\n", "[mujoco]: unknown key 'solvr'"),
    ("[cuts]\nmax_cone = 2\n", "[cuts]: unknown key 'max_cone'"),
    ("[tune]\niteration = 2\n", "[tune]: unknown key 'iteration'"),
    ("[pattern]\nspacing = true\n", "[pattern]: spacing=True must be of type `float`"),
    ("pattern = 3\n", "[pattern] must be a table, got 3"),
    ("[target]\nmesh = 'x.obj'\nunit = 'mm'\n", "[target]: unknown key 'unit' (known: mesh, units)"),
])
def test_unknown_tables_and_keys_name_the_file_table_and_key(tmp_path, text, message):
    p = _scene(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_deploy_scene(p, auto=False)
    assert str(e.value).startswith(f"{p}: ") and message in str(e.value), str(e.value)


@pytest.mark.parametrize("text, where", [
    ("[material]\nyoung = -1.0\n", "material.young"), ("[material]\npoisson = 0.6\n", "material.poisson"),
    ("[deploy]\nincrements = 0\n", "deploy.increments"), ("[deploy]\nclamp_edge = 2.0\n", "deploy.clamp_edge"),
    ("[pattern]\nlayout = 'hex'\n", "pattern.layout"), ("[mujoco]\nsolver = 'X'\n", "mujoco.solver"),
    ("[cuts]\nmax_cones = -1\n", "cuts.max_cones"), ("[tune]\niterations = 2.5\n", "tune.iterations"),
])
def test_a_bad_value_of_the_file_names_the_file_and_table_key(tmp_path, text, where):
    p = _scene(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_deploy_scene(p, auto=False)
    assert str(e.value).startswith(f"{p}: {where}: "), str(e.value)


def test_a_count_written_as_a_whole_float_reads_as_the_int():
    # the scenes always accepted increments = 8.0; 8.5 is refused
    p = bundled_path("dome")
    s = load_deploy_scene(p, auto=False, overrides={"deploy": {"increments": 6.0}})
    assert s.deploy.increments == 6 and isinstance(s.deploy.increments, int)
    with pytest.raises(InputError, match=r"increments.*int"):
        load_deploy_scene(p, auto=False, overrides={"deploy": {"increments": 6.5}})


def test_material_and_deploy_tables_fill_one_config():
    s = load_deploy_scene(bundled_path("dome"), auto=False,
                          overrides={"material": {"young": 1.0e9}, "deploy": {"increments": 5}})
    assert s.deploy.young == pytest.approx(1.0e9) and s.deploy.increments == 5
    assert s.deploy.poisson == pytest.approx(0.35)  # the file's [material] value kept


@pytest.mark.parametrize("table, key, value, flag", [
    ("material", "young", -1.0, "--young"), ("pattern", "spacing", 0.0, "--spacing"),
    ("tune", "iterations", -1, "--tune"), ("pattern", "beam_width", float("nan"), "--beam-width"),
])
def test_a_flags_bad_value_is_blamed_on_the_flag(tmp_path, table, key, value, flag):
    p = _scene(tmp_path, f"[{table}]\n{key} = {0.002 if key == 'beam_width' else 1}\n")
    with pytest.raises(InputError) as e:
        load_deploy_scene(p, auto=False, overrides={table: {key: Override(value, flag)}})
    assert str(e.value).startswith(f"{flag}: ") and "s.toml" not in str(e.value), str(e.value)


def test_a_flag_replacing_a_file_value_is_noted_once(tmp_path):
    p = _scene(tmp_path, "[tune]\niterations = 2\n\n[material]\nyoung = 2e9\n")
    notes: list = []
    s = load_deploy_scene(p, auto=False, log=notes.append,
                          overrides={"tune": {"iterations": Override(0, "--tune")},
                                     "material": {"young": Override(1e9, "--young")},
                                     "pattern": {"spacing": Override(0.03, "--spacing")}})  # not in the file
    assert s.tune.iterations == 0 and s.deploy.young == pytest.approx(1e9)
    assert sorted(notes) == ["--tune 0 overrides s.toml [tune] iterations = 2",
                             "--young 1000000000.0 overrides s.toml [material] young = 2000000000.0"]


def test_an_override_of_an_unknown_table_or_key_is_refused():
    with pytest.raises(InputError, match=r"overrides: unknown table \[patern\]"):
        load_deploy_scene(bundled_path("dome"), auto=False, overrides={"patern": {"spacing": 0.02}})
    with pytest.raises(InputError, match=r"--spcing: unknown key of \[pattern\]"):
        load_deploy_scene(bundled_path("dome"), auto=False, overrides={"pattern": {"spcing": Override(1, "--spcing")}})


def test_the_keys_a_file_or_flag_sets_are_not_decided_by_auto(tmp_path):
    p = _scene(tmp_path, "[pattern]\nspacing = 0.04\n")
    assert load_deploy_scene(p).pattern.spacing == pytest.approx(0.04)
    s = load_deploy_scene(p, overrides={"pattern": {"spacing": Override(0.05, "--spacing")}})
    assert s.pattern.spacing == pytest.approx(0.05) and "pattern.spacing" not in s.decisions.decided


def test_a_bad_cell_parameter_names_the_scene_file_and_numeric(tmp_path):
    src = Path(unitcell.default_scene_path()).read_text()
    bad = tmp_path / "cell.xml"
    bad.write_text(re.sub(r'(<numeric name="cell_gap" data=")[^"]*"', r'\g<1>0.05"', src))
    with pytest.raises(InputError) as e:
        unitcell.load_cell_scene(bad)
    assert str(e.value).startswith(f"{bad}: cell_gap: ") and "no room for the spokes" in str(e.value)
    cfg, inserts = unitcell.load_cell_scene(unitcell.default_scene_path())
    assert cfg.gap == pytest.approx(0.015) and isinstance(cfg.segments, int) and inserts


def test_a_check_of_the_decided_values_at_a_flags_key_names_the_flag(tmp_path):
    # the cell-count bound is checked after the tables load (simfab.deploy.auto); a flag's spacing is blamed
    big = tmp_path / "big.toml"  # a 6 m disk: 31,000 cells of 3 cm
    big.write_text('[target]\nkind = "saddle"\ndisk_radius = 3\ncurvature_radius = 6\nrings = 8\n')
    with pytest.raises(InputError) as e:
        load_deploy_scene(big, overrides={"pattern": {"spacing": Override(0.03, "--spacing")}})
    assert str(e.value).startswith("--spacing: ") and "cells" in str(e.value)
