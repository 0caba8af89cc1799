"""The finite-horizon problem a planner solves at each control step, and what a solve reports."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PyTree


class Problem(eqx.Module):
    """``min_u  sum_{k<H} loss(x_k, u_k) + terminal_weight * terminal_cost(x_H)`` subject to
    ``x_{k+1} = f(x_k, u_k)`` from a given ``x_0`` and ``low <= u_k <= high``.

    ``f`` and the per-step loss are the task's own ``step`` and step loss (for Pendulum the
    Gymnasium dynamics and cost); the model's terminations are ignored (a planner treats the
    plan as if the episode went on).

    ``terminal_cost`` is part of the PyTree: an ``eqx.Module`` (a ``mpc.ValueNetwork``) is
    differentiated and trained like the model's parameters; a plain function is held in a
    ``FixedCost`` (static, a constant of the compiled solve).
    """

    task: Any = eqx.field(static=True)
    step_loss: Callable = eqx.field(static=True)
    terminal_cost: Any
    params: PyTree
    low: Float[Array, " m"]
    high: Float[Array, " m"]
    terminal_weight: Float[Array, ""]

    def dynamics(self, state: Array, action: Array) -> Array:
        return self.task.step(self.params, state, action)[0]

    def running_cost(self, state: Array, action: Array) -> Array:
        nxt, reward, _ = self.task.step(self.params, state, action)
        return self.step_loss(self.params, state, action, nxt, reward)

    def final_cost(self, state: Array) -> Array:
        if self.terminal_cost is None:
            return jnp.zeros(())
        return self.terminal_weight * self.terminal_cost(state)

    def rollout(self, x0: Array, actions: Float[Array, "H m"]) -> tuple[Array, Array]:
        """The states ``x_0 ... x_H`` ([H+1, d]) of a plan and its total cost."""

        def one(x, u):
            nxt, reward, _ = self.task.step(self.params, x, u)
            return nxt, (nxt, self.step_loss(self.params, x, u, nxt, reward))

        last, (xs, costs) = jax.lax.scan(one, x0, actions)
        states = jnp.concatenate([x0[None], xs])
        return states, costs.sum() + self.final_cost(last)

    def cost(self, x0: Array, actions: Float[Array, "H m"]) -> Array:
        return self.rollout(x0, actions)[1]


class FixedCost(eqx.Module):
    """A plain function ``cost(state) -> scalar`` as a terminal cost: static (not trained), so
    that the problem's PyTree holds only arrays."""

    function: Callable = eqx.field(static=True)

    def __call__(self, state: Array) -> Array:
        return self.function(state)


def as_terminal_cost(cost: Any) -> Any:
    """``cost`` as a ``Problem.terminal_cost``: an ``eqx.Module`` (trainable) as it is, a plain
    function wrapped in ``FixedCost``, ``None`` as ``None``."""
    if cost is None or isinstance(cost, eqx.Module):
        return cost
    return FixedCost(cost)


class SolveInfo(eqx.Module):
    """What one plan's solve reports (arrays, so that a closed-loop scan stacks them per step).

    Attributes:
        initial_cost: the warm start's cost.
        cost: the returned plan's cost (never above ``initial_cost``: a solver returns the best
            plan it saw).
        last_improvement: the decrease of the cost in the solver's last iteration.
        converged: the last iteration improved the cost by less than the solver's ``tol``
            (relative to the cost); ``False`` means the fixed iteration budget ended while the
            plan was still improving.
        finite: the solver's plan was finite; where it was not, the planner applied the warm
            start instead (never a NaN action).
    """

    initial_cost: Float[Array, ""]
    cost: Float[Array, ""]
    last_improvement: Float[Array, ""]
    converged: Bool[Array, ""]
    finite: Bool[Array, ""]

    @classmethod
    def of(cls, plan: Array, initial_cost: Array, cost: Array, last: Array, tol: float):
        """The report of a solve that returned ``plan`` at ``cost``, its last iteration having
        improved the cost by ``last`` (converged: ``last <= tol |cost|``)."""
        return cls(
            initial_cost=initial_cost,
            cost=cost,
            last_improvement=last,
            converged=last <= tol * jnp.abs(cost),
            finite=jnp.all(jnp.isfinite(plan)) & jnp.isfinite(cost),
        )


def stop_gradient(tree: Any) -> Any:
    """``lax.stop_gradient`` on the arrays of ``tree``, other leaves (a network's activation
    function) as they are."""
    return jax.tree.map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, tree)


def squash(z: Array, low: Array, high: Array) -> Array:
    """``low + (high - low) (tanh z + 1) / 2``: any real ``z`` to an action within the bounds."""
    return low + (high - low) * (jnp.tanh(z) + 1) / 2


def unsquash(u: Array, low: Array, high: Array) -> Array:
    """The inverse of ``squash``, with ``u`` kept just inside the bounds (tanh saturates)."""
    s = jnp.clip(2 * (u - low) / (high - low) - 1, -0.999, 0.999)
    return jnp.arctanh(s)
