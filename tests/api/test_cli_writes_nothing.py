"""``simfab/cli/`` only parses, calls the library and prints: no CLI module writes an output file
itself. Read with :mod:`ast` from every module of the package: no ``open`` for writing, no
``Path.write_text``/``write_bytes``/``mkdir``, no ``os.makedirs``, no call of a writer
(``write_*``, ``save_*``, ``savefig``, ``atomic_path(s)``, ``make_out_dir``, ``*_outputs``,
``np.save*``) and no import of one. The library's ``run`` functions write when given ``out``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

CLI = Path(__file__).resolve().parents[2] / "simfab" / "cli"

#: CLI modules whose orchestration has not moved into the library yet (none left).
KNOWN_EXCEPTIONS: set[str] = set()

WRITER_NAMES = {"write_csv", "write_json", "write_text", "write_all", "save_figure", "savefig", "save_mesh",
                "atomic_path", "atomic_paths", "make_out_dir", "makedirs", "mkdir", "write_bytes", "save", "savez",
                "savez_compressed", "export"}
WRITER_MODULES = {"simfab.io.atomic": {"write_csv", "write_json", "write_text", "atomic_path", "atomic_paths",
                                       "save_figure"},
                  "simfab.io.mesh": {"save_mesh"}, "simfab.io.outpaths": {"make_out_dir"}}


def _name(func) -> str:
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""


def _write_mode(call: ast.Call) -> bool:
    mode = call.args[1] if len(call.args) > 1 else next((k.value for k in call.keywords if k.arg == "mode"), None)
    return isinstance(mode, ast.Constant) and isinstance(mode.value, str) and any(c in mode.value for c in "wax+")


def offences(source: str) -> list[str]:
    """Where ``source`` writes a file itself: one "line: what" per offence."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            name = _name(node.func)
            if name == "open" and _write_mode(node):
                found.append(f"{node.lineno}: open for writing")
            elif name in WRITER_NAMES or name.endswith("_outputs"):
                found.append(f"{node.lineno}: calls {name}")
        elif isinstance(node, ast.ImportFrom) and node.module in WRITER_MODULES:
            bad = sorted(a.name for a in node.names if a.name in WRITER_MODULES[node.module])
            if bad:
                found.append(f"{node.lineno}: imports {', '.join(bad)} from {node.module}")
    return sorted(found, key=lambda s: int(s.split(":")[0]))


def test_the_check_finds_writes():
    src = ("from simfab.io.atomic import write_json\n"
           "def run(args):\n"
           "    open(args.out + '/x.txt', 'w').write('x')\n"
           "    with open(p, mode='a') as f: pass\n"
           "    open(p).read()\n"  # reading is fine
           "    Path(p).write_text('x')\n"
           "    os.makedirs(args.out)\n"
           "    truth_outputs(rows, args.out)\n")
    got = offences(src)
    assert [g.split(":")[0] for g in got] == ["1", "3", "4", "6", "7", "8"], got


@pytest.mark.parametrize("path", sorted(CLI.glob("*.py")), ids=lambda p: p.name)
def test_cli_module_writes_no_file_itself(path):
    found = offences(path.read_text(encoding="utf-8"))
    if path.name in KNOWN_EXCEPTIONS:
        pytest.xfail(f"{path.name}: orchestration not yet moved into the library ({len(found)} writes)")
    assert not found, f"simfab/cli/{path.name} writes files itself:\n" + "\n".join(found)


def test_known_exceptions_are_cli_modules():
    assert KNOWN_EXCEPTIONS <= {p.name for p in CLI.glob("*.py")}
