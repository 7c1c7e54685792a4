"""Progress bars that vanish with ``--quiet`` and when stderr is not a terminal."""

from __future__ import annotations

import sys
from typing import Iterable, Iterator, TypeVar

T = TypeVar("T")


def progress(iterable: Iterable[T], *, total: int | None = None, desc: str = "", quiet: bool = False) -> Iterator[T]:
    """Iterate ``iterable`` with a rich progress bar on stderr when appropriate."""
    if quiet or not sys.stderr.isatty():
        yield from iterable
        return
    from rich.console import Console
    from rich.progress import Progress

    with Progress(console=Console(stderr=True), transient=True) as bar:
        if total is None and hasattr(iterable, "__len__"):
            total = len(iterable)
        task = bar.add_task(desc, total=total)
        for item in iterable:
            yield item
            bar.advance(task)


def log(msg: str, *, quiet: bool = False) -> None:
    """Chatter on stderr (never stdout, which ``--json`` reserves)."""
    if not quiet:
        print(msg, file=sys.stderr)
