"""Shapes and dtypes of a task's methods by ``jax.eval_shape``: ``checks.validate_task``."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import PyTree

from ..rollout import force_fn
from ..tasks import AnyTask, ContinuousTask, Task
from .util import controller_for, fail, trace


def task_shapes(task: AnyTask, params: PyTree) -> jax.ShapeDtypeStruct:
    """See ``diffcontrol.checks.validate_task``."""
    name = type(task).__name__
    for attr in ("observation_size", "action_size"):
        value = getattr(task, attr, None)
        if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
            fail(f"{name}.{attr} must be a positive integer (a class attribute), got {value!r}")
    if isinstance(task, ContinuousTask):
        return _continuous_shapes(task, params)
    if isinstance(task, Task):
        return _discrete_shapes(task, params)
    fail(f"{task!r} is neither a diffcontrol.Task nor a diffcontrol.ContinuousTask")


def _array(name: str, what: str, out: Any) -> jax.ShapeDtypeStruct:
    """``out`` must be one floating-point array (an abstract value of ``jax.eval_shape``)."""
    if not isinstance(out, jax.ShapeDtypeStruct):
        fail(f"{name} returned {_describe(out)} as {what}; it must be one array")
    if not jnp.issubdtype(out.dtype, jnp.floating):
        fail(f"{name} returned {what} of dtype {out.dtype}; it must be a floating-point array")
    return out


def _describe(out: Any) -> str:
    if isinstance(out, jax.ShapeDtypeStruct):
        return f"an array of shape {out.shape} and dtype {out.dtype}"
    if isinstance(out, tuple | list):
        return f"a {type(out).__name__} of {len(out)} items"
    return f"a {type(out).__name__}"


def _observation_shape(task: AnyTask, state: jax.ShapeDtypeStruct) -> None:
    name = type(task).__name__
    obs = trace(f"{name}.observe", f"a state of shape {state.shape}", task.observe, state)
    obs = _array(f"{name}.observe", "the observation", obs)
    if obs.shape != (task.observation_size,):
        fail(
            f"{name}.observe returned an observation of shape {obs.shape}, but "
            f"{name}.observation_size is {task.observation_size} (expected shape "
            f"({task.observation_size},))"
        )


def _discrete_shapes(task: Task, params: PyTree) -> jax.ShapeDtypeStruct:
    name = type(task).__name__
    key = jax.eval_shape(lambda: jax.random.PRNGKey(0))  # abstract: nothing runs
    state = trace(f"{name}.reset", "a PRNG key and the parameters", task.reset, key, params)
    state = _array(f"{name}.reset", "the state", state)
    _observation_shape(task, state)
    action = jax.ShapeDtypeStruct((task.action_size,), state.dtype)
    inputs = f"a state of shape {state.shape} and an action of shape {action.shape}"
    out = trace(f"{name}.step", inputs, task.step, params, state, action)
    if not (isinstance(out, tuple | list) and len(out) == 3):
        fail(
            f"{name}.step returned {_describe(out)}; it must return "
            "(next_state, reward, terminated)"
        )
    next_state, reward, terminated = out
    next_state = _array(f"{name}.step", "the next state", next_state)
    if next_state.shape != state.shape:
        fail(
            f"{name}.step returned a state of shape {next_state.shape} for a state of shape "
            f"{state.shape}"
        )
    if next_state.dtype != state.dtype:
        fail(
            f"{name}.step returned a state of dtype {next_state.dtype} for a state of dtype "
            f"{state.dtype}; keep the state's dtype (the trainer carries it through lax.scan)"
        )
    reward = _array(f"{name}.step", "the reward", reward)
    if reward.shape != ():
        fail(
            f"{name}.step returned a reward of shape {reward.shape}; it must be a scalar (shape ())"
        )
    if reward.dtype != state.dtype and not reward.weak_type:
        fail(
            f"{name}.step returned a reward of dtype {reward.dtype} for a state of dtype "
            f"{state.dtype}; return it in the state's dtype"
        )
    if not (
        isinstance(terminated, jax.ShapeDtypeStruct)
        and terminated.shape == ()
        and terminated.dtype == jnp.bool_
    ):
        fail(
            f"{name}.step returned {_describe(terminated)} as terminated; it must be a boolean "
            "scalar such as jnp.asarray(False) or x > limit"
        )
    return state


def _continuous_shapes(task: ContinuousTask, params: PyTree) -> jax.ShapeDtypeStruct:
    name = type(task).__name__
    y0 = trace(f"{name}.initial_state", "the parameters", task.initial_state, params)
    y0 = _array(f"{name}.initial_state", "the initial state", y0)
    if y0.ndim != 1:
        fail(
            f"{name}.initial_state returned shape {y0.shape}; the ODE state must be a vector "
            "(shape (n,))"
        )
    _observation_shape(task, y0)

    def field(t, y, params):
        controller = controller_for(task, jax.random.PRNGKey(0))
        return task.vector_field(t, y, (params, force_fn(task, controller)))

    t = jax.ShapeDtypeStruct((), y0.dtype)
    # force_fn gives the action as controller(obs) does, a one-action task's as a scalar
    gives = "a scalar (the one action)" if task.action_size == 1 else f"shape ({task.action_size},)"
    inputs = (
        f"t, a state of shape {y0.shape} and args (params, force_fn), whose force_fn(t, y) "
        f"gives {gives}"
    )
    dy = trace(f"{name}.vector_field", inputs, field, t, y0, params)
    dy = _array(f"{name}.vector_field", "dy/dt", dy)
    if dy.shape != y0.shape:
        fail(
            f"{name}.vector_field returned dy/dt of shape {dy.shape} for a state of shape "
            f"{y0.shape} (force_fn(t, y) gives {gives})"
        )
    if dy.dtype != y0.dtype:
        fail(
            f"{name}.vector_field returned dy/dt of dtype {dy.dtype} for a state of dtype "
            f"{y0.dtype}; keep the state's dtype"
        )
    return y0
