"""One place that imports and initializes NVIDIA Warp quietly.

Modules that define kernels do ``from simfab._warp import wp`` at import time; Warp's
own start-up cost is paid only by code that uses kernels, never by ``import simfab``.
:class:`Replay` replays a recorded launch with its argument struct built once (the FEM workspace's
and the friction kernel's launches).
"""

from __future__ import annotations

import ctypes
import functools
import threading

import warp as wp

from simfab.errors import InputError

#: Held while a launch is recorded (``record_cmd=True``): the first launch of a kernel loads (and
#: may build) its module, which must not happen from two threads at once. Replaying recorded
#: launches from two threads is safe as long as they use different buffers.
RECORD_LOCK = threading.Lock()

# Warp prints its start-up banner on stdout at INFO level, which would corrupt ``--json``
# output; only warnings and errors are wanted (they go to stderr).
wp.config.log_level = wp.LOG_WARNING


def _init_quietly() -> None:
    """``wp.init()`` without the native 'no CUDA driver' notice on CPU-only machines.

    Warp's native library writes that notice straight to file descriptor 2; it is expected
    here (CPU is the default device), so it is filtered out and anything else is replayed.
    """
    import os
    import sys
    import tempfile

    try:
        saved = os.dup(2)
    except OSError:  # no real stderr (embedded interpreters): just initialize
        wp.init()
        return
    with tempfile.TemporaryFile(mode="w+b") as buf:
        sys.stderr.flush()
        os.dup2(buf.fileno(), 2)
        try:
            wp.init()
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        buf.seek(0)
        text = buf.read().decode(errors="replace")
    kept = [ln for ln in text.splitlines() if ln.strip() and "CUDA driver" not in ln]
    if kept:
        print("\n".join(kept), file=sys.stderr)


_init_quietly()


def device(name: str | None = None) -> str:
    """Validate a device name ("cpu", "cuda", "cuda:0"); InputError when it does not exist."""

    name = name or "cpu"
    if name.startswith("cuda") and not wp.is_cuda_available():
        # asking Warp for the device would first print its native driver errors on stderr
        raise InputError(f"Warp device {name!r} is not available here (no CUDA driver or device)", where="--device")
    try:
        return str(wp.get_device(name))
    except Exception as e:  # Warp raises RuntimeError/ValueError for unknown devices
        raise InputError(f"Warp device {name!r} is not available here ({e})", where="--device") from None


class Replay:
    """A recorded launch (``wp.launch(..., record_cmd=True)``) as ``launch()``. On the CPU it calls the
    kernel's entry point with an argument struct built once: ``wp.Launch.launch`` builds that ctypes
    struct field by field on every call, a few microseconds against a kernel of a few microseconds on
    a small mesh (every buffer the launch reads or writes is persistent, so the struct stays valid).
    Where the recorded launch does not have that form (another device, a block launch, another Warp
    release's attributes) ``launch`` is the recorded one's."""

    __slots__ = ("launch", "_keep")

    def __init__(self, cmd):
        self.launch, self._keep = cmd.launch, cmd
        try:
            if not (cmd.device.is_cpu and not cmd.adjoint and cmd.block_dim == 1):
                return
            params, names = cmd.params, [a.label for a in cmd.kernel.adj.args]
            if len(params) != len(names) + 1:
                return
            fields = [(name, type(v)) for name, v in zip(names, params[1:])]
            args = type("LaunchArgs", (ctypes.Structure,), {"_fields_": fields})()
            for name, v in zip(names, params[1:]):
                setattr(args, name, v)
            forward = cmd.hooks.forward
        except (AttributeError, TypeError):
            return
        self._keep = (cmd, args)  # (the struct and the arrays it points into stay alive with the command)
        self.launch = functools.partial(forward, ctypes.byref(params[0]), ctypes.byref(args))


__all__ = ["wp", "device", "Replay", "RECORD_LOCK"]
