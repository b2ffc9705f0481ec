"""The console scripts: Ctrl-C and SIGTERM handled in every command, from before its heavy imports.

SIGTERM (how SLURM, launchers and ``kill`` stop a job) raises ``Terminated``, a ``KeyboardInterrupt``, where the
program is, so every command stops the same way on both: what the command keeps is kept (its outputs are
written whole or not at all: ``vical.io.atomic``), one line says so, and the exit status is 130 for Ctrl-C and 143
for SIGTERM (128 + the signal's number, as a shell reports them). ``vical-train`` and ``vical-collect`` say
themselves what they kept (the checkpoint to resume from, the recording so far) and return
``interrupted_status``.

Until the command's module is imported (its start-up: torch, GTSAM, MuJoCo, ~0.3-2 s) a signal ends the process at
once with the same line and status (``during_start_up``): nothing has been written yet, and an exception raised
inside an extension module's initialisation does not arrive as itself (GTSAM's becomes ``ImportError: initialization
failed``). A module run with ``python -m`` is its own start-up: ``vical.apps`` sets the same handling before the
module's imports (``start_up_of_module``). Then an interrupt that arrives during an import statement waits for its
end (``vical.signals.imports_run_whole``); one that arrives inside another import (``importlib.import_module``), as
the cause of the error that import raised, ends the command as the interrupt itself.

A full disk or a read-only folder (``is_write_fault``) is reported once, by the command, in one line
(``vical.apps.cli.write_faults_in_one_line``): a library's writer thread that meets it (TensorBoard's event
writer) hands it to the thread that writes through it, so the thread's own traceback is not printed
(``_write_faults_reported_by_their_owner``).

This module imports nothing heavy: the command's module is imported inside the handling.
"""

from __future__ import annotations

import contextlib
import errno
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from itertools import pairwise
from typing import NoReturn

from vical.signals import after_imports, imports_run_whole


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program was."""


def interrupted_status(err: BaseException) -> int:
    """The exit status of a command stopped by ``err``: 143 for SIGTERM, 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(err, Terminated) else signal.SIGINT)


def interrupted_by(err: BaseException) -> str:
    return "SIGTERM" if isinstance(err, Terminated) else "Ctrl-C"


def _terminate(signum, frame) -> NoReturn:
    raise Terminated()


# What each command keeps when stopped, by its output flag (--out or out=): they write their outputs whole (a
# directory at once, or vical-evaluate's files together once all are made), so it is as it was.
AS_IT_WAS = "{where} is as it was: the outputs are written whole or not at all"
OUT_FLAGS = {"vical-calibrate": "--out", "vical-imu-noise": "--out", "vical-export": "--out", "vical-target": "--out",
             "vical-record": "out=", "vical-evaluate": "out="}  # fmt: skip


def _kept(app: str, argv: list[str]) -> str:
    """What an interrupted ``app`` kept: its output directory, named as the command line gave it."""
    if app not in OUT_FLAGS:
        return "nothing was written"
    flag = OUT_FLAGS[app]
    if flag.endswith("="):  # a Hydra override
        given = next((a for a in argv if a.startswith(flag)), None)
    else:
        given = next((f"{a} {b}" for a, b in pairwise(argv) if a == flag), None)
    return AS_IT_WAS.format(where=given or f"{flag.strip('-=')} (its default)")


def _interrupted_line(app: str, err: BaseException) -> str:
    # From the line's start: a progress bar the interrupt cut short ends without a newline.
    return f"\r{app}: interrupted ({interrupted_by(err)}); {_kept(app, sys.argv[1:])}"


def _exit_at_once(app: str) -> Callable[[int, object], NoReturn]:
    """A signal handler for the start-up of ``app``: the line and the status, and the process ends there."""

    def handler(signum, frame) -> NoReturn:
        err = Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()
        try:
            sys.stdout.flush()
            print(_interrupted_line(app, err), file=sys.stderr, flush=True)
        finally:
            os._exit(interrupted_status(err))

    handler.start_up = True
    return handler


def _python_default(sig: int, handler: object) -> object:
    """``handler``, or Python's own for ``sig`` where it is a start-up's."""
    if not getattr(handler, "start_up", False):
        return handler
    return signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL


def _handled(ctrl_c: object) -> list[int]:
    """The signals a command handles: SIGTERM, and Ctrl-C where Python does (a job started with SIGINT ignored
    keeps it ignored)."""
    return [signal.SIGTERM] + (
        [signal.SIGINT] if _python_default(signal.SIGINT, ctrl_c) is signal.default_int_handler else []
    )


def during_start_up(app: str) -> None:
    """Signals end ``app`` at once from here until the command runs."""
    for sig in _handled(signal.getsignal(signal.SIGINT)):
        signal.signal(sig, _exit_at_once(app))


def start_up_of_module(argv: list[str]) -> None:
    """For ``python -m vical.apps.<command>`` (``argv``: the interpreter's own, ``sys.orig_argv``): the start-up's
    handling, set before the module's imports; its ``run`` takes over at the module's end."""
    module = argv[argv.index("-m") + 1] if "-m" in argv[:-1] else ""
    if module.startswith("vical.apps.") and module.count(".") == 2:
        during_start_up("vical-" + module.rsplit(".", 1)[1].replace("_", "-"))


# What the file system refuses a writer for: a full disk or quota, a read-only or forbidden folder, a file too big.
WRITE_FAULTS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG})


def is_write_fault(err: BaseException) -> bool:
    return isinstance(err, OSError) and err.errno in WRITE_FAULTS


def _write_faults_reported_by_their_owner(default: Callable) -> Callable:
    """A thread hook that leaves a writer thread's full disk or read-only folder to the thread it writes for (which
    re-raises it: TensorBoard's ``_check_worker_status``) and prints any other thread's error as ``default`` does."""

    def hook(args) -> None:
        if not is_write_fault(args.exc_value):
            default(args)

    return hook


def _interrupt_within(err: BaseException) -> KeyboardInterrupt | None:
    """The interrupt that caused ``err`` (an import's ``ImportError``, raised for the interrupt inside it), if any."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


@contextlib.contextmanager
def interrupts_as_raised() -> Iterator[None]:
    """An error that an interrupt caused inside the block is raised as that interrupt: a signal's exception raised in
    the middle of a lock's release (a ``ThreadPoolExecutor.submit`` in the guide's decisions) leaves the lock half
    released, and its ``with`` then raises ``RuntimeError: release unlocked lock`` in the interrupt's place, which
    Hydra would print as a traceback with status 1."""
    try:
        yield
    except Exception as err:
        if (interrupt := _interrupt_within(err)) is None:
            raise
        raise interrupt from None


def run(app: str, target: str | Callable[[], int | None]) -> NoReturn:
    """Run the command ``target`` (``module:function``, imported here, or the function itself: a module run with
    ``python -m``) as ``app``: a signal during its import ends it at once; then SIGTERM raises ``Terminated``; an
    interrupt that the command did not handle itself ends in one line and 130 / 143."""
    previous = {sig: _python_default(sig, signal.getsignal(sig)) for sig in (signal.SIGTERM, signal.SIGINT)}
    handled = _handled(previous[signal.SIGINT])
    thread_hook = threading.excepthook
    try:
        if isinstance(target, str):
            during_start_up(app)
            module, function = target.split(":")
            target = getattr(importlib.import_module(module), function)
        threading.excepthook = _write_faults_reported_by_their_owner(thread_hook)
        signal.signal(signal.SIGTERM, after_imports(_terminate))
        if signal.SIGINT in handled:
            signal.signal(signal.SIGINT, after_imports(signal.default_int_handler))
        with imports_run_whole():
            status = target()
    except KeyboardInterrupt as err:
        print(_interrupted_line(app, err), file=sys.stderr)
        status = interrupted_status(err)
    except Exception as err:
        if (interrupt := _interrupt_within(err)) is None:
            raise
        print(_interrupted_line(app, interrupt), file=sys.stderr)
        _exit_unfinalised(interrupted_status(interrupt))
    finally:
        for sig, handler in previous.items():  # as they were (a test calls this in its own process)
            signal.signal(sig, handler)
        threading.excepthook = thread_hook
    sys.exit(status)


def _exit_unfinalised(status: int) -> NoReturn:
    """End the process without the interpreter's finalisation: an extension whose initialisation an interrupt cut
    short (pybind11's) can abort it (``Fatal Python error``, status -6) where the command has said its line."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def train() -> NoReturn:
    run("vical-train", "vical.apps.train:main")


def calibrate() -> NoReturn:
    run("vical-calibrate", "vical.apps.calibrate:main")


def record() -> NoReturn:
    run("vical-record", "vical.apps.record:main")


def export() -> NoReturn:
    run("vical-export", "vical.apps.export:main")


def sim_demo() -> NoReturn:
    run("vical-sim-demo", "vical.apps.sim_demo:main")


def evaluate() -> NoReturn:
    run("vical-evaluate", "vical.apps.evaluate:main")


def collect() -> NoReturn:
    run("vical-collect", "vical.apps.collect:main")


def guide() -> NoReturn:
    run("vical-guide", "vical.apps.guide:main")


def imu_noise() -> NoReturn:
    run("vical-imu-noise", "vical.apps.imu_noise:main")


def target() -> NoReturn:
    run("vical-target", "vical.apps.target:main")
