"""Discrete-time rollouts: a controller in closed loop with a task's simulator, under ``lax.scan``."""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray, PyTree

from .tasks import Task

Controller = Callable[[Array], Array]


class Trajectory(eqx.Module):
    """One closed-loop rollout of ``T`` steps.

    ``alive[t]`` is true for the steps that count: those up to and including the step on
    which the episode terminated. Later steps are still simulated (shapes are static under
    ``jit``) but masked out of ``total_return``.
    """

    states: Float[Array, "T+1 state"]
    observations: Float[Array, "T obs"]
    actions: Float[Array, "T act"]
    rewards: Float[Array, " T"]
    terminated: Bool[Array, " T"]
    alive: Bool[Array, " T"]

    @property
    def total_return(self) -> Array:
        """Sum of the rewards of the steps that count."""
        return jnp.sum(jnp.where(self.alive, self.rewards, 0.0))

    @property
    def length(self) -> Array:
        """Number of steps that count (the episode length)."""
        return jnp.sum(self.alive)


def rollout(
    task: Task, params: PyTree, controller: Controller, state0: Array, num_steps: int
) -> Trajectory:
    """Run ``controller`` on ``task`` from ``state0`` for ``num_steps`` steps.

    Differentiable end to end with respect to ``params``, ``state0`` and the controller's
    weights: this is the unrolled computation graph that BPTT differentiates.
    """

    def body(carry, _):
        state, alive = carry
        obs = task.observe(state)
        action = controller(obs)
        next_state, reward, term = task.step(params, state, action)
        return (next_state, alive & ~term), (state, obs, action, reward, term, alive)

    (last, _), (states, obs, actions, rewards, term, alive) = jax.lax.scan(
        body, (state0, jnp.asarray(True)), None, length=num_steps
    )
    return Trajectory(
        states=jnp.concatenate([states, last[None]], axis=0),
        observations=obs,
        actions=actions,
        rewards=rewards,
        terminated=term,
        alive=alive,
    )


def batch_returns(
    task: Task, params: PyTree, controller: Controller, keys: PRNGKeyArray, num_steps: int
) -> Float[Array, " batch"]:
    """Returns of ``len(keys)`` episodes from the task's reset distribution (one per key)."""

    def one(key):
        return rollout(task, params, controller, task.reset(key, params), num_steps).total_return

    return jax.vmap(one)(keys)
