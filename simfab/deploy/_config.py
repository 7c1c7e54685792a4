"""Checks shared by the deployment area's scene-loaded configuration dataclasses."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from simfab.errors import InputError


def require_positive(cfg, prefix: str | Callable[[str], str]) -> None:
    """Refuse the first field of dataclass ``cfg`` that is not a finite positive number.

    Args:
        cfg: the configuration dataclass (string fields skipped: choices its owner checks; a list
            field: each entry).
        prefix: what the error names: ``<prefix><field>`` (``"pattern."``, or ``"cell_"`` for a
            ``<numeric>`` name), or a function field -> name.

    Raises:
        InputError: located at the field's name.
    """
    name = prefix if callable(prefix) else lambda f: f"{prefix}{f}"
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if isinstance(v, str):  # a choice: checked by its owner
            continue
        if isinstance(v, (tuple, list)):  # a list field: every entry (an empty list is checked by its owner)
            for k, x in enumerate(v):
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not (np.isfinite(x) and x > 0):
                    raise InputError(f"entry {k} must be a positive number (got {x!r})", where=name(f.name))
            continue
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"must be a positive number (got {v})", where=name(f.name))
        if f.name == "poisson" and not v < 0.5:
            raise InputError(f"Poisson ratio must be below 0.5 (got {v})", where=name(f.name))
