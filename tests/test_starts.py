"""A reset distribution for continuous-time tasks: several starts per update."""

from __future__ import annotations

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol.training import make_ode_trainer, task_params
from examples.continuous_task import Spring


class RandomSpring(Spring):
    name = "random-spring"
    env_name = "RandomSpring"

    def reset(self, key, params):
        return jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)


TASK = diffcontrol.register(RandomSpring())


def _one(controller):
    return jax.tree.map(lambda x: x[None] if isinstance(x, jax.Array) else x, controller)


def test_the_default_reset_is_the_initial_state():
    spring = Spring()
    params = task_params(spring)
    np.testing.assert_array_equal(
        spring.reset(jax.random.PRNGKey(3), params), spring.initial_state(params)
    )
    assert (
        make_ode_trainer(spring, spring.default_config()).starts_of(jax.random.PRNGKey(0), params)
        is None
    )


@pytest.mark.slow
def test_several_starts_train_and_evaluate_on_the_reset_distribution():
    config = TASK.default_config().replace(updates=4, eval_every=2, starts=3, population=1)
    result = diffcontrol.train(TASK, config)
    assert result.metrics["simulated_episodes"] == 4 * 3  # updates x starts (of 2 windows each)
    trainer = make_ode_trainer(TASK, config)
    params = task_params(TASK)
    y0s = trainer.starts_of(jax.random.PRNGKey(0), params)
    assert y0s.shape == (3, 2) and not np.allclose(y0s[0], y0s[1])
    evaluate = jax.jit(trainer.evaluate)  # one program, not the solve's operations one by one
    a = evaluate(_one(result.controller), params, jax.random.PRNGKey(0))
    b = evaluate(_one(result.controller), params, jax.random.PRNGKey(1))
    assert np.isfinite(a).all() and not np.allclose(a, b)  # the starts come from the key
    loss, _ = jax.jit(trainer.member_loss)(result.controller, params, jnp.asarray(4.0), y0s)
    assert float(-a[0]) == pytest.approx(float(loss), rel=1e-5)


def test_the_gymnasium_environment_resets_from_the_distribution():
    env = gymnasium.make("diffcontrol/RandomSpring-v0")
    starts = {tuple(np.round(env.reset(seed=s)[0], 6)) for s in range(3)}
    assert len(starts) == 3


@pytest.mark.parametrize(
    "name", ["pendulum", "cartpole", "acrobot", "mountain-car-continuous", "trebuchet"]
)
def test_a_seed_gives_the_same_starts_with_float64_on(name):
    """Turning on ``jax_enable_x64`` changes the starts' precision, not which starts a key
    draws: the float64 starts are the float32 ones up to float32's rounding (the draws are
    the same float32 numbers; a task may scale them in float64, as the trebuchet's wind).
    Drawn in float64, the same key gives other numbers altogether (pendulum's key 0 gave
    [2.81, 0.96] in float32 and [-0.51, -0.57] in float64)."""
    task = diffcontrol.make(name)
    keys = jax.random.split(jax.random.PRNGKey(0), 64)
    starts32 = np.asarray(jax.vmap(lambda k: task.reset(k, task.default_params()))(keys))
    with jax.enable_x64(True):
        params = task.default_params()
        starts64 = np.asarray(jax.vmap(lambda k: task.reset(k, params))(keys))
    assert starts32.dtype == np.float32 and starts64.dtype == np.float64
    np.testing.assert_allclose(starts64, starts32, rtol=1e-6, atol=1e-7)
    assert np.ptp(starts32, axis=0).max() > 0  # the keys draw different starts
