"""The FEM core benchmark (``python tools/bench.py fem_core``) runs end to end on a tiny size
(timings are not asserted)."""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from benchmarks.fem_core import run  # noqa: E402


def test_benchmark_runs_and_reports_every_figure():
    out = run(["--sizes", "300", "--repeat", "1"])
    json.dumps(out)  # JSON-able
    for entry in [out["tri_2d"], *out["tet_3d"]]:
        for key in ("energy_ms", "energy_gradient_ms", "energy_gradient_hessian_ms", "hessian_svd_route_ms",
                    "eigh_projection_ms", "factorization_ms", "newton_static_s"):
            assert entry[key] > 0
        assert 1 <= entry["newton_static_iterations"] <= 10
    assert 150 <= out["tet_3d"][0]["elements"] <= 600
