"""Campaign stores under concurrency and crashes: the lock, half-created stores, durable
and checksummed tasks (damaged chunks found and redone).

Driven by ``campaign_helpers.shift_task`` (a cheap real task), like test_campaign_engine.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dicblur.campaign import (
    VARIABLES,
    CampaignStore,
    campaign_status,
    open_results,
    parse_spec,
    run_campaign,
)
from dicblur.campaign import store as store_mod
from dicblur.campaign.lock import StoreLock, lock_holder, lock_path
from dicblur.cli import main
from dicblur.errors import StoreError
from helpers.campaign import kill_spec, shift_task, small_spec_dict

HERE = Path(__file__).resolve().parent

COMPARED = [v for v in VARIABLES if v != "time_s"]


def assert_same_results(a, b):
    for name in [*COMPARED, "done"]:
        assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "r.zarr"
    run_campaign(parse_spec(small_spec_dict()), path, serial=True, task=shift_task)
    return path


# -- one runner per store ------------------------------------------------------------------


def test_second_runner_is_refused_while_the_first_holds_the_lock(tmp_path):
    out = tmp_path / "r.zarr"
    with StoreLock(out) as lock:
        assert lock.held and lock_path(out).exists()
        holder = lock_holder(out)
        assert holder is not None and holder.pid == os.getpid()
        with pytest.raises(
            StoreError,
            match=r"another campaign run is using this store "
            rf"\(pid {os.getpid()} on host .* since .*UTC\); wait",
        ):
            run_campaign(parse_spec(small_spec_dict()), out, serial=True, task=shift_task)
        assert not out.exists()  # refused before creating anything
    assert not lock_path(out).exists() and lock_holder(out) is None
    assert run_campaign(parse_spec(small_spec_dict()), out, serial=True, task=shift_task).complete


RUNNER = """
import sys, time
sys.path.insert(0, {tests!r})
from helpers.campaign import kill_spec, shift_task
from dicblur.campaign import run_campaign
from dicblur.errors import StoreError

def slow(image, batch, spec):
    time.sleep({delay})
    return shift_task(image, batch, spec)

try:
    s = run_campaign(kill_spec(), {out!r}, serial=True, task=slow)
except StoreError as exc:
    print("refused:", exc)
    sys.exit(3)
print("ran", s.n_run, "skipped", s.n_skipped)
"""


def _runner(tmp_path: Path, out: Path, delay: float = 0.0) -> list[str]:
    script = tmp_path / f"runner_{delay}.py"
    script.write_text(RUNNER.format(tests=str(HERE), out=str(out), delay=delay))
    return [sys.executable, str(script)]


@pytest.mark.slow  # 7-11 s: keeps the README's test command under 4 min (CI runs it)
def test_two_concurrent_runners_on_a_new_store(tmp_path):
    # Before the lock: one crashed (FileNotFoundError '.creating' -> store) or both
    # computed every task.
    out = tmp_path / "new.zarr"
    cmd = _runner(tmp_path, out, delay=0.01)
    procs = [
        subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE) for _ in range(2)
    ]
    res = [p.communicate(timeout=300) for p in procs]
    codes = sorted(p.returncode for p in procs)
    assert codes == [0, 3], [r[1].decode()[-2000:] for r in res]
    outs = [r[0].decode() for r in res]
    assert any("ran 192 skipped 0" in o for o in outs), outs
    assert any("another campaign run is using this store" in o for o in outs), outs
    assert not any(r[1] for p, r in zip(procs, res, strict=True) if p.returncode == 3)
    assert campaign_status(out).complete
    assert not (tmp_path / "new.zarr.creating").exists() and not lock_path(out).exists()
    ref = tmp_path / "ref.zarr"
    run_campaign(kill_spec(), ref, serial=True, task=shift_task)
    assert_same_results(open_results(ref), open_results(out))


def test_second_runner_on_an_existing_store_computes_nothing(tmp_path):
    out = tmp_path / "old.zarr"

    def stop(done, total):
        if done >= 8:
            raise KeyboardInterrupt

    assert run_campaign(kill_spec(), out, serial=True, task=shift_task, progress=stop).interrupted
    first = subprocess.Popen(
        _runner(tmp_path, out, delay=0.02), stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 120
    while lock_holder(out) is None and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    second = subprocess.run(_runner(tmp_path, out), capture_output=True, timeout=120)
    o1, e1 = first.communicate(timeout=300)
    assert first.returncode == 0, e1.decode()[-2000:]
    assert "ran 184 skipped 8" in o1.decode()
    assert second.returncode == 3 and b"another campaign run" in second.stdout


def test_cli_second_runner_gets_one_line_and_exit_2(tmp_path, capsys):
    spec_path = tmp_path / "s.toml"
    spec_path.write_text(_toml(small_spec_dict()))
    out = tmp_path / "c.zarr"
    with StoreLock(out):
        rc = main(["campaign", "run", str(spec_path), "-o", str(out), "--serial", "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err
    # the CLI names the option the user typed (-o/--out), not the API's results=
    assert err.startswith(f"error: --out={str(out)!r}: another campaign run")


def test_lock_of_a_killed_runner_does_not_block(tmp_path):
    # The holder dies by SIGKILL (no clean-up): the OS drops its flock, the file stays.
    out = tmp_path / "k.zarr"
    code = (
        "import sys, time; from dicblur.campaign.lock import StoreLock; "
        f"l = StoreLock({str(out)!r}); l.acquire(); print('locked', flush=True); "
        "time.sleep(60)"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    assert proc.stdout is not None and proc.stdout.readline().strip() == b"locked"
    assert lock_holder(out) is not None and lock_holder(out).pid == proc.pid
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    proc.stdout.close()
    assert lock_path(out).exists() and lock_holder(out) is None  # stale: not held
    assert run_campaign(parse_spec(small_spec_dict()), out, serial=True, task=shift_task).complete
    assert not lock_path(out).exists()


def test_status_names_the_running_holder(reference, tmp_path):
    copy = tmp_path / "s.zarr"
    shutil.copytree(reference, copy)
    assert campaign_status(copy).running is None
    with StoreLock(copy):
        st = campaign_status(copy)
    assert st.running is not None and f"pid {os.getpid()}" in st.running
    assert st.to_dict()["running"] == st.running


# -- creation interrupted ------------------------------------------------------------------


def test_crash_during_creation_leaves_nothing_that_blocks(tmp_path, monkeypatch):
    out = tmp_path / "c.zarr"

    def crash(root):
        raise KeyboardInterrupt  # e.g. Ctrl-C, or a kill, while the metadata is written

    monkeypatch.setattr(store_mod, "_fsync_tree", crash)
    with pytest.raises(KeyboardInterrupt):
        run_campaign(parse_spec(small_spec_dict()), out, serial=True, task=shift_task)
    assert not out.exists() and (tmp_path / "c.zarr.creating").exists()
    monkeypatch.undo()
    assert run_campaign(parse_spec(small_spec_dict()), out, serial=True, task=shift_task).complete
    assert not (tmp_path / "c.zarr.creating").exists()


def test_half_created_store_is_recreated_and_status_says_so(reference, tmp_path):
    # What the race of two creators left before the lock: the arrays but no root
    # attributes ("layout None, expected 1" on every later run, with no hint).
    half = tmp_path / "h.zarr"
    shutil.copytree(reference, half)
    for sub in ("done", *VARIABLES, "checksum"):
        shutil.rmtree(half / sub / "c", ignore_errors=True)
    meta = json.loads((half / "zarr.json").read_text())
    meta["attributes"] = {}
    (half / "zarr.json").write_text(json.dumps(meta))
    with pytest.raises(StoreError, match=r"half-created store .* run the campaign again"):
        campaign_status(half)
    summary = run_campaign(parse_spec(small_spec_dict()), half, serial=True, task=shift_task)
    assert summary.complete and summary.n_run == 40
    assert_same_results(open_results(reference), open_results(half))


def test_foreign_folder_is_not_deleted(tmp_path):
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "readme.txt").write_text("mine")
    with pytest.raises(StoreError, match=r"results=.*not a .*; choose a new results path$"):
        run_campaign(parse_spec(small_spec_dict()), plain, serial=True, task=shift_task)
    assert (plain / "readme.txt").read_text() == "mine"


# -- durable, checksummed tasks ------------------------------------------------------------


def _chunk(store: Path, name: str) -> Path:
    return next(
        p
        for p in sorted((store / name / "c").rglob("*"))
        if p.is_file() and not p.name.startswith(".")
    )


@pytest.mark.parametrize("damage", ["truncate", "flip", "delete", "truncate-checksum"])
def test_damaged_chunk_is_reported_and_redone(reference, tmp_path, damage):
    # Before: status said complete, a rerun did nothing, open_results failed "damaged"
    # (truncated) or returned the altered value silently (flipped bits).
    copy = tmp_path / "d.zarr"
    shutil.copytree(reference, copy)
    target = _chunk(copy, "checksum" if damage == "truncate-checksum" else "u_e")
    raw = target.read_bytes()
    if damage.startswith("truncate"):
        target.write_bytes(raw[: len(raw) // 2])
    elif damage == "flip":
        target.write_bytes(raw[:3] + bytes([raw[3] ^ 0x01]) + raw[4:])
    else:
        target.unlink()
    st = campaign_status(copy)
    hit = 1 if damage == "flip" else 2  # a flipped bit: one task's checksum; else the batch
    assert st.n_damaged == hit and st.n_done == 40 - hit and not st.complete
    with pytest.raises(StoreError, match=rf"{hit} finished task\(s\) are damaged.*rerun"):
        open_results(copy)
    again = run_campaign(parse_spec(small_spec_dict()), copy, serial=True, task=shift_task)
    assert again.n_run == 2 and again.n_skipped == 38 and again.complete
    assert campaign_status(copy).n_damaged == 0
    assert_same_results(open_results(reference), open_results(copy))


def test_cli_status_reports_damaged_tasks(reference, tmp_path, capsys):
    copy = tmp_path / "d.zarr"
    shutil.copytree(reference, copy)
    _chunk(copy, "bias").write_bytes(b"\0")
    assert main(["campaign", "status", str(copy)]) == 0
    out = capsys.readouterr().out
    assert "2 tasks (rerun the campaign to recompute them)" in out
    assert main(["campaign", "status", str(copy), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n_damaged"] == 2 and d["complete"] is False


@pytest.mark.parametrize("syncfs", [True, False])
def test_every_batch_is_synced_to_disk(tmp_path, monkeypatch, syncfs):
    # Before: nothing was fsynced (a power loss could keep the flags and lose the values).
    spec = parse_spec(small_spec_dict())
    out = tmp_path / "f.zarr"
    run_campaign(
        spec,
        out,
        serial=True,
        task=shift_task,
        progress=lambda d, t: (_ for _ in ()).throw(KeyboardInterrupt) if d else 0,
    )
    store = CampaignStore.open(out)
    key = "/".join(map(str, (0, 0, 0, 0, 0, 0)))
    files = [f"{name}/c/{key}" for name in (*VARIABLES, "checksum", "done")]
    for f in files:
        (out / f).unlink()
    events: list[tuple[str, object]] = []
    real_syncfs = store_mod._syncfs

    def fake_syncfs(path):
        # at the sync, every chunk of the batch is in place
        events.append(("syncfs", all((out / f).is_file() for f in files)))
        return real_syncfs(path) if syncfs else False

    real_fsync = os.fsync

    def fsync(fd):
        events.append(
            ("fsync", os.path.relpath(os.readlink(f"/proc/self/fd/{fd}"), os.path.realpath(out)))
        )
        real_fsync(fd)

    monkeypatch.setattr(store_mod, "_syncfs", fake_syncfs)
    monkeypatch.setattr(os, "fsync", fsync)
    from dicblur.campaign import iter_batches, make_pattern

    b = next(iter_batches(spec))
    store.write_batch(b, shift_task(make_pattern(spec, spec.patterns[0]), b, spec))
    assert events[0] == ("syncfs", True)
    if syncfs:
        assert len(events) == 1
    else:  # no syncfs: each chunk file and its folder
        synced = {e[1] for e in events[1:]}
        assert synced == set(files) | {os.path.dirname(f) for f in files}
    assert campaign_status(out).n_done == 2


def test_layout_1_store_is_still_read_and_resumed(reference, tmp_path):
    old = tmp_path / "v1.zarr"
    shutil.copytree(reference, old)
    shutil.rmtree(old / "checksum")
    meta = json.loads((old / "zarr.json").read_text())
    meta["attributes"]["dicblur_layout"] = 1
    (old / "zarr.json").write_text(json.dumps(meta))
    assert campaign_status(old).complete
    _chunk(old, "mig").write_bytes(b"\0\0")
    assert campaign_status(old).n_damaged == 2
    assert run_campaign(parse_spec(small_spec_dict()), old, serial=True, task=shift_task).n_run == 2
    assert_same_results(open_results(reference), open_results(old))


def _toml(d: dict) -> str:
    lines: list[str] = []

    def val(v):
        return (
            json.dumps(v)
            if not isinstance(v, dict)
            else ("{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }")
        )

    for sec, body in d.items():
        if sec == "pattern":
            for p in body:
                lines.append("[[pattern]]")
                lines += [f"{k} = {val(v)}" for k, v in p.items()]
        else:
            lines.append(f"[{sec}]")
            lines += [f"{k} = {val(v)}" for k, v in body.items()]
    return "\n".join(lines) + "\n"
