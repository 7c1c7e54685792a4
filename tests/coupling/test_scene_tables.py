"""Coupling scenes' TOML: every table and key checked (simfab.coupling.scene.SCENE_TABLES); an
outline CSV may start with a header row."""

import shutil
from dataclasses import fields

import numpy as np
import pytest

from simfab.coupling.config import InsertionConfig, ObjectConfig
from simfab.coupling.scene import SCENE_TABLES, bundled_dir, check_tables, load_coupling_scene, read_scene_toml
from simfab.errors import InputError


@pytest.mark.parametrize("toml", sorted(bundled_dir().glob("*.toml")), ids=lambda p: p.stem)
def test_every_bundled_scene_passes_the_table_check(toml):
    check_tables(read_scene_toml(toml), str(toml))


def test_each_table_knows_its_configuration_fields():
    assert SCENE_TABLES["simulation"] == {f.name for f in fields(InsertionConfig)}
    assert SCENE_TABLES["object"] == {f.name for f in fields(ObjectConfig)}


CLAMP = dict(inner_radius=0.0095, width=0.0025, opening_deg=60.0, base_depth=0.004, base_height=0.02)


@pytest.mark.parametrize("cfg, where", [
    ({"dim": 2, "bogus": {"x": 1}}, "unknown table [bogus]"),
    ({"dim": 2, "contakt": {"friction": 0.3}}, "unknown table [contakt]"),  # a misspelt table is not ignored
    ({"dim": 2, "units": "mm"}, "unknown key 'units'"),
    ({"dim": 2, "object": {"body": "object", "sampels": 60}}, "[object]: unknown key 'sampels'"),
    ({"dim": 2, "fixed": {"site": "fixed", "size": 1}}, "[fixed]: unknown key 'size'"),
    ({"dim": 2, "material": {"name": "PLA", "colour": "red"}}, "[material]: unknown key 'colour'"),
    ({"dim": 2, "simulation": {"stepz": 3}}, "[simulation]: unknown key 'stepz'"),
    ({"dim": 2, "compliant": {"generator": "c_clamp", "widht": 0.003, **CLAMP}}, "[compliant]: unknown key 'widht'"),
    ({"dim": 2, "compliant": {"generator": "outline", "outline": "o.csv", "segments": 48}},
     "[compliant]: unknown key 'segments'"),  # an outline has no generator parameters
    ({"dim": 3, "compliant": {"generator": "extruded_clamp", "height": 0.01, "thickness": 0.005, **CLAMP}},
     "[compliant]: unknown key 'thickness'"),  # thickness is a 2D key
    ({"dim": 3, "compliant": {"generator": "mesh", "mesh": "p.stl", "layers": 2}}, "[compliant]: unknown key 'layers'"),
    ({"dim": 2, "object": 3}, "[object] must be a table"),
])
def test_unknown_tables_and_keys_name_the_file_table_and_key(cfg, where):
    with pytest.raises(InputError) as e:
        check_tables(cfg, "s.toml")
    assert str(e.value).startswith("s.toml: ") and where in str(e.value)


@pytest.mark.parametrize("table", sorted(t for t, keys in SCENE_TABLES.items() if isinstance(keys, frozenset)))
def test_every_table_rejects_an_unknown_key(table):
    with pytest.raises(InputError) as e:
        check_tables({"dim": 2, table: {"bogus_key": 1}}, "s.toml")
    assert str(e.value).startswith("s.toml: ") and f"[{table}]: unknown key 'bogus_key'" in str(e.value)


def test_generators_accept_their_own_parameters():
    check_tables({"dim": 3, "compliant": {"generator": "extruded_clamp", "layers": 2, "height": 0.01, "segments": 48,
                                          "target_elements": 100, **CLAMP}}, "s.toml")
    check_tables({"dim": 3, "compliant": {"generator": "cross_claw", "height": 0.01, "mesh_file": "p.npz", **CLAMP}},
                 "s.toml")
    check_tables({"dim": 2, "compliant": {"outline": "o.csv", "thickness": 0.005, "units": "mm"}}, "s.toml")


def test_an_outline_csv_may_start_with_a_header_row(tmp_path):
    src = bundled_dir()
    for suffix in (".xml", ".toml"):
        shutil.copy(src / f"block2d_tight{suffix}", tmp_path / f"block2d_tight{suffix}")
    csv = src / "block2d_tight_outline.csv"
    (tmp_path / csv.name).write_text("x,y\n" + csv.read_text())
    ov = {"simulation": {"steps": 2}}
    plain = load_coupling_scene(src / "block2d_tight.xml", overrides=ov)
    headed = load_coupling_scene(tmp_path / "block2d_tight.xml", overrides=ov)
    assert plain.fem.n_elements == headed.fem.n_elements
    np.testing.assert_array_equal(headed.fem.rest, plain.fem.rest)


def test_an_outline_csv_with_numbered_loops_meshes_its_holes(tmp_path):
    """loop,x,y rows (as couple optimize writes a 2D part's boundary): the largest loop is the outline,
    the others holes, in any order; a loop of two points or a fractional loop number is refused."""
    from simfab.coupling.scene import read_outline
    from simfab.fem.meshing import triangulate_polygon

    square = [(0, 0), (20, 0), (20, 10), (0, 10)]
    hole = [(5, 3), (9, 3), (9, 7), (5, 7)]
    rows = [f"1,{x},{y}" for x, y in hole] + [f"0,{x},{y}" for x, y in square]
    (tmp_path / "o.csv").write_text("loop,x_mm,y_mm\n" + "\n".join(rows) + "\n")
    outline, holes = read_outline(tmp_path / "o.csv", 1e-3)
    assert np.allclose(outline, np.array(square) * 1e-3) and len(holes) == 1
    V, F = triangulate_polygon(outline, holes=holes, max_area=2e-6)
    area = 0.5 * np.abs(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])).sum()
    assert np.isclose(area, (200 - 16) * 1e-6, rtol=1e-12)  # 20 x 10 mm less the 4 x 4 mm hole
    for text, what in (("0,0,0\n0,1,0\n1,0,1\n1,1,1\n1,1,2\n", "loop 0 has 2 point(s)"),
                       ("0.5,0,0\n0.5,1,0\n0.5,1,1\n", "integers"),
                       ("0,0,0\n0,1,0,3\n0,1,1\n", "line 2: expected 3")):
        (tmp_path / "bad.csv").write_text(text)
        with pytest.raises(InputError) as e:
            read_outline(tmp_path / "bad.csv", 1e-3)
        assert what in str(e.value) and "bad.csv" in str(e.value)


def test_object_options_are_validated_naming_the_key(tmp_path):
    src = bundled_dir()
    shutil.copy(src / "cclamp2d.xml", tmp_path / "s.xml")
    text = (src / "cclamp2d.toml").read_text()
    for old, new, key in (("samples = 50", "samples = 50.5", "samples"), ('body = "object"', "body = 3", "body"),
                          ("samples = 50", "samples = 50\nsigma = -1.0", "sigma"),
                          ("samples = 50", "samples = 50\nseed = -2", "seed")):
        (tmp_path / "s.toml").write_text(text.replace(old, new))
        with pytest.raises(InputError) as e:
            load_coupling_scene(tmp_path / "s.xml")
        assert str(tmp_path / "s.toml") in str(e.value) and "[object]" in str(e.value) and key in str(e.value)


# --- issue 44 class 1: a value given on the command line is blamed on the flag, not on the scene file
@pytest.mark.parametrize("argv, flag", [
    (["couple", "simulate", "cclamp2d", "--friction", "-0.3", "--steps", "3"], "--friction"),
    (["couple", "converge", "cclamp2d", "--friction", "2.5"], "--friction"),
    (["couple", "optimize", "block2d_tight", "--friction", "nan"], "--friction"),
    (["couple", "optimize", "cclamp2d", "--hold-force", "5", "1"], "--hold-force"),
    (["couple", "optimize", "cclamp2d", "--grip-force", "-1", "3"], "--grip-force"),
])
def test_a_flag_value_is_blamed_on_the_flag(argv, flag, tmp_path, capsys):
    from simfab.cli import main

    out = tmp_path / "o"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"simfab: error: {flag}: "), err
    assert ".toml" not in err[0] and "Traceback" not in err[0]
    assert not out.exists() or not any(out.iterdir())


def _scene_with(tmp_path, extra: str):
    src = bundled_dir()
    shutil.copy(src / "cclamp2d.xml", tmp_path / "s.xml")
    (tmp_path / "s.toml").write_text((src / "cclamp2d.toml").read_text() + extra)
    return tmp_path / "s.xml"


def test_a_file_value_is_blamed_on_the_file_table_and_key(tmp_path):
    from simfab.io.tables import Override

    xml = _scene_with(tmp_path, "\n[contact]\nfriction = -0.3\n")
    with pytest.raises(InputError) as e:
        load_coupling_scene(xml)
    assert str(e.value) == f"{tmp_path / 's.toml'}: [contact]: friction=-0.3 must be a Coulomb coefficient in [0, 2]"
    # the same value from a flag names the flag; a valid flag replaces the file's bad value
    with pytest.raises(InputError) as e:
        (tmp_path / "clean").mkdir()
        load_coupling_scene(_scene_with(tmp_path / "clean", ""),
                            overrides={"contact": {"friction": Override(-0.3, "--friction")}})
    assert str(e.value) == "--friction: must be a Coulomb coefficient in [0, 2], got -0.3"
    cm = load_coupling_scene(xml, overrides={"contact": {"friction": Override(0.2, "--friction")}})
    assert cm.contact.friction == pytest.approx(0.2)


def test_a_flag_over_a_scene_value_is_logged_once(tmp_path, capsys):
    from simfab.io.tables import Override

    xml = _scene_with(tmp_path, "\n[contact]\nfriction = 0.4\n")
    ov = {"contact": {"friction": Override(0.1, "--friction")}, "simulation": {"steps": Override(3, "--steps")},
          "object": {"seed": Override(4, "--seed")}}
    cm = load_coupling_scene(xml, overrides=ov, quiet=False)
    assert cm.contact.friction == pytest.approx(0.1) and len(cm.s_steps) == 4
    err = capsys.readouterr().err.strip().splitlines()
    # one line per flag that replaces a value of the file ([object] seed is not in it: nothing to say)
    assert err == ["--steps 3 overrides s.toml [simulation] steps = 35",
                   "--friction 0.1 overrides s.toml [contact] friction = 0.4"]
    load_coupling_scene(xml, overrides=ov)  # quiet (the default for library calls): nothing
    load_coupling_scene(xml, overrides={"contact": {"friction": Override(0.4, "--friction")}}, quiet=False)
    assert capsys.readouterr().err == ""  # the same value as the file's: nothing replaced
    # a bad value elsewhere: the error alone (no note before it: bad input is one line)
    (tmp_path / "s.toml").write_text((tmp_path / "s.toml").read_text().replace("samples = 50", "samples = 5"))
    with pytest.raises(InputError, match=r"\[object\]: samples=5"):
        load_coupling_scene(xml, overrides=ov, quiet=False)
    assert capsys.readouterr().err == ""


def test_a_mistyped_value_is_refused_naming_the_key(tmp_path):
    """Types come from the config classes' annotations (msgspec): a value their own range checks would
    let through is refused too (``refine = "no"`` is not a boolean)."""
    xml = _scene_with(tmp_path, "")
    text = (tmp_path / "s.toml").read_text()
    (tmp_path / "s.toml").write_text(text.replace("[simulation]", '[simulation]\nrefine = "no"'))
    with pytest.raises(InputError) as e:
        load_coupling_scene(xml)
    assert str(e.value).startswith(f"{tmp_path / 's.toml'}: [simulation]: refine='no' must be of type `bool`")


def test_help_does_not_load_the_table_library():
    """The scene-table loader's library (msgspec) is imported on first use only: ``--help`` of the
    commands whose scene files it reads does not load it."""
    import subprocess
    import sys

    code = ("import sys; from simfab.cli import main\n"
            "for argv in (['--help'], ['couple', 'simulate', '--help'], ['couple', 'optimize', '--help'],\n"
            "             ['sweep', '--help']):\n"
            "    try:\n"
            "        main(argv)\n"
            "    except SystemExit:\n"
            "        pass\n"
            "print('msgspec' in sys.modules, 'simfab.io.tables' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-2:] == ["False", "False"]


@pytest.mark.parametrize("edit, where", [
    (('mpos="0.0007 0 0"', 'mpos="0.0007 0 0.002"'), "keyframe 1 puts the object at z = 0.002 m"),
    (('<key name="k1" mpos="0.0007 0 0" mquat="1 0 0 0"', '<key name="k1" mpos="0.0007 0 0" mquat="0.9 0.1 0 0"'),
     "keyframe 1 turns the object about an axis other than z"),
])
def test_a_2d_scene_whose_object_leaves_the_plane_is_refused_naming_the_keyframe(tmp_path, edit, where):
    # the 2D model meets O's section with z = 0: off the plane no point of the part would ever be within O's
    # field (the barrier never acts; the first contact became an infeasible step, "not finite at the start")
    src = bundled_dir()
    shutil.copy(src / "cclamp2d.toml", tmp_path / "cclamp2d.toml")
    xml = (src / "cclamp2d.xml").read_text()
    assert edit[0] in xml
    (tmp_path / "cclamp2d.xml").write_text(xml.replace(edit[0], edit[1]))
    with pytest.raises(InputError) as e:
        load_coupling_scene(tmp_path / "cclamp2d.xml")
    assert str(e.value).startswith(f"{tmp_path / 'cclamp2d.xml'}: ") and where in str(e.value)
