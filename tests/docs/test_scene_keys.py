"""The docs' scene-file reference is generated from the configuration dataclasses: every field of every
scene table has a description (else the docs build fails under -W), and no hand-kept description names
a field that is gone."""

import sys
from pathlib import Path

import pytest

pytest.importorskip("sphinx")
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "docs" / "_ext"))
import scenekeys  # noqa: E402

TABLES = [
    ("simfab.coupling.config.InsertionConfig", None),
    ("simfab.coupling.config.ContactConfig", None),
    ("simfab.coupling.config.ObjectConfig", None),
    ("simfab.design.brief.DesignConfig", "simfab.design.brief"),
    ("simfab.growth.config.GrowthConfig", None),
    ("simfab.growth.config.RadiusConfig", None),
    ("simfab.growth.config.SmoothingConfig", None),
    ("simfab.growth.config.SymmetryConfig", None),
    ("simfab.growth.config.ProfileConfig", None),
    ("simfab.growth.config.StagesConfig", None),
    ("simfab.growth.config.SkinConfig", None),
    ("simfab.growth.config.MaterialConfig", None),
    ("simfab.growth.config.StructureConfig", None),
    ("simfab.deploy.pattern.PatternConfig", None),
    ("simfab.deploy.network.DeployConfig", None),
    ("simfab.deploy.mjcf_sim.SimConfig", None),
    ("simfab.deploy.tuning.TuneConfig", None),
    ("simfab.deploy.cuts.CutsConfig", None),
]


@pytest.mark.parametrize("path, toml_doc", TABLES)
def test_every_field_is_described(path, toml_doc):
    import dataclasses
    import importlib

    rows, missing, stale = scenekeys.rows_for(path, toml_doc=toml_doc)
    mod, _, name = path.rpartition(".")
    n = len(dataclasses.fields(getattr(importlib.import_module(mod), name)))
    assert len(rows) == n and not missing and not stale
    assert all(len(desc) > 8 for _, _, _, desc in rows)


def test_docstring_parsers_read_the_project_styles():
    doc = """Title.

    friction : Coulomb coefficient [-]; 0 is frictionless.
        Continued here.
    lag_tol : tolerance.
    """
    assert scenekeys.docstring_entries(doc) == {
        "friction": "Coulomb coefficient [-]; 0 is frictionless. Continued here.", "lag_tol": "tolerance."}
    prose = "Settings. timestep [s]; omega_dt [-]: target frequency x dt; body_mass, insert_mass [kg]: masses."
    got = scenekeys.prose_entries(prose, ["timestep", "omega_dt", "body_mass", "insert_mass"])
    assert got["omega_dt"] == "target frequency x dt [-]"
    assert got["body_mass"] == got["insert_mass"] == "masses. [kg]"
    assert "timestep" not in got  # a unit without a description is no description


def test_google_args_sections_are_read_entry_by_entry():
    # each entry ends where the next begins (the prose reader would run on to the next ';')
    doc = """Pattern parameters.

    Args:
        spacing: grid spacing h [m] (``layout = "mesh"``: the target edge length).
        beam_width, beam_thickness: the section [m];
            continued here.
        layout (str): "grid" or "mesh".

    A closing paragraph: not an entry.
    """
    assert scenekeys.args_entries(doc) == {
        "spacing": 'grid spacing h [m] (``layout = "mesh"``: the target edge length).',
        "beam_width": "the section [m]; continued here.", "beam_thickness": "the section [m]; continued here.",
        "layout": '"grid" or "mesh".'}
    rows, _, _ = scenekeys.rows_for("simfab.deploy.pattern.PatternConfig")
    spacing = next(desc for key, _, _, desc in rows if key == "spacing")
    assert spacing.startswith("grid spacing h [m]") and "beam_width" not in spacing
