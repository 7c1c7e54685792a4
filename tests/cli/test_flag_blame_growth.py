"""``simfab grow``: a value given by a flag is blamed on the flag, a value of the scene TOML on the
file, its table and key (issue 44, class 1); the flags reach the growth parameters as
:class:`simfab.io.tables.Override` s through the one scene-table loader, which notes once when a
flag replaces a value of the file."""

import shutil
from pathlib import Path

import pytest

from simfab.cli import main
from simfab.errors import InputError
from simfab.growth.scene import load_growth_scene
from simfab.io.tables import Override

SCENES = Path(__file__).resolve().parents[2] / "scenes" / "growth"


def _scene(tmp_path, toml: str | None = None) -> Path:
    """phone_stand.xml copied to tmp_path as p.xml, with its TOML or ``toml``."""
    shutil.copy(SCENES / "phone_stand.xml", tmp_path / "p.xml")
    (tmp_path / "p.toml").write_text(toml if toml is not None else (SCENES / "phone_stand.toml").read_text())
    return tmp_path / "p.xml"


def _fails(argv, out: Path, capsys) -> str:
    """The one stderr line of a run that must fail with exit 2 leaving ``out`` untouched."""
    code = main([*argv, "--out", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())  # nothing written
    return lines[0].removeprefix("simfab: error: ")


# (flags, the flag blamed, a word of the reason). The scene sets neither kill nor influence: the other
# one is derived from its design box, and the cross-key check influence > kill is blamed on the flag.
CASES = [
    (["--kill", "0.1"], "--kill", "must exceed kill"),  # the example
    (["--influence", "0.001"], "--influence", "must exceed kill"),  # against the derived kill
    (["--influence", "0.01", "--kill", "0.02"], "--kill", "must exceed kill"),  # two flags
    (["--attractors", "300", "--kill", "0.1"], "--kill", "must exceed kill"),  # over a file value, then a bad one
    (["--kill", "5"], "--kill", "diagonal"),  # beyond the design box
    (["--branch-length", "-1"], "--branch-length", "positive"),
    (["--smooth-iterations", "-2"], "--smooth-iterations", ">= 0"),
]


@pytest.mark.parametrize("flags, flag, reason", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_a_flag_value_is_blamed_on_the_flag(tmp_path, capsys, flags, flag, reason):
    line = _fails(["grow", str(_scene(tmp_path)), *flags], tmp_path / "out", capsys)
    assert line.startswith(flag + ":") and reason in line, line
    assert ".toml" not in line and "p.xml" not in line


def test_a_flag_is_blamed_against_a_value_of_the_file(tmp_path, capsys):
    # the file's influence is fine alone; the flag's kill is the value that breaks influence > kill
    xml = _scene(tmp_path, '[growth]\nmode = "volume"\ninfluence = 0.02\n')
    line = _fails(["grow", str(xml), "--kill", "0.03"], tmp_path / "out", capsys)
    assert line.startswith("--kill: influence distance (0.02 m) must exceed kill distance (0.03 m)"), line
    xml = _scene(tmp_path, '[growth]\nmode = "volume"\nkill = 0.01\n')
    line = _fails(["grow", str(xml), "--influence", "0.005"], tmp_path / "out", capsys)
    assert line.startswith("--influence: influence distance (0.005 m) must exceed kill"), line


@pytest.mark.parametrize("toml, where", [
    ('[growth]\ninfluence = 0.01\nkill = 0.02\n', "p.toml: growth.kill: influence distance (0.01 m) must exceed"),
    ('[growth]\nkill = 0.1\n', "p.toml: growth.kill: influence distance"),  # against the derived influence
    ('[growth]\nattractors = -5\n', "p.toml: growth.attractors: must be positive, got -5"),
    ('[growth]\nkil = 0.1\n', "p.toml: [growth]: unknown key 'kil'"),
    ('[smoothing]\niterations = 1.5\n', "p.toml: smoothing.iterations: expected an integer, got 1.5"),
    ('[colonize]\nkill = 0.1\n', "p.toml: unknown table [colonize]"),
])
def test_a_file_value_is_blamed_on_the_file_table_and_key(tmp_path, capsys, toml, where):
    line = _fails(["grow", str(_scene(tmp_path, toml))], tmp_path / "out", capsys)
    assert line.endswith(where) or where in line, line
    assert not line.startswith("--")


def test_a_flag_over_a_value_of_the_file_is_noted_once(tmp_path):
    scene = load_growth_scene(_scene(tmp_path))  # phone_stand.toml: attractors = 2000, mode = "volume"
    s = scene.with_params(attractors=Override(300, "--attractors"), mode=Override("volume", "--mode"),
                          kill=Override(0.005, "--kill"))
    assert s.params.attractors == 300 and s.params.growth.kill == 0.005
    # noted: only the flag that changes a value the file gives (the same mode and a key it lacks are not)
    assert s.notes == ("--attractors 300 overrides p.toml [growth] attractors = 2000",)
    with pytest.raises(InputError) as e:  # a bad flag value through the library: still the flag's name
        scene.with_params(attractors=Override(0, "--attractors"))
    assert str(e.value) == "--attractors: must be positive, got 0"


def test_the_note_is_logged_once_by_a_run_that_stands(tmp_path, capsys):
    # a strut from the ground to one target: a small growth that succeeds
    xml = tmp_path / "s.xml"
    xml.write_text('<mujoco><worldbody><body name="ground"><geom type="box" size="0.03 0.03 0.005" '
                   'pos="0 0 -0.005"/></body><site name="root_0" pos="0 0 0"/><site name="target_0" pos="0 0 0.04"/>'
                   '</worldbody></mujoco>')
    (tmp_path / "s.toml").write_text("[growth]\nattractors = 300\n")
    code = main(["grow", str(xml), "--attractors", "250", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert err.count("--attractors 250 overrides s.toml [growth] attractors = 300") == 1, err
