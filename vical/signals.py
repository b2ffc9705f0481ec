"""Ctrl-C and SIGTERM held across code that cannot be interrupted cleanly, then raised as they would have been.

Some libraries turn an exception raised inside them into their own error: ctypes (PyOpenGL's argument converters,
the GL context's calls at every render) into ``ctypes.ArgumentError``, OmegaConf (Hydra composing a config) into
an ``AttributeError`` about a half-built node. An interrupt landing there would end a command as an error (status
1) instead of as an interrupt (status 130 / 143 and its one line: ``vical.apps.entry``), so such calls run with
the interrupts held.

An import is such code too: an extension module whose initialisation an interrupt lands in reports
``ImportError: initialization failed`` instead (pybind11: matplotlib's ``ft2font``, GTSAM), and may leave the
interpreter unable to finalise (``Fatal Python error``, status -6); a library that imports an optional module
inside ``except Exception`` / ``except ImportError`` (matplotlib's 3D axes) then goes on as if the interrupt had
never come, and the command ends with status 0. So while a command runs, an interrupt that arrives during the main
thread's import statement waits for the import's end and is raised there (``imports_run_whole``); a second one of
the same kind stops the import at once, so that an import that hangs can still be stopped. Imports nothing of vical.
"""

from __future__ import annotations

import builtins
import contextlib
import signal
import threading
from collections.abc import Callable, Iterator

INTERRUPTS = (signal.SIGINT, signal.SIGTERM)  # Ctrl-C, and how launchers stop a job


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Ctrl-C and SIGTERM held until the block ends, then raised, each once, in the order they came. Only the main
    thread runs Python's signal handlers: elsewhere the block runs as it is."""
    handlers = {sig: signal.getsignal(sig) for sig in INTERRUPTS}
    if threading.current_thread() is not threading.main_thread() or None in handlers.values():
        yield  # (None: a handler not installed from Python, which this could not put back)
        return
    held: list[int] = []
    for sig in INTERRUPTS:
        signal.signal(sig, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(held):  # the handler raises in this thread
            signal.raise_signal(sig)


# The main thread's import statements in progress, and the interrupts that wait for the outermost one's end.
_imports_in_progress = 0
_held_for_imports: list[int] = []


def _whole(original: Callable) -> Callable:
    """``__import__`` (``original``) that raises an interrupt held during the main thread's import at its end."""
    main = threading.main_thread()

    def __import__(name, globals=None, locals=None, fromlist=(), level=0):
        global _imports_in_progress
        if threading.current_thread() is not main:
            return original(name, globals, locals, fromlist, level)
        _imports_in_progress += 1
        try:
            return original(name, globals, locals, fromlist, level)
        finally:
            _imports_in_progress -= 1
            if not _imports_in_progress and _held_for_imports:
                sig = _held_for_imports[0]
                _held_for_imports.clear()
                signal.raise_signal(sig)  # the handler raises here, in place of the import's result

    return __import__


def after_imports(handler: Callable) -> Callable:
    """``handler`` for Ctrl-C or SIGTERM, run at the end of the import the main thread is in, if any (at once for a
    second signal of the kind: an import that hangs)."""

    def waits_for_the_import(signum, frame):
        if _imports_in_progress and signum not in _held_for_imports:
            _held_for_imports.append(signum)
            return
        _held_for_imports.clear()
        handler(signum, frame)

    return waits_for_the_import


@contextlib.contextmanager
def imports_run_whole() -> Iterator[None]:
    """Within the block, the import statements pass through ``_whole``: with ``after_imports`` handlers, an
    interrupt never lands inside an import."""
    original = builtins.__import__
    builtins.__import__ = _whole(original)
    try:
        yield
    finally:
        builtins.__import__ = original
        _held_for_imports.clear()
