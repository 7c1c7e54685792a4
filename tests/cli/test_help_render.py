"""--help as a newcomer reads it: descriptions render their paragraphs as written (kept verbatim on a
wide terminal; on a narrow one each paragraph or list entry is refilled whole, never broken in the
middle of a sentence), and asking for help loads no simulator (Warp, MuJoCo, OpenUSD)."""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from simfab.cli import build_parser, help_items

ROOT = Path(__file__).resolve().parents[2]


def _parsers():
    """(prog, parser) of the top level, every command and every action."""
    out = []

    def walk(p):
        out.append((p.prog, p))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sp in a.choices.values():
                    walk(sp)

    walk(build_parser())
    return out


PARSERS = _parsers()


def _words(item: list[str]) -> list[str]:
    text = ""
    for line in (x.strip() for x in item):
        text += line if not text or (text[-1] == "-" and text[-2:-1].isalpha()) else " " + line
    return text.split()


def _rendered_description(parser, columns: int, monkeypatch) -> list[str]:
    monkeypatch.setenv("COLUMNS", str(columns))
    text = parser.format_help()
    body = text.split("\n\n", 1)[1]  # past the usage
    for stop in ("\n\npositional arguments:", "\n\noptions:", "\n\ncommon options:"):
        body = body.split(stop, 1)[0]
    return body.splitlines()


@pytest.mark.parametrize("prog, parser", PARSERS, ids=[p for p, _ in PARSERS])
def test_description_paragraphs_render_as_written(prog, parser, monkeypatch):
    parser.format_help()  # (a validation's parser adds its arguments and description when first shown)
    source = [line.rstrip() for line in parser.description.splitlines()]
    src_items = [item for item in help_items(source) if item[0].strip()]
    # wide enough for every line: exactly as written
    assert _rendered_description(parser, 5000, monkeypatch) == source
    for columns in (60, 80):
        width = columns - 2  # argparse's text width
        lines = [line for line in _rendered_description(parser, columns, monkeypatch) if line.strip()]
        # the same paragraphs and list entries, word for word, in the same order: each entry's
        # rendered lines are the next ones whose words make up the entry
        for src in src_items:
            want, item = _words(src), []
            while lines and len(_words(item)) < len(want):
                item.append(lines.pop(0))
            assert _words(item) == want, (prog, columns)
            assert all(len(line) <= width or len(line.split()) == 1 for line in item), item  # (a long path alone)
            if all(len(line) <= width for line in src):
                assert item == src  # an entry that fits stays as written
            else:  # refilled: no line ends where the next word would still have fitted
                for a, b in zip(item, item[1:]):
                    assert len(a) + 1 + len(b.split()[0]) > width, (prog, columns, a, b)
        assert not lines


def test_deploy_surface_target_paragraph_reads_whole(monkeypatch):
    # issue 44's example: "... saddle.toml,\nmixed.toml,\nor a bundled name" at 80 columns
    p = dict(PARSERS)["simfab deploy"]
    text = "\n".join(_rendered_description(p, 80, monkeypatch))
    assert "saddle.toml,\nmixed.toml,\nor" not in text
    assert "surface TARGET: TARGET is a scene TOML (scenes/deploy/dome.toml, saddle.toml,\nmixed.toml, or a" in text


HEAVY = ("warp", "mujoco", "pxr")


def _help_commands():
    out = [[]]
    for prog, _ in PARSERS[1:]:
        out.append(prog.split()[1:])
    return out


@pytest.mark.parametrize("words", _help_commands(), ids=lambda w: "simfab " + " ".join(w))
def test_help_loads_no_simulator(words):
    code = ("import sys\nfrom simfab.cli import main\n"
            f"assert main({[*words, '--help']!r}) == 0\n"
            f"print('LOADED:' + ','.join(m for m in {HEAVY!r} if m in sys.modules))")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    loaded = r.stdout.strip().splitlines()[-1].removeprefix("LOADED:")
    assert loaded == "", f"simfab {' '.join(words)} --help imports {loaded}"


def test_top_level_help_costs_little_cpu():
    # the parser of every command built, no library: ~0.17 s of CPU (0.09 s of it Python's own start)
    # where it was ~2.1 s with the crowd and validate modules importing Warp
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run([sys.executable, "-m", "simfab", "--help"], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert r.returncode == 0 and "COMMAND" in r.stdout
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert cpu <= 0.3, cpu
