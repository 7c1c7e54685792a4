"""What a newcomer reads first (issue 44, class 5): a listing shows its whole list, every figure of
a result table carries its unit (fractions the READMEs quote in percent shown in percent), header
words are never split, every output path printed pastes, and the demo says what the yield
warnings on its own bundled scenes mean."""

from __future__ import annotations

import os
from pathlib import Path

from simfab.cli import main
from simfab.cli._summary import display_path, render_text

ROOT = Path(__file__).resolve().parents[2]


def test_couple_scenes_lists_every_name(capsys):
    assert main(["couple", "scenes"]) == 0
    out = capsys.readouterr().out
    names = sorted(p.stem for p in (ROOT / "scenes" / "coupling").glob("*.toml"))
    assert len(names) >= 15
    assert all(n in out for n in names) and "in all" not in out and "…" not in out


# the demo's couple and deploy figures as the pipelines report them (issue 44: E_max, F_in, F_rm,
# F_grip and max_von_mises had no unit)
DEMO = {"out": "simfab-out", "pipelines": {
    "couple": {"cclamp2d": {"category": "tight", "E_max": 0.0686, "E_ss": 0.0121, "coupling_ratio": 17.6,
                            "F_in": 9.1, "F_rm": 4.2, "F_grip": 3.3, "max_von_mises": 7.6e7,
                            "averaged_von_mises": 5.7e7, "yield_stress": 6e7, "seconds": 12.0},
               "clip3d": {"category": "tight", "E_max": 0.002, "E_ss": 0.001, "coupling_ratio": 50.0, "F_in": 2.0,
                          "F_rm": 1.0, "F_grip": 0.5, "max_von_mises": 9e7, "averaged_von_mises": 7e7,
                          "yield_stress": 6e7, "seconds": 30.0}},
    "deploy": {"surface_dome": {"kind": "dome", "rms": 0.00198, "hausdorff": 0.0113, "inserts": 61}}}}


def _row(text: str, quantity: str) -> list[str]:
    return next(line.split() for line in text.splitlines() if line.split()[:1] == [quantity])


def test_demo_tables_carry_units_on_every_figure():
    from simfab.cli import demo

    text = render_text(DEMO, units=demo.UNITS, title="simfab demo", width=110)
    for q, unit in (("E_max", "J"), ("E_ss", "J"), ("coupling_ratio", "%"), ("F_in", "N"), ("F_rm", "N"),
                    ("F_grip", "N"), ("max_von_mises", "Pa"), ("averaged_von_mises", "Pa"), ("yield_stress", "Pa"),
                    ("seconds", "s")):
        assert _row(text, q)[-1] == unit, (q, _row(text, q))
    # the deployed dome's deviation in percent of its diameter, as scenes/deploy/README.md quotes it
    assert _row(text, "rms")[-2:] == ["0.198", "%"] and _row(text, "hausdorff")[-2:] == ["1.13", "%"]


def test_deploy_deviation_in_percent():
    text = render_text({"deviation": {"rms": 0.00198, "hausdorff": 0.0113, "rms_mm": 0.2},
                        "tuning": {"rms_before": 0.004}}, title="simfab deploy surface")
    assert _row(text, "rms")[1:] == ["0.198", "%"] and _row(text, "rms_before")[1:] == ["0.4", "%"]
    assert _row(text, "rms_mm")[1:] == ["0.2", "mm"]


def test_row_table_headers_keep_their_words_whole():
    rows = [{"orientation": "up", "support_volume": 1e-6, "overhang_area": 2e-4, "raycast_volume": 1.1e-6,
             "raycast_rel_diff": 0.1, "support_score": 10.0, "finish_score": 1.0, "percentile_mean": 80.0,
             "bias_mean": 0.1}] * 3
    units = {"support_volume": "m³", "overhang_area": "m²", "raycast_volume": "m³"}
    for width in (60, 80, 110):
        text = render_text({"rows": rows}, units=units, title="t", width=width)
        head = text[text.index("t › rows"):text.index("──")]
        words = head.split()[3:]  # past the title
        shown = [k for k in rows[0] if k in words]
        assert shown and shown == list(rows[0])[:len(shown)], (width, words)  # whole words, in order
        assert all(w in list(rows[0]) or w.startswith("[") for w in words), (width, words)
        if len(shown) < len(rows[0]):
            assert f"{len(rows[0]) - len(shown)} more columns: all of them with --json" in text


def test_output_paths_printed_paste(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    xml = tmp_path / "s.xml"
    xml.write_text('<mujoco><worldbody><geom type="sphere" size="0.1"/></worldbody></mujoco>\n')
    # inside the working folder: relative (whether it was named relative or absolute); outside: absolute
    assert display_path(str(tmp_path / "o" / "a.png")) == os.path.join("o", "a.png")
    assert display_path("o/./b/../a.png") == os.path.join("o", "a.png")
    assert display_path("/elsewhere/a.png") == "/elsewhere/a.png"
    for target in ("sub/s.png", str(tmp_path / "sub2" / "s.png")):
        assert main(["render", "s.xml", "-o", target, "--width", "64", "--height", "48", "--quiet"]) == 0
        out = capsys.readouterr().out
        printed = next(w for line in out.splitlines() for w in line.split() if w.endswith("s.png"))
        assert Path(printed).is_file() and not Path(printed).is_absolute()


def test_demo_says_what_its_yield_warnings_mean():
    from simfab.cli.demo import yield_notes

    notes = yield_notes(DEMO["pipelines"]["couple"])
    assert len(notes) == 2
    assert notes[0].startswith("cclamp2d: the yield warning is about its largest element stress, 76 MPa > 60 MPa")
    assert "57 MPa, below yield: expected for this bundled scene, not a failure" in notes[0]
    assert "still 70 MPa: the part as bundled would yield" in notes[1]
    ok = {"s": {"max_von_mises": 5e7, "averaged_von_mises": 4e7, "yield_stress": 6e7}}
    assert yield_notes(ok) == []
    text = render_text({"notes": notes}, title="simfab demo", width=110)
    assert "expected for this bundled scene" in text
