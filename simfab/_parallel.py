"""A second thread for independent work (simfab targets machines with two cores or more).

Warp CPU kernels run single-threaded and release the GIL while they run, so two independent
kernel launches can overlap: ``submit(fn, ...)`` runs ``fn`` on one worker thread while the caller
goes on. Work submitted from the worker itself runs inline (a single worker waiting on itself
would deadlock).
"""

from __future__ import annotations

import threading

_POOL = None
_LOCK = threading.Lock()
_NAME = "simfab-worker"


def _worker():
    global _POOL
    with _LOCK:
        if _POOL is None:
            from concurrent.futures import ThreadPoolExecutor

            _POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix=_NAME)
    return _POOL


class _Done:
    """The result of work that ran inline, with the interface of a future."""

    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


def submit(fn, *args, **kwargs):
    """Run ``fn(*args, **kwargs)`` on the worker thread (inline when called from it); returns an
    object whose ``result()`` gives the value (or raises the exception)."""
    if threading.current_thread().name.startswith(_NAME):
        return _Done(fn(*args, **kwargs))
    return _worker().submit(fn, *args, **kwargs)
