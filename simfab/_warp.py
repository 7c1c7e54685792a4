"""One place that imports and initializes NVIDIA Warp quietly.

Modules that define kernels do ``from simfab._warp import wp`` at import time; Warp's
own start-up cost is paid only by code that uses kernels, never by ``import simfab``.
"""

from __future__ import annotations

import warp as wp

# Warp prints its start-up banner on stdout at INFO level, which would corrupt ``--json``
# output; only warnings and errors are wanted (they go to stderr).
wp.config.log_level = wp.LOG_WARNING
wp.init()


def device(name: str | None = None) -> str:
    """Validate a device name ("cpu", "cuda", "cuda:0"); InputError when it does not exist."""
    from simfab.errors import InputError

    name = name or "cpu"
    try:
        return str(wp.get_device(name))
    except Exception as e:  # Warp raises RuntimeError/ValueError for unknown devices
        raise InputError(f"Warp device {name!r} is not available here ({e})", where="--device") from None


__all__ = ["wp", "device"]
