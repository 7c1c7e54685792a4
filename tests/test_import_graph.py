"""The package's module graph, drawn from every ``import`` statement in ``simfab/`` (top-level and
function-local alike, read with :mod:`ast`): it has no cycle, and the library never imports the
command line (``simfab.cli``).

Edges: ``import a.b.c`` -> ``a.b.c``; ``from a.b import name`` -> ``a.b.name`` when that is a
module, else ``a.b``; relative imports are resolved against the importing module's package. A
function-local import is an edge like any other: deferring it hides a cycle from the import
machinery, not from the design.
"""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

import simfab

ROOT = Path(simfab.__file__).resolve().parent
#: Modules allowed to import simfab.cli: the command line itself and ``python -m simfab``.
CLI_IMPORTERS = ("simfab.cli", "simfab.__main__")


def _modules(root: Path) -> dict[str, Path]:
    """{dotted module name: file} of every module and package in the package directory ``root``."""
    out = {}
    for f in sorted(root.rglob("*.py")):
        parts = (root.name,) + f.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def _resolve(name: str, modules) -> str | None:
    """``name`` if it is one of ``modules``, else its longest prefix that is one (None outside the package)."""
    parts = name.split(".")
    while parts:
        if ".".join(parts) in modules:
            return ".".join(parts)
        parts.pop()
    return None


def import_graph(root: Path = ROOT) -> nx.DiGraph:
    """The directed graph module -> module it imports, over the modules of the package directory
    ``root`` (edges into other packages are left out); each edge's ``line`` is where the first such
    import is."""
    modules = _modules(root)
    g = nx.DiGraph()
    g.add_nodes_from(modules)
    for mod, path in modules.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    origin = ".".join(base + ([node.module] if node.module else []))
                else:
                    origin = node.module
                targets = [f"{origin}.{a.name}" if f"{origin}.{a.name}" in modules else origin for a in node.names]
            else:
                continue
            for t in targets:
                t = _resolve(t, modules)
                if t is not None and t != mod and not g.has_edge(mod, t):
                    g.add_edge(mod, t, line=f"{path.relative_to(root.parent)}:{node.lineno}")
    return g


def import_cycles(g: nx.DiGraph) -> list[str]:
    """One named cycle (:func:`_describe`) per strongly connected component of more than one module."""
    return [_describe(g, c) for c in nx.strongly_connected_components(g) if len(c) > 1]


def _describe(g: nx.DiGraph, component) -> str:
    """One cycle through the strongly connected ``component`` (with the import lines), and its modules."""
    edges = nx.find_cycle(g.subgraph(component))
    cycle = " -> ".join(f"{a} ({g.edges[a, b]['line']})" for a, b in edges) + f" -> {edges[0][0]}"
    return cycle if len(edges) == len(component) else f"{cycle}; all of: {', '.join(sorted(component))}"


def test_graph_sees_function_local_and_relative_imports():
    """The walk reads what it must: the graph has the package's modules and, e.g., the command
    line's own (function-local) imports of the library."""
    g = import_graph()
    assert len(g) > 50
    assert any(b.startswith("simfab.design") for a, b in g.edges if a.startswith("simfab.cli"))


def test_graph_finds_a_cycle_through_function_local_and_relative_imports(tmp_path):
    """On a small package: a cycle closed by a function-local import and a relative one is found and
    named; a package whose __init__ re-exports a submodule that imports a sibling module through the
    package (``from pkg.g import tol``) is no cycle (the edge goes to ``pkg.g.tol``, not ``pkg.g``)."""
    files = {
        "__init__.py": "",
        "a.py": "def f():\n    from pkg import b\n",  # -> pkg.b (a module)
        "b.py": "from .c import name\n",  # -> pkg.c (name is not a module)
        "c.py": "import pkg.a\n",  # -> pkg.a: closes a -> b -> c -> a
        "g/__init__.py": "from pkg.g.s import x\n",  # -> pkg.g.s
        "g/s.py": "from pkg.g import tol\nx = 1\n",  # -> pkg.g.tol
        "g/tol.py": "",
    }
    root = tmp_path / "pkg"
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    g = import_graph(root)
    assert {("pkg.a", "pkg.b"), ("pkg.b", "pkg.c"), ("pkg.c", "pkg.a"), ("pkg.g", "pkg.g.s"),
            ("pkg.g.s", "pkg.g.tol")} == set(g.edges)
    (cycle,) = import_cycles(g)
    assert "pkg/a.py:2" in cycle and "pkg/c.py:1" in cycle and "pkg.g" not in cycle


def test_no_import_cycle():
    cycles = import_cycles(import_graph())
    assert not cycles, "import cycles in simfab/:\n" + "\n".join(cycles)


def test_library_never_imports_cli():
    g = import_graph()
    bad = [f"{a} -> {b} ({g.edges[a, b]['line']})" for a, b in g.edges
           if (b == "simfab.cli" or b.startswith("simfab.cli."))
           and not any(a == m or a.startswith(m + ".") for m in CLI_IMPORTERS)]
    assert not bad, "the library imports the command line:\n" + "\n".join(bad)


#: Private names still imported across modules ("module: name"): none.
PRIVATE_IMPORT_ALLOWLIST: frozenset[str] = frozenset()


def private_imports(root: Path = ROOT) -> list[str]:
    """``"importer: module.name"`` for every ``from module import _name`` (and ``module._name`` read
    through an imported module) across modules of the package at ``root``: a name with one leading
    underscore that is not itself a module of the importer's own package."""
    modules = _modules(root)
    out = []
    for mod, path in modules.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        aliases = {}
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    origin = ".".join(base + ([node.module] if node.module else []))
                else:
                    origin = node.module or ""
                for a in node.names:
                    full = f"{origin}.{a.name}"
                    if full in modules:
                        aliases[a.asname or a.name] = full
                    if origin in modules and origin != mod and _private(a.name) and not (
                            full in modules and full.rpartition(".")[0] == package):
                        out.append(f"{mod}: {full}")
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in modules and a.asname:
                        aliases[a.asname] = a.name
            elif isinstance(node, ast.Attribute) and _private(node.attr):
                chain = _dotted(node.value)
                target = aliases.get(chain, chain)
                if target in modules and target != mod and f"{target}.{node.attr}" not in modules:
                    out.append(f"{mod}: {target}.{node.attr}")
    return sorted(set(out))


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _dotted(node) -> str:
    """``a.b.c`` of a chain of attribute reads on a name, else ""."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return ".".join([node.id, *reversed(parts)]) if isinstance(node, ast.Name) else ""


def test_private_imports_are_found(tmp_path):
    """On a small package: ``from pkg.a import _x``, ``pkg.a._x`` and ``m._x`` (``import pkg.a as m``)
    are found; a private module of the importer's own package and a dunder are not."""
    files = {
        "__init__.py": "",
        "a.py": "_x = 1\n__version__ = '1'\n",
        "b.py": "from pkg.a import _x\nfrom pkg.a import __version__\nfrom pkg import _k\n",
        "c.py": "import pkg.a\nimport pkg.a as m\ny = pkg.a._x + m._x\n",
        "_k.py": "",
    }
    root = tmp_path / "pkg"
    root.mkdir()
    for name, text in files.items():
        (root / name).write_text(text)
    assert private_imports(root) == ["pkg.b: pkg.a._x", "pkg.c: pkg.a._x"]


def test_no_private_name_crosses_modules():
    found = private_imports()
    bad = [p for p in found if p not in PRIVATE_IMPORT_ALLOWLIST]
    assert not bad, "private names imported across modules (give them public names):\n" + "\n".join(bad)
    stale = sorted(PRIVATE_IMPORT_ALLOWLIST - set(found))
    assert not stale, "allowlisted private imports that are gone (drop them from the list):\n" + "\n".join(stale)
