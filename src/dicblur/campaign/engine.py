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
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .spec import CampaignSpec, load_spec
from .store import CampaignStore
from .tasks import Batch, input_hashes, iter_batches, make_pattern

__all__ = ["CampaignStatus", "RunSummary", "TaskFunction", "campaign_status", "run_campaign"]


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


def _timed_task(fn: TaskFunction, image: NDArray[np.float64], batch: Batch,
                spec: CampaignSpec) -> dict[str, Any]:
    """Call the task function and add its process CPU time (s) as ``"_cpu_s"``."""
    t = time.process_time()
    out = dict(fn(image, batch, spec))
    out["_cpu_s"] = time.process_time() - t
    return out


_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ucx|ws|wss)://)?(?:\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+)"
                      r":\d{1,5}/?$|^inproc://\S+$")


def check_scheduler_address(address: str) -> str:
    """Check the form of a Dask scheduler address (``tcp://HOST:PORT``) before connecting.

    Raises
    ------
    InputError
        If ``address`` is not ``[tcp|tls|ucx|ws|wss://]HOST:PORT`` or ``inproc://...``.
    """
    if not isinstance(address, str) or not _ADDRESS.match(address.strip()):
        raise InputError(f"scheduler={address!r}: not a Dask scheduler address; give "
                         "tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786 (or omit it for a "
                         "local cluster)")
    return address.strip()


def _default_task() -> TaskFunction:
    from .simulate import simulate_batch

    return simulate_batch


def _prepare(spec: CampaignSpec, results: Path) -> tuple[CampaignStore, dict[str, Any]]:
    images = {p.name: make_pattern(spec, p) for p in spec.patterns}
    hashes = input_hashes(spec, images)
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
        On a bad spec, a store holding another campaign or a damaged store, before any
        task runs. An exception raised by a task is re-raised after the batches already
        finished are stored.

    Notes
    -----
    ``KeyboardInterrupt`` (Ctrl-C) during the run cancels the pending tasks, shuts the
    local cluster down and returns a summary with ``interrupted=True``; every batch
    finished before is stored and is skipped by the next run.
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
    store, images = _prepare(spec, path)
    fn = task if task is not None else _default_task()
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
            spec, images, pending, fn, finish, scheduler=scheduler, workers=workers,
            connect_timeout=connect_timeout, started=started,
        )
    return RunSummary(
        path=str(path), n_tasks=n_total, n_skipped=n_skipped, n_run=counts["run"],
        interrupted=interrupted, wall_s=time.perf_counter() - t0,
        setup_s=started[0] - t0, compute_s=max(0.0, finished[0] - started[0]),
        task_s=task_s[0], task_cpu_s=task_s[1],
        workers=n_workers, scheduler=where,
    )


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
    import dask
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        n = int(workers) if workers is not None else (os.cpu_count() or 1)
        if n < 1:
            raise InputError(f"workers={workers!r}: must be >= 1 (or omit it: all cores)")
        # One single-threaded process per core: the tasks are CPU-bound numpy/numba code
        # (the Correlator runs with workers=1 inside a task), so processes avoid the GIL.
        # Dask sets MALLOC_TRIM_THRESHOLD_ in its workers, which disables glibc's dynamic
        # mmap threshold: every large temporary array (a 512^2 image is 2 MiB) is then a
        # fresh mmap with page faults, ~25% more CPU per task here. Keep the thread limits,
        # drop that one.
        env = {k: v for k, v in
               dask.config.get("distributed.nanny.pre-spawn-environ", {}).items()
               if k != "MALLOC_TRIM_THRESHOLD_"}
        with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.ERROR)
        client = Client(cluster)
        where = "local"
    else:
        try:
            client = Client(scheduler, timeout=f"{connect_timeout}s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"scheduler={scheduler!r}: cannot connect to a Dask scheduler "
                             f"({exc}); check the address (tcp://HOST:PORT) and that it "
                             "runs") from exc
        where = scheduler
    interrupted = False
    futures: list[Any] = []
    try:
        n_workers = max(1, len(client.scheduler_info(n_workers=-1).get("workers", {})))
        # Load the task's compiled code (numba cache) on every worker at once, as part of
        # the start-up, rather than inside each worker's first batch.
        warm = getattr(fn, "warm_up", None)
        if callable(warm):
            client.run(warm)
        # Each pattern image travels to every worker once, not once per batch.
        remote = {name: client.scatter(img, broadcast=True, hash=False)
                  for name, img in images.items()}
        started[0] = time.perf_counter()
        by_key: dict[Any, Batch] = {}
        for b in pending:
            # Larger blur costs more DIC iterations: start the batches of large W first
            # (longest-first scheduling shortens the idle tail of the last workers).
            fut = client.submit(_timed_task, fn, remote[b.pattern], b, spec, pure=False,
                                priority=b.loc[5],
                                key=f"dicblur-batch-{b.index}-{os.urandom(4).hex()}")
            by_key[fut.key] = b
            futures.append(fut)
        for fut in as_completed(futures):
            finish(by_key[fut.key], fut.result())
    except KeyboardInterrupt:
        interrupted = True
    finally:
        try:
            client.cancel(futures)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    return n_workers, where, interrupted


@dataclass(frozen=True)
class CampaignStatus:
    """Progress of a stored campaign (see :func:`campaign_status`)."""

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

    @property
    def complete(self) -> bool:
        """Whether every task is stored."""
        return self.n_done == self.n_tasks

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "path": self.path, "name": self.name, "spec_hash": self.spec_hash,
            "n_tasks": self.n_tasks, "n_done": self.n_done, "complete": self.complete,
            "dims": dict(self.dims), "done_by_pattern": dict(self.done_by_pattern),
            "tasks_per_pattern": self.tasks_per_pattern,
            "input_hashes": dict(self.input_hashes), "versions": dict(self.versions),
            "total_task_s": self.total_task_s,
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
    mask = store.done_mask()
    spec = store.spec_dict()
    names = [p["name"] for p in spec["pattern"]]
    dims = dict(zip(("pattern", "angle", "subset", "noise", "blur", "rep"), mask.shape,
                    strict=True))
    per_pattern = {n: int(mask[i].sum()) for i, n in enumerate(names)}
    times = store.read("time_s")
    return CampaignStatus(
        path=str(results), name=spec["campaign"]["name"],
        spec_hash=str(store.attrs["spec_hash"]), n_tasks=int(mask.size),
        n_done=int(mask.sum()), dims=dims, done_by_pattern=per_pattern,
        tasks_per_pattern=int(mask[0].size),
        input_hashes=json.loads(store.attrs.get("input_hashes", "{}")),
        versions=json.loads(store.attrs.get("versions", "{}")),
        total_task_s=float(np.nansum(np.where(mask, times, np.nan))),
    )
