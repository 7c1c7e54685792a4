"""run_tasks: order, failure as data, a dying worker retried, version check (LocalCluster)."""

import os
import sys

import cloudpickle
import pytest

from simfab.errors import ConvergenceError, InputError
from simfab.sweep.tasks import check_worker_versions, connect, run_tasks

cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers need not import the tests


def square(*, x):
    if x == 3:
        raise InputError("x = 3 is not allowed", where="--x")
    if x == 4:
        raise ConvergenceError("Newton did not converge in 5 iterations")
    if x == 5:
        raise ZeroDivisionError("division by zero")
    return x * x


def die_once(*, marker):
    """Kills its worker process the first time (no marker yet); returns 'survived' when rerun."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(1)
    return "survived"


@pytest.fixture(scope="module")
def client():
    with connect(None, quiet=True) as c:
        yield c


EXPECTED = [(0, "ok", 0), (1, "ok", 1), (2, "ok", 4), (3, "bad_input", None), (4, "not_converged", None),
            (5, "error", None), (6, "ok", 36)]


def _check(results):
    assert [r.index for r in results] == list(range(7))
    for r, (i, status, value) in zip(results, EXPECTED):
        assert r.status == status and r.value == value, (i, r)
        assert (r.message == "") == (status == "ok")
        assert r.seconds >= 0
    assert results[3].message == "--x: x = 3 is not allowed"
    assert results[4].message.startswith("Newton did not converge")
    assert results[5].message == "ZeroDivisionError: division by zero"


def test_serial_and_local_cluster_agree(client):
    ser = run_tasks(square, [{"x": i} for i in range(7)], scheduler="serial", quiet=True)
    _check(ser)
    assert {r.worker for r in ser} == {"serial"}
    seen = []
    par = run_tasks(square, [{"x": i} for i in range(7)], scheduler=client, quiet=True, on_result=seen.append)
    _check(par)
    assert sorted(r.index for r in seen) == list(range(7))  # on_result saw every task once
    assert {r.worker for r in par} <= set(client.scheduler_info()["workers"])


def test_worker_that_dies_is_retried(client, tmp_path):
    res = run_tasks(die_once, [{"marker": str(tmp_path / "marker")}], scheduler=client, quiet=True)
    assert res[0].status == "ok" and res[0].value == "survived"


def test_version_check(client):
    from simfab import __version__

    assert set(check_worker_versions(client).values()) == {__version__}
    # every worker differs here; how many the cluster has by now depends on the tests before (order dependence
    # found in random order): the message names the first and counts the others
    with pytest.raises(InputError, match=r"has simfab .*this client 9\.9\.9( \(and \d+ more workers\))?: install the "
                                         "same simfab on every worker"):
        check_worker_versions(client, "9.9.9")


def test_unreachable_scheduler_is_input_error():
    import socket

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there
    with pytest.raises(InputError, match="--scheduler: cannot connect to a Dask scheduler"):
        run_tasks(square, [{"x": 1}], scheduler=f"127.0.0.1:{port}", quiet=True)
