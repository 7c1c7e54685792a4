#!/usr/bin/env python
"""Benchmarks: ``python tools/bench.py NAME`` prints one JSON object.

NAME is a module in ``tools/benchmarks/`` (growth, insertion, rods, crowd, ...). Each
defines ``run(argv) -> dict`` and includes the published reference figure it compares
against (read from ``../shared/reference/figures.json`` when present) and the ratio.
"""

from __future__ import annotations

import importlib
import json
import pathlib
import sys

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))


def available() -> list[str]:
    return sorted(p.stem for p in (HERE / "benchmarks").glob("*.py") if not p.stem.startswith("_"))


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in available():
        print(f"usage: python tools/bench.py NAME [options]; NAME in {available()}", file=sys.stderr)
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    mod = importlib.import_module(f"benchmarks.{argv[0]}")
    from simfab.errors import InputError
    from simfab.io.atomic import to_jsonable

    try:
        out = mod.run(argv[1:])
    except InputError as e:  # bad input: one line, exit code 2, no traceback
        print(f"bench {argv[0]}: error: {e}", file=sys.stderr)
        return 2
    print(json.dumps(to_jsonable(out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
