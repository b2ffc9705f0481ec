"""Worker pools: task order kept, errors and crashed workers reported (never a hang), bad settings refused."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from vical.config_checks import ConfigError
from vical.parallel import MAX_WORKERS, ParallelConfig, WorkerCrashed, imap_ordered

TWO = ParallelConfig(workers=2)


def square_after(task: tuple[int, float]) -> tuple[int, int]:
    """(the task, its square, the worker's pid), the first tasks slower: later tasks finish first."""
    value, delay = task
    time.sleep(delay)
    return value, value * value, os.getpid()


def fail_on_three(value: int) -> int:
    if value == 3:
        raise ValueError(f"task {value} cannot be done")
    return value


def die_on_two(value: int) -> int:
    if value == 2:
        os._exit(9)  # as a kill -9 or the OOM killer would end it
    return value


def test_results_come_in_task_order_from_several_processes():
    tasks = [(k, 0.3 if k < 2 else 0.0) for k in range(8)]
    results = list(imap_ordered(square_after, tasks, TWO))
    assert [(v, s) for v, s, _ in results] == [(k, k * k) for k in range(8)]
    assert len({pid for _, _, pid in results}) == 2 and os.getpid() not in {pid for _, _, pid in results}


def test_one_worker_runs_in_this_process():
    results = list(imap_ordered(square_after, [(3, 0.0)], ParallelConfig()))
    assert results == [(3, 9, os.getpid())]


def test_a_task_error_reaches_the_caller_with_its_message():
    results = imap_ordered(fail_on_three, range(6), TWO)
    assert [next(results) for _ in range(3)] == [0, 1, 2]
    with pytest.raises(ValueError, match="task 3 cannot be done"):
        next(results)


def test_a_killed_worker_is_a_clear_error_not_a_hang():
    start = time.perf_counter()
    with pytest.raises(WorkerCrashed, match="a worker process died"):
        list(imap_ordered(die_on_two, range(6), TWO))
    assert time.perf_counter() - start < 60


HOLDING_CALLER = """
    import os, sys, time
    from pathlib import Path
    from vical.parallel import ParallelConfig, imap_ordered

    def hold(path):
        Path(path).write_text(str(os.getpid()))
        time.sleep(120)

    if __name__ == "__main__":
        list(imap_ordered(hold, [os.path.join(sys.argv[1], f"task{k}") for k in range(6)], ParallelConfig(workers=2)))
"""


def _running(pid: int) -> bool:
    """Whether ``pid`` is a live process (a zombie left unreaped by its adopter is not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _holding_caller(tmp_path: Path, **popen) -> tuple[subprocess.Popen, list[int]]:
    """A process running ``HOLDING_CALLER`` and the pids of its two workers, once both hold a task."""
    script = tmp_path / "caller.py"
    script.write_text(textwrap.dedent(HOLDING_CALLER))
    caller = subprocess.Popen([sys.executable, str(script), str(tmp_path)], **popen)
    deadline = time.monotonic() + 60
    while len(started := sorted(tmp_path.glob("task*"))) < 2 and time.monotonic() < deadline:
        assert caller.poll() is None
        time.sleep(0.1)
    time.sleep(0.2)  # both pids written whole
    return caller, [int(path.read_text()) for path in started]


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads process states from /proc")
def test_workers_end_soon_after_their_caller_is_killed(tmp_path):
    caller, workers = _holding_caller(tmp_path)
    assert len(workers) == 2 and all(_running(pid) for pid in workers)
    caller.send_signal(signal.SIGKILL)  # no cleanup runs: as a scheduler's or a user's kill -9
    caller.wait()
    deadline = time.monotonic() + 10
    while any(_running(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_running(pid) for pid in workers), "workers went on with their queued tasks"
    assert len(list(tmp_path.glob("task*"))) == 2  # and started none of the tasks queued after


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads process states from /proc")
def test_an_interrupted_caller_ends_its_workers_mid_task_and_exits(tmp_path):
    """Ctrl-C while the workers run 120-s tasks: the caller ends them and exits in seconds (it waited for the
    running tasks before: an evaluation's episodes, seconds each, after every Ctrl-C or SIGTERM)."""
    caller, workers = _holding_caller(tmp_path, stderr=subprocess.PIPE)
    caller.send_signal(signal.SIGINT)
    deadline = time.monotonic() + 20
    while caller.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    if caller.poll() is None:
        caller.kill()  # its workers follow it (test_workers_end_soon_after_their_caller_is_killed)
        pytest.fail("the caller waited for its workers' tasks")
    assert b"KeyboardInterrupt" in caller.stderr.read()
    assert not any(_running(pid) for pid in workers)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"workers": 0}, "parallel.workers"),
        ({"workers": MAX_WORKERS + 1}, "parallel.workers"),
        ({"workers": True}, "parallel.workers"),
        ({"backend": "slurm"}, "parallel.backend"),
        ({"ray_address": ""}, "parallel.ray_address"),
    ],
)
def test_bad_settings_are_refused_by_key(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        ParallelConfig(**kwargs)


def test_unknown_keys_are_refused():
    with pytest.raises(ConfigError, match="only the keys workers, backend, ray_address"):
        ParallelConfig.from_config({"workers": 2, "nodes": 4})


def test_a_missing_key_is_the_dataclass_default():
    assert ParallelConfig.from_config(None) == ParallelConfig.from_config({}) == ParallelConfig()
    assert ParallelConfig.from_config({"workers": 2}) == ParallelConfig(workers=2, backend="local", ray_address=None)


def test_an_unreachable_ray_address_is_refused_within_seconds():
    config = ParallelConfig(workers=2, backend="ray", ray_address="127.0.0.1:9")  # the discard port: closed
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=r"parallel.ray_address='127.0.0.1:9': nothing answers at 127.0.0.1:9"):
        list(imap_ordered(fail_on_three, range(2), config))
    assert time.perf_counter() - start < 10


@pytest.fixture(scope="module")
def local_ray():
    import ray  # a dev dependency: `make test` installs it, so this test never skips

    config = ParallelConfig(workers=2, backend="ray")
    yield config
    ray.shutdown()


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_tasks_run_on_a_local_ray_instance_in_order(local_ray):
    tasks = [(k, 0.2 if k < 2 else 0.0) for k in range(6)]
    results = list(imap_ordered(square_after, tasks, local_ray))
    assert [(v, s) for v, s, _ in results] == [(k, k * k) for k in range(6)]
    assert os.getpid() not in {pid for _, _, pid in results}


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_a_task_error_on_ray_reaches_the_caller(local_ray):
    with pytest.raises(ValueError, match="task 3 cannot be done"):
        list(imap_ordered(fail_on_three, range(6), local_ray))


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_errors_while_other_tasks_finish_leave_the_caller_running(local_ray):
    # Tasks that finish as the error reaches the caller: cancelling them could abort this process inside Ray.
    for _ in range(12):
        with pytest.raises(ValueError, match="task 3 cannot be done"):
            list(imap_ordered(fail_on_three, range(10), local_ray))
    assert list(imap_ordered(fail_on_three, range(3), local_ray)) == [0, 1, 2]
