"""dicblur track in chunks (issue 17): agreement with the serial loop, resume, store, Dask."""

from __future__ import annotations

import os

import numpy as np
import pytest

import dicblur
from dicblur.campaign import ChunkStore
from dicblur.errors import InputError, StoreError
from dicblur.track import TrackInterrupted
from dicblur.track.parallel import HISTORY, ChunkedRun, plan_chunks
from helpers.track import track_pattern, vibrating_target

# the variables set by the correlation (the rest derive from them)
RAW = ("u", "v", "zncc", "status", "fallback")
KW = {"static": "0:4", "subset": 21, "step": 12, "shape": "translation", "advice": False}


def _target():
    p = track_pattern(96, seed=2)
    return vibrating_target(p, exposure=0.4e-3, amplitude=5.0, static=4, seed=4)


@pytest.fixture(scope="module")
def serial():
    """The serial loop on 20 frames, reference 6 (so frames 0..5 are tracked backwards)."""
    rec = _target().recording(20)
    return rec, dicblur.track(rec, reference=6, **KW)


def test_plan_chunks_cover_the_order_with_history():
    order = list(range(6, 20)) + list(range(5, -1, -1))
    chunks = plan_chunks(order, 6, 5)
    flat = [k for c in chunks for k in c.frames]
    assert sorted(flat) == list(range(20)) and len(flat) == 20
    # each chunk is warmed by the frames before it in its run (backwards: from the reference)
    assert chunks[0].frames == (6, 7, 8, 9, 10) and chunks[0].warm == ()
    assert chunks[1].warm == (8, 9, 10) and chunks[1].frames[0] == 11
    back = [c for c in chunks if c.frames[0] < 6]
    assert back[0].warm == (6,) and back[0].frames == (5, 4, 3, 2, 1)
    assert back[1].warm == (3, 2, 1) and back[1].frames == (0,)
    assert all(len(c.warm) <= HISTORY for c in chunks)
    with pytest.raises(InputError, match="chunk_frames"):
        plan_chunks(order, 6, 0)


def test_chunked_agrees_with_serial(serial):
    """Frames whose chunk's warm-up reaches back to the reference are bit-identical to the
    serial run; the others converge within twice the IC-GN tolerance of it (each run stops
    when its estimated error left is below the tolerance, so two starts may differ by
    twice that; measured 2.2e-4 px at 1e-3 here) with identical statuses, fallbacks and
    outlier flags."""
    rec, a = serial
    b = dicblur.track(rec, reference=6, chunks=ChunkedRun(chunk_frames=5), **KW)
    tol = float(a.attrs["tolerance"])
    assert b.attrs["tolerance"] == tol and 1e-4 <= tol <= 1e-3
    assert b.attrs["chunks_n_chunks"] == 5 and b.attrs["chunks_n_run"] == 5
    np.testing.assert_array_equal(a["frame"].values, b["frame"].values)
    for name in ("status", "fallback", "outlier", "valid"):
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    conv = a["status"].values == dicblur.PointStatus.CONVERGED
    assert conv.mean() > 0.8
    for c in ("u", "v"):
        d = np.abs(a[c].values - b[c].values)
        assert np.all(d[conv] < 2 * tol), float(d[conv].max())
        # chunk 0 (frames 6..10) starts at the reference, chunk 3 (5..1) is warmed by it
        same = np.isin(a["frame"].values, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10])
        np.testing.assert_array_equal(a[c].values[same], b[c].values[same])
    # derived after all chunks from the whole track: the blur within 4 x the tolerance
    # (the local trajectory fit's gain on the bound above is below 2), the sigma
    # (tabulated, measured <= 0.2 %) within 1 %
    np.testing.assert_allclose(b["W"].values, a["W"].values, atol=4 * tol, equal_nan=True)
    for c in ("sigma_u", "sigma_v"):
        np.testing.assert_allclose(b[c].values, a[c].values, rtol=1e-2, equal_nan=True)


@pytest.mark.parametrize("shape", ["translation", "affine"])
def test_chunks_on_threads_equal_chunks_one_after_the_other(serial, shape):
    """ChunkedRun(threads=2): the chunks run at the same time on two threads of this
    process (each with its own Correlator; the kernels release the GIL), the results bit
    for bit those of one thread."""
    from dicblur.track.parallel import thread_safe_kernels

    rec, _ = serial
    kw = {**KW, "shape": shape}
    one = dicblur.track(rec, reference=6, chunks=ChunkedRun(chunk_frames=3), **kw)
    two = dicblur.track(rec, reference=6, chunks=ChunkedRun(chunk_frames=3, threads=2), **kw)
    if not thread_safe_kernels():
        pytest.skip("numba's threading layer is not thread-safe here (workqueue)")
    assert two.attrs["chunks_scheduler"] == "threads" and two.attrs["chunks_threads"] == 2
    assert one.attrs["chunks_scheduler"] == "serial"
    for name in (*RAW, "outlier", "valid", "W", "sigma_u", "sigma_v"):
        np.testing.assert_array_equal(one[name].values, two[name].values, err_msg=name)
    with pytest.raises(InputError, match="threads"):
        ChunkedRun(threads=0)


def test_chunk_threads_fork_the_callers_correlator(serial, monkeypatch):
    """In this process the chunk threads fork the caller's prepared Correlator and seeds
    (Correlator.fork) instead of preparing their own: the same results bit for bit."""
    import dicblur.track.parallel as parallel

    rec, _ = serial
    kw = {**KW, "shape": "affine"}
    forks = []
    fork = dicblur.Correlator.fork

    def spy(self, **k):
        forks.append(self.n_points)
        return fork(self, **k)

    monkeypatch.setattr(dicblur.Correlator, "fork", spy)
    shared = dicblur.track(rec, reference=6, chunks=ChunkedRun(chunk_frames=3, threads=2), **kw)
    assert forks and not parallel._SHARED  # forked, and dropped after the run

    class NoShare(dict):  # nothing shared: each thread prepares its own Correlator
        def __setitem__(self, key, value):
            pass

    monkeypatch.setattr(parallel, "_SHARED", NoShare())
    forks.clear()
    own = dicblur.track(rec, reference=6, chunks=ChunkedRun(chunk_frames=3, threads=2), **kw)
    assert not forks
    for name in (*RAW, "outlier", "valid", "W", "sigma_u", "sigma_v"):
        np.testing.assert_array_equal(shared[name].values, own[name].values, err_msg=name)


def test_interrupted_run_resumes_to_the_uninterrupted_result(serial, tmp_path):
    rec, _ = serial
    whole = dicblur.track(rec, reference=6, chunks=ChunkedRun(chunk_frames=4), **KW)
    store = tmp_path / "track.chunks"
    seen = []

    def stop(done, total):
        seen.append(done)
        if done >= 8:  # after two chunks of 4
            raise KeyboardInterrupt

    with pytest.raises(TrackInterrupted) as info:
        dicblur.track(
            rec, reference=6, chunks=ChunkedRun(store=store, chunk_frames=4), progress=stop, **KW
        )
    part = info.value.dataset
    assert isinstance(info.value.__cause__, KeyboardInterrupt)
    assert part.attrs["complete"] == 0 and part.sizes["frame"] == 8
    assert len(list(store.glob("chunk-*.npz"))) == 2
    again = ChunkedRun(store=store, chunk_frames=4)
    resumed = dicblur.track(rec, reference=6, chunks=again, **KW)
    assert again.summary["n_resumed"] == 2 and again.summary["n_run"] == 4
    assert resumed.attrs["complete"] == 1
    for name in whole.data_vars:
        np.testing.assert_array_equal(resumed[name].values, whole[name].values, err_msg=name)
    # a damaged chunk (a copy cut short) is recomputed, to the same values
    victim = store / "chunk-000001.npz"
    victim.write_bytes(victim.read_bytes()[:-100])
    third = ChunkedRun(store=store, chunk_frames=4)
    redone = dicblur.track(rec, reference=6, chunks=third, **KW)
    assert third.summary["n_resumed"] == 5 and third.summary["n_run"] == 1
    for name in RAW:
        np.testing.assert_array_equal(redone[name].values, whole[name].values, err_msg=name)
    # other settings on the same store: refused, naming the difference
    with pytest.raises(StoreError, match=r"another run.*subset"):
        dicblur.track(
            rec, reference=6, chunks=ChunkedRun(store=store, chunk_frames=4), **{**KW, "subset": 23}
        )


def test_chunk_store_checksums_lock_and_keys(tmp_path):
    path = tmp_path / "job.chunks"
    with ChunkStore(path, key={"a": 1}, n_chunks=3) as st:
        st.write(0, {"x": np.arange(4.0), "s": np.array([1, 2], np.uint8)})
        st.write(2, {"x": np.ones(2)})
        assert st.done() == {0, 2}
        np.testing.assert_array_equal(st.read(0)["s"], [1, 2])
        # one writer: a second opening is refused while the first holds the lock
        with pytest.raises(StoreError, match="another"), ChunkStore(path, key={"a": 1}, n_chunks=3):
            pass
    # flipped bytes inside an array: the checksum catches it
    raw = bytearray((path / "chunk-000002.npz").read_bytes())
    i = raw.index(np.ones(2).tobytes())
    raw[i] ^= 0xFF
    (path / "chunk-000002.npz").write_bytes(bytes(raw))
    with ChunkStore(path, key={"a": 1}, n_chunks=3) as st:
        assert st.done() == {0}
        with pytest.raises(StoreError, match=r"checksum|CRC"):
            st.read(2)
    with pytest.raises(StoreError, match="another run"), ChunkStore(path, key={"a": 2}, n_chunks=3):
        pass
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "x.txt").write_text("mine")
    with (
        pytest.raises(StoreError, match="not a chunk store"),
        ChunkStore(tmp_path / "other", key={}, n_chunks=1),
    ):
        pass


def test_chunked_run_bad_options():
    with pytest.raises(InputError, match="--workers"):
        ChunkedRun(workers=0)
    with pytest.raises(InputError, match="--chunk-frames"):
        ChunkedRun(chunk_frames=0)
    with pytest.raises(InputError, match="scheduler"):
        ChunkedRun(scheduler="not an address")
    with pytest.raises(InputError, match="--update-reference"):
        dicblur.track(
            _target().recording(6), update_reference=True, chunks=ChunkedRun(chunk_frames=2), **KW
        )


def _write_frames(folder, rec, n):
    import tifffile

    folder.mkdir()
    for k in range(n):
        tifffile.imwrite(
            folder / f"f{k}.tif", np.clip(np.rint(rec.frame(k)), 0, 255).astype(np.uint8)
        )


@pytest.mark.slow  # a local cluster starts in ~10 s on the loaded machine
@pytest.mark.numba_cache
def test_local_dask_cluster_equals_serial_chunks(tmp_path):
    """Two worker processes, each reading its frames from the folder: the same results as
    the chunks run in this process, bit for bit (both passes of --compensate-blur)."""
    frames = tmp_path / "frames"
    _write_frames(frames, _target().recording(14), 14)
    kw = {**KW, "noise": 2.0, "static": None, "exposure": "0.4ms", "fps": 2000}
    kw["compensate_blur"] = True
    here = dicblur.track(str(frames), chunks=ChunkedRun(chunk_frames=4), **kw)
    run = ChunkedRun(workers=2, chunk_frames=4, store=tmp_path / "track.chunks")
    dask = dicblur.track(str(frames), chunks=run, **kw)
    assert run.summary["scheduler"] == "local" and run.summary["workers"] == 2
    for name in here.data_vars:
        np.testing.assert_array_equal(dask[name].values, here[name].values, err_msg=name)


def test_cli_chunks_resume(tmp_path, capsys):
    from dicblur.cli import main

    frames = tmp_path / "frames"
    _write_frames(frames, _target().recording(10), 10)
    out = tmp_path / "out"
    args = [
        "track", str(frames), "--exposure", "0.4ms", "--fps", "2000", "--noise", "2",
        "--shape", "translation", "--step", "12", "--chunk-frames", "4", "--no-report",
        "-o", str(out),
    ]  # fmt: skip
    assert main(args) == 0
    assert "3 run, 0 resumed of 3" in capsys.readouterr().out
    assert sorted(os.listdir(out / "track.chunks")) == [
        "chunk-000000.npz", "chunk-000001.npz", "chunk-000002.npz", "store.json"
    ]  # fmt: skip
    assert main(args) == 0
    assert "0 run, 3 resumed of 3" in capsys.readouterr().out
    assert main([*args, "--workers", "2", "--scheduler", "tcp://h:1"]) == 2
    assert "--workers and --scheduler" in capsys.readouterr().err
    # --threads with --chunk-frames alone: the chunks on two threads, the same dataset
    out2 = tmp_path / "out2"
    args2 = [*args[:-1], str(out2), "--threads", "2"]
    assert main(args2) == 0
    import xarray as xr

    with xr.open_dataset(out / "track.nc") as a, xr.open_dataset(out2 / "track.nc") as b:
        assert b.attrs["chunks_threads"] in (1, 2)  # 1 where numba's layer is workqueue
        for name in ("u", "v", "status", "sigma_u"):
            np.testing.assert_array_equal(a[name].values, b[name].values)


def test_compensated_pass_in_chunks_agrees_and_resumes(serial, tmp_path):
    """--compensate-blur with chunks: the compensated pass runs in chunks too (stored
    beside the first pass's), agreeing with the serial run within the IC-GN tolerance."""
    rec, _ = serial
    kw = {**KW, "compensate_blur": True}
    a = dicblur.track(rec, reference=6, **kw)
    store = tmp_path / "track.chunks"
    run = ChunkedRun(store=store, chunk_frames=8)
    b = dicblur.track(rec, reference=6, chunks=run, **kw)
    assert b.attrs["matcher"] == a.attrs["matcher"] != "plain"
    assert b.attrs["compensation_passes"] == a.attrs["compensation_passes"]
    np.testing.assert_array_equal(a["status"].values, b["status"].values)
    conv = a["status"].values == dicblur.PointStatus.CONVERGED
    for c in ("u", "v"):
        assert np.all(np.abs(a[c].values - b[c].values)[conv] < 2 * a.attrs["tolerance"])
    passes = int(b.attrs["compensation_passes"])
    assert (tmp_path / f"track.chunks-compensated-{passes}" / "store.json").is_file()
    again = ChunkedRun(store=store, chunk_frames=8)
    c = dicblur.track(rec, reference=6, chunks=again, **kw)
    assert again.summary["n_run"] == 0 and again.summary["compensated_n_run"] == 0
    for name in RAW:
        np.testing.assert_array_equal(c[name].values, b[name].values, err_msg=name)


@pytest.mark.slow  # two CLI runs in subprocesses
def test_killed_cli_run_resumes_to_the_uninterrupted_output(tmp_path):
    """SIGKILL a `dicblur track --chunk-frames 2` run once two chunks are stored; the same
    command again finishes it, and its track.nc equals an uninterrupted run's."""
    import signal
    import subprocess
    import sys
    import time

    import xarray as xr

    frames = tmp_path / "frames"
    _write_frames(frames, _target().recording(16), 16)

    def args(out):
        return [
            sys.executable, "-m", "dicblur", "track", str(frames), "--exposure", "0.4ms",
            "--fps", "2000", "--noise", "2", "--shape", "translation", "--step", "12",
            "--chunk-frames", "2", "--no-report", "-o", str(out),
        ]  # fmt: skip

    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    whole = subprocess.run(args(tmp_path / "whole"), env=env, capture_output=True, timeout=600)
    assert whole.returncode == 0, whole.stderr.decode()
    out = tmp_path / "killed"
    proc = subprocess.Popen(args(out), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 300
    while len(list((out / "track.chunks").glob("chunk-*.npz"))) < 2:
        assert proc.poll() is None and time.monotonic() < deadline, "run ended before the kill"
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    n_kept = len(list((out / "track.chunks").glob("chunk-*.npz")))
    assert 2 <= n_kept < 8 and not (out / "track.nc").exists()
    again = subprocess.run(args(out), env=env, capture_output=True, timeout=600)
    assert again.returncode == 0, again.stderr.decode()
    assert f"{8 - n_kept} run, {n_kept} resumed of 8" in again.stdout.decode()
    a = xr.open_dataset(tmp_path / "whole" / "track.nc", engine="scipy")
    b = xr.open_dataset(out / "track.nc", engine="scipy")
    for name in a.data_vars:
        np.testing.assert_array_equal(b[name].values, a[name].values, err_msg=name)
    a.close()
    b.close()


def test_cli_default_chunks_on_threads_and_serial_opt_out(tmp_path, capsys):
    """issue 17: on several cores `dicblur track` runs chunks of 100 frames on --threads
    threads by default (not stored); --chunk-frames 0 is the serial loop; bad values are
    refused before anything is written."""
    from dicblur.cli import main

    frames = tmp_path / "frames"
    _write_frames(frames, _target().recording(10), 10)
    base = [
        "track", str(frames), "--exposure", "0.4ms", "--fps", "2000", "--noise", "2",
        "--shape", "translation", "--step", "12", "--no-report",
    ]  # fmt: skip
    import xarray as xr

    assert main([*base, "--threads", "2", "-o", str(tmp_path / "a")]) == 0
    assert "1 run, 0 resumed of 1" in capsys.readouterr().out
    assert not (tmp_path / "a" / "track.chunks").exists()
    assert main([*base, "--threads", "2", "--chunk-frames", "0", "-o", str(tmp_path / "b")]) == 0
    assert main([*base, "--threads", "1", "-o", str(tmp_path / "c")]) == 0
    with (
        xr.open_dataset(tmp_path / "a" / "track.nc") as a,
        xr.open_dataset(tmp_path / "b" / "track.nc") as b,
        xr.open_dataset(tmp_path / "c" / "track.nc") as c,
    ):
        assert a.attrs["chunks_n_chunks"] == 1
        assert "chunks_n_chunks" not in b.attrs and "chunks_n_chunks" not in c.attrs
        # one chunk from the reference: the serial loop's frames, bit for bit
        for name in ("u", "v", "status"):
            np.testing.assert_array_equal(a[name].values, b[name].values)
            np.testing.assert_array_equal(b[name].values, c[name].values)
    capsys.readouterr()
    for bad, what in (
        (["--chunk-frames", "-1"], "--chunk-frames=-1"),
        (["--threads", "0"], "--threads=0"),
        (["--chunk-frames", "0", "--workers", "2"], "--chunk-frames 0"),
    ):
        out = tmp_path / "bad"
        assert main([*base, *bad, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert what in err and "Traceback" not in err
        assert not out.exists()


@pytest.mark.parametrize("threads", [1, 2])
def test_chunk_keeps_the_frames_before_a_bad_frame(tmp_path, threads):
    """A frame of another size in the middle of a chunk: the frames tracked before it in
    that chunk are kept (as in the serial loop; they were lost before), the other chunks
    run to their end whatever the threads (the chunks not yet started were dropped,
    so the frames kept varied with the scheduling), and the error names the frame."""
    import tifffile

    frames = tmp_path / "frames"
    _write_frames(frames, _target().recording(20), 20)
    tifffile.imwrite(frames / "f13.tif", np.zeros((96, 90), np.uint8))
    run = ChunkedRun(chunk_frames=5, threads=threads)
    with pytest.raises(TrackInterrupted, match="f13") as info:
        dicblur.track(str(frames), exposure="0.4ms", fps=2000, noise=2, chunks=run, **{
            k: v for k, v in KW.items() if k != "static"
        })  # fmt: skip
    ds = info.value.dataset
    got = set(ds["frame"].values.tolist())
    assert got == set(range(13)) | set(range(15, 20))
    assert int(ds.attrs["complete"]) == 0
    if threads == 1:
        # the serial loop's frames, as far as they go (chunk 0 starts at the reference)
        ser = dicblur.track(str(frames), exposure="0.4ms", fps=2000, noise=2, frames="0:13", **{
            k: v for k, v in KW.items() if k != "static"
        })  # fmt: skip
        first = ds.sel(frame=list(range(13)))
        np.testing.assert_array_equal(first["status"].values, ser["status"].values)
        assert np.nanmax(np.abs(first["u"].values - ser["u"].values)) < 2 * ser.attrs["tolerance"]


def test_blur_estimated_within_each_run_of_frames_around_a_gap(tmp_path):
    """Frames tracked with a gap (chunks resumed from a store on both sides of a chunk that
    met a bad frame): the blur and sigma are estimated within each run of consecutive
    frames (before, a gap anywhere left every frame without them)."""
    import tifffile

    frames = tmp_path / "frames"
    _write_frames(frames, _target().recording(20), 20)
    kw = {k: v for k, v in KW.items() if k != "static"}
    kw.update(exposure="0.4ms", fps=2000, noise=2)
    store = tmp_path / "track.chunks"
    full = dicblur.track(str(frames), chunks=ChunkedRun(store=store, chunk_frames=5), **kw)
    (store / "chunk-000002.npz").unlink()  # frames 10..14 run again, and meet a bad frame
    tifffile.imwrite(frames / "f12.tif", np.zeros((96, 90), np.uint8))
    with pytest.raises(TrackInterrupted, match="f12") as info:
        dicblur.track(str(frames), chunks=ChunkedRun(store=store, chunk_frames=5), **kw)
    ds = info.value.dataset
    got = ds["frame"].values
    assert set(got.tolist()) == set(range(12)) | set(range(15, 20))
    assert "separate runs" in ds.attrs["notes"]
    for run in (got < 12, got >= 15):
        ok = ds["status"].values[run] == dicblur.PointStatus.CONVERGED
        share = full["W"].sel(frame=got[run]).values[ok]
        assert np.isfinite(ds["W"].values[run][ok]).mean() > 0.8 * np.isfinite(share).mean()
        assert np.isfinite(ds["sigma_u"].values[run][ok]).mean() > 0.8
    # inside a run, away from its ends, the blur is the uninterrupted run's
    mid = (got >= 2) & (got <= 9)
    ref = full["W"].sel(frame=got[mid]).values
    np.testing.assert_allclose(ds["W"].values[mid], ref, rtol=1e-5, atol=1e-6)
