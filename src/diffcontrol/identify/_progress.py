"""Progress of model learning's long steps (a large data file read, a long fit), reported to
the command's printer without every function on the way taking it.

``fit_dir`` (``diffcontrol fit``, and the loop's fits) runs its read and its fit inside
``reporting(progress)``; the long loops ask ``reporter()`` and say how far they are at most
every ``SECONDS``, once they have run that long.
"""

from __future__ import annotations

import contextlib
import contextvars
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")

SECONDS = 5.0
"""A long step reports at most this often, and not before it has run this long."""

_PROGRESS: contextvars.ContextVar[Callable[[str], None] | None] = contextvars.ContextVar(
    "identify_progress", default=None
)


@contextlib.contextmanager
def reporting(progress: Callable[[str], None] | None) -> Iterator[None]:
    """Within the block, the long steps of model learning report to ``progress``."""
    token = _PROGRESS.set(progress)
    try:
        yield
    finally:
        _PROGRESS.reset(token)


def reporter() -> Callable[[str], None] | None:
    """The progress printer of the enclosing ``reporting`` block, or ``None``."""
    return _PROGRESS.get()


def due(since: float) -> bool:
    """Whether ``SECONDS`` have passed since ``since`` (a ``time.perf_counter()``)."""
    return time.perf_counter() - since >= SECONDS


def ticking(items: Iterable[T], total: int, what: str) -> Iterator[T]:
    """``items`` as they are, saying ``what: i of total rows (s)`` to the enclosing
    ``reporting`` block every ``SECONDS`` while they are gone through (a large file's rows)."""
    progress = reporter()
    if progress is None:
        yield from items
        return
    t0 = said = time.perf_counter()
    for i, item in enumerate(items):
        if i % 10_000 == 0 and due(said):
            said = time.perf_counter()
            progress(f"{what}: {i:,} of {total:,} rows ({said - t0:.0f} s)")
        yield item
