"""The contract battery over every registered task, discrete and continuous.

What every trainer, environment and policy relies on, checked the same way for each task by
the pieces of ``diffcontrol.check_task``: the class attributes and the built-in losses; the
shapes and dtypes of ``reset``/``step``/``observe`` (``initial_state``/``vector_field``/
``observe``) by ``jax.eval_shape``; and, in one compiled program a task, the methods under
``jit``, ``vmap`` and ``grad`` on a small batch in float32: finite outputs and gradients, an
action that reaches the outputs, the same result for the same key. (Parity with Gymnasium is
``tests/test_checks.py``'s and ``tests/test_systems_vs_gymnasium.py``'s.)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import pytest

import diffcontrol
from diffcontrol.checks import CONTRACT, check_contract, default_params, validate_task
from diffcontrol.config import ODETrainConfig, TrainConfig
from diffcontrol.controllers import HEADS
from diffcontrol.tasks import ContinuousTask, Task
from diffcontrol.training import make_ode_trainer

from ._tasks import walked

NAMES = walked()
DISCRETE = [n for n in NAMES if isinstance(diffcontrol.make(n), Task)]
BATCH = 8


@pytest.fixture(params=NAMES)
def task(request):
    return diffcontrol.make(request.param)


def test_every_task_is_in_the_contract():
    assert len(NAMES) >= 7
    kinds = {isinstance(diffcontrol.make(n), ContinuousTask) for n in NAMES}
    assert kinds == {True, False}  # both trainers' tasks are covered


def test_attributes(task):
    assert diffcontrol.make(task.name) is task and task.summary
    assert isinstance(task, Task | ContinuousTask)
    assert task.action_head in HEADS
    for attr, size in (
        ("action_low", task.action_size),
        ("action_high", task.action_size),
        ("obs_offset", task.observation_size),
        ("obs_scale", task.observation_size),
    ):
        value = getattr(task, attr)
        assert value is None or len(value) == size, attr
    if task.action_head in ("tanh", "sigmoid") and task.action_low is not None:
        assert all(lo < hi for lo, hi in zip(task.action_low, task.action_high))
    assert isinstance(task.episode_length, int) and task.episode_length > 0
    expected = ODETrainConfig if isinstance(task, ContinuousTask) else TrainConfig
    assert isinstance(task.default_config(), expected)
    for recipe in task.recipes().values():
        task.default_config().replace(**recipe)  # every recipe is a valid configuration


def test_builtin_losses_return_a_scalar(task):
    """Each built-in loss, traced on abstract inputs of the task's shapes, is one number."""
    assert task.losses, "a built-in task names at least one loss"
    params = default_params(task)
    state = validate_task(task, params)
    for name in task.losses:
        if isinstance(task, ContinuousTask):
            # The ODE trainer traces the loss itself when it is built (make_ode_trainer).
            make_ode_trainer(task, task.default_config().replace(loss=name))
            continue
        loss = task.step_loss(name)
        action = jax.ShapeDtypeStruct((task.action_size,), state.dtype)
        reward = jax.ShapeDtypeStruct((), state.dtype)
        out = jax.eval_shape(loss, params, state, action, state, reward)
        assert out.shape == () and jnp.issubdtype(out.dtype, jnp.floating), name


def test_shapes_and_dtypes(task):
    state = validate_task(task)
    assert state.dtype == jnp.float32  # JAX's default precision, the one tasks train in
    if isinstance(task, ContinuousTask):
        assert state.ndim == 1


@pytest.mark.slow
def test_jit_vmap_grad_finite_same_key(task):
    """One compiled program a task: reset/step/observe (or the vector field) batched, their
    gradients, finiteness, the action's reach, and the same key giving the same state."""
    assert check_contract(task, states=BATCH, seed=0) == CONTRACT


@pytest.mark.parametrize("name", DISCRETE)
def test_reset_is_a_function_of_its_key(name):
    """Same key, same state; different keys, different states (a random reset distribution).
    (A continuous-time task starts from one initial state.)"""
    task = diffcontrol.make(name)
    params = default_params(task)
    keys = jax.random.split(jax.random.PRNGKey(3), BATCH)
    # Two separate traces and compilations, so nothing but the key can make them agree.
    first, again = (jax.jit(jax.vmap(task.reset, (0, None)))(keys, params) for _ in range(2))
    assert jnp.array_equal(first, again)
    assert len({tuple(map(float, s)) for s in first}) == BATCH
