"""Bring your own continuous-time system: a controller inside your ODE, trained through the solve.

A mass on a damped spring must be moved to x = 1 m and held there. The dynamics are an
ordinary vector field ``f(t, y, args)``; the controller's force enters through ``args``
(``force_fn``), so every gradient method, the continuous adjoint included, reaches its
weights; the loss is any function of the saved trajectory.

    python examples/continuous_task.py        # trains in a few seconds and prints the result
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

import diffcontrol


class SpringParams(eqx.Module):
    mass: float = 1.0  # kg
    stiffness: float = 4.0  # N/m
    damping: float = 0.2  # N s/m


class SpringTrajectory(eqx.Module):
    t: jax.Array
    x: jax.Array
    v: jax.Array
    force: jax.Array


class Spring(diffcontrol.ContinuousTask):
    name = "spring"
    summary = "move a mass on a damped spring to x = 1 m and hold it there"
    observation_size = 2
    action_size = 1
    action_head = "linear"
    losses = ("reach",)
    state_names = ("x", "v")
    feature_names = ("x", "v")

    def default_params(self):
        return SpringParams()

    def default_config(self):
        return diffcontrol.ODETrainConfig(horizon_s=4.0, saves=41, updates=300, learning_rate=0.02)

    def initial_state(self, params):
        return jnp.zeros(2)  # at rest at x = 0

    def vector_field(self, t, y, args):
        p, force_fn = args
        x, v = y
        force = force_fn(t, y)
        return jnp.stack([v, (force - p.stiffness * x - p.damping * v) / p.mass])

    def observe(self, state):
        return state

    def trajectory(self, params, controller, ts, ys):
        force = jax.vmap(lambda y: controller(self.observe(y))[0])(ys)
        return SpringTrajectory(t=ts, x=ys[:, 0], v=ys[:, 1], force=force)

    def trajectory_loss(self, name):
        return lambda tr: jnp.mean((tr.x - 1.0) ** 2) + 1e-3 * jnp.mean(tr.force**2)


def main(updates: int = 300) -> diffcontrol.TrainResult:
    task = Spring()
    config = task.default_config().replace(updates=updates)
    result = diffcontrol.train(task, config)
    first, last = result.curve[0]["eval_loss"], result.curve[-1]["eval_loss"]
    print(f"loss {first:.3f} -> {last:.3f} after {updates} updates")
    return result


if __name__ == "__main__":
    main()
