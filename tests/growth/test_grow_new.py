"""``simfab grow new``: a growth scene from a user's object mesh on a plate, which ``simfab grow`` grows."""

import json

import pytest

from simfab.cli import main


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    import trimesh

    d = tmp_path_factory.mktemp("meshes")
    b = trimesh.creation.box(extents=[40.0, 40.0, 10.0])  # mm: a 40 x 40 x 10 block held 30 mm above the plate
    b.apply_translation([0.0, 0.0, 35.0])
    b.export(d / "block.stl")
    return d / "block.stl"


TARGETS = ["--target=15,15,30", "--target=-15,15,30", "--target=15,-15,30", "--target=-15,-15,31"]


def test_new_scene_grows_and_reaches_every_target(block, tmp_path, capsys):
    out = tmp_path / "scene"
    assert main(["grow", "new", str(block), "--root", "0,0,0", *TARGETS, "--out", str(out), "--json"]) == 0
    made = json.loads(capsys.readouterr().out)
    assert made["next_commands"][0] == f"simfab grow {made['outputs']['scene_xml']}"
    # the last target was 1 mm below the block's underside: snapped onto it, and said so
    assert made["targets"][3][2] == pytest.approx(0.030, abs=1e-9)
    assert any("target_3 snapped 1 mm" in n for n in made["notes"])
    # no --mass: MuJoCo's default density 1000 kg/m^3 x 16 cm^3 = 0.016 kg, and the notes say so
    assert made["masses"]["block"] == pytest.approx(0.016, rel=1e-6)
    assert any("default density" in n for n in made["notes"])
    from simfab.growth.scene import load_growth_scene
    from simfab.growth.structure import body_masses, ground_objects

    scene = load_growth_scene(made["outputs"]["scene_xml"])
    assert body_masses(scene)["block"] == pytest.approx(0.016, rel=1e-6)  # the load the check applies
    assert ground_objects(scene) == ["plate"]  # the root stands on the plate, which is no load
    grown = tmp_path / "grown"
    assert main(["grow", made["outputs"]["scene_xml"], "--out", str(grown), "--json"]) == 0
    g = json.loads(capsys.readouterr().out)
    assert g["targets_reached"] == g["targets_total"] == 4


def test_mass_given_is_the_load(block, tmp_path, capsys):
    assert main(["grow", "new", str(block), "--root", "0,0,0", *TARGETS, "--mass", "0.25", "--out",
                 str(tmp_path / "s"), "--json"]) == 0
    made = json.loads(capsys.readouterr().out)
    from simfab.growth.scene import load_growth_scene
    from simfab.growth.structure import body_masses

    assert body_masses(load_growth_scene(made["outputs"]["scene_xml"]))["block"] == pytest.approx(0.25, rel=1e-9)
    assert not any("default density" in n for n in made["notes"])


def test_far_target_and_misplaced_flags_are_bad_input(block, tmp_path, capsys):
    out = tmp_path / "bad"
    assert main(["grow", "new", str(block), "--root", "0,0,0", "--target", "0,0,90", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--target" in err and "from the nearest object" in err
    assert not out.exists() or not any(out.iterdir())
    assert main(["grow", "scenes/growth/phone_stand.xml", "--root", "0,0,0", "--out", str(out)]) == 2
    assert "grow new" in capsys.readouterr().err
