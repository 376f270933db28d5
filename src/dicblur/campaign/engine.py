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
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..arrays import Float64Array
from .cluster import Interrupt, TaskMap, check_scheduler_address, map_dask
from .lock import StoreLock
from .mapping import TasksSummary as TasksSummary
from .mapping import run_tasks as run_tasks
from .spec import CampaignSpec, load_spec
from .status import CampaignStatus as CampaignStatus
from .status import campaign_status as campaign_status
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


TaskFunction = Callable[[Float64Array, Batch, CampaignSpec], Mapping[str, Any]]
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
    fn: TaskFunction, image: Float64Array, batch: Batch, spec: CampaignSpec
) -> dict[str, Any]:
    """Call the task function and add its process CPU time (s) as ``"_cpu_s"``."""
    t = time.process_time()
    out = dict(fn(image, batch, spec))
    out["_cpu_s"] = time.process_time() - t
    return out


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

    with Interrupt() as interrupt:
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


def _run_dask(
    spec: CampaignSpec,
    images: Mapping[str, Float64Array],
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
    return map_dask(
        TaskMap(
            func=_timed_task,
            items=pending,
            args=lambda b, remote: (fn, remote[b.pattern], b, spec),
            finish=finish,
            shared=images,
        ),
        priority=lambda b: int(b.loc[5]),
        key=lambda b: f"dicblur-batch-{b.index}",
        warm_up=getattr(fn, "warm_up", None),
        scheduler=scheduler,
        workers=workers,
        connect_timeout=connect_timeout,
        started=started,
    )
