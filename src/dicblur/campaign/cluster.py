"""The Dask side of the campaign engine: the scheduler address check, the local cluster's
workers spawned deaf to Ctrl-C, quiet ``distributed`` logs, and the mapping of tasks onto
a cluster with its interrupt handling (:func:`map_dask`).
"""

from __future__ import annotations

import logging
import os
import re
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from ..errors import InputError

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


class Interrupt:
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

    def __enter__(self) -> Interrupt:
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


def _wait_all(futures: list[Any], interrupt: Interrupt) -> None:
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


@dataclass(frozen=True)
class TaskMap:
    """Independent tasks and where their results go, however they run (Dask, threads):
    ``func(*args(item, shared))`` for each of ``items``, each result handed to
    ``finish(item, result)`` in this process, in completion order. ``shared`` maps names
    to the large objects every task needs (on Dask each travels to every worker once and
    ``args`` receives the workers' copies)."""

    func: Callable[..., Any]
    items: list[Any]
    args: Callable[[Any, Mapping[str, Any]], tuple[Any, ...]]
    finish: Callable[[Any, Any], None]
    shared: Mapping[str, Any]


def map_dask(
    tasks: TaskMap,
    *,
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
    with Interrupt() as interrupt:
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
                for name, obj in tasks.shared.items()
            }
            interrupt.check()
            started[0] = time.perf_counter()
            by_key: dict[Any, Any] = {}
            for i, it in enumerate(tasks.items):
                fut = client.submit(
                    tasks.func,
                    *tasks.args(it, remote),
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
                    tasks.finish(by_key[fut.key], fut.result())
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
