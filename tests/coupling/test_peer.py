"""The IPC reference of ``tools/bench.py peer`` (ipctk) against simfab on the frictionless snap-fit:
two barrier methods with the same d_hat on the same linear mesh must give the same profile."""

import importlib
import pathlib
import sys

import pytest

pytest.importorskip("ipctk")

TOOLS = pathlib.Path(__file__).resolve().parents[2] / "tools"


@pytest.fixture(scope="module")
def peer():
    sys.path.insert(0, str(TOOLS))
    try:
        return importlib.import_module("benchmarks.peer")
    finally:
        sys.path.remove(str(TOOLS))


def test_snapfit_forces_agree_with_the_ipc_reference(peer):
    row = peer.compare("snapfit2d", 0.0)
    # both place the contact within d_hat (~1e-2 of the mesh size) of the face: the profiles agree
    # to the barriers' geometric difference, well below 2 % (a wrong reaction sign, direction or
    # energy would be off by 100 %)
    assert row["simfab"]["F_in"] > 0.1  # N: the beam is deflected 0.5 mm, a real load
    for k in ("F_in", "E_max"):
        assert abs(row["relative_difference"][k]) < 0.02, (k, row["simfab"][k], row["ipc"][k])
    f_s, f_i = row["profile"]["force_simfab"], row["profile"]["force_ipc"]
    peak = max(abs(v) for v in f_s)
    assert max(abs(a - b) for a, b in zip(f_s, f_i)) < 0.02 * peak  # the whole profile, step by step
    assert row["ipc"]["newton_iterations"] >= row["records"]  # the reference solved every step
