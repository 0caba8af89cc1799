"""Listening to JAX's monitoring events for the length of a block, on every JAX the pins
allow: JAX 0.8 has no way to unregister a listener, so there the listener stays registered
and is silenced when the block ends."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

from jax import monitoring


@contextlib.contextmanager
def listening(kind: str, callback: Callable[..., Any]) -> Iterator[None]:
    """Call ``callback`` with each monitoring record of ``kind`` (``"event"`` or
    ``"event_duration"``, as in ``jax.monitoring.register_<kind>_listener``) while the block
    runs."""
    live = True

    def listener(*args: Any, **kwargs: Any) -> None:
        if live:
            callback(*args, **kwargs)

    register = (
        "register_event_listener" if kind == "event" else "register_event_duration_secs_listener"
    )
    getattr(monitoring, register)(listener)
    try:
        yield
    finally:
        live = False
        unregister = getattr(monitoring, f"unregister_{kind}_listener", None)
        if unregister is not None:
            unregister(listener)
