"""simfab sweep end to end: a LocalCluster and a real cluster (dask scheduler + two dask worker
subprocesses on loopback) give the same table; a failing run is a row; resume after the table
is truncated runs only what is missing."""

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

import simfab
from simfab.cli import main
from simfab.sweep.table import write_table

ROOT = str(Path(simfab.__file__).resolve().parent.parent)


def _free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


@pytest.fixture(scope="module")
def remote():
    """Address of a Dask cluster of one scheduler and two single-threaded workers, started as
    subprocesses the way a user starts one (the workers import this checkout's simfab)."""
    from distributed import Client

    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], **quiet)]
    try:
        deadline = time.time() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.time() < deadline and procs[0].poll() is None, "dask scheduler did not start"
                time.sleep(0.2)
        for i in range(2):
            procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", addr, "--nthreads", "1",
                                           "--nworkers", "1", "--no-dashboard", "--host", "127.0.0.1",
                                           "--name", f"w{i}"], **quiet))
        with Client(addr, timeout=60) as c:
            c.wait_for_workers(2, timeout=60)
        yield addr
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs[::-1]:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def _sweep(capsys, *argv) -> dict:
    assert main(["sweep", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _check_table(df: pd.DataFrame, out: Path) -> None:
    assert list(df["run"]) == list(range(6))
    assert list(zip(df["practitioners"], df["public"])) == [(p, q) for p in (0, 3, 6) for q in (0, 10)]
    bad = df[df["status"] != "ok"]
    assert list(bad["run"]) == [0]  # no raters at all: the only failing run
    assert bad["status"].iloc[0] == "bad_input" and "need at least one rater" in bad["message"].iloc[0]
    assert bad[["raters", "malicious", "first_task", "malicious_share"]].isna().all(axis=None)
    ok = df[df["status"] == "ok"]
    assert (ok["raters"] == ok["practitioners"] + ok["public"]).all()
    assert (ok["first_task"] == "q1").all() and (ok["message"].fillna("") == "").all()
    assert (ok["malicious_share"] - ok["malicious"] / ok["raters"]).abs().max() < 1e-15
    assert ((ok["public"] == 0) == (ok["malicious"] == 0)).all()  # only the public has malicious raters
    assert (df["seconds"] > 0).all() and df["key"].str.fullmatch("[0-9a-f]{16}").all()
    for _, r in ok.iterrows():  # every run wrote its outputs into its own folder
        assert (out / r["outputs"] / "ratings.csv").is_file()


def _same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    drop = ["seconds", "worker"]
    pd.testing.assert_frame_equal(a.drop(columns=drop), b.drop(columns=drop))


def test_local_and_remote_cluster_same_table(tiny_spec, remote, tmp_path, capsys):
    lo = _sweep(capsys, tiny_spec, "--out", tmp_path / "local")
    assert (lo["runs"], lo["ran"], lo["ok"], lo["failed"]) == (6, 6, 5, {"bad_input": 1})
    local = pd.read_parquet(lo["outputs"]["table_parquet"])
    _check_table(local, tmp_path / "local")
    varying = ["message", "worker", "outputs", "first_task"]
    pd.testing.assert_frame_equal(pd.read_csv(lo["outputs"]["table_csv"], dtype={"key": str}).drop(columns=varying),
                                  local.drop(columns=varying), check_dtype=False)

    re = _sweep(capsys, tiny_spec, "--out", tmp_path / "remote", "--scheduler", remote)
    remote_df = pd.read_parquet(re["outputs"]["table_parquet"])
    _check_table(remote_df, tmp_path / "remote")
    assert set(remote_df["worker"]) <= {w for w in remote_df["worker"] if w.startswith("tcp://127.0.0.1:")}
    _same(local, remote_df)
    for name in ("raters", "malicious_share"):
        assert os.path.isfile(re["outputs"]["plots"][name])


def test_resume_after_truncation_on_remote_cluster(tiny_spec, remote, tmp_path, capsys):
    out = tmp_path / "sweep"
    full = pd.read_parquet(_sweep(capsys, tiny_spec, "--out", out, "--scheduler", remote)["outputs"]["table_parquet"])
    cut = full.iloc[:3].copy()
    cut.loc[1, "status"] = "error"  # an internal error is run again on resume
    write_table(cut, out, "tiny")
    s = _sweep(capsys, tiny_spec, "--out", out, "--scheduler", remote)
    assert (s["runs"], s["skipped"], s["ran"]) == (6, 2, 4)  # runs 0 (bad input) and 2 kept
    again = pd.read_parquet(s["outputs"]["table_parquet"])
    _same(full, again)
    for i in (0, 2):  # kept rows were not run again: their timings are the old ones
        assert again.loc[i, "seconds"] == full.loc[i, "seconds"] and again.loc[i, "worker"] == full.loc[i, "worker"]
    s = _sweep(capsys, tiny_spec, "--out", out, "--scheduler", remote)
    assert (s["skipped"], s["ran"]) == (6, 0)
    s = _sweep(capsys, tiny_spec, "--out", out, "--scheduler", remote, "--retry-failed")
    assert (s["skipped"], s["ran"], s["failed"]) == (5, 1, {"bad_input": 1})


def test_unreachable_scheduler_exit_2_no_output(tiny_spec, tmp_path, capsys):
    port = _free_port()
    assert main(["sweep", str(tiny_spec), "--out", str(tmp_path / "o"), "--scheduler", f"127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("simfab: error: --scheduler: cannot connect") and len(err.splitlines()) == 1
    assert not (tmp_path / "o").exists()  # nothing written before the cluster is reachable
