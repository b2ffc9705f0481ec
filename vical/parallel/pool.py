"""``imap_ordered``: a task function over a list of tasks, in this process, on local processes or on Ray."""

from __future__ import annotations

import collections
import contextlib
import itertools
import multiprocessing
import os
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlparse

from vical.config_checks import ConfigError, require

MAX_WORKERS = 1024  # more processes than any machine or allocation this runs on has cores
BACKENDS = ("local", "ray")
RAY_CONNECT_TIMEOUT_S = 3.0  # an address that does not answer within this is refused (never a hang)
RAY_DEFAULT_PORTS = {"ray": 10001, "": 6379}  # Ray client (ray://) and GCS ports
# Tasks submitted ahead per worker: a slow task holds back the yield of later ones, not their running.
RAY_WINDOW_PER_WORKER = 4
PARENT_POLL_S = 0.5  # how soon a local worker notices that the process that started it is gone


class WorkerCrashed(RuntimeError):
    """A worker process died (killed, out of memory) while running a task."""


@dataclass(frozen=True)
class ParallelConfig:
    """Where tasks run (``conf/parallel/``).

    Attributes:
        workers: worker processes (1: in this process, no pool).
        backend: ``local`` (processes on this machine) or ``ray`` (a Ray cluster).
        ray_address: the cluster (``auto``, ``host:port`` or ``ray://host:port``); None starts a local
            Ray instance with ``workers`` CPUs (or as many as the caller needs, ``connect_ray``).
    """

    workers: int = 1
    backend: str = "local"
    ray_address: str | None = None

    def __post_init__(self) -> None:
        ok = isinstance(self.workers, int) and not isinstance(self.workers, bool) and 1 <= self.workers <= MAX_WORKERS
        require(ok, "parallel.workers", f"an integer from 1 to {MAX_WORKERS} (worker processes)", self.workers)
        require(self.backend in BACKENDS, "parallel.backend", f"one of {list(BACKENDS)}", self.backend)
        ok = self.ray_address is None or (isinstance(self.ray_address, str) and bool(self.ray_address))
        require(ok, "parallel.ray_address", "null, 'auto', 'host:port' or 'ray://host:port'", self.ray_address)

    @classmethod
    def from_config(cls, cfg: Any) -> ParallelConfig:
        """From a mapping (``cfg.parallel``); None or a missing section means serial."""
        if cfg is None:
            return cls()
        require(hasattr(cfg, "get"), "parallel", "a mapping with workers, backend, ray_address", cfg)
        unknown = set(cfg) - {"workers", "backend", "ray_address"}
        require(not unknown, "parallel", "only the keys workers, backend, ray_address", sorted(unknown))
        return cls(**{key: cfg[key] for key in cfg})  # a missing key: the field's default

    @property
    def serial(self) -> bool:
        return self.workers == 1 and self.backend == "local"


def imap_ordered(fn: Callable[[Any], Any], tasks: Sequence[Any], config: ParallelConfig) -> Iterator[Any]:
    """``fn(task)`` for every task, yielded in task order as soon as each (and all before it) is done.

    An exception of ``fn`` is re-raised here (the tasks already handed to workers finish first, the
    rest are dropped); a worker process that dies raises ``WorkerCrashed``.
    """
    if config.serial:
        return (fn(task) for task in tasks)
    if config.backend == "ray":
        return _ray_imap(fn, tasks, config)
    return _process_imap(fn, tasks, config.workers)


def _process_imap(fn: Callable[[Any], Any], tasks: Sequence[Any], workers: int) -> Iterator[Any]:
    # spawn, not fork: a forked MuJoCo renderer or GTSAM/TBB state is not safe in the child.
    executor = ProcessPoolExecutor(
        max_workers=min(workers, max(len(tasks), 1)), mp_context=_spawn(),
        initializer=_end_with_parent, initargs=(os.getpid(),),
    )  # fmt: skip
    finished = False
    try:
        with single_threaded_children():  # the workers start with the first submissions
            futures = [executor.submit(fn, task) for task in tasks]
        for index, future in enumerate(futures):
            try:
                yield future.result()
            except BrokenProcessPool as err:
                raise WorkerCrashed(
                    f"a worker process died (killed, or out of memory) while task {index} of {len(tasks)} ran; "
                    "the results of the finished tasks are lost with this run: start it again"
                ) from err
        finished = True
    finally:
        if not finished:  # Ctrl-C, SIGTERM, an error, a caller that stopped reading: nobody wants what still runs
            _terminate_workers(executor)
        executor.shutdown(wait=True, cancel_futures=True)


def _terminate_workers(executor: ProcessPoolExecutor) -> None:
    """End the pool's workers now, the tasks they run unfinished: shutting down waits for those tasks (an episode
    takes seconds) and the interpreter's exit joins the pool too. (``ProcessPoolExecutor`` offers no public way
    before Python 3.14's ``terminate_workers``.)"""
    for process in list((executor._processes or {}).values()):
        process.terminate()


def _spawn():
    return multiprocessing.get_context("spawn")


def _end_with_parent(parent_pid: int) -> None:
    """Pool initializer: end this worker as soon as the process that started it is gone.

    A caller killed by a signal (``kill``, a job scheduler) runs no cleanup; its workers would go on
    with the tasks already queued to them, for minutes, holding cores nobody reads results from.
    """

    def watch() -> None:
        while os.getppid() == parent_pid:  # an orphan is adopted by another process
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="vical-parent-watch", daemon=True).start()


# One thread per worker for the numerical libraries: their default (a thread per core in every worker)
# oversubscribes the cores. Measured: 12 evaluation episodes on 2 workers took 19.7 s with the default
# threads and 17.8 s with one (serially 30.5 s and 31.2 s).
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def single_threaded_children():
    """Processes started inside see one thread for OpenMP / OpenBLAS / MKL (unless the user set a number)."""
    saved = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    for name, value in saved.items():
        if value is None:
            os.environ[name] = "1"
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)


def worker_environment() -> dict[str, str]:
    """The thread settings of ``single_threaded_children`` as environment variables (for Ray's workers)."""
    return {name: os.environ.get(name, "1") for name in THREAD_VARIABLES}


# ------------------------------------------------------------------------------------------------ Ray
def _ray_imap(fn: Callable[[Any], Any], tasks: Sequence[Any], config: ParallelConfig) -> Iterator[Any]:
    # Tasks are submitted a window ahead and never cancelled: ray.cancel on a task that finishes at that
    # moment can abort the calling process (a failed check in Ray's task manager, seen with Ray 2.60).
    # A stopped iteration waits for the window's tasks instead, as the local pool waits for its running ones.
    ray = connect_ray(config)
    remote = ray.remote(num_cpus=1, max_retries=0)(fn)
    upcoming = iter(enumerate(tasks))
    ahead = RAY_WINDOW_PER_WORKER * config.workers
    window = collections.deque((index, remote.remote(task)) for index, task in itertools.islice(upcoming, ahead))
    try:
        while window:
            index, ref = window[0]
            try:
                result = ray.get(ref)
            except ray.exceptions.WorkerCrashedError as err:
                raise WorkerCrashed(
                    f"a Ray worker died (killed, or out of memory) while task {index} of {len(tasks)} ran; "
                    "start the run again"
                ) from err
            window.popleft()
            window.extend((i, remote.remote(task)) for i, task in itertools.islice(upcoming, 1))
            yield result
    finally:
        if window:
            ray.wait([ref for _, ref in window], num_returns=len(window))


def import_ray():
    """The ``ray`` module, or ``ConfigError`` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "parallel.backend=ray needs Ray, which is not installed: pip install 'vical[ray]' (or pip install ray)"
        ) from None
    return ray


def check_ray_address(config: ParallelConfig) -> None:
    """Refuse within seconds a Ray address where nothing answers (before a run writes anything); else nothing."""
    if config.backend == "ray" and config.ray_address not in (None, "auto"):
        _check_reachable(config.ray_address)


def connect_ray(config: ParallelConfig, cpus: int | None = None):
    """``ray`` connected to ``config.ray_address`` (checked to answer first) or to a new local instance.

    A local instance gets ``cpus`` CPUs (default ``config.workers``): a caller whose Ray actors each hold a
    CPU for their lifetime asks for as many as it starts.
    """
    ray = import_ray()
    if ray.is_initialized():
        return ray
    address = config.ray_address
    check_ray_address(config)
    try:
        if address is None:  # a local instance: its workers import what this process imports
            path = {"env_vars": {"PYTHONPATH": os.pathsep.join(p for p in sys.path if p), **worker_environment()}}
            ray.init(
                num_cpus=cpus or config.workers, include_dashboard=False, log_to_driver=False, logging_level="ERROR",
                runtime_env=path,
            )  # fmt: skip
        else:
            ray.init(address=address, log_to_driver=False, logging_level="ERROR")
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise ConfigError(f"parallel.ray_address={address!r}: Ray could not connect ({err}); start the cluster "
                          "(ray start --head) or fix the address") from None  # fmt: skip
    return ray


def _check_reachable(address: str) -> None:
    """Refuse within ``RAY_CONNECT_TIMEOUT_S`` an address where nothing listens (Ray itself would retry for long)."""
    parsed = urlparse(address if "://" in address else f"//{address}")
    host = parsed.hostname
    try:
        port = parsed.port or RAY_DEFAULT_PORTS.get(parsed.scheme, 6379)
    except ValueError:
        port = None
    allowed = "'auto', 'host:port' or 'ray://host:port'"
    require(bool(host) and port is not None, "parallel.ray_address", allowed, address)
    try:
        with socket.create_connection((host, port), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as err:
        raise ConfigError(
            f"parallel.ray_address={address!r}: nothing answers at {host}:{port} ({err}); start the cluster "
            "(ray start --head) or fix the address"
        ) from None
