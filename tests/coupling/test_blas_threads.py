"""The insertion loop runs NumPy's OpenBLAS on one thread (simfab._threads) and restores it."""

from threadpoolctl import threadpool_info


def _numpy_blas_threads():
    return [lib["num_threads"] for lib in threadpool_info() if lib["prefix"].startswith("libscipy_openblas")]


def test_single_threaded_blas_inside_the_simulation_only(coarse_block_model):
    from simfab.coupling.simulate import simulate_insertion

    simulate_insertion(coarse_block_model(True))  # loads every library the run uses
    before = _numpy_blas_threads()
    seen = []
    res = simulate_insertion(coarse_block_model(True), callback=lambda k, rec: seen.append(_numpy_blas_threads()))
    assert len(res.steps) == 5 and len(seen) == 5 and all(n == 1 for threads in seen for n in threads)
    assert _numpy_blas_threads() == before
