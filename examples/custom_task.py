"""Bring your own simulator: a task in about 40 lines, trained by BPTT like the built-in ones.

The system is a cart on a rail with friction (a double integrator with drag) that must stop at
x = 0 from a random start. The dynamics are ordinary JAX code; the physical constants live in
an ``equinox.Module`` so they could be fitted or randomised; the loss is any differentiable
function of a step.

    python examples/custom_task.py            # trains in a few seconds and prints the result
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

import diffcontrol


class RailParams(eqx.Module):
    mass: float = 1.0  # kg
    drag: float = 0.3  # N s/m
    dt: float = 0.05  # s


class Rail(diffcontrol.Task):
    name = "rail"
    summary = "stop a cart with drag at x = 0 using a force of at most 1 N"
    episode_length = 100
    observation_size = 2
    action_size = 1
    action_head = "tanh"
    action_low, action_high = (-1.0,), (1.0,)
    losses = ("quadratic",)

    def default_params(self):
        return RailParams()

    def reset(self, key, params):
        return jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)  # (x, v)

    def step(self, params, state, action):
        x, v = state
        a = (action[0] - params.drag * v) / params.mass
        v = v + a * params.dt  # semi-implicit Euler
        x = x + v * params.dt
        next_state = jnp.stack([x, v])
        reward = -(x**2 + 0.1 * v**2)
        return next_state, reward, jnp.asarray(False)

    def observe(self, state):
        return state

    def step_loss(self, name):
        return lambda params, state, action, next_state, reward: -reward

    def default_config(self):
        return diffcontrol.TrainConfig(
            updates=200, batch=32, window=25, horizon=100, learning_rate=1e-2
        )


def main(updates: int = 200) -> diffcontrol.TrainResult:
    task = diffcontrol.register(Rail())
    result = diffcontrol.train(task, task.default_config().replace(updates=updates), progress=print)
    first, last = result.curve[0]["eval_return"], result.curve[-1]["eval_return"]
    print(f"return of an episode: {first:.2f} untrained -> {last:.2f} trained")
    return result


if __name__ == "__main__":
    main()
