"""simfab.growth.run / simfab.growth.check: frozen typed results whose to_json() is the CLI's --json object."""

import dataclasses
import json

import pytest
from test_grow_check_contact import _plate_scene
from test_growth_structure import _strut_skeleton

import simfab.growth as growth
from simfab.cli import main
from simfab.cli.grow import summary_json
from simfab.errors import InputError


def test_run_writes_nothing_without_out_and_matches_the_cli(tmp_path, capsys):
    xml = _plate_scene(tmp_path, 0.003)
    (tmp_path / "plate.toml").write_text("[growth]\nattractors = 300\n")
    res = growth.run(xml, seed=0, check=True)
    assert isinstance(res, growth.GrowthResult) and isinstance(res.check, growth.CheckResult)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.nodes = 0
    assert res.outputs == {} and res.skin_stl is None and res.check.check_usd is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plate.toml", "plate.xml"]
    assert res.check.supported_objects["plate"]["carried_by"] == ["target_0"]
    out = tmp_path / "out"
    assert main(["grow", str(xml), "--check", "--out", str(out), "--json", "--quiet"]) == 0
    cli = json.loads(capsys.readouterr().out)
    lib = summary_json(res)  # to_json() without the keys that do not apply (None)
    assert set(cli) == set(lib) and set(cli["check"]) == set(lib["check"])
    for key in ("nodes", "segments", "targets_reached", "volume"):
        assert cli[key] == lib[key], key  # same seed, same growth
    assert cli["check"]["safety_factor"] == lib["check"]["safety_factor"]  # same mesh, bit for bit


def test_check_of_a_skeleton_object_and_bad_device(tmp_path):
    from simfab.growth.scene import load_growth_scene

    scene = load_growth_scene(_plate_scene(tmp_path, 0.001))
    c = growth.check(_strut_skeleton(), scene=scene, loads={"target_0": (0.1, 0.0, 0.0)})
    assert c.targets["target_0"]["touching"] and c.outputs == {}
    assert c.target_forces_N["target_0"][0] == pytest.approx(0.1)
    with pytest.raises(InputError):
        growth.check(_strut_skeleton(), scene=scene, device="cuda")
    with pytest.raises(InputError):
        growth.check(_strut_skeleton())  # a Skeleton needs its scene
