"""The plain-text summary: compact tables with 4 significant digits, units, nested results as
sub-tables and the output files; --quiet keeps the result and the paths; --json is one object."""

from __future__ import annotations

import json

from simfab.cli import main
from simfab.cli._summary import render_text

RESULT = {
    "E_max": 0.06856697398105184, "steps": 35, "ok": True, "units": {"E_max": "J"},
    "time_split": {"assembly": 0.09952703100006488, "total": 0.6067450339999994},
    "rows": [{"size": 5, "bias_m": 0.123456789}, {"size": 6, "bias_m": 0.2}],
    "inserts": {"insert_large": {"kind": "dome", "gaussian_curvature": 12.3456, "outputs": {"png": "/o/a/large.png"}},
                "insert_small": {"kind": "saddle", "gaussian_curvature": -7.891, "outputs": {"png": "/o/a/small.png"}}},
    "plot_png": "/o/a/plot.png", "scene": "/in/scene.xml",
}


def test_tables_have_4_significant_digits_units_subtables_and_paths():
    text = render_text(RESULT, title="simfab test", units={"seconds": "s"})
    assert "0.06857" in text and "0.068566" not in text  # 4 significant digits, never 17
    assert "0.0995" in text and "0.6067" in text  # nested dict as its own table
    assert "simfab test › time_split" in text
    assert "bias_m [m]" in text and "0.1235" in text  # list of rows as a table with the unit in the header
    assert "insert_large" in text and "dome" in text and "12.35" in text  # dict of results: one row each
    for p in ("/o/a/plot.png", "/o/a/large.png", "/o/a/small.png"):
        assert p in text
    out_files = text[text.index("output files"):]
    assert "/in/scene.xml" not in out_files  # an input is not an output
    line = next(ln for ln in text.splitlines() if ln.startswith("E_max"))
    assert line.split()[-1] == "J"
    assert "{" not in text  # no JSON blobs


def test_quiet_still_prints_result_and_paths(tmp_path, capsys):
    xml = tmp_path / "s.xml"
    xml.write_text('<mujoco><worldbody><geom type="sphere" size="0.1"/></worldbody></mujoco>\n')
    png = tmp_path / "s.png"
    assert main(["render", str(xml), "-o", str(png), "--width", "64", "--height", "48", "--quiet"]) == 0
    cap = capsys.readouterr()
    assert str(png) in cap.out and cap.err == ""


def test_json_is_exactly_one_object(tmp_path, capsys):
    xml = tmp_path / "s.xml"
    xml.write_text('<mujoco><worldbody><geom type="sphere" size="0.1"/></worldbody></mujoco>\n')
    assert main(["inspect", str(xml), "--json"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1 and json.loads(out)["kind"] == "mjcf"
