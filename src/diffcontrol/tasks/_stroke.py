"""An open-loop stroke: a periodic drive a task can start its training from
(``training._stroke``)."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array


class Stroke(NamedTuple):
    """``action_i(t) = clip(amplitude_i sin(2 pi t / period + phase_i), low_i, high_i)`` at
    step ``t`` of an episode: a square-ish wave where the amplitude is past the bounds."""

    period: float
    """Steps per cycle."""
    amplitude: tuple[float, ...]
    """Per action, in the action's units, before the clip to its bounds."""
    phase: tuple[float, ...]
    """Per action, in radians."""

    def actions(self, step: Array, low: Array, high: Array) -> Array:
        """The drive's action at ``step`` (an integer array)."""
        angle = 2 * jnp.pi * step / self.period + jnp.asarray(self.phase)
        return jnp.clip(jnp.asarray(self.amplitude) * jnp.sin(angle), low, high)
