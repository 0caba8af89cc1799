"""Gradient shooting: the plan's actions optimised directly by an optax optimiser."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, Float

from ._problem import Problem, SolveInfo, squash, unsquash


class Shooting(eqx.Module):
    """Single shooting through the model: ``J(u(z))`` minimised over unconstrained ``z`` with
    ``u = low + (high - low) (tanh z + 1) / 2`` (so every iterate is within the bounds), by a
    fixed number of steps of any optax optimiser (a value, like a diffrax solver).

    The gradient is reverse-mode through the rollout (``jax.value_and_grad``); the optimiser's
    ``update`` also gets ``value``, ``grad`` and ``value_fn``, so optimisers with a line search
    (``optax.lbfgs()``) work as they are. The best plan seen is returned.

    Attributes:
        optimizer: an ``optax.GradientTransformation`` (default Adam with learning rate 0.3).
        iterations: optimiser steps per solve.
        tol: converged when the last step changed the cost by less than ``tol`` times it.
    """

    optimizer: Any = eqx.field(static=True, default_factory=lambda: optax.adam(0.3))
    iterations: int = eqx.field(static=True, default=30)
    tol: float = 1e-4

    def solve(self, problem: Problem, x0: Array, actions: Float[Array, "H m"]):
        """Improve the plan ``actions`` from ``x0``; returns ``(plan, SolveInfo)``."""

        def value_fn(z):
            return problem.cost(x0, squash(z, problem.low, problem.high))

        z0 = unsquash(actions, problem.low, problem.high)
        first = value_fn(z0)
        state = self.optimizer.init(z0)

        def iteration(carry, _):
            z, state, best_z, best, previous = carry
            value, grad = jax.value_and_grad(value_fn)(z)
            better = value < best
            best_z = jnp.where(better, z, best_z)
            best = jnp.where(better, value, best)
            updates, state = self.optimizer.update(
                grad, state, z, value=value, grad=grad, value_fn=value_fn
            )
            return (optax.apply_updates(z, updates), state, best_z, best, value), previous - value

        init = (z0, state, z0, first, first)
        (z, _, best_z, best, _), changes = jax.lax.scan(
            iteration, init, None, length=self.iterations
        )
        last_value = value_fn(z)  # the last update's plan, not yet scored
        best_z = jnp.where(last_value < best, z, best_z)
        best = jnp.minimum(best, jnp.where(jnp.isfinite(last_value), last_value, jnp.inf))
        plan = squash(best_z, problem.low, problem.high)
        last = jnp.abs(changes[-1])
        return plan, SolveInfo.of(plan, first, best, last, self.tol)
