"""Ctrl-C and SIGTERM held across code that cannot be interrupted cleanly, then raised as they would have been.

Some libraries turn an exception raised inside them into their own error: ctypes (PyOpenGL's argument converters,
the GL context's calls at every render) into ``ctypes.ArgumentError``, OmegaConf (Hydra composing a config) into
an ``AttributeError`` about a half-built node. An interrupt landing there would end a command as an error (status
1) instead of as an interrupt (status 130 / 143 and its one line: ``vical.apps.entry``), so such calls run with
the interrupts held. Imports nothing of vical.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

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
