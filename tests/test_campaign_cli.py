"""Campaign CLI and an external Dask cluster (real ``dask scheduler`` + ``dask worker``)."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dicblur.campaign import open_results, parse_spec, run_campaign
from dicblur.cli import main
from helpers.campaign import shift_task, small_spec_dict

HERE = Path(__file__).resolve().parent

BIN = Path(sys.executable).parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)  # own session: only this process and children
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """A real scheduler and one worker process on 127.0.0.1, always torn down."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = tmp_path_factory.mktemp("dask")
    # The scheduler and the worker must import what the client sends (Dask pickles
    # importable functions by reference): put tests/ on their path, as a deployment
    # installs the same environment everywhere.
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])]),
    )
    procs: list[subprocess.Popen] = []
    sched_log = open(logs / "scheduler.log", "w")  # closed in finally
    worker_log = open(logs / "worker.log", "w")
    try:
        procs.append(
            subprocess.Popen(
                [
                    str(BIN / "dask"),
                    "scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    str(port),
                    "--no-dashboard",
                ],
                stdout=sched_log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                env=env,
            )
        )
        procs.append(
            subprocess.Popen(
                [
                    str(BIN / "dask"),
                    "worker",
                    address,
                    "--nworkers",
                    "1",
                    "--nthreads",
                    "1",
                    "--host",
                    "127.0.0.1",
                    "--no-dashboard",
                ],
                stdout=worker_log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                env=env,
            )
        )
        from distributed import Client

        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(address, timeout="2s") as c:
                    if c.scheduler_info(n_workers=-1)["workers"]:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline or any(p.poll() is not None for p in procs):
                pytest.fail(
                    "dask cluster did not start:\n"
                    + (logs / "scheduler.log").read_text()
                    + (logs / "worker.log").read_text()
                )
            time.sleep(0.3)
        yield address
    finally:
        for p in reversed(procs):
            _stop(p)
        sched_log.close()
        worker_log.close()


@pytest.mark.slow
@pytest.mark.numba_cache
def test_external_cluster_equals_serial(dask_cluster, tmp_path):
    spec = parse_spec(small_spec_dict())
    remote = run_campaign(spec, tmp_path / "remote.zarr", scheduler=dask_cluster, task=shift_task)
    assert remote.complete and remote.scheduler == dask_cluster and remote.workers == 1
    run_campaign(spec, tmp_path / "serial.zarr", serial=True, task=shift_task)
    a, b = open_results(tmp_path / "remote.zarr"), open_results(tmp_path / "serial.zarr")
    for name in a.data_vars:
        if name != "time_s":
            assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name


@pytest.mark.slow
@pytest.mark.numba_cache
def test_cli_run_through_scheduler_equals_serial(dask_cluster, tmp_path, capsys):
    # the real task (blur + noise + DIC) on the external worker, through the CLI
    spec_path = tmp_path / "s.toml"
    spec_path.write_text(SPEC_TOML)
    out = tmp_path / "remote.zarr"
    code = main(
        ["campaign", "run", str(spec_path), "-o", str(out), "--scheduler", dask_cluster, "-q"]
    )
    assert code == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "tasks" in text and dask_cluster in text
    from dicblur.campaign import VARIABLES, load_spec

    run_campaign(load_spec(spec_path), tmp_path / "serial.zarr", serial=True)
    a, b = open_results(out), open_results(tmp_path / "serial.zarr")
    for name in VARIABLES:
        if name != "time_s":
            assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    assert np.isfinite(a["u_e"].values).all()


def test_unreachable_scheduler_is_a_clear_error(tmp_path):
    from dicblur.errors import InputError

    port = _free_port()
    with pytest.raises(
        InputError,
        match=r"scheduler='tcp://127\.0\.0\.1:\d+': cannot "
        "connect",
    ):
        run_campaign(
            parse_spec(small_spec_dict()),
            tmp_path / "r.zarr",
            scheduler=f"tcp://127.0.0.1:{port}",
            task=shift_task,
            connect_timeout=1.0,
        )


SPEC_TOML = """
[campaign]
name = "cli"
seed = 3

[[pattern]]
name = "p"
generator = "speckle"
shape = [64, 64]
speckle_size = 4.0
seed = 1

[blur]
lengths = [0.0, 1.0, 2.0]

[noise]
model = "per-exposure"
levels = [1.0]

[dic]
subsets = [21]
step = 10
"""


def test_status_and_export_commands(tmp_path, capsys):
    spec = parse_spec(small_spec_dict())
    out = tmp_path / "r.zarr"
    run_campaign(spec, out, serial=True, task=shift_task)
    assert main(["campaign", "status", str(out), "--json"]) == 0
    st = json.loads(capsys.readouterr().out)
    assert st["n_done"] == 40 and st["complete"] and st["spec_hash"] == spec.content_hash()
    assert main(["campaign", "status", str(out)]) == 0
    assert "40 / 40" in capsys.readouterr().out
    csv_path = tmp_path / "r.csv"
    assert main(["campaign", "export", str(out), "--csv", str(csv_path)]) == 0
    assert "40 rows" in capsys.readouterr().out
    with open(csv_path, newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 40


def test_cli_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(SPEC_TOML.replace('model = "per-exposure"', 'model = "loud"'))
    assert main(["campaign", "run", str(bad), "-o", str(tmp_path / "x.zarr")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: noise.model='loud'") and "\n" not in err
    assert main(["campaign", "status", str(tmp_path / "none.zarr")]) == 2
    assert "no such store" in capsys.readouterr().err
