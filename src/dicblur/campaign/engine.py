"""Campaign runner: executes the pending batches of a campaign and stores them as they finish.

The runner is independent of what a task computes: a *task function*
``task(image, batch, spec) -> {variable: ndarray (len(batch.blur),)}`` is called once per
batch (default :func:`dicblur.campaign.simulate_batch`). Execution is serial (in this
process) or on Dask: a :class:`distributed.LocalCluster` of worker processes by default,
or an existing cluster given by its scheduler address. Results are written by this
process only (one writer), batch by batch, in completion order.
"""

from __future__ import annotations

import logging
import os
import re
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .lock import StoreLock, lock_holder
from .spec import CampaignSpec, load_spec
from .store import CampaignStore, half_created
from .tasks import Batch, input_hashes, iter_batches, make_pattern

logger = logging.getLogger(__name__)

__all__ = [
    "CampaignStatus",
    "RunSummary",
    "TaskFunction",
    "TasksSummary",
    "campaign_status",
    "check_scheduler_address",
    "run_campaign",
    "run_tasks",
]


TaskFunction = Callable[[NDArray[np.float64], Batch, CampaignSpec], Mapping[str, Any]]
ProgressCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class RunSummary:
    """What a call of :func:`run_campaign` did.

    Attributes
    ----------
    path : str
        Results store.
    n_tasks : int
        Tasks in the campaign.
    n_skipped : int
        Tasks already stored before this run (resumed).
    n_run : int
        Tasks computed and stored by this run.
    interrupted : bool
        True if the run was stopped (Ctrl-C) before finishing; what finished is stored.
    wall_s : float
        Wall time of the run (s), cluster start-up and pattern preparation included.
    setup_s : float
        Part of ``wall_s`` before the first task could start (patterns, store, cluster
        start-up, image upload to the workers).
    compute_s : float
        Part of ``wall_s`` from the first task's start to the last batch stored (the
        rest is set-up and the cluster's shutdown).
    task_s : float
        Sum of the tasks' own wall times (s) on their workers.
    task_cpu_s : float
        Sum of the CPU time (s) of the worker processes inside the task function: against
        ``task_s`` it shows how much the workers were slowed by sharing the cores.
    workers : int
        Number of worker processes (1 for serial).
    scheduler : str
        ``"serial"``, ``"local"`` or the scheduler address.
    """

    path: str
    n_tasks: int
    n_skipped: int
    n_run: int
    interrupted: bool
    wall_s: float
    setup_s: float
    compute_s: float
    task_s: float
    task_cpu_s: float
    workers: int
    scheduler: str

    @property
    def complete(self) -> bool:
        """Whether every task of the campaign is now stored."""
        return self.n_skipped + self.n_run == self.n_tasks


def _timed_task(
    fn: TaskFunction, image: NDArray[np.float64], batch: Batch, spec: CampaignSpec
) -> dict[str, Any]:
    """Call the task function and add its process CPU time (s) as ``"_cpu_s"``."""
    t = time.process_time()
    out = dict(fn(image, batch, spec))
    out["_cpu_s"] = time.process_time() - t
    return out


_ADDRESS = re.compile(
    r"^(?:(?:tcp|tls|ucx|ws|wss)://)?(?:\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+)"
    r":\d{1,5}/?$|^inproc://\S+$"
)


def check_scheduler_address(address: str) -> str:
    """Check the form of a Dask scheduler address (``tcp://HOST:PORT``) before connecting.

    Raises
    ------
    InputError
        If ``address`` is not ``[tcp|tls|ucx|ws|wss://]HOST:PORT`` or ``inproc://...``.
    """
    if not isinstance(address, str) or not _ADDRESS.match(address.strip()):
        raise InputError(
            f"scheduler={address!r}: not a Dask scheduler address; give "
            "tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786 (or omit it for a "
            "local cluster)"
        )
    return address.strip()


def _default_task() -> TaskFunction:
    from .simulate import simulate_batch

    return simulate_batch


def _prepare(spec: CampaignSpec, results: Path) -> tuple[CampaignStore, dict[str, Any]]:
    """Open (or create) the store; the caller holds its lock."""
    images = {p.name: make_pattern(spec, p) for p in spec.patterns}
    hashes = input_hashes(spec, images)
    if half_created(results):
        # Left by an interrupted creation of an older dicblur; it holds no task.
        logger.warning(
            "results=%r: removing a half-created store (no finished task) and creating it again",
            str(results),
        )
        import shutil

        shutil.rmtree(results)
    if results.exists():
        store = CampaignStore.open(results)
        store.check_matches(spec, hashes)
    else:
        store = CampaignStore.create(results, spec, hashes)
    return store, images


def run_campaign(
    spec: CampaignSpec | str | os.PathLike[str],
    results: str | os.PathLike[str],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    serial: bool = False,
    task: TaskFunction | None = None,
    progress: ProgressCallback | None = None,
    connect_timeout: float = 10.0,
) -> RunSummary:
    """Run (or resume) a campaign and store its results.

    Parameters
    ----------
    spec : CampaignSpec or path
        The campaign, or its TOML file.
    results : path
        Zarr store. Created if absent; if present, it must hold the same campaign (same
        spec hash and input images) and only its unfinished tasks are run.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``). Default: a local
        cluster of worker processes on this machine.
    workers : int, optional
        Worker processes of the local cluster (default: all cores). Ignored with
        ``scheduler``.
    serial : bool
        Run every batch in this process, without Dask (the reference for tests).
    task : callable, optional
        ``task(image, batch, spec) -> {variable: (len(batch.blur),) array}``; default
        :func:`dicblur.campaign.simulate_batch`. Must be importable by the workers. If it
        has a ``warm_up`` attribute (a callable without arguments), Dask workers run it
        once at start-up (e.g. to load compiled kernels).
    progress : callable, optional
        ``progress(done, total)`` in tasks, called at the start and after every batch.
    connect_timeout : float
        Seconds to wait for the scheduler given by ``scheduler``.

    Returns
    -------
    RunSummary

    Raises
    ------
    ConfigError, StoreError
        On a bad spec, a store holding another campaign, a damaged store or a store that
        another run is using (its lock, see :mod:`dicblur.campaign.lock`), before any
        task runs. An exception raised by a task is re-raised after the batches already
        finished are stored.

    Notes
    -----
    ``KeyboardInterrupt`` (Ctrl-C) during the run cancels the pending tasks, shuts the
    local cluster down and returns a summary with ``interrupted=True``; every batch
    finished before is stored and is skipped by the next run. Finished tasks whose stored
    chunks are damaged (see :meth:`CampaignStore.scan`) are recomputed.
    """
    t0 = time.perf_counter()
    if scheduler is not None and not serial:
        check_scheduler_address(scheduler)
    from ..io import check_output

    # the one output rule (docs/reliability.md): the store folder may be created, its
    # parent must exist
    path = check_output(results, "results", folder=True)
    if not isinstance(spec, CampaignSpec):
        spec = load_spec(spec)
    with StoreLock(path):
        return _run_locked(
            spec,
            path,
            t0,
            scheduler=scheduler,
            workers=workers,
            serial=serial,
            task=task,
            progress=progress,
            connect_timeout=connect_timeout,
        )


def _run_locked(
    spec: CampaignSpec,
    path: Path,
    t0: float,
    *,
    scheduler: str | None,
    workers: int | None,
    serial: bool,
    task: TaskFunction | None,
    progress: ProgressCallback | None,
    connect_timeout: float,
) -> RunSummary:
    store, images = _prepare(spec, path)
    fn = task if task is not None else _default_task()
    if task is None:
        _compile_kernels_first(spec.dic_shape)
    mask = store.done_mask()
    pending = [b for b in iter_batches(spec) if not mask[b.region].all()]
    n_total = spec.n_tasks
    n_skipped = int(mask.sum())
    # A batch partially marked done (impossible with this writer, possible in a store
    # edited by hand) is rerun whole; count its finished tasks as rerun, not skipped.
    n_skipped -= sum(int(mask[b.region].sum()) for b in pending)
    counts = {"done": n_skipped, "run": 0}
    task_s = [0.0, 0.0]
    started = [time.perf_counter()]
    finished = [0.0]
    if progress is not None:
        progress(counts["done"], n_total)

    def finish(batch: Batch, result: Mapping[str, Any]) -> None:
        store.write_batch(batch, result)
        counts["done"] += len(batch.blur)
        counts["run"] += len(batch.blur)
        task_s[0] += float(np.sum(result["time_s"]))
        task_s[1] += float(result.get("_cpu_s", 0.0))
        finished[0] = time.perf_counter()
        if progress is not None:
            progress(counts["done"], n_total)

    interrupted = False
    if serial or not pending:
        n_workers, where = 1, "serial"
        started[0] = time.perf_counter()
        try:
            for b in pending:
                finish(b, _timed_task(fn, images[b.pattern], b, spec))
        except KeyboardInterrupt:
            interrupted = True
    else:
        n_workers, where, interrupted = _run_dask(
            spec,
            images,
            pending,
            fn,
            finish,
            scheduler=scheduler,
            workers=workers,
            connect_timeout=connect_timeout,
            started=started,
        )
    return RunSummary(
        path=str(path),
        n_tasks=n_total,
        n_skipped=n_skipped,
        n_run=counts["run"],
        interrupted=interrupted,
        wall_s=time.perf_counter() - t0,
        setup_s=started[0] - t0,
        compute_s=max(0.0, finished[0] - started[0]),
        task_s=task_s[0],
        task_cpu_s=task_s[1],
        workers=n_workers,
        scheduler=where,
    )


def _compile_kernels_first(shape: str) -> None:
    """Compile a cold numba cache in a subprocess before the tasks, so that every process
    (this one, the workers, a later resume) runs the same cached kernels: bit-identical
    results however the campaign is interrupted (:func:`dicblur.dic.cache.compile_kernels`).

    Ctrl-C meanwhile is a flag (numba's cache look-up could swallow a KeyboardInterrupt),
    raised as ``KeyboardInterrupt`` once the step is over. If the subprocess fails the
    kernels compile in this process as before (results correct, a resume on another cold
    cache may then differ in the last bits), with a warning.
    """
    import subprocess

    from ..dic.cache import compile_kernels

    with _Interrupt() as interrupt:
        try:
            compile_kernels((shape,))
        except (subprocess.SubprocessError, OSError) as exc:
            if not interrupt.flag:
                logger.warning(
                    "compiling the DIC kernels in a subprocess failed (%s); they "
                    "compile in this process",
                    type(exc).__name__,
                )
    interrupt.check()


class _Interrupt:
    """Ctrl-C during a Dask run, turned into a flag checked at safe points.

    A ``KeyboardInterrupt`` raised at an arbitrary point inside distributed (a cluster half
    started, a comm half closed) leaves it in a state whose clean-up prints tracebacks
    (``AssertionError: Status.init`` from an atexit hook, ``CommClosedError``). Instead,
    SIGINT sets a flag; the runner polls it between steps and then shuts down in order.
    The local cluster's worker processes start with SIGINT ignored
    (:func:`_spawn_ignoring_sigint`): a terminal's Ctrl-C goes to the whole process group,
    and the parent alone must handle it.
    """

    def __init__(self) -> None:
        self.flag = False
        self._old: Any = None

    def _handler(self, signum: int, frame: Any) -> None:
        self.flag = True

    def __enter__(self) -> _Interrupt:
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc: object) -> None:
        import signal

        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if Ctrl-C was pressed."""
        if self.flag:
            raise KeyboardInterrupt


@contextmanager
def _spawn_ignoring_sigint() -> Iterator[None]:
    """Processes spawned by :mod:`multiprocessing` inside the block start with SIGINT
    ignored (so Python installs no ``KeyboardInterrupt`` handler in them).

    An ignored signal is the one disposition that survives ``exec``; a signal mask does not
    (``_posixsubprocess`` resets it) and ignoring SIGINT here would lose the user's Ctrl-C.
    So the spawn executable is, for the block's duration, a two-line ``/bin/sh`` wrapper
    (``trap '' INT; exec python "$@"``). Falls back to the plain interpreter where the
    wrapper cannot run (no /bin/sh, a noexec temporary folder).
    """
    import multiprocessing.spawn as mp_spawn
    import shlex
    import shutil
    import subprocess
    import tempfile

    exe = mp_spawn.get_executable()
    if os.name != "posix" or not os.path.exists("/bin/sh") or not exe:
        yield
        return
    folder = tempfile.mkdtemp(prefix="dicblur-spawn-")
    try:
        wrapper = os.path.join(folder, "python")
        with open(wrapper, "w", encoding="utf-8") as fh:
            fh.write(f"#!/bin/sh\ntrap '' INT\nexec {shlex.quote(os.fsdecode(exe))} \"$@\"\n")
        os.chmod(wrapper, 0o755)
        try:
            ok = (
                subprocess.run(
                    [wrapper, "-I", "-S", "-c", "pass"], timeout=60, capture_output=True
                ).returncode
                == 0
            )
        except (OSError, subprocess.SubprocessError):
            ok = False
        if not ok:
            yield
            return
        mp_spawn.set_executable(wrapper)
        try:
            yield
        finally:
            mp_spawn.set_executable(exe)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@contextmanager
def _quiet_distributed() -> Iterator[None]:
    """Silence distributed's (and tornado's, asyncio's) loggers in this process: a shutdown
    while comms are still open logs ``CommClosedError`` tracebacks that mean nothing to
    the user."""
    names = [
        n
        for n in list(logging.root.manager.loggerDict)
        if n.split(".")[0] in ("distributed", "tornado", "asyncio")
    ]
    names += ["distributed", "tornado", "asyncio"]
    saved = {n: (logging.getLogger(n).level, logging.getLogger(n).disabled) for n in names}
    for n in names:
        logging.getLogger(n).disabled = True
    try:
        yield
    finally:
        for n, (level, disabled) in saved.items():
            logging.getLogger(n).setLevel(level)
            logging.getLogger(n).disabled = disabled


def _wait_all(futures: list[Any], interrupt: _Interrupt) -> None:
    """Wait for futures (re-raising a task's exception), polling for Ctrl-C."""
    from distributed import wait

    while True:
        interrupt.check()
        try:
            wait(futures, timeout=0.1)
        except TimeoutError:
            continue
        for f in futures:
            f.result()
        return


def _run_dask(
    spec: CampaignSpec,
    images: Mapping[str, NDArray[np.float64]],
    pending: list[Batch],
    fn: TaskFunction,
    finish: Callable[[Batch, Mapping[str, Any]], None],
    *,
    scheduler: str | None,
    workers: int | None,
    connect_timeout: float,
    started: list[float],
) -> tuple[int, str, bool]:
    # Larger blur costs more DIC iterations: start the batches of large W first
    # (longest-first scheduling shortens the idle tail of the last workers).
    return _map_dask(
        _timed_task,
        pending,
        lambda b, remote: (fn, remote[b.pattern], b, spec),
        finish,
        shared=images,
        priority=lambda b: int(b.loc[5]),
        key=lambda b: f"dicblur-batch-{b.index}",
        warm_up=getattr(fn, "warm_up", None),
        scheduler=scheduler,
        workers=workers,
        connect_timeout=connect_timeout,
        started=started,
    )


@dataclass(frozen=True)
class TasksSummary:
    """What a call of :func:`run_tasks` did.

    Attributes
    ----------
    n_run : int
        Tasks finished (their ``finish`` called).
    interrupted : bool
        True if Ctrl-C stopped the run; the tasks finished before were passed to ``finish``.
    workers : int
        Worker processes (1 for serial).
    scheduler : str
        ``"serial"``, ``"local"`` or the scheduler address.
    wall_s : float
        Wall time (s), cluster start-up included.
    """

    n_run: int
    interrupted: bool
    workers: int
    scheduler: str
    wall_s: float


def run_tasks(
    func: Callable[..., Any],
    items: Sequence[Any],
    finish: Callable[[Any, Any], None],
    *,
    args: Callable[[Any, Mapping[str, Any]], tuple[Any, ...]] | None = None,
    shared: Mapping[str, Any] | None = None,
    serial: bool = False,
    scheduler: str | None = None,
    workers: int | None = None,
    priority: Callable[[Any], int] | None = None,
    warm_up: Callable[[], Any] | None = None,
    name: str = "task",
    connect_timeout: float = 10.0,
    threads: int = 1,
) -> TasksSummary:
    """Run independent tasks serially or on Dask (the campaign engine's machinery), handing
    each result to ``finish`` in this process, in completion order (one writer).

    Parameters
    ----------
    func : callable
        Module-level (importable by the workers); called as ``func(*args(item, shared))``.
    items : sequence
        One task each (picklable).
    finish : callable(item, result)
        Called in this process as each task finishes (e.g. to store its result).
    args : callable(item, shared) -> tuple, optional
        Arguments of ``func`` for ``item``; ``shared`` maps the names of ``shared`` to the
        objects (serial) or to their copies already on the workers (Dask: each travels to
        every worker once). Default ``(item,)``.
    shared : mapping, optional
        Large objects every task needs.
    serial : bool
        Run in this process, without Dask.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``); default a local
        cluster of ``workers`` single-threaded processes.
    workers : int, optional
        Processes of the local cluster (default all cores).
    priority : callable(item) -> int, optional
        Higher starts first.
    warm_up : callable, optional
        Run once on every worker before the tasks (e.g. loading compiled kernels).
    name : str
        Prefix of the Dask task keys.
    connect_timeout : float
        Seconds to wait for ``scheduler``.
    threads : int
        With ``serial``: run the tasks on this many threads of this process (``func``
        must be thread-safe and release the GIL for this to pay, e.g. ``nogil`` compiled
        kernels); results still reach ``finish`` in this thread, in completion order.

    Returns
    -------
    TasksSummary

    Notes
    -----
    Ctrl-C cancels the pending tasks, shuts the local cluster down and returns with
    ``interrupted=True``; so does a ``KeyboardInterrupt`` raised by ``finish``. A task's
    exception is re-raised after the results finished before it were passed to ``finish``.
    """
    t0 = time.perf_counter()
    if scheduler is not None and not serial:
        check_scheduler_address(scheduler)
    call_args = args if args is not None else (lambda item, _shared: (item,))
    share = dict(shared or {})
    count = [0]

    def done(item: Any, result: Any) -> None:
        finish(item, result)
        count[0] += 1

    if (serial or not items) and threads > 1 and len(items) > 1:
        interrupted = _map_threads(func, list(items), call_args, done, share, threads)
        return TasksSummary(count[0], interrupted, 1, "threads", time.perf_counter() - t0)
    if serial or not items:
        interrupted = False
        try:
            for it in items:
                done(it, func(*call_args(it, share)))
        except KeyboardInterrupt:
            interrupted = True
        return TasksSummary(count[0], interrupted, 1, "serial", time.perf_counter() - t0)
    n_workers, where, interrupted = _map_dask(
        func,
        list(items),
        call_args,
        done,
        shared=share,
        priority=priority,
        key=lambda it: f"dicblur-{name}",
        warm_up=warm_up,
        scheduler=scheduler,
        workers=workers,
        connect_timeout=connect_timeout,
        started=[0.0],
    )
    return TasksSummary(count[0], interrupted, n_workers, where, time.perf_counter() - t0)


def _map_threads(
    func: Callable[..., Any],
    items: list[Any],
    args: Callable[[Any, Mapping[str, Any]], tuple[Any, ...]],
    finish: Callable[[Any, Any], None],
    shared: Mapping[str, Any],
    threads: int,
) -> bool:
    """:func:`run_tasks` on ``threads`` threads of this process; returns whether Ctrl-C
    stopped it (the pending tasks are cancelled, the running ones finish first). A task's
    exception, or one raised by ``finish``, is re-raised once the tasks running beside it
    have finished and been passed to ``finish``."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    pool = ThreadPoolExecutor(max_workers=int(threads), thread_name_prefix="dicblur-task")
    futures = {pool.submit(func, *args(it, shared)): it for it in items}
    pending = set(futures)
    error: BaseException | None = None
    interrupted = False
    try:
        while pending:
            done_now, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            for fut in sorted(done_now, key=lambda f: items.index(futures[f])):
                exc = fut.exception()
                if exc is None:
                    exc = _finish_or_error(finish, futures[fut], fut.result())
                if exc is not None:
                    error = error or exc
            if error is not None:
                for fut in pending:
                    fut.cancel()
                rest = [f for f in pending if not f.cancelled()]
                for fut in wait(rest)[0]:
                    if fut.exception() is None:
                        _finish_or_error(finish, futures[fut], fut.result())
                pending = set()
    except KeyboardInterrupt:
        interrupted = True
        for fut in pending:
            fut.cancel()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    if error is not None:
        raise error
    return interrupted


def _finish_or_error(
    finish: Callable[[Any, Any], None], item: Any, result: Any
) -> Exception | None:
    """``finish(item, result)``, returning the exception it raised (a KeyboardInterrupt
    propagates): an error raised while passing a result on stops the run as the task's
    own error would, once the tasks running beside it are passed on too."""
    try:
        finish(item, result)
    except Exception as exc:
        return exc
    return None


def _map_dask(
    func: Callable[..., Any],
    items: list[Any],
    args: Callable[[Any, Mapping[str, Any]], tuple[Any, ...]],
    finish: Callable[[Any, Any], None],
    *,
    shared: Mapping[str, Any],
    priority: Callable[[Any], int] | None,
    key: Callable[[Any], str],
    warm_up: Callable[[], Any] | None,
    scheduler: str | None,
    workers: int | None,
    connect_timeout: float,
    started: list[float],
) -> tuple[int, str, bool]:
    import dask
    from distributed import Client, LocalCluster, as_completed

    n_workers = 0
    interrupted = False
    futures: list[Any] = []
    cluster = client = None
    with _Interrupt() as interrupt:
        try:
            if scheduler is None:
                n = int(workers) if workers is not None else (os.cpu_count() or 1)
                if n < 1:
                    raise InputError(f"workers={workers!r}: must be >= 1 (or omit it: all cores)")
                # One single-threaded process per core: the tasks are CPU-bound
                # numpy/numba code (the Correlator runs with workers=1 inside a task), so
                # processes avoid the GIL. Dask sets MALLOC_TRIM_THRESHOLD_ in its workers,
                # which disables glibc's dynamic mmap threshold: every large temporary
                # array (a 512^2 image is 2 MiB) is then a fresh mmap with page faults,
                # ~25% more CPU per task here. Keep the thread limits, drop that one.
                env = {
                    k: v
                    for k, v in dask.config.get("distributed.nanny.pre-spawn-environ", {}).items()
                    if k != "MALLOC_TRIM_THRESHOLD_"
                }
                with (
                    dask.config.set({"distributed.nanny.pre-spawn-environ": env}),
                    _spawn_ignoring_sigint(),
                ):
                    cluster = LocalCluster(
                        n_workers=n,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=":0",
                        silence_logs=logging.CRITICAL,
                    )
                client = Client(cluster)
                where = "local"
            else:
                try:
                    client = Client(scheduler, timeout=f"{connect_timeout}s")
                except (OSError, TimeoutError) as exc:
                    raise InputError(
                        f"scheduler={scheduler!r}: cannot connect to a Dask "
                        f"scheduler ({exc}); check the address "
                        "(tcp://HOST:PORT) and that it runs"
                    ) from exc
                where = scheduler
            interrupt.check()
            info = client.scheduler_info(n_workers=-1).get("workers", {})
            n_workers = max(1, len(info))
            # Load the task's compiled code (numba cache) on every worker at once, as part
            # of the start-up, rather than inside each worker's first task. A task per
            # worker (not client.run), so that Ctrl-C can interrupt a long compilation.
            if callable(warm_up):
                _wait_all(
                    [
                        client.submit(
                            warm_up,
                            workers=[addr],
                            allow_other_workers=False,
                            pure=False,
                            key=f"dicblur-warm-up-{i}-{os.urandom(4).hex()}",
                        )
                        for i, addr in enumerate(info)
                    ],
                    interrupt,
                )
            # Each shared object travels to every worker once, not once per task.
            remote = {
                name: client.scatter(obj, broadcast=True, hash=False)
                for name, obj in shared.items()
            }
            interrupt.check()
            started[0] = time.perf_counter()
            by_key: dict[Any, Any] = {}
            for i, it in enumerate(items):
                fut = client.submit(
                    func,
                    *args(it, remote),
                    pure=False,
                    priority=0 if priority is None else priority(it),
                    key=f"{key(it)}-{i}-{os.urandom(4).hex()}",
                )
                by_key[fut.key] = it
                futures.append(fut)
            ready = as_completed(futures)
            while not ready.is_empty():
                interrupt.check()
                batch = ready.next_batch(block=False)
                if not batch:
                    time.sleep(0.02)  # a signal sets the flag; sleep resumes (PEP 475)
                for fut in batch:
                    finish(by_key[fut.key], fut.result())
        except KeyboardInterrupt:
            interrupted = True
        finally:
            # In order, quietly: drop the pending tasks, disconnect, stop the workers.
            with _quiet_distributed():
                try:
                    if client is not None:
                        client.cancel(futures)
                        client.close()
                finally:
                    if cluster is not None:
                        cluster.close()
    return n_workers, where, interrupted


@dataclass(frozen=True)
class CampaignStatus:
    """Progress of a stored campaign (see :func:`campaign_status`).

    ``n_done`` counts the finished tasks (flagged done and verified against their
    checksums); ``n_damaged`` the tasks flagged done whose stored chunks are missing,
    truncated or altered (a rerun recomputes them); ``running`` describes the run holding
    the store's lock (``"pid 123 on host h since ..."``), or is None.
    """

    path: str
    name: str
    spec_hash: str
    n_tasks: int
    n_done: int
    dims: Mapping[str, int]
    done_by_pattern: Mapping[str, int]
    tasks_per_pattern: int
    input_hashes: Mapping[str, str]
    versions: Mapping[str, str]
    total_task_s: float
    n_damaged: int = 0
    running: str | None = None

    @property
    def complete(self) -> bool:
        """Whether every task is stored (and none damaged)."""
        return self.n_done == self.n_tasks

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "path": self.path,
            "name": self.name,
            "spec_hash": self.spec_hash,
            "n_tasks": self.n_tasks,
            "n_done": self.n_done,
            "complete": self.complete,
            "dims": dict(self.dims),
            "done_by_pattern": dict(self.done_by_pattern),
            "tasks_per_pattern": self.tasks_per_pattern,
            "input_hashes": dict(self.input_hashes),
            "versions": dict(self.versions),
            "total_task_s": self.total_task_s,
            "n_damaged": self.n_damaged,
            "running": self.running,
        }


def campaign_status(results: str | os.PathLike[str]) -> CampaignStatus:
    """Progress and provenance of a campaign store.

    Raises
    ------
    StoreError
        If the store is missing, not a campaign store or damaged.
    """
    import json

    store = CampaignStore.open(results)
    scan = store.scan()
    mask = scan.finished
    holder = lock_holder(results)
    spec = store.spec_dict()
    names = [p["name"] for p in spec["pattern"]]
    dims = dict(
        zip(("pattern", "angle", "subset", "noise", "blur", "rep"), mask.shape, strict=True)
    )
    per_pattern = {n: int(mask[i].sum()) for i, n in enumerate(names)}
    try:
        times = store.read("time_s")
    except Exception:  # a damaged time_s chunk (counted in n_damaged)
        times = np.full(mask.shape, np.nan)
    return CampaignStatus(
        path=str(results),
        name=spec["campaign"]["name"],
        spec_hash=str(store.attrs["spec_hash"]),
        n_tasks=int(mask.size),
        n_done=int(mask.sum()),
        dims=dims,
        done_by_pattern=per_pattern,
        tasks_per_pattern=int(mask[0].size),
        input_hashes=json.loads(store.attrs.get("input_hashes", "{}")),
        versions=json.loads(store.attrs.get("versions", "{}")),
        total_task_s=float(np.nansum(np.where(mask, times, np.nan))),
        n_damaged=scan.n_damaged,
        running=holder.describe() if holder is not None else None,
    )
