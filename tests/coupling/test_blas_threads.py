"""The insertion loop runs NumPy's OpenBLAS on one thread (simfab._threads) and restores it."""

from threadpoolctl import threadpool_info


def _numpy_blas_threads():
    return [lib["num_threads"] for lib in threadpool_info() if lib["prefix"].startswith("libscipy_openblas")]


def test_single_threaded_blas_inside_the_simulation_only(coarse_block_model, monkeypatch):
    import simfab.coupling.simulate as S

    S.simulate(coarse_block_model(True))  # loads every library the run uses
    before = _numpy_blas_threads()
    seen = []
    real = S._simulate
    monkeypatch.setattr(S, "_simulate", lambda *a, **k: (seen.append(_numpy_blas_threads()), real(*a, **k))[1])
    res = S.simulate(coarse_block_model(True))
    assert len(res.steps) == 5 and seen and all(n == 1 for n in seen[0])
    assert _numpy_blas_threads() == before
