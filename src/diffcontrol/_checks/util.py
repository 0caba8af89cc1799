"""Small pieces shared by the task checks."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NoReturn

import jax
import jax.numpy as jnp
import numpy as np

from ..controllers import MLPController, apply_head
from ..errors import TaskCheckError
from ..tasks import controller_kwargs

ACTION_SCALE = 2.0
"""Random valid actions are the task's action head applied to raw outputs ``~ N(0, 2^2)``:
spread over a bounded head's range, ``+-1`` for ``sign``, a few units for ``linear``."""

SAME_RTOL, SAME_ATOL = 1e-4, 1e-5
"""How far a batched (``vmap``) result may be from the same example computed alone: rounding
(XLA fuses and reorders operations differently). A function that is not pure is off by far
more."""


def fail(message: str) -> NoReturn:
    raise TaskCheckError(message)


def first_line(error: Exception) -> str:
    """The first line of an exception's message (JAX's run to many)."""
    lines = str(error).strip().splitlines()
    return lines[0] if lines else ""


def trace(who: str, inputs: str, fn: Callable[..., Any], *args: Any) -> Any:
    """``jax.eval_shape(fn, *args)``; a failure names ``who`` and the ``inputs`` it got."""
    try:
        return jax.eval_shape(fn, *args)
    except TaskCheckError:
        raise
    except Exception as e:  # a user's method can fail in any way: say whose and on what
        raise TaskCheckError(
            f"{who} failed on {inputs}: {type(e).__name__}: {first_line(e)}"
        ) from e


def fmt(x: Any) -> str:
    """A value on one line: ``0.5``, ``[0.1, -2]``, ``True``."""
    a = np.asarray(x)
    if a.dtype == np.bool_:
        return str(a.tolist())
    if a.ndim == 0:
        return f"{float(a):.6g}"
    return "[" + ", ".join(f"{float(v):.6g}" for v in a.reshape(-1)) + "]"


def same(a: Any, b: Any) -> bool:
    """Equal up to the rounding of ``SAME_RTOL``/``SAME_ATOL`` (booleans exactly)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return False
    if a.dtype == np.bool_ or b.dtype == np.bool_:
        return bool(np.array_equal(a, b))
    return bool(np.allclose(a, b, rtol=SAME_RTOL, atol=SAME_ATOL, equal_nan=True))


def valid_action(task: Any, raw: jax.Array) -> jax.Array:
    """The task's action head applied to the raw output ``raw`` (shape ``(action_size,)``)."""
    n = task.action_size
    low = jnp.asarray(task.action_low if task.action_low is not None else (-1.0,) * n, raw.dtype)
    high = jnp.asarray(task.action_high if task.action_high is not None else (1.0,) * n, raw.dtype)
    return apply_head(task.action_head, raw, low, high).astype(raw.dtype)


def controller_for(task: Any, key: jax.Array) -> MLPController:
    """A small random controller of the task's shape (one hidden layer of 8)."""
    return MLPController(key, hidden=(8,), **controller_kwargs(task))
