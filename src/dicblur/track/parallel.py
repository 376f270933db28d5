"""Tracking in chunks of frames: parallel on Dask (the campaign engine) and resumable.

Once its initial guesses are known a frame is independent of the others, so the recording
is split into chunks of consecutive frames (in tracking order: forwards from the reference,
then backwards). Each chunk starts the way the serial loop of :func:`~dicblur.track.track`
would reach it: it first tracks the (up to) three frames before it, the first of them from
the engine's FFT-CC start (global phase correlation, per-subset FFT-CC), so that its first
frame gets the same quadratic extrapolation the serial run uses. A chunk whose warm-up
reaches back to the reference frame is therefore bit-identical to the serial run; the
others agree with it within the IC-GN convergence tolerance, with the same statuses
(tests/test_track_parallel.py).

Every worker reads its frames itself from the recording's path (one at a time: bounded
memory); results come back to this process, which stores each finished chunk in a
:class:`~dicblur.campaign.ChunkStore` (lock, checksums, atomic writes), so a run that is
stopped (Ctrl-C, a crash, SIGKILL) continues from the finished chunks when run again with
the same settings. The kinematics, the sigma prediction and the exposure advice need the
whole track (the 5-frame trajectory fit crosses chunk boundaries), so they run afterwards
on all frames: the chunking changes nothing there.
"""

from __future__ import annotations

import hashlib
import os
import threading
import zlib
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arrays import BoolArray, Float64Array, Int64Array
from ..campaign import ChunkStore, run_tasks
from ..campaign.cluster import check_scheduler_address
from ..dic import Correlator, PointStatus
from ..dic.initial import window_spectrum
from ..errors import DicblurError, ImageReadError, InputError
from ..sequence import Recording, open_recording
from .compensate import PassStart, pass_frames
from .frames import correlate_frame, frame_gradients, frame_guess, poi_grid, seed_correlator

__all__ = [
    "HISTORY",
    "Chunk",
    "ChunkedRun",
    "CompensationChunk",
    "TrackJob",
    "compensate_chunk",
    "plan_chunks",
    "thread_safe_kernels",
    "track_chunk",
]

#: Frames of history the per-frame guess uses (quadratic extrapolation of the last three).
HISTORY = 3
#: Recordings a worker re-opens from their path.
_FILE_KINDS = ("folder", "tiff-stack", "cine", "mraw")


@dataclass(frozen=True)
class Chunk:
    """Frames tracked by one task.

    Attributes
    ----------
    index : int
        Chunk number (its file in the store).
    frames : tuple of int
        Frames whose results the chunk returns, in tracking order.
    warm : tuple of int
        Frames tracked before them (not returned) to rebuild the serial history.
    """

    index: int
    frames: tuple[int, ...]
    warm: tuple[int, ...]


@dataclass(frozen=True)
class CompensationChunk:
    """Frames of one task of the compensated pass, with their guesses and blur vectors
    (the previous pass's track of them, ``start``)."""

    index: int
    start: PassStart

    @property
    def frames(self) -> Int64Array:
        """The chunk's frames."""
        return self.start.frames


def plan_chunks(order: Sequence[int], reference: int, chunk_frames: int) -> list[Chunk]:
    """Split the tracking order of :func:`~dicblur.track.track` into chunks.

    ``order`` is the forward run ``reference, reference + 1, ...`` followed by the backward
    run ``reference - 1, reference - 2, ...`` (which the serial loop starts from the
    reference's field). Each chunk holds up to ``chunk_frames`` frames of one run and, as
    ``warm``, the up to :data:`HISTORY` frames before them in that run.
    """
    n = int(chunk_frames)
    if n < 1:
        raise InputError(f"chunk_frames={chunk_frames!r}: must be >= 1, e.g. 100")
    forward = [k for k in order if k >= reference]
    backward = [k for k in order if k < reference]
    out: list[Chunk] = []
    for run, first in ((forward, 0), ([reference, *backward], 1)):
        for p in range(first, len(run), n):
            out.append(
                Chunk(
                    index=len(out),
                    frames=tuple(run[p : p + n]),
                    warm=tuple(run[max(0, p - HISTORY) : p]),
                )
            )
    return out


@dataclass(frozen=True)
class TrackJob:
    """What every chunk of one recording shares (small: no frame in it).

    Attributes
    ----------
    source : str or Recording
        The recording's path (re-opened by each worker), or the lazy recording itself
        when it has no path (a synthetic one).
    n_frames : int
    shape : (rows, cols)
    reference : int
    correlator : dict
        Keyword arguments of :class:`~dicblur.Correlator` (``roi``, ``points``, ``subset``,
        ``step``, ``shape``, ``min_zncc``, ``workers``).
    ok0 : ndarray of bool, shape (n_points,)
        Points that can be correlated at all (from the reference frame's own result).
    key : str
        Hash of the above (a worker keeps one prepared Correlator per key).
    """

    source: Any
    n_frames: int
    shape: tuple[int, int]
    reference: int
    correlator: dict[str, Any]
    ok0: BoolArray
    key: str


# a worker process keeps the last job's recording and prepared Correlator (one per
# thread: ChunkedRun(threads=N) runs chunks on N threads of this process), keyed by
# "job key@thread id"
_PREPARED: dict[str, tuple[Recording, Correlator, Float64Array, Any]] = {}
# ... and the seed POIs of its Correlator (track.frames.seed_correlator)
_SEEDS: dict[str, Any] = {}
# in-process runs (ChunkedRun with neither workers nor scheduler): the caller's prepared
# Correlator, reference, its spectrum and seeds by job key, which each chunk thread forks
# (Correlator.fork) instead of preparing its own (~0.3 s per thread at 2,401 POIs)
_SHARED: dict[str, tuple[Correlator, Float64Array, Any, Any]] = {}
# recordings this module opened (closed when dropped)
_OPENED: set[int] = set()
# per recording this module opened: frame -> its non-finite pixels (filled when read)
_NON_FINITE: dict[int, dict[int, int]] = {}
# one reader at a time: a recording's frames are read by seek + read on one file handle
_READ = threading.Lock()
_PREPARE = threading.Lock()


def _key(job: TrackJob) -> str:
    return f"{job.key}@{threading.get_ident()}"


def _frame(rec: Recording, k: int) -> Float64Array:
    with _READ:
        return rec.frame(k)


def thread_safe_kernels() -> bool:
    """Whether the compiled kernels may run on several threads of this process at once:
    numba's threading layer is thread-safe (``omp`` or ``tbb``; ``workqueue`` aborts the
    process on concurrent calls). Call after a first correlation (the layer is chosen on
    the first parallel kernel call)."""
    import numba

    try:
        return str(numba.threading_layer()) in ("omp", "tbb")
    except ValueError:  # no parallel kernel has run yet
        return False


def _prepared(job: TrackJob) -> tuple[Recording, Correlator, Float64Array, Any]:
    got = _PREPARED.get(_key(job))
    if got is not None:
        return got
    with _PREPARE:
        _release(keep=job.key)
        if isinstance(job.source, str):
            # non-finite pixels filled, their count per frame kept for the chunk's result
            # (this process's track then fails the points they touch: track.nan_pixels)
            seen: dict[int, int] = {}
            rec = open_recording(job.source).with_non_finite_filled(
                lambda i, mask: seen.__setitem__(i, int(mask.sum()))
            )
            _NON_FINITE[id(rec)] = seen
            _OPENED.add(id(rec))
        else:
            rec = job.source
        if len(rec) != job.n_frames or tuple(rec.shape) != tuple(job.shape):
            raise ImageReadError(
                f"recording={rec.source!r}: re-opened by a worker it has {len(rec)} frames "
                f"of {rec.shape}, the run started with {job.n_frames} of {job.shape}; "
                "the recording changed during the run"
            )
        shared = _SHARED.get(job.key)
        if shared is not None:
            # the caller's Correlator (built with the same arguments but ``workers``)
            base, ref, spectrum, seeds = shared
            corr = base.fork(workers=job.correlator.get("workers"))
            got = (rec, corr, ref, spectrum)
            if seeds is not None:
                _SEEDS[_key(job)] = (seeds[0].fork(workers=corr.workers), seeds[1])
        else:
            ref = _frame(rec, job.reference)
            corr = Correlator(ref, **job.correlator)
            got = (rec, corr, ref, window_spectrum(ref))
        _PREPARED[_key(job)] = got
    return got


def _release(keep: str | None = None) -> None:
    """Drop the prepared jobs but ``keep`` (closing a recording this module opened)."""
    for key in list(_PREPARED):
        if keep is not None and key.split("@")[0] == keep:
            continue
        rec = _PREPARED.pop(key)[0]
        _SEEDS.pop(key, None)
        if id(rec) in _OPENED and not any(v[0] is rec for v in _PREPARED.values()):
            _OPENED.discard(id(rec))
            _NON_FINITE.pop(id(rec), None)
            rec.close()


def _release_own(rec: Recording) -> None:
    """Drop a job prepared in this process on ``rec`` (the caller's recording stays open)."""
    for key in list(_SHARED):
        if key.endswith(f"-{id(rec)}"):
            del _SHARED[key]
    for key in list(_PREPARED):
        if _PREPARED[key][0] is rec:
            del _PREPARED[key]
            _SEEDS.pop(key, None)


def track_chunk(job: TrackJob, chunk: Chunk) -> dict[str, NDArray[Any]]:
    """Track one chunk (the task a worker runs): its warm-up frames, then its frames.

    Returns
    -------
    dict
        ``frames`` (m,), ``u``, ``v``, ``zncc`` (m, n_points) float64, ``status`` (m,
        n_points) uint8, ``fallback`` (m,) bool: as the serial loop records them. When a
        frame cannot be read or tracked after some of the chunk's frames were, the frames
        before it (none, if it was the first) and ``error`` (the exception): nothing
        tracked is lost, as in the serial loop (:meth:`ChunkedRun.run` keeps them and
        runs the other chunks). A warm-up frame that cannot be read is skipped (the
        next frame starts from the engine's FFT-CC start).
    """
    rec, corr, ref, spectrum = _prepared(job)
    if _key(job) not in _SEEDS:
        _SEEDS[_key(job)] = seed_correlator(ref, corr, job.correlator)
    seeds = _SEEDS[_key(job)]
    n = corr.n_points
    m = len(chunk.frames)
    out: dict[str, Any] = {
        "frames": np.asarray(chunk.frames, np.int64),
        "u": np.empty((m, n)),
        "v": np.empty((m, n)),
        "zncc": np.empty((m, n)),
        "status": np.empty((m, n), np.uint8),
        "fallback": np.zeros(m, bool),
        "non_finite": np.zeros(m, np.int64),
    }
    seen = _NON_FINITE.get(id(rec), {})
    keep = {k: i for i, k in enumerate(chunk.frames)}
    grid = poi_grid(corr)
    base = np.zeros((n, 2))
    ones = np.ones(n, bool)
    # the serial loop's state (track.core.track): fields, rigid shifts, affine gradients
    hist: list[tuple[Float64Array, Float64Array]] = []
    rig: list[Float64Array | None] = []
    grads: Float64Array | None = None
    done = 0  # the chunk's frames finished, in order
    warm = set(chunk.warm)
    try:
        for k in (*chunk.warm, *chunk.frames):
            # one prefilter for the seeds, the frame and a fallback
            try:
                img = corr.prefilter(_frame(rec, k))
            except (DicblurError, OSError):
                if k not in warm:
                    raise
                # a bad frame in the warm-up (the one that stopped the chunk before this
                # one): the next frame starts afresh, as a chunk's first warm-up frame does
                hist, rig, grads = [], [], None
                continue
            guess, g_abs = frame_guess(
                hist, rig, img, spectrum, base, seeds, grid=grid, grads=grads
            )
            ok0 = ones if k == job.reference else job.ok0
            res, fb = correlate_frame(corr, img, guess, ok0, grads)
            u = np.asarray(res.u, np.float64) + base[:, 0]
            v = np.asarray(res.v, np.float64) + base[:, 1]
            good = res.status == PointStatus.CONVERGED
            hist.append((np.where(good, u, np.nan), np.where(good, v, np.nan)))
            del hist[:-HISTORY]
            rig.append(g_abs)
            del rig[:-HISTORY]
            grads = frame_gradients(res)
            i = keep.get(k)
            if i is not None:
                out["u"][i], out["v"][i] = u, v
                out["zncc"][i] = np.asarray(res.zncc, np.float64)
                out["status"][i] = np.asarray(res.status, np.uint8)
                out["fallback"][i] = bool(fb)
                out["non_finite"][i] = seen.get(k, 0)
                done = i + 1
    except (DicblurError, OSError) as exc:
        # even with no frame done: the run records the error and its other chunks go on
        part: dict[str, Any] = {key: a[:done] for key, a in out.items()}
        part["error"] = exc
        return part
    return out


def compensate_chunk(job: TrackJob, chunk: CompensationChunk) -> dict[str, Any]:
    """One chunk of the compensated pass (the task a worker runs)."""
    rec, corr, _, _ = _prepared(job)
    res = pass_frames(rec, corr, chunk.start, progress=None)
    res["n_zeroed"] = np.int64(res["n_zeroed"])
    res["max_groups"] = np.int64(res["max_groups"])
    return res


def _crc(a: NDArray[Any]) -> int:
    return zlib.crc32(np.ascontiguousarray(a).tobytes())


def _jsonable(v: Any) -> Any:
    if v is None or isinstance(v, bool | int | float | str):
        return v
    return np.asarray(v).tolist()


@dataclass
class ChunkedRun:
    """Run the correlation of :func:`~dicblur.track.track` in chunks of frames.

    Parameters
    ----------
    store : path, optional
        Folder of the finished chunks (a :class:`~dicblur.campaign.ChunkStore`); a run on
        an existing store with the same recording and settings continues from it. Without
        it nothing is kept between runs.
    workers : int, optional
        Processes of a local Dask cluster. With neither ``workers`` nor ``scheduler`` the
        chunks run in this process (resumable all the same): one after the other, or on
        ``threads`` threads.
    scheduler : str, optional
        Address of an existing Dask scheduler, ``tcp://HOST:PORT`` (its workers must see
        the recording at the same path).
    chunk_frames : int
        Frames per chunk (each chunk also tracks the :data:`HISTORY` frames before it).
    threads : int
        Without ``workers`` and ``scheduler``: threads of this process that track chunks
        at the same time, each with its own fork of the caller's Correlator
        (:meth:`~dicblur.Correlator.fork`: the prepared reference shared, read-only) on
        single-threaded kernels (the compiled kernels release the GIL). The results equal
        those of ``threads=1`` bit for bit (each chunk is computed alone either way). Falls
        back to one thread when numba's threading layer is not thread-safe
        (:func:`thread_safe_kernels`).

    Attributes
    ----------
    summary : dict
        After :meth:`run`: ``n_chunks``, ``n_resumed``, ``n_run``, ``workers``,
        ``scheduler``.

    Examples
    --------
    >>> import dicblur
    >>> from dicblur.track.parallel import ChunkedRun
    >>> ds = dicblur.track("frames/", fps=2000, exposure="0.2ms", noise=2,
    ...                    chunks=ChunkedRun(workers=2, store="out/track.chunks"))  # doctest: +SKIP
    """

    store: str | os.PathLike[str] | None = None
    workers: int | None = None
    scheduler: str | None = None
    chunk_frames: int = 100
    threads: int = 1
    summary: dict[str, Any] = field(default_factory=dict)
    _passes: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.workers is not None and (
            isinstance(self.workers, bool) or int(self.workers) != self.workers or self.workers < 1
        ):
            raise InputError(f"--workers={self.workers!r}: must be an integer >= 1, e.g. 2")
        if self.scheduler is not None:
            self.scheduler = check_scheduler_address(self.scheduler)
        if isinstance(self.chunk_frames, bool) or int(self.chunk_frames) < 1:
            raise InputError(f"--chunk-frames={self.chunk_frames!r}: must be >= 1, e.g. 100")
        self.chunk_frames = int(self.chunk_frames)
        if isinstance(self.threads, bool) or int(self.threads) != self.threads or self.threads < 1:
            raise InputError(f"threads={self.threads!r}: must be an integer >= 1, e.g. 2")
        self.threads = int(self.threads)

    @property
    def serial(self) -> bool:
        """Whether the chunks run in this process."""
        return self.workers is None and self.scheduler is None

    def run(
        self,
        rec: Recording,
        corr: Correlator,
        *,
        reference: int,
        order: list[int],
        correlator: dict[str, Any],
        progress: Callable[[int, int], None] | None,
    ) -> dict[str, Any]:
        """Track the frames of ``order`` (see :class:`~dicblur.track.frames.ChunkRunner`).

        ``corr`` is the Correlator of ``correlator`` on the ``reference`` frame (any
        ``workers``); in this process the chunk threads fork it (:meth:`Correlator.fork`)."""
        chunks = plan_chunks(order, reference, self.chunk_frames)
        self._passes = 0
        # the points that can be correlated at all: the reference frame's own result, as
        # the serial loop sets them
        ref_img = rec.frame(reference)
        first, _ = correlate_frame(corr, ref_img, None, np.ones(corr.n_points, bool))
        ok0 = ~np.isin(first.status, (PointStatus.LOW_TEXTURE, PointStatus.OUT_OF_BOUNDS))
        opts = dict(correlator)
        if not self.serial or self.threads > 1:
            opts["workers"] = 1  # one single-threaded process (thread) per core
        key = {
            "job": "dicblur track chunks",
            "source": os.path.abspath(rec.source) if rec.kind in _FILE_KINDS else rec.source,
            "kind": rec.kind,
            "n_frames": len(rec),
            "shape": list(rec.shape),
            "reference": reference,
            "reference_crc32": _crc(ref_img),
            "last_frame_crc32": _crc(rec.frame(max(order))),
            "order": [order[0], order[-1], len(order)],
            "chunk_frames": self.chunk_frames,
            "correlator": {k: _jsonable(v) for k, v in correlator.items() if k != "workers"},
        }
        job = self._job(rec, key, reference=reference, correlator=opts, ok0=ok0)
        if self.serial:
            # in this process: the chunk threads fork ``corr`` and the seeds made from it
            # (dropped after the run, _release_own)
            _SHARED[job.key] = (
                corr,
                ref_img,
                window_spectrum(ref_img),
                seed_correlator(ref_img, corr, opts),
            )
        results, error, self.summary = self._execute(
            rec,
            track_chunk,
            chunks,
            job,
            key=key,
            store=None if self.store is None else Path(self.store),
            total=len(order),
            progress=progress,
            threads=self.threads,
        )
        got: dict[str, Any] = {
            k: [] for k in ("frames", "u", "v", "zncc", "status", "fallback", "non_finite")
        }
        for c in chunks:
            res = results.get(c.index)
            if res is None:
                continue
            for j in range(len(res["frames"])):
                got["frames"].append(int(res["frames"][j]))
                got["u"].append(res["u"][j])
                got["v"].append(res["v"][j])
                got["zncc"].append(res["zncc"][j])
                got["status"].append(res["status"][j])
                got["fallback"].append(bool(res["fallback"][j]))
                # non-finite pixels a worker filled (0: none, or a store of an earlier version)
                got["non_finite"].append(int(res["non_finite"][j]) if "non_finite" in res else 0)
        got["error"] = error
        return got

    def _job(
        self,
        rec: Recording,
        key: dict[str, Any],
        *,
        reference: int,
        correlator: dict[str, Any],
        ok0: BoolArray,
    ) -> TrackJob:
        """The :class:`TrackJob` of ``rec`` whose store key is ``key``."""
        # a worker re-opens a file recording from its path; in this process, or without a
        # path (a synthetic recording: lazy, no frame in it), the recording itself is used
        source: Any = (
            os.path.abspath(rec.source) if rec.kind in _FILE_KINDS and not self.serial else rec
        )
        return TrackJob(
            source=source,
            n_frames=len(rec),
            shape=(int(rec.shape[0]), int(rec.shape[1])),
            reference=reference,
            correlator=correlator,
            ok0=ok0,
            key=hashlib.sha256(repr(sorted(key.items())).encode()).hexdigest()
            + ("" if isinstance(source, str) else f"-{id(rec)}"),
        )

    def _execute(
        self,
        rec: Recording,
        task: Callable[..., dict[str, Any]],
        chunks: Sequence[Any],
        job: Any,
        *,
        key: dict[str, Any],
        store: Path | None,
        total: int,
        progress: Callable[[int, int], None] | None,
        threads: int = 1,
    ) -> tuple[dict[int, dict[str, Any]], BaseException | None, dict[str, Any]]:
        """Run the chunks not yet in ``store`` through the campaign engine (in this
        process on ``threads`` threads when serial), storing each as it finishes; returns
        the results by chunk index, the exception that stopped the run (a
        ``KeyboardInterrupt`` for Ctrl-C) and the run's summary."""
        results: dict[int, dict[str, Any]] = {}
        error: BaseException | None = None
        summary = None
        store_cm: Any = (
            ChunkStore(store, key=key, n_chunks=len(chunks)) if store is not None else nullcontext()
        )
        with store_cm as st:
            if st is not None:
                for i in sorted(st.done()):
                    results[i] = st.read(i)
            n_resumed = len(results)
            pending = [c for c in chunks if c.index not in results]
            done_frames = [sum(len(chunks[i].frames) for i in results)]
            if progress is not None:
                progress(done_frames[0], total)

            failures: list[tuple[int, BaseException]] = []

            def finish(chunk: Any, res: dict[str, Any]) -> None:
                failed = res.pop("error", None)
                if failed is not None:
                    # the frames of a chunk before a bad frame: kept, not stored (the
                    # chunk is not finished); the other chunks still run, so the frames
                    # kept do not depend on which chunks happened to be running (they
                    # did: on threads or workers the chunks not started were dropped)
                    results[chunk.index] = res
                    failures.append((chunk.index, failed))
                    done_frames[0] += len(res["frames"])
                    if progress is not None:
                        progress(done_frames[0], total)
                    return
                if st is not None:
                    st.write(chunk.index, res)
                results[chunk.index] = res
                done_frames[0] += len(chunk.frames)
                if progress is not None:
                    progress(done_frames[0], total)

            try:
                summary = run_tasks(
                    task,
                    pending,
                    finish,
                    args=lambda c, shared: (shared["job"], c),
                    shared={"job": job},
                    serial=self.serial,
                    scheduler=self.scheduler,
                    workers=self.workers,
                    name="track-chunk",
                    threads=threads if self.serial and thread_safe_kernels() else 1,
                )
            except (DicblurError, OSError, MemoryError) as exc:
                error = exc
            finally:
                if self.serial:
                    _release_own(rec)
            if summary is not None and summary.interrupted:
                error = KeyboardInterrupt()
            if error is None and failures:
                error = min(failures, key=lambda f: f[0])[1]  # the first in the order
        stats = {
            "n_chunks": len(chunks),
            "n_resumed": n_resumed,
            "n_run": len(results) - n_resumed,
            "workers": 1 if summary is None else summary.workers,
            "scheduler": "serial" if summary is None else summary.scheduler,
            "chunk_frames": self.chunk_frames,
            "threads": threads if summary is not None and summary.scheduler == "threads" else 1,
        }
        return results, error, stats

    def compensate(
        self,
        rec: Recording,
        start: PassStart,
        *,
        reference: int,
        correlator: dict[str, Any],
        progress: Callable[[int, int], None] | None,
    ) -> dict[str, Any]:
        """:func:`.compensate.compensated_pass` in chunks (stored beside :attr:`store` as
        ``<store>-compensated-N``, N the pass, its key holding a checksum of the inputs).

        Raises
        ------
        KeyboardInterrupt, DicblurError
            When a chunk fails or the run is interrupted (the finished chunks are kept).
        """
        self._passes += 1
        n = self.chunk_frames
        frames = start.frames
        chunks = [
            CompensationChunk(index=j, start=start.rows(a, a + n))
            for j, a in enumerate(range(0, len(frames), n))
        ]
        opts = dict(correlator)
        if not self.serial:
            opts["workers"] = 1
        inputs = zlib.crc32(
            b"".join(
                _crc(a).to_bytes(4, "little")
                for a in (start.u, start.v, start.blur_u, start.blur_v, start.status)
            )
        )
        key = {
            "job": "dicblur track compensated pass",
            "pass": self._passes,
            "source": os.path.abspath(rec.source) if rec.kind in _FILE_KINDS else rec.source,
            "n_frames": len(rec),
            "shape": list(rec.shape),
            "reference": reference,
            "frames": [int(frames[0]), int(frames[-1]), len(frames)],
            "inputs_crc32": inputs,
            "chunk_frames": n,
            "correlator": {k: _jsonable(x) for k, x in correlator.items() if k != "workers"},
        }
        opts["blur"] = "given"
        job = self._job(rec, key, reference=reference, correlator=opts, ok0=np.ones(0, bool))
        store = (
            None
            if self.store is None
            else Path(self.store).with_name(f"{Path(self.store).name}-compensated-{self._passes}")
        )
        results, error, stats = self._execute(
            rec, compensate_chunk, chunks, job, key=key, store=store, total=len(frames),
            progress=progress,
        )  # fmt: skip
        self.summary.update({f"compensated_{k}": x for k, x in stats.items() if k.startswith("n_")})
        if error is not None:
            raise error
        out: dict[str, Any] = {
            k: np.concatenate([results[c.index][k] for c in chunks])
            for k in ("u", "v", "zncc", "status")
        }
        out["n_zeroed"] = int(sum(int(results[c.index]["n_zeroed"]) for c in chunks))
        out["max_groups"] = int(max(int(results[c.index]["max_groups"]) for c in chunks))
        return out
