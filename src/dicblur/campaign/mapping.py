"""Running any list of independent tasks serially, on threads or on Dask
(:func:`run_tasks`, :class:`TasksSummary`), e.g. the chunks of ``dicblur track --workers``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .cluster import TaskMap, check_scheduler_address, map_dask


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

    tasks = TaskMap(func=func, items=list(items), args=call_args, finish=done, shared=share)
    if (serial or not items) and threads > 1 and len(items) > 1:
        interrupted = _map_threads(tasks, threads)
        return TasksSummary(count[0], interrupted, 1, "threads", time.perf_counter() - t0)
    if serial or not items:
        interrupted = False
        try:
            for it in items:
                done(it, func(*call_args(it, share)))
        except KeyboardInterrupt:
            interrupted = True
        return TasksSummary(count[0], interrupted, 1, "serial", time.perf_counter() - t0)
    n_workers, where, interrupted = map_dask(
        tasks,
        priority=priority,
        key=lambda it: f"dicblur-{name}",
        warm_up=warm_up,
        scheduler=scheduler,
        workers=workers,
        connect_timeout=connect_timeout,
        started=[0.0],
    )
    return TasksSummary(count[0], interrupted, n_workers, where, time.perf_counter() - t0)


def _map_threads(tasks: TaskMap, threads: int) -> bool:
    """:func:`run_tasks` on ``threads`` threads of this process; returns whether Ctrl-C
    stopped it (the pending tasks are cancelled, the running ones finish first). A task's
    exception, or one raised by ``finish``, is re-raised once the tasks running beside it
    have finished and been passed to ``finish``."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    items, finish = tasks.items, tasks.finish
    pool = ThreadPoolExecutor(max_workers=int(threads), thread_name_prefix="dicblur-task")
    futures = {pool.submit(tasks.func, *tasks.args(it, tasks.shared)): it for it in items}
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
