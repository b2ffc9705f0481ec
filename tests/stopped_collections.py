"""Collections that stopped early: a child process whose files the kernel stops growing (what a full disk does to a
writer, without filling one), one that Ctrl-C reaches, one still running when its test ends, and the calibration of
the recording a stopped collection left."""

import resource
import signal
import subprocess
from collections.abc import Callable
from pathlib import Path

from vical.apps import calibrate


def file_size_limit(nbytes: int) -> Callable[[], None]:
    """A ``preexec_fn`` for ``subprocess``: no file of the child grows past ``nbytes`` (``RLIMIT_FSIZE``); a write
    across the limit is cut short and the next fails with EFBIG, as a full disk's with ENOSPC (the signal the kernel
    sends first is ignored, as a process that handles write errors does)."""

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))

    return limit


def default_sigint() -> None:
    """A ``preexec_fn`` for ``subprocess``: SIGINT's default action, as a terminal gives it (a shell's background job
    inherits SIGINT ignored; Ctrl-C reaches the command only with the default action)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def kill_if_running(proc: subprocess.Popen) -> None:
    """Kill ``proc`` if it still runs (a test that failed before it stopped), and reap it."""
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def calibrate_joint(out: Path, calibration: Path) -> int:
    """``vical-calibrate``'s status on the recording ``vical-collect`` or ``vical-guide`` left in ``out`` (joint task,
    the detections it stored)."""
    return calibrate.main([str(out / "recording"), "--task", "joint", "--target", str(out / "target.yaml"),
                           "--stored-corners", "--imu-yaml", str(out / "imu.yaml"), "--no-report",
                           "--out", str(calibration)])  # fmt: skip
