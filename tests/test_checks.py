"""``check_task``: the built-in tasks pass, with parity against their Gymnasium twins; a broken
task fails with one line that names the method and what is wrong; ``train`` checks shapes
before it compiles anything, and trains a task without built-in losses on a loss passed in."""

from __future__ import annotations

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import ConfigError, check_task
from diffcontrol.checks import RTOL, validate_task
from diffcontrol.errors import TaskCheckError
from diffcontrol.tasks import CartPole, Pendulum

from ._tasks import walked

GYM_TASKS = [name for name in walked() if diffcontrol.make(name).gym_id]


@pytest.mark.slow
@pytest.mark.parametrize("name", GYM_TASKS)
def test_builtin_tasks_pass_with_parity(name):
    task = diffcontrol.make(name)
    report = check_task(task, states=16, steps=40)
    assert report.env_id == task.gym_id
    assert report.passed == (
        "shapes",
        "jit",
        "vmap",
        "grad",
        "finite",
        "deterministic",
        "action reaches the outputs",
        f"parity with {task.gym_id}",
    )
    assert report.skipped == ()
    assert report.dtype == "float32"
    # Every trajectory compares its steps until it terminates (CartPole's random pushes end
    # episodes within 40 steps; the pendulum never terminates).
    assert 16 <= report.compared_steps <= 16 * 40
    if name == "cartpole":
        assert report.compared_steps < 16 * 40
    else:
        assert report.compared_steps == 16 * 40
    # float32 against Gymnasium's float64: a few ulps of quantities up to ~20.
    assert 0 < report.max_errors["observation"] < 1e-5
    assert report.max_errors["reward"] < 1e-4
    assert "parity with" in str(report)


class RailParams(eqx.Module):
    mass: float = 1.0
    drag: float = 0.3
    dt: float = 0.05


class Rail(diffcontrol.Task):
    """The custom task of ``examples/custom_task.py``: a cart with drag on a rail."""

    name = "test-rail"
    summary = "a cart on a rail"
    episode_length = 20
    observation_size = 2
    action_size = 1
    action_head = "tanh"
    losses = ("quadratic",)

    def default_params(self):
        return RailParams()

    def reset(self, key, params):
        return jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)

    def step(self, params, state, action):
        x, v = state
        v = v + (action[0] - params.drag * v) / params.mass * params.dt
        x = x + v * params.dt
        return jnp.stack([x, v]), -(x**2 + 0.1 * v**2), jnp.asarray(False)

    def observe(self, state):
        return state

    def step_loss(self, name):
        return lambda params, state, action, next_state, reward: -reward

    def default_config(self):
        return diffcontrol.TrainConfig(
            updates=4, batch=4, window=2, horizon=20, eval_every=2, eval_episodes=2
        )


def test_a_custom_task_passes_and_parity_is_skipped():
    report = check_task(Rail(), states=8)
    assert "grad" in report.passed and "deterministic" in report.passed
    assert report.env_id is None and report.max_errors == {}
    assert report.skipped == ("parity: the task has no Gymnasium twin (set gym_id or pass env_id)",)


def _one_line_error(task, **kwargs) -> str:
    with pytest.raises(TaskCheckError) as info:
        check_task(task, **{"states": 8, "steps": 10, **kwargs})
    message = str(info.value)
    assert "\n" not in message
    return message


class LongStateRail(Rail):
    def step(self, params, state, action):
        next_state, reward, terminated = super().step(params, state, action)
        return jnp.append(next_state, 0.0), reward, terminated


class WideObservationRail(Rail):
    observation_size = 3


class NanRewardRail(Rail):
    def step(self, params, state, action):
        next_state, reward, terminated = super().step(params, state, action)
        return next_state, jnp.sqrt(reward - 1.0), terminated  # reward <= 0: sqrt of < 0


class NumpyRandomRail(Rail):
    def reset(self, key, params):
        return jnp.asarray(np.random.uniform(-1.0, 1.0, 2), jnp.float32)


class ActionBlindRail(Rail):
    def step(self, params, state, action):
        return super().step(params, state, 0.0 * action)


class VectorRewardRail(Rail):
    def step(self, params, state, action):
        next_state, reward, terminated = super().step(params, state, action)
        return next_state, reward * jnp.ones(2), terminated


class FloatTerminatedRail(Rail):
    def step(self, params, state, action):
        next_state, reward, _ = super().step(params, state, action)
        return next_state, reward, jnp.asarray(0.0)


class TwoTupleRail(Rail):
    def step(self, params, state, action):
        return super().step(params, state, action)[:2]


class KinkedRail(Rail):
    def step(self, params, state, action):
        next_state, reward, terminated = super().step(params, state, action)
        return next_state, reward - jnp.sqrt(action[0] ** 2 * 0.0), terminated  # d/da = nan


@pytest.mark.parametrize(
    "task, message",
    [
        (
            LongStateRail(),
            "LongStateRail.step returned a state of shape (3,) for a state of shape (2,)",
        ),
        (
            WideObservationRail(),
            "WideObservationRail.observe returned an observation of shape (2,), but "
            "WideObservationRail.observation_size is 3 (expected shape (3,))",
        ),
        (
            VectorRewardRail(),
            "VectorRewardRail.step returned a reward of shape (2,); it must be a scalar (shape ())",
        ),
        (
            FloatTerminatedRail(),
            "FloatTerminatedRail.step returned an array of shape () and dtype float32 as "
            "terminated; it must be a boolean scalar",
        ),
        (
            TwoTupleRail(),
            "TwoTupleRail.step returned a tuple of 2 items; it must return (next_state, reward, "
            "terminated)",
        ),
        (NanRewardRail(), "NanRewardRail.step returned a non-finite reward (nan) at state ["),
        (NumpyRandomRail(), "NumpyRandomRail.reset is not deterministic: the same key gave ["),
        (ActionBlindRail(), "ActionBlindRail.step ignores the action"),
        (KinkedRail(), "the gradient of KinkedRail.step with respect to the action is not finite"),
    ],
    ids=lambda x: type(x).__name__ if isinstance(x, Rail) else None,
)
def test_a_broken_task_fails_with_one_line(task, message):
    assert _one_line_error(task).startswith(message)


class HeavyPendulum(Pendulum):
    """Pendulum-v1 with the wrong gravity: every step but those from rest disagrees."""

    def default_params(self):
        return eqx.tree_at(lambda p: p.g, super().default_params(), 12.0)


class EndlessCartPole(CartPole):
    """CartPole-v1 that never terminates."""

    def step(self, params, state, action):
        next_state, reward, _ = super().step(params, state, action)
        return next_state, reward, jnp.asarray(False)


@pytest.mark.slow
def test_parity_failure_names_the_state():
    message = _one_line_error(HeavyPendulum())
    pattern = (
        r"HeavyPendulum\.step does not match Gymnasium's Pendulum-v1 on the observation from "
        r"state \[\S+, \S+\] with action \[\S+\] \(reset state 0, step 0\): \[.*\] against "
        rf"Gymnasium's \[.*\] \(rtol {RTOL:g}, atol .*\)"
    )
    assert re.fullmatch(pattern, message), message

    message = _one_line_error(EndlessCartPole(), steps=40)
    assert re.match(
        r"EndlessCartPole\.step does not match Gymnasium's CartPole-v1 on termination from "
        r"state \[.*\] with action \[-?1\] \(reset state \d+, step \d+\): terminated=False "
        r"against Gymnasium's True$",
        message,
    ), message


class SwappedPendulum(Pendulum):
    """The pendulum with its state stored as ``(theta_dot, theta)``: Gymnasium's layout is
    ``(theta, theta_dot)``, so it says how to set its twin's state."""

    gym_id = None  # no twin of its own: the check is told which one

    def reset(self, key, params):
        return super().reset(key, params)[::-1]

    def step(self, params, state, action):
        next_state, reward, terminated = super().step(params, state[::-1], action)
        return next_state[::-1], reward, terminated

    def observe(self, state):
        return super().observe(state[::-1])

    def set_gym_state(self, env, state):
        env.unwrapped.state = np.asarray(state[::-1], np.float64)


@pytest.mark.slow
def test_set_gym_state_hook_and_env_id():
    report = check_task(SwappedPendulum(), env_id="Pendulum-v1", states=8, steps=10)
    assert report.env_id == "Pendulum-v1" and report.compared_steps == 80


@pytest.mark.slow
def test_a_continuous_task_is_checked_without_parity():
    report = check_task(diffcontrol.make("cartpole-swingup"), states=4)
    assert report.passed[-1] == "action reaches the outputs"
    assert report.skipped[0].startswith("parity: a continuous-time task")
    with pytest.raises(ConfigError, match="continuous-time"):
        check_task(diffcontrol.make("cartpole-swingup"), env_id="Pendulum-v1", states=4)


def test_bad_arguments():
    with pytest.raises(ConfigError, match="states must be a positive integer"):
        check_task(Rail(), states=0)


# --- train checks the task first (part of the trainer's entry point) ---------------------


def test_train_names_a_wrong_state_shape_before_compiling():
    task = LongStateRail()
    with pytest.raises(TaskCheckError) as info:
        diffcontrol.train(task)
    assert str(info.value) == (
        "LongStateRail.step returned a state of shape (3,) for a state of shape (2,)"
    )


def test_validate_task_only_traces():
    state = validate_task(Rail())
    assert state.shape == (2,) and state.dtype == jnp.float32
    with pytest.raises(TaskCheckError, match=r"^WideObservationRail\.observe returned"):
        validate_task(WideObservationRail())


class LosslessRail(Rail):
    """A task without built-in losses: every run passes its own."""

    losses = ()
    step_loss = diffcontrol.Task.step_loss


@pytest.mark.slow
def test_a_task_without_builtin_losses_trains_on_a_loss_passed_in():
    task = LosslessRail()
    assert LosslessRail.losses == () and "step_loss" not in diffcontrol.Task.__abstractmethods__

    def cost(params, state, action, next_state, reward):
        return -reward

    result = diffcontrol.train(task, step_loss=cost)
    assert result.metrics["updates"] == 4
    with pytest.raises(ConfigError, match=r"has no built-in losses; pass one to .*step_loss="):
        diffcontrol.train(task)
