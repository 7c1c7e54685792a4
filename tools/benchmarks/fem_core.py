"""FEM core timings (kernels, assembly, factorization) at the reference model sizes.

``python tools/bench.py fem_core``; the published figures cover whole insertion runs only
(see ``insertion``), so this benchmark reports absolute times.
"""

from simfab.fem.benchmark import run  # noqa: F401
