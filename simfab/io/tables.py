"""One loader for the tables of scene files and sweep specs: a TOML table into a keyword-only config dataclass.

:func:`load_table` merges a table read from a file with overrides (e.g. command-line flags), refuses
unknown keys naming the file, the table and the key, converts each value to its field's annotated type
(:func:`msgspec.convert`: ``int`` where ``int``, lists to tuples, ``None`` only where optional) and
builds the dataclass, whose ``__post_init__`` checks ranges and raises :class:`FieldError` naming the
key. An error is located where the value came from: ``FILE: [table]: ...`` for a value of the file,
the flag (``--friction: ...``) for an :class:`Override` carrying its source. A flag that replaces a
value of the file is reported once through ``log``.

Config types end in ``Config`` (``ContactConfig``, ``DesignConfig``, ``SweepConfig``). A new scene
table is a dataclass plus one ``load_table`` call; a config nested like its TOML (one dataclass per
table, e.g. growth's parameters) loads with :func:`load_nested`. msgspec is imported on first use only (``simfab
--help`` never loads it).
"""

from __future__ import annotations

import dataclasses
import tomllib
import typing
from collections.abc import Callable, Collection, Mapping
from pathlib import Path
from typing import Any

from simfab.errors import InputError

__all__ = ["FieldError", "Override", "check_keys", "flag_overrides", "load_nested", "load_table", "read_toml"]


@dataclasses.dataclass(frozen=True)
class Override:
    """A value given from outside the scene file, with where it came from.

    Args:
        value: the value (``None``: the key is removed, its field takes its default).
        source: where it came from as a user would name it, e.g. ``"--friction"``.
    """

    value: Any
    source: str


def flag_overrides(values: Mapping[str, Any]) -> dict[str, Override]:
    """Command-line values as overrides named after their flags (``hold_force`` -> ``--hold-force``).

    Args:
        values: {table key: value} of the flags given (``None`` values are left out: flag not given).

    Returns:
        {key: Override(value, "--key-with-dashes")}.
    """
    return {k: v if isinstance(v, Override) else Override(v, "--" + k.replace("_", "-"))
            for k, v in values.items() if v is not None}


class FieldError(InputError):
    """A value a config dataclass refuses, with the key it belongs to.

    Args:
        message: the message as it reads for a value of the scene file (e.g. ``friction=-0.3 must be ...``).
        key: the table key of the value.
        where: the table (e.g. ``"[contact]"``), prefixed with the file by :func:`load_table`.
        flag_message: the message as it reads after a flag's name (e.g. ``must be ..., got -0.3``);
            None: ``message``.
    """

    def __init__(self, message: str, *, key: str, where: str | None = None, flag_message: str | None = None):
        super().__init__(message, where=where)
        self.key = key
        self.flag_message = flag_message if flag_message is not None else message


def read_toml(path: Path, *, missing: str = "file not found") -> dict:
    """A TOML file's tables.

    Args:
        path: the file.
        missing: the message when it does not exist.

    Returns:
        The parsed document. Raises InputError naming the file when it is missing or not valid TOML.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(missing, where=str(path))
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"invalid TOML: {e}", where=str(path)) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read: {getattr(e, 'strerror', None) or e}", where=str(path)) from None


def check_keys(table: Mapping, known, *, table_name: str, file: str | None) -> None:
    """Refuse the first key of ``table`` that is not in ``known``.

    Args:
        table: the table's keys and values.
        known: the allowed keys.
        table_name: its name as written in the file, e.g. ``"contact"`` or ``"parameters.x"``.
        file: the file (None: not from a file).

    Raises:
        InputError: ``FILE: [table]: unknown key 'k' (known: a, b, ...)``.
    """
    extra = sorted(k for k in table if k not in known)
    if extra:
        raise InputError(f"[{table_name}]: unknown key {extra[0]!r} (known: {', '.join(sorted(known))})", where=file)


def load_table(cls, table: Mapping | None, *, table_name: str, file: str | None = None,
               overrides: Mapping[str, Any] | None = None, parsers: Mapping[str, Callable] | None = None,
               log: Callable[[str], None] | None = None, keys: Collection[str] | None = None):
    """Build the keyword-only config dataclass ``cls`` from a scene table and its overrides.

    Args:
        cls: a ``kw_only`` dataclass whose ``__post_init__`` checks its values (raising
            :class:`FieldError`, or InputError located at the table or at ``table.key``).
        table: the table as read from ``file`` (None: the file has none).
        table_name: the table's name in the file (``"contact"``).
        file: the file it was read from (None: none).
        overrides: {key: value or :class:`Override`} replacing the file's values; a plain value's
            error is located at ``[table] key (override)``; ``None`` removes the key.
        parsers: {key: function(value, where) -> value} run on a key's value before the type check
            (e.g. a pair [lo, hi] read into a tuple with its own messages).
        log: called once with a note for each flag that replaces a value of the file.
        keys: the keys this table may hold (None: every field of ``cls``; fewer where one config
            is read from several tables, the others' fields left at their defaults).

    Returns:
        The ``cls`` instance. Raises InputError naming the file, table and key (or the flag).
    """
    if table is not None and not isinstance(table, Mapping):
        raise InputError(f"[{table_name}] must be a table, got {table!r}", where=file)
    known = set(keys) if keys is not None else {f.name for f in dataclasses.fields(cls)}
    values = dict(table or {})
    check_keys(values, known, table_name=table_name, file=file)
    sources: dict[str, str] = {}
    for k, v in (overrides or {}).items():
        source = v.source if isinstance(v, Override) else f"[{table_name}] {k} (override)"
        value = v.value if isinstance(v, Override) else v
        if k not in known:
            raise InputError(f"unknown key of [{table_name}] (known: {', '.join(sorted(known))})", where=source)
        if value is None:
            values.pop(k, None)
            continue
        if isinstance(v, Override) and log is not None and k in values and values[k] != value:
            log(f"{source} {value!r} overrides {Path(file).name if file else ''} [{table_name}] {k} = {values[k]!r}")
        values[k] = value
        sources[k] = source

    def located(e: InputError, key: str | None) -> InputError:
        if key in sources:
            msg = e.flag_message if isinstance(e, FieldError) else e.message
            return InputError(msg, where=sources[key])
        return e.in_file(file) if file else e

    where_table = f"[{table_name}]"
    hints = typing.get_type_hints(cls)
    kw, refused = {}, {}
    for k, v in values.items():
        try:
            if parsers and k in parsers:
                v = parsers[k](v, f"{where_table} {k}")
        except InputError as e:
            raise located(e, k) from None
        kw[k], why = _typed(v, hints[k])
        if why:
            refused[k] = why
    try:
        obj = cls(**kw)
    except FieldError as e:
        raise located(e, e.key) from None
    except InputError as e:  # a plain InputError at ``table.key`` belongs to that key
        key = str(e.where or "").rpartition(".")[2]
        raise located(e, key if key in known else next(iter(refused), None) if len(refused) == 1 else None) from None
    except TypeError:  # a check that could not compare a value of the wrong type: msgspec's reason below
        if not refused:
            raise
    if refused:  # a type the dataclass's own checks let through (e.g. refine = "no"): msgspec's reason
        k, why = next(iter(refused.items()))
        raise located(FieldError(f"{k}={kw[k]!r} {why}", key=k, where=where_table,
                                 flag_message=f"{why}, got {kw[k]!r}"), k) from None
    return obj


def _typed(value, tp) -> tuple[Any, str]:
    """(``value`` converted to the annotation ``tp``, "") with msgspec; (``value`` itself, msgspec's reason)
    when it refuses it: the dataclass's own check then refuses it first, with its own message."""
    import msgspec

    try:
        return msgspec.convert(value, tp, strict=True), ""
    except msgspec.ValidationError as e:
        return value, "must be of type " + str(e).split(" - at ")[0].removeprefix("Expected ").split(", got")[0]


def load_nested(cls, doc: Mapping | None, *, file: str | None = None, overrides: Mapping | None = None,
                log: Callable[[str], None] | None = None):
    """Build a config whose fields are config dataclasses, one per TOML table (``[colonize]`` ->
    field ``colonize``), each loaded by :func:`load_table`; the remaining fields are top-level keys.

    A check across tables belongs in ``cls.__post_init__``: a :class:`FieldError` whose key is
    ``"table.key"`` is then blamed on the flag that gave that value, or on the file's table and key.

    Args:
        cls: a ``kw_only`` dataclass.
        doc: the TOML document (None: empty).
        file: the file it was read from.
        overrides: {table: {key: value or Override}} for the table fields, {key: value or Override}
            for the top-level ones.
        log: as in :func:`load_table`.

    Returns:
        The ``cls`` instance; InputError naming the file, table and key (or the flag).
    """
    doc = dict(doc or {})
    overrides = dict(overrides or {})
    hints = typing.get_type_hints(cls)
    tables = {f.name for f in dataclasses.fields(cls) if dataclasses.is_dataclass(hints[f.name])}
    top = {f.name for f in dataclasses.fields(cls)} - tables
    for k, v in doc.items():
        if k not in tables and k not in top:
            what = f"table [{k}]" if isinstance(v, Mapping) else f"key {k!r}"
            raise InputError(f"unknown {what} (known: {', '.join([f'[{t}]' for t in sorted(tables)] + sorted(top))})",
                             where=file)
    kw, sources = {}, {}
    for t in sorted(tables):
        ov = overrides.get(t) or {}
        kw[t] = load_table(hints[t], doc.get(t), table_name=t, file=file, overrides=ov, log=log)
        sources.update({f"{t}.{k}": v.source for k, v in ov.items() if isinstance(v, Override)})
    for k in top:
        v = overrides.get(k, doc.get(k))
        if isinstance(v, Override):
            sources[k] = v.source
            v = v.value
        if v is not None:
            kw[k] = v
    try:
        return cls(**kw)
    except FieldError as e:
        if e.key in sources:
            raise InputError(e.flag_message, where=sources[e.key]) from None
        raise e.in_file(file) if file else e from None
