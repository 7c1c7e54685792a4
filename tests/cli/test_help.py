"""--help reads as plain text for every subcommand and action: no reST markup, every option
explained, and the keys of the --json summary documented."""

from __future__ import annotations

import argparse
import re

import pytest

from simfab.cli import build_parser

MARKUP = re.compile(r"``|::\s*$|:(mod|func|class|meth|attr|data):`", re.MULTILINE)


def _leaf_parsers():
    """(prog, parser) of every command and action that runs something."""
    out = []

    def walk(p):
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            out.append((p.prog, p))
        for s in subs:
            for name, sp in s.choices.items():
                walk(sp)

    walk(build_parser())
    return [x for x in out if x[0] != "simfab"]


LEAVES = _leaf_parsers()


def test_every_action_is_listed():
    progs = {p for p, _ in LEAVES}
    for need in ("simfab grow", "simfab couple simulate", "simfab couple scenes", "simfab deploy",
                 "simfab validate buckling", "simfab crowd aggregate", "simfab crowd study", "simfab crowd truth",
                 "simfab crowd simulate", "simfab crowd bracket", "simfab demo", "simfab render", "simfab inspect"):
        assert need in progs


@pytest.mark.parametrize("prog, parser", LEAVES, ids=[p for p, _ in LEAVES])
def test_help_is_plain_documented_and_lists_json_keys(prog, parser):
    text = parser.format_help()
    assert not MARKUP.search(text), MARKUP.search(text).group(0)
    undocumented = [a.option_strings or [a.dest] for a in parser._actions
                    if a.help is None and not isinstance(a, argparse._HelpAction)]
    assert not undocumented, undocumented
    assert "--json keys" in text, f"{prog} --help does not document its --json keys"


@pytest.mark.parametrize("cmd", ["couple", "crowd", "validate"])
def test_actions_have_descriptions(cmd):
    p = build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[cmd]
    acts = next(a for a in sub._actions if isinstance(a, argparse._SubParsersAction))
    for name, sp in acts.choices.items():
        assert sp.description and len(sp.description) > 40, f"simfab {cmd} {name} has no description"
    helps = {c.dest: c.help for c in acts._choices_actions}
    assert all(helps.values()), helps


def test_demo_runs_every_pipeline_and_says_which():
    # the README's claim: 'simfab demo' covers every pipeline, and its --help says exactly what it runs
    from simfab.cli import SUBCOMMANDS, demo, subcommand_module

    with_demo = {n for n in SUBCOMMANDS if hasattr(subcommand_module(n), "demo")}
    assert with_demo == set(demo.PIPELINES) >= {"grow", "couple", "deploy", "crowd", "validate"}
    for name in demo.PIPELINES:
        assert f"\n  {name} " in demo.DESCRIPTION
    assert "grow edit" in demo.DESCRIPTION or "sketch edit" in demo.DESCRIPTION


def test_a_command_builds_only_its_own_subcommand():
    # the invoked subcommand is found past the common options and their values; help/version flags
    # before it (the top-level help lists every subcommand) and unknown words give None
    from simfab.cli import invoked_subcommand

    assert invoked_subcommand(["--out", "deploy", "--seed", "3", "--quiet", "deploy", "surface", "dome"]) == "deploy"
    assert invoked_subcommand(["--help", "deploy"]) is None and invoked_subcommand(["--version"]) is None
    assert invoked_subcommand(["bogus"]) is None and invoked_subcommand([]) is None
    # so a deploy command does not import the crowd CLI's FEM stack
    import subprocess
    import sys

    code = ("import sys; from simfab.cli import main; rc = main(['deploy', 'surface', '--help']); "
            "print(rc, 'simfab.crowd.outputs' in sys.modules, 'simfab.fem.neohookean' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-3:] == ["0", "False", "False"]
