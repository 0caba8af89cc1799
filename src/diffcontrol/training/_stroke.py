"""A start from an open-loop stroke: a periodic drive distilled into the controller.

A swimming or walking task's return comes from a gait, a limit cycle of the closed loop. From
random weights, truncated BPTT settles in a pose held at the joint limits or in a slow stroke
(Swimmer: docs/benchmarks.md), and no small step of the weights leaves such a fixed point. A
task that declares a ``stroke`` (a clipped sinusoid per action, from a search of open-loop
drives: ``benchmarks/swimmer_gaits.py``) starts its training from a controller that plays it
in closed loop: the drive runs from the task's own resets on its own simulator, and the
network is fitted by least squares to the drive's actions at the states it passes through
(behaviour cloning of a clock by the state it leaves). BPTT then trains from there.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optax
from jaxtyping import Array, PRNGKeyArray, PyTree

from ..controllers import MLPController
from ..tasks import Stroke
from ..tasks._hooks import task_hook


@task_hook
def stroke(task: Any) -> Stroke | None:
    """The open-loop stroke that ``task``'s training starts from, or ``None`` (random weights):
    a task declares one with a method ``stroke(self)``."""
    del task
    return None


def imitate(
    task: Any,
    controller: MLPController,
    params: PyTree,
    key: PRNGKeyArray,
    drive: Stroke,
    *,
    episodes: int = 16,
    settle: int = 100,
    fit_steps: int = 3000,
    learning_rate: float = 3e-3,
) -> tuple[MLPController, float]:
    """``controller`` fitted to play ``drive`` in closed loop, and the fit's mean squared error.

    The drive runs for ``task.episode_length`` steps from ``episodes`` resets; the states after
    the first ``settle`` steps (the transient from the reset into the cycle) and the drive's
    actions there are the data. Adam fits the whole batch ``fit_steps`` times, in one program.
    """
    low, high = controller.action_low, controller.action_high
    steps = jnp.arange(task.episode_length)

    def episode(k: PRNGKeyArray) -> tuple[Array, Array]:
        def body(state: Array, t: Array) -> tuple[Array, tuple[Array, Array]]:
            action = drive.actions(t, low, high)
            next_state, _, _ = task.step(params, state, action)
            return next_state, (task.observe(state), action)

        _, (obs, actions) = jax.lax.scan(body, task.reset(k, params), steps)
        return obs[settle:], actions[settle:]

    @eqx.filter_jit
    def fit(controller: MLPController, keys: PRNGKeyArray) -> tuple[MLPController, Array]:
        obs, actions = jax.vmap(episode)(keys)
        obs, actions = obs.reshape(-1, obs.shape[-1]), actions.reshape(-1, actions.shape[-1])
        weights, rest = eqx.partition(controller, eqx.is_inexact_array)
        optimizer = optax.adam(learning_rate)

        def loss(w: PyTree) -> Array:
            c = eqx.combine(w, rest)
            return jnp.mean(jnp.square(jax.vmap(c)(obs) - actions))

        def update(carry: tuple[PyTree, Any], _: Any) -> tuple[tuple[PyTree, Any], Array]:
            w, opt = carry
            value, grad = jax.value_and_grad(loss)(w)
            change, opt = optimizer.update(grad, opt, w)
            return (optax.apply_updates(w, change), opt), value

        (weights, _), _ = jax.lax.scan(update, (weights, optimizer.init(weights)), None, fit_steps)
        return eqx.combine(weights, rest), loss(weights)

    fitted, error = fit(controller, jax.random.split(key, episodes))
    return fitted, float(error)
