"""How a command ends when it is told to stop: SIGTERM (``kill``, a job scheduler's stop) and
Ctrl-C both become a ``KeyboardInterrupt`` in the main thread, which the command line turns
into one line, a resume command and no partial file (``cli.main``); ``training``
holds them while XLA compiles (``interrupts_deferred``)."""

from __future__ import annotations

import _thread
import contextlib
import gc
import os
import signal
import threading
import time
from collections.abc import Iterator
from typing import Any


@contextlib.contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM (``kill``, a job scheduler's stop) takes the path of Ctrl-C, and both become a
    ``KeyboardInterrupt`` through ``interrupt``, so that a run ends with the same line and
    resume command, leaves no partial file, and is held while XLA compiles
    (``training.interrupts_deferred``). Ctrl-C is left alone where it is ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, interrupt)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not where ignored
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, interrupt)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def interrupt(signum: int, frame: Any) -> None:
    """The handler of SIGTERM and Ctrl-C: ``KeyboardInterrupt``, as Python's own for Ctrl-C.

    Python drops an exception raised inside a garbage-collection callback (it prints
    "Exception ignored" and goes on), and JAX registers one: a signal that lands there would
    be lost and the run would go on. There it is sent again a moment later, from a thread of
    its own (``_thread``, which takes none of ``threading``'s locks inside a handler)."""
    if frame is not None and frame.f_code in {getattr(c, "__code__", None) for c in gc.callbacks}:
        _thread.start_new_thread(_send_again, (signum,))
        return
    raise KeyboardInterrupt


def _send_again(signum: int) -> None:
    """Send ``signum`` to this process after 10 ms, unless the command has ended meanwhile
    (its handler is Python's default again: the signal would then kill the exiting process
    or raise in its last lines). A handler of ``interrupts_deferred`` holds it, as any."""
    time.sleep(0.01)
    if signal.getsignal(signum) not in (signal.SIG_DFL, signal.SIG_IGN, signal.default_int_handler):
        os.kill(os.getpid(), signum)
