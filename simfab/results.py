"""Typed results of the public API: one base class, one JSON form.

Every area's ``run`` returns a frozen, keyword-only dataclass derived from :class:`Result`.
Figures are plain fields whose units are stated in the field's docstring (or its
``metadata["unit"]``); arrays and profiles are attributes; the files a run wrote are in
``outputs`` (label -> path). :func:`to_json` is the one function that turns any result into
the JSON object the CLI prints with ``--json``: nested dataclasses become objects, NumPy
scalars become numbers, NaN and infinities become ``null``, paths become strings; fields
marked ``metadata={"json": False}`` (large arrays, meshes, models) are left out, and fields
marked ``optional`` only when they are None (entries a run has only in some modes).
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import numpy as np

__all__ = ["Result", "field", "to_json", "units"]


def field(*, unit: str | None = None, json: bool = True, optional: bool = False, **kw) -> Any:
    """A dataclass field with its unit and whether it belongs in the JSON summary.

    Args:
        unit: the field's unit ("m", "N", "Pa", "-" for dimensionless), shown by the CLI's tables.
        json: False for fields left out of :func:`to_json` (arrays, meshes, models).
        optional: True for a field left out of :func:`to_json` when it is None (an entry only some runs
            have); its default is None unless ``kw`` gives one.
        **kw: passed to :func:`dataclasses.field` (``default``, ``default_factory``).

    Returns:
        A :class:`dataclasses.Field`.
    """
    if optional and "default" not in kw and "default_factory" not in kw:
        kw["default"] = None
    return dataclasses.field(metadata={"unit": unit, "json": json, "optional": optional}, **kw)


def _jsonable(v: Any) -> Any:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return to_json(v)
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    return v


def to_json(result: Any) -> dict:
    """The JSON object of a result dataclass (see the module docstring for the rules).

    Args:
        result: a dataclass instance (a :class:`Result` or any nested dataclass of one).

    Returns:
        A dict of JSON-serialisable values, in field order.
    """
    out = {}
    for f in dataclasses.fields(result):
        v = getattr(result, f.name)
        if not f.metadata.get("json", True) or (v is None and f.metadata.get("optional", False)):
            continue
        out[f.name] = _jsonable(v)
    return out


def units(result: Any) -> dict[str, str]:
    """Field name -> unit of a result dataclass's fields that state one.

    Args:
        result: a result dataclass (instance or class).

    Returns:
        A dict field name -> unit string, for the fields declared with ``field(unit=...)``.
    """
    return {f.name: f.metadata["unit"] for f in dataclasses.fields(result) if f.metadata.get("unit")}


@dataclasses.dataclass(frozen=True, kw_only=True)
class Result:
    """Base of every area's result: ``to_json()`` and the files written (``outputs``)."""

    outputs: dict[str, str] = dataclasses.field(default_factory=dict)
    """Label -> path of every file the run wrote (empty when ``out`` was None)."""

    def to_json(self) -> dict:
        """This result as the JSON object ``--json`` prints (:func:`to_json`).

        Returns:
            A dict of JSON values, in field order.
        """
        return to_json(self)
