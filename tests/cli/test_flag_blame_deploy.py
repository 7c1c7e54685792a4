"""Issue 44 class 1 for deployment: a bad value given by a flag is blamed on the flag, never on the
scene file that does not hold it; a bad value in the file is still blamed on the file and its key."""

import pytest

from simfab.cli import main


@pytest.mark.parametrize("argv, flag", [(["--tune", "-1"], "--tune"), (["--spacing", "0"], "--spacing"),
                                        (["--spacing", "-0.01"], "--spacing")])
def test_a_flags_bad_value_names_the_flag(tmp_path, capsys, argv, flag):
    out = tmp_path / "out"
    assert main(["deploy", "surface", "dome", *argv, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"simfab: error: {flag}: "), err
    assert ".toml" not in err[0] and "Traceback" not in err[0]
    assert not out.exists()


def test_a_files_bad_value_names_the_file_and_key(tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text('[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 50\nrings = 12\n\n'
                     '[tune]\niterations = -2\n')
    assert main(["deploy", "surface", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.toml" in err[0] and "tune.iterations" in err[0], err


def test_a_flag_over_a_scene_value_is_said_once(tmp_path, capsys):
    scene = tmp_path / "cap.toml"  # a small cap whose file sets [tune] iterations, replaced by --tune 0
    scene.write_text('[target]\nkind = "spherical_cap"\nradius = 0.15\nangle_deg = 40\nrings = 8\n\n'
                     '[pattern]\nspacing = 0.04\n\n[tune]\niterations = 2\n')
    assert main(["deploy", "surface", str(scene), "--tune", "0", "--no-mujoco-check",
                 "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    notes = [ln for ln in err.splitlines() if "overrides" in ln]
    assert notes == ["--tune 0 overrides cap.toml [tune] iterations = 2"], err
