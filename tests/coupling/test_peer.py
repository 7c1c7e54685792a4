"""The IPC reference of ``tools/bench.py peer`` (ipctk) against simfab on the frictionless snap-fit:
two barrier methods with the same d_hat on the same linear mesh must give the same profile."""

import importlib
import os
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
    row = peer.compare("snapfit2d", 0.0, repeat=2)  # (a repeated run must give the same records, else it raises)
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
    for who in ("simfab", "ipc"):  # the median of two runs lies between them
        lo, hi = row[who]["seconds_range"]
        assert 0 < lo <= row[who]["seconds"] <= hi, (who, row[who]["seconds"], lo, hi)


def test_refine_factors_are_parsed_and_checked(peer):
    from simfab.errors import InputError

    assert peer.parse_refine("1,2,4") == [1.0, 2.0, 4.0]
    for bad in ("0.5", "x", "1,,2", "100"):
        with pytest.raises(InputError, match="--refine"):
            peer.parse_refine(bad)
    with pytest.raises(InputError, match="--refine"):  # before any case runs
        peer.run(["--scenes", "snapfit2d", "--refine", "1,0"])
    with pytest.raises(InputError, match="--frictions"):
        peer.run(["--scenes", "snapfit2d", "--frictions", "-0.3"])
    with pytest.raises(InputError, match="--repeat"):
        peer.run(["--scenes", "snapfit2d", "--repeat", "0"])


def test_refine_scales_the_element_count(peer):
    # the snap-fit's beam: cells through the thickness times sqrt(factor), so 4x the triangles
    base = peer.case_model("snapfit2d", 0.0, 1.0).fem.n_elements
    assert peer.case_model("snapfit2d", 0.0, 4.0).fem.n_elements == 4 * base
    # clip3d by the scene's own rule (converge.level_mesh): at 2x the section is meshed twice as finely
    n1, n2 = (peer.case_model("clip3d", 0.0, f).fem.n_elements for f in (1.0, 2.0))
    assert 1.6 < n2 / n1 < 2.4, (n1, n2)


def test_bench_cli_rejects_a_bad_refine_factor():
    import subprocess

    out = subprocess.run([sys.executable, str(TOOLS / "bench.py"), "peer", "--refine", "0"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "--refine" in out.stderr
    assert out.stdout == ""


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc, where nothing can be created")
def test_bench_cli_rejects_a_plot_folder_that_cannot_be_made_before_any_case_runs():
    # the plots are drawn after each case: a bad folder was a traceback (exit 1) after the first case
    import subprocess

    out = subprocess.run([sys.executable, str(TOOLS / "bench.py"), "peer", "--scenes", "snapfit2d", "--frictions", "0",
                          "--plot", "/proc/simfab-x"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr.strip().count("\n") == 0 and "--plot" in out.stderr, out.stderr
