"""simfab's Warp modules start from their cached binaries without regenerating code.

Warp looks a module's binary up by a hash of its kernels' sources. A ``wp.static`` expression that
reads a kernel's local variables (e.g. an element type's length) cannot be evaluated when the kernel
is declared; Warp then runs its whole code generation for the module in every process before the
first launch, to hash it (~1.3 s for the P2 kernels, per process, with the binary already cached).
"""

import importlib
import pkgutil

import pytest

import simfab

warp_context = pytest.importorskip("warp._src.context")


def _kernel_modules() -> list[str]:
    """Every simfab module that declares Warp kernels (found by reading the sources)."""
    root = simfab.__path__[0]
    names = []
    for info in pkgutil.walk_packages([root], prefix="simfab."):
        spec = importlib.util.find_spec(info.name)
        if spec is not None and spec.origin and spec.origin.endswith(".py"):
            with open(spec.origin, encoding="utf-8") as f:
                if "@wp.kernel" in f.read():
                    names.append(info.name)
    return names


def test_every_kernel_module_is_hashed_without_code_generation():
    names = _kernel_modules()
    assert {"simfab.fem.neohookean", "simfab.fem.neohookean_p2", "simfab.contact.imls"} <= set(names)
    for name in names:
        importlib.import_module(name)
    modules = {n: m for n, m in warp_context.user_modules.items() if n in names}
    assert set(modules) == set(names)
    if not all(hasattr(m, "has_unresolved_static_expressions") for m in modules.values()):
        pytest.skip("this Warp version does not expose deferred static expressions")
    deferred = sorted(n for n, m in modules.items() if m.has_unresolved_static_expressions)
    assert deferred == [], f"wp.static reading a kernel's locals in {deferred}: code generation in every process"
