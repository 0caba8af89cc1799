"""Random draws that do not depend on ``jax_enable_x64``, for the reset distributions of the
built-in systems and of a user's own.

``jax.random.uniform`` and ``jax.random.normal`` turn the same key into other numbers in
float64 than in float32 (they use 64 random bits instead of 32), so a user who turns on
``jax_enable_x64`` would get other initial states from the same reset seeds. The draws here
are always made in float32, the default precision, and only then cast to the default float
type: the same key gives the same starts in both modes (in float64, the float32 values
exactly), and float32 runs are unchanged bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, PRNGKeyArray


def _default_float(x: Array) -> Array:
    return x.astype(jnp.result_type(float))


def uniform(
    key: PRNGKeyArray,
    shape: Sequence[int] = (),
    minval: ArrayLike = 0.0,
    maxval: ArrayLike = 1.0,
) -> Array:
    """``jax.random.uniform(key, shape, float32, minval, maxval)`` in the default float type."""
    return _default_float(jax.random.uniform(key, shape, jnp.float32, minval, maxval))


def normal(key: PRNGKeyArray, shape: Sequence[int] = ()) -> Array:
    """``jax.random.normal(key, shape, float32)`` in the default float type."""
    return _default_float(jax.random.normal(key, shape, jnp.float32))
