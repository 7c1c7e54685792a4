"""Module docstrings stay short: what the module does, the method's equations and where things are,
in at most :data:`MAX_LINES` lines; long design notes and measured figures live in docs/ (methods.md,
decisions.md, validation/). Read with :mod:`ast` from every module of the package."""

from __future__ import annotations

import ast
from pathlib import Path

SIMFAB = Path(__file__).resolve().parents[1] / "simfab"
MAX_LINES = 25


def test_every_module_docstring_is_at_most_25_lines():
    long = {}
    for path in sorted(SIMFAB.rglob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")))
        if doc and len(doc.splitlines()) > MAX_LINES:
            long[str(path.relative_to(SIMFAB.parent))] = len(doc.splitlines())
    assert not long, f"module docstrings over {MAX_LINES} lines (move the notes to docs/): {long}"
