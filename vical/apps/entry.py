"""The console scripts: Ctrl-C and SIGTERM handled in every command, from before its heavy imports.

SIGTERM (how SLURM, launchers and ``kill`` stop a job) raises ``Terminated``, a ``KeyboardInterrupt``, where the
program is, so every command stops the same way on both: what the command keeps is kept (its outputs are
written whole or not at all: ``vical.io.atomic``), one line says so, and the exit status is 130 for Ctrl-C and 143
for SIGTERM (128 + the signal's number, as a shell reports them). ``vical-train`` and ``vical-collect`` say
themselves what they kept (the checkpoint to resume from, the recording so far) and return
``interrupted_status``.

This module imports nothing heavy: the command's module is imported inside the handling.
"""

from __future__ import annotations

import importlib
import signal
import sys
from collections.abc import Callable
from itertools import pairwise
from typing import NoReturn


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
OUT_FLAGS = {"vical-calibrate": "--out", "vical-imu-noise": "--out", "vical-export": "--out", "vical-record": "out=",
             "vical-evaluate": "out="}  # fmt: skip


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


def run(app: str, target: str | Callable[[], int | None]) -> NoReturn:
    """Run the command ``target`` (``module:function``, imported here, or the function itself: a module run with
    ``python -m``) as ``app``: SIGTERM raises ``Terminated``; an interrupt that the command did not handle itself
    ends in one line and 130 / 143."""
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        if isinstance(target, str):
            module, function = target.split(":")
            target = getattr(importlib.import_module(module), function)
        status = target()
    except KeyboardInterrupt as err:
        # From the line's start: a progress bar the interrupt cut short ends without a newline.
        print(f"\r{app}: interrupted ({interrupted_by(err)}); {_kept(app, sys.argv[1:])}", file=sys.stderr)
        status = interrupted_status(err)
    finally:
        signal.signal(signal.SIGTERM, previous)  # as it was (a test calls this in its own process)
    sys.exit(status)


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
