"""Layers point one way: the command line imports the library, never the reverse."""

import re
from pathlib import Path

PKG = Path(__file__).resolve().parents[2] / "simfab"


def test_library_never_imports_the_cli():
    offenders = []
    for f in PKG.rglob("*.py"):
        if f.is_relative_to(PKG / "cli") or f.name == "__main__.py":  # python -m simfab is the CLI
            continue
        text = f.read_text(encoding="utf-8")
        if re.search(r"^\s*(from\s+simfab\.cli\b|import\s+simfab\.cli\b|from\s+simfab\s+import\s+cli\b)", text, re.M):
            offenders.append(str(f.relative_to(PKG)))
    assert not offenders, offenders
