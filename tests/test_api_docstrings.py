"""Every public function and class of the API has a Google-style ``Args:`` / ``Returns:`` docstring.

The API is collected by import, from the same lists the documentation and the packages keep (no
name is copied here by hand):

- every ``.. api-entry::`` of ``docs/api.rst`` (a module entry: its ``__all__``, else the public
  functions and classes it defines, as ``automodule :members:`` documents them);
- every name an area package exports (its ``__all__``, which its lazy ``__getattr__`` serves; a
  package without ``__all__``: the public functions and classes bound in its ``__init__``);
- the top-level command modules and ``simfab.results`` / ``simfab.errors``;
- every result dataclass of an area (a :class:`simfab.results.Result` subclass or a dataclass named
  ``*Result`` defined in one of the area packages' modules), and the simfab dataclasses their fields
  are typed with (a design's figures, an optimizer's problem and evaluations, a check's structure).

A function (or a class's constructor, or a public method of a collected class) that takes arguments
has an ``Args:`` section; one that returns a value has ``Returns:`` (``Yields:`` for a generator). A
result dataclass documents every field (its ``Args:``/``Attributes:`` section or the field's own
docstring), and every float figure states its unit (``field(unit=...)`` or ``[unit]`` in its doc).
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import pkgutil
import re
import textwrap
import typing
from pathlib import Path

import pytest

import simfab
from simfab.results import Result

ROOT = Path(simfab.__file__).resolve().parent
API_RST = ROOT.parent / "docs" / "api.rst"
#: The area packages whose exports are the API (besides docs/api.rst).
AREAS = ("coupling", "design", "growth", "crowd", "deploy", "sweep", "rods", "verification", "fem", "contact", "io")
#: The top-level modules: the commands as functions, the result base and the errors.
TOP = ("couple", "grow", "validate", "results", "errors")
#: Nothing is excluded (a prefix here would leave a package's API unchecked).
EXCLUDED_PREFIXES = ()

ARGS = re.compile(r"^\s*(Args|Arguments|Parameters|Keyword Args|Keyword Arguments|Attributes):\s*$", re.M)
RETURNS = re.compile(r"^\s*(Returns|Return):\s*$", re.M)
YIELDS = re.compile(r"^\s*(Yields|Yield):\s*$", re.M)


def _excluded(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in EXCLUDED_PREFIXES)


def _api_entries() -> list[str]:
    """The names of docs/api.rst's ``api-entry`` directives."""
    return re.findall(r"^\.\. api-entry::\s*(\S+)", API_RST.read_text(), re.M)


def _resolve(name: str):
    try:
        return importlib.import_module(name)
    except ImportError:
        mod, _, attr = name.rpartition(".")
        return getattr(importlib.import_module(mod), attr)


def _module_members(mod) -> dict[str, object]:
    """A module's public functions and classes: its ``__all__``, else those it defines."""
    names = getattr(mod, "__all__", None)
    if names is not None:
        return {f"{mod.__name__}.{n}": getattr(mod, n) for n in names}
    return {f"{mod.__name__}.{n}": v for n, v in vars(mod).items()
            if not n.startswith("_") and (inspect.isfunction(v) or inspect.isclass(v))
            and getattr(v, "__module__", None) == mod.__name__}


def _package_exports(pkg) -> dict[str, object]:
    """An area package's exports: its ``__all__`` (served by its lazy ``__getattr__``), else the public
    functions and classes its ``__init__`` binds."""
    names = getattr(pkg, "__all__", None)
    if names is not None:
        return {f"{pkg.__name__}.{n}": getattr(pkg, n) for n in names}
    return {f"{pkg.__name__}.{n}": v for n, v in vars(pkg).items()
            if not n.startswith("_") and (inspect.isfunction(v) or inspect.isclass(v))
            and getattr(v, "__module__", "").startswith("simfab")}


def _area_modules():
    """Every module of the area packages (their result dataclasses live in them)."""
    for area in AREAS:
        if _excluded(f"simfab.{area}"):
            continue
        pkg = importlib.import_module(f"simfab.{area}")
        yield pkg
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"simfab.{area}."):
            yield importlib.import_module(info.name)


def _is_result_class(obj) -> bool:
    return inspect.isclass(obj) and dataclasses.is_dataclass(obj) and (
        issubclass(obj, Result) or obj.__name__.endswith("Result"))


def _result_classes() -> dict[str, type]:
    out = {}
    for mod in _area_modules():
        for n, v in vars(mod).items():
            if _is_result_class(v) and v.__module__ == mod.__name__ and not n.startswith("_"):
                out[f"{mod.__name__}.{n}"] = v
    return out


def _field_types(classes) -> dict[str, type]:
    """The simfab dataclasses the fields of ``classes`` are typed with (one level: ``X``, ``X | None``,
    ``tuple[X, ...]``), e.g. a design result's figures or an optimizer result's problem."""
    out = {}

    def walk(t):
        if inspect.isclass(t) and dataclasses.is_dataclass(t) and t.__module__.startswith("simfab"):
            out[f"{t.__module__}.{t.__qualname__}"] = t
        for arg in typing.get_args(t):
            walk(arg)

    for cls in classes:
        for hint in typing.get_type_hints(cls).values():
            walk(hint)
    return out


def collect_api() -> dict[str, object]:
    """Qualified name -> object of every public function and class of the API (simfab.deploy excluded)."""
    api: dict[str, object] = {}
    for name in _api_entries():
        obj = _resolve(name)
        api.update(_module_members(obj) if inspect.ismodule(obj) else {name: obj})
    for area in AREAS:
        if not _excluded(f"simfab.{area}"):
            api.update(_package_exports(importlib.import_module(f"simfab.{area}")))
    for top in TOP:
        api.update(_module_members(importlib.import_module(f"simfab.{top}")))
    results = _result_classes()
    api.update(results)
    api.update(_field_types([*results.values(), *(v for v in api.values() if _is_result_class(v))]))
    out, seen = {}, set()
    for name, obj in api.items():  # one entry per object (a package re-exports its modules' names)
        home = f"{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', '')}"
        if _excluded(name) or _excluded(home) or not (inspect.isfunction(obj) or inspect.isclass(obj)) \
                or id(obj) in seen:
            continue
        seen.add(id(obj))
        out[name] = obj
    return out


def _methods(cls) -> dict[str, object]:
    """A class's own public methods (properties and dunders left out)."""
    out = {}
    for n, v in vars(cls).items():
        if n.startswith("_"):
            continue
        if isinstance(v, (staticmethod, classmethod)):
            v = v.__func__
        if inspect.isfunction(v):
            out[n] = v
    return out


def _function_body(fn) -> ast.AST | None:
    try:
        src = textwrap.dedent(inspect.getsource(fn))
    except (OSError, TypeError):
        return None
    tree = ast.parse(src)
    return next((n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))), None)


def _own_nodes(fn_node):
    """The nodes of a function's body, nested functions, lambdas and classes left out."""
    stack = list(fn_node.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        yield node
        stack.extend(ast.iter_child_nodes(node))


def _returns(fn) -> str | None:
    """"yields" for a generator, "returns" when the function returns a value, else None."""
    if inspect.isgeneratorfunction(fn):
        return "yields"
    ann = inspect.signature(fn).return_annotation
    if ann is not inspect.Signature.empty:
        return None if ann in (None, "None") else "returns"
    node = _function_body(fn)
    if node is None:
        return None
    for n in _own_nodes(node):
        if isinstance(n, ast.Return) and n.value is not None and not (
                isinstance(n.value, ast.Constant) and n.value.value is None):
            return "returns"
    return None


def _takes_args(fn, *, bound: bool) -> bool:
    params = list(inspect.signature(fn).parameters.values())
    if bound and params and params[0].name in ("self", "cls"):
        params = params[1:]
    return bool(params)


def _function_problems(fn, *, bound: bool = False) -> list[str]:
    doc = inspect.getdoc(fn) or ""
    problems = []
    if not doc:
        return ["no docstring"]
    if _takes_args(fn, bound=bound) and not ARGS.search(doc):
        problems.append("no Args: section")
    kind = _returns(fn)
    if kind == "returns" and not (RETURNS.search(doc) or YIELDS.search(doc)):  # a context manager yields
        problems.append("no Returns: section")
    if kind == "yields" and not (YIELDS.search(doc) or RETURNS.search(doc)):
        problems.append("no Yields: section")
    return problems


def _constructor_args(cls) -> list[str]:
    """The names a class's constructor takes (a dataclass's init fields; a simfab ``__init__``'s params)."""
    if dataclasses.is_dataclass(cls):
        return [f.name for f in dataclasses.fields(cls) if f.init]
    for klass in cls.__mro__:
        init = vars(klass).get("__init__")
        if init is not None:
            if not klass.__module__.startswith("simfab"):
                return []
            return [p for p in inspect.signature(init).parameters if p != "self"]
    return []


def _field_docs(cls) -> dict[str, str]:
    """Fields of a dataclass documented by a string right after their declaration (in any simfab
    base, the nearest first): name -> that string."""
    out: dict[str, str] = {}
    for klass in cls.__mro__:
        if not klass.__module__.startswith("simfab"):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body
        for a, b in zip(body, body[1:]):
            if isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name) and isinstance(b, ast.Expr) \
                    and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str):
                out.setdefault(a.target.id, b.value.value)
    return out


def _section_text(doc: str) -> str:
    """The text of a docstring's Args:/Attributes: sections."""
    m = ARGS.search(doc)
    return doc[m.start():] if m else ""


def _class_problems(cls, name: str) -> list[str]:
    doc = inspect.getdoc(cls) if cls.__doc__ else ""
    if not doc or (dataclasses.is_dataclass(cls) and doc.startswith(f"{cls.__name__}(")):
        return ["no docstring"]
    problems = []
    args = _constructor_args(cls)
    if dataclasses.is_dataclass(cls):
        # a field inherited from a simfab base may be documented in that base's docstring
        section = "\n".join(_section_text(inspect.getdoc(k) or "") for k in cls.__mro__
                             if k.__module__.startswith("simfab") and dataclasses.is_dataclass(k))
        own = _field_docs(cls)
        for f in args:
            if f not in own and not re.search(rf"(^|[\s,(`]){re.escape(f)}\b", section):
                problems.append(f"field {f} undocumented")
        if _is_result_class(cls):
            problems += _unit_problems(cls, section)
    elif args and not ARGS.search(doc):
        problems.append("no Args: section")
    for mname, meth in _methods(cls).items():
        bound = not isinstance(vars(cls)[mname], staticmethod)
        problems += [f"{mname}: {p}" for p in _function_problems(meth, bound=bound)]
    return problems


def _unit_problems(cls, section: str) -> list[str]:
    """Float figures of a result dataclass without a stated unit."""
    problems = []
    lines = section.splitlines()
    for f in dataclasses.fields(cls):
        ftype = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        if not re.fullmatch(r"float( \| None)?", ftype) or f.metadata.get("unit"):
            continue
        doc = next((ln for i, ln in enumerate(lines) if re.search(rf"(^|[\s,(`]){re.escape(f.name)}\b", ln)), "")
        idx = lines.index(doc) if doc else -1
        text = " ".join(lines[idx:idx + 3]) if doc else _field_docs(cls).get(f.name, "")
        if "[" not in text:
            problems.append(f"field {f.name}: no unit")
    return problems


API = collect_api()


def test_api_is_collected():
    """The collection finds the API the docs list (a broken list would make every check vacuous)."""
    from simfab.coupling.insertion import CouplingResult
    from simfab.design.pipeline import DesignResult

    assert "simfab.couple.simulate" in API and "simfab.coupling.run" in API and "simfab.crowd.aggregate" in API
    objects = {id(obj) for obj in API.values()}
    assert id(CouplingResult) in objects and id(DesignResult) in objects and id(Result) in objects
    assert len(API) > 50


@pytest.mark.parametrize("name", sorted(API))
def test_docstring(name):
    obj = API[name]
    problems = _class_problems(obj, name) if inspect.isclass(obj) else _function_problems(obj)
    assert not problems, f"{name}: " + "; ".join(problems)
