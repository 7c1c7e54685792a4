"""One concept, one name: no two modules of simfab define a public class of the same name, and
public functions of the same name are either re-exports (a function that imports and forwards to
the same-named one, as ``simfab.grow.run`` does ``simfab.growth.run``), one of the per-module
conventions (:data:`CONVENTIONS`: every CLI module's ``run``, every area's ``run`` and writers),
or listed in :data:`KNOWN_DUPLICATES` (still to be given specific names; the list only shrinks).
Read with :mod:`ast` from the top level of every module; imports (re-exports) are not definitions,
and ``name = other`` aliases of public names count as definitions.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

SIMFAB = Path(__file__).resolve().parents[1] / "simfab"

#: Function names that many modules define by design: the CLI subcommand protocol (``add_args``,
#: ``run``, ``demo``, ``format_text``, ``output_roots``, ``api_call``: hooks :mod:`simfab.cli` and the
#: sweep runner look up on a subcommand's module), every area's ``run``, ``author.new_scene`` (``simfab
#: couple new``, ``simfab grow new``) and the writers of its files.
CONVENTIONS = frozenset({"add_args", "run", "demo", "format_text", "output_roots", "api_call", "new_scene",
                         "write_all", "write_usd", "write_mjcf"})

#: Public functions still defined under the same name in several modules ("name": modules), to be
#: renamed to what each one does; a name leaves the list when only one module defines it.
KNOWN_DUPLICATES: dict = {}


def _module(path: Path, root: Path) -> str:
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _forwards(fn: ast.FunctionDef) -> bool:
    """A re-export: the function imports the function of its own name (and calls it)."""
    return any(isinstance(n, ast.ImportFrom) and any(a.name == fn.name for a in n.names) for n in ast.walk(fn))


def definitions(root: Path = SIMFAB) -> tuple[dict, dict]:
    """(class name -> modules, function name -> modules) of the public top-level definitions."""
    classes, functions = defaultdict(set), defaultdict(set)
    for path in sorted(root.rglob("*.py")):
        mod = _module(path, root)
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                classes[node.name].add(mod)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
                if not _forwards(node):
                    functions[node.name].add(mod)
            elif isinstance(node, ast.Assign) and isinstance(node.value, ast.Name):  # ``load_scene = load_mjcf``
                for t in node.targets:
                    if isinstance(t, ast.Name) and not t.id.startswith("_") and not t.id.isupper():
                        functions[t.id].add(mod)
    return classes, functions


def test_the_scan_finds_shared_names(tmp_path):
    pkg = tmp_path / "simfab"
    (pkg / "a").mkdir(parents=True)
    (pkg / "a" / "__init__.py").write_text("from simfab.b import Thing\nclass Other: pass\n")
    (pkg / "a" / "m.py").write_text("class Thing: pass\ndef load(): pass\n"
                                    "def fwd(x):\n    from simfab.b import fwd\n    return fwd(x)\n")
    (pkg / "b.py").write_text("class Thing: pass\ndef fwd(x): pass\n_p = 1\nload = fwd\n")
    classes, functions = definitions(pkg)
    assert classes["Thing"] == {"simfab.a.m", "simfab.b"} and classes["Other"] == {"simfab.a"}
    assert functions["fwd"] == {"simfab.b"}  # the forwarder is a re-export
    assert functions["load"] == {"simfab.a.m", "simfab.b"}  # an alias is a definition


def test_no_two_modules_define_a_public_class_of_the_same_name():
    classes, _ = definitions()
    shared = {k: sorted(v) for k, v in classes.items() if len(v) > 1}
    assert not shared, "public classes of the same name in several modules (give them specific names):\n" + \
        "\n".join(f"{k}: {', '.join(v)}" for k, v in sorted(shared.items()))


def test_public_functions_of_the_same_name_are_conventions_or_known():
    _, functions = definitions()
    shared = {k: v for k, v in functions.items() if len(v) > 1 and k not in CONVENTIONS}
    new = {k: sorted(v) for k, v in shared.items() if KNOWN_DUPLICATES.get(k) != v}
    assert not new, "public functions of the same name in several modules (rename one; or, if the list " \
        "shrank, update KNOWN_DUPLICATES):\n" + "\n".join(f"{k}: {', '.join(v)}" for k, v in sorted(new.items()))
    stale = sorted(set(KNOWN_DUPLICATES) - set(shared))
    assert not stale, f"no longer shared (drop them from KNOWN_DUPLICATES): {', '.join(stale)}"
