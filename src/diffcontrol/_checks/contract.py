"""A task's methods under ``jit``, ``vmap`` and ``grad`` (``diffcontrol.checks.check_contract``)."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree

from ..errors import TaskCheckError
from ..rollout import force_fn
from ..tasks import AnyTask, ContinuousTask, Task
from .util import ACTION_SCALE, controller_for, fail, first_line, fmt, same, valid_action


def task_contract(task: AnyTask, params: PyTree, state: Any, n: int, seed: int) -> None:
    """See ``diffcontrol.checks.check_contract``; ``state`` is ``validate_task``'s."""
    if isinstance(task, ContinuousTask):
        _continuous_contract(task, params, n, seed)
    else:
        _discrete_contract(task, params, state, n, seed)


def _nonfinite_rows(x: Any) -> np.ndarray:
    """Indices of the leading axis where any leaf of ``x`` has a non-finite entry."""
    bad = None
    for leaf in jax.tree.leaves(eqx.filter(x, eqx.is_inexact_array)):
        leaf = np.asarray(leaf).reshape(len(np.asarray(leaf)), -1)
        rows = ~np.all(np.isfinite(leaf), axis=1)
        bad = rows if bad is None else bad | rows
    return np.flatnonzero(bad) if bad is not None else np.zeros(0, int)


def _all_zero(x: Any) -> bool:
    return all(
        not np.any(np.asarray(leaf))
        for leaf in jax.tree.leaves(eqx.filter(x, eqx.is_inexact_array))
    )


def _discrete_contract(task: Task, params: PyTree, state: Any, n: int, seed: int) -> None:
    name = type(task).__name__

    def outputs(state, action, params):
        # One scalar that every output of a step feeds, so its gradient is zero only where
        # none of them depends on the input; the outputs themselves come out as aux.
        next_state, reward, terminated = task.step(params, state, action)
        next_obs = task.observe(next_state)
        total = jnp.sum(next_state) + reward + jnp.sum(next_obs)
        return total, (next_state, reward, terminated, next_obs)

    def probe(key, params):
        # Everything in one compiled program: eager JAX would compile every operation.
        k_reset, k_action = jax.random.split(key)
        keys = jax.random.split(k_reset, n)
        raw = ACTION_SCALE * jax.random.normal(k_action, (n, task.action_size), state.dtype)
        s = jax.vmap(task.reset, (0, None))(keys, params)
        a = jax.vmap(lambda z: valid_action(task, z))(raw)
        obs = jax.vmap(task.observe)(s)
        # The gradients BPTT takes: with respect to the state and the action. (The parameters'
        # are left to system identification: for a large simulator they double the compile.)
        step_grad = jax.value_and_grad(outputs, argnums=(0, 1), has_aux=True)
        (_, (next_s, reward, term, next_obs)), grads = jax.vmap(step_grad, (0, 0, None))(
            s, a, params
        )
        reset_sum = lambda p: jnp.sum(jax.vmap(task.reset, (0, None))(keys, p))  # noqa: E731
        # The first example again, unbatched, in traces of its own (reset twice): NumPy or
        # Python randomness, or state kept between calls, gives different constants here.
        alone = (
            task.reset(keys[0], params),
            task.reset(keys[0], params),
            task.step(params, s[0], a[0]),
            task.observe(s[0]),
        )
        outs = (s, a, next_s, reward, term, obs, next_obs)
        return outs, grads, eqx.filter_grad(reset_sum)(params), alone

    try:
        out = eqx.filter_jit(probe)(jax.random.PRNGKey(seed), params)
    except Exception as e:
        raise _blame(task, params, state, n, e) from e
    (s, a, next_s, reward, term, obs, next_obs), grads, reset_grad, alone = jax.tree.map(
        np.asarray, out
    )
    at = lambda i: f"at state {fmt(s[i])} with action {fmt(a[i])}"  # noqa: E731

    for i in _nonfinite_rows(s)[:1]:
        fail(
            f"{name}.reset returned a non-finite state {fmt(s[i])} (reset {i} of {n}, seed {seed})"
        )
    for i in _nonfinite_rows(obs)[:1]:
        fail(
            f"{name}.observe returned a non-finite observation {fmt(obs[i])} for the state "
            f"{fmt(s[i])}"
        )
    for i in _nonfinite_rows(next_s)[:1]:
        fail(f"{name}.step returned a non-finite state {fmt(next_s[i])} {at(i)}")
    for i in _nonfinite_rows(reward)[:1]:
        fail(f"{name}.step returned a non-finite reward ({fmt(reward[i])}) {at(i)}")
    for i in _nonfinite_rows(next_obs)[:1]:
        fail(
            f"{name}.observe returned a non-finite observation {fmt(next_obs[i])} for the state "
            f"{fmt(next_s[i])}"
        )
    for what, g in zip(("state", "action"), grads):
        for i in _nonfinite_rows(g)[:1]:
            fail(
                f"the gradient of {name}.step with respect to the {what} is not finite {at(i)}; "
                "something in step has an infinite or undefined derivative there (sqrt(0), "
                "log(0), a division by zero, also inside a jnp.where branch not taken)"
            )
    if _nonfinite_rows(jax.tree.map(lambda x: x[None], reset_grad)).size:
        fail(f"the gradient of {name}.reset with respect to the parameters is not finite")
    if _all_zero(grads[1]):
        fail(
            f"{name}.step ignores the action: the gradient of the next state and the reward "
            f"with respect to the action is zero at all {n} checked states, so no controller "
            "can be trained through it"
        )

    first, again, step0, obs0 = alone
    if not np.array_equal(first, again, equal_nan=True):
        fail(
            f"{name}.reset is not deterministic: the same key gave {fmt(first)} and then "
            f"{fmt(again)}; draw every random number from the key (jax.random), not from NumPy "
            "or Python's random"
        )
    if not same(first, s[0]):
        fail(
            f"{name}.reset is not a pure function of its key: it gives {fmt(first)} alone and "
            f"{fmt(s[0])} under jax.vmap for the same key"
        )
    batched = (next_s, reward, term)
    for what, ours, theirs in zip(("state", "reward", "terminated"), step0, batched):
        if not same(ours, theirs[0]):
            fail(
                f"{name}.step is not a pure function: {at(0)} it returns the {what} "
                f"{fmt(ours)} alone and {fmt(theirs[0])} under jax.vmap"
            )
    if not same(obs0, obs[0]):
        fail(
            f"{name}.observe is not a pure function: it gives {fmt(obs0)} alone and "
            f"{fmt(obs[0])} under jax.vmap for the state {fmt(s[0])}"
        )


def _blame(task: Task, params: PyTree, state: Any, n: int, error: Exception) -> TaskCheckError:
    """The compiled probe failed: trace its parts one by one to say which method, and how."""
    name = type(task).__name__
    keys = jax.eval_shape(lambda: jax.random.split(jax.random.PRNGKey(0), n))
    state = jax.ShapeDtypeStruct((n, *state.shape), state.dtype)
    action = jax.ShapeDtypeStruct((n, task.action_size), state.dtype)
    parts = [
        (f"{name}.reset under jax.vmap", lambda: jax.vmap(task.reset, (0, None))(keys, params)),
        (f"{name}.observe under jax.vmap", lambda: jax.vmap(task.observe)(state)),
        (
            f"{name}.step under jax.vmap",
            lambda: jax.vmap(task.step, (None, 0, 0))(params, state, action),
        ),
        (
            f"{name}.step under jax.grad",
            lambda: jax.grad(lambda s, a: jnp.sum(task.step(params, s, a)[0]), argnums=(0, 1))(
                state[0], action[0]
            ),
        ),
    ]
    for what, part in parts:
        try:
            jax.eval_shape(part)
        except Exception as e:
            return TaskCheckError(f"{what} failed: {type(e).__name__}: {first_line(e)}")
    return TaskCheckError(
        f"{name} failed under jax.jit: {type(error).__name__}: {first_line(error)}"
    )


def _continuous_contract(task: ContinuousTask, params: PyTree, n: int, seed: int) -> None:
    name = type(task).__name__

    def field(controller, t, y, params):
        return task.vector_field(t, y, (params, force_fn(task, controller)))

    def probe(key, params):
        k_ctrl, k_t = jax.random.split(key)
        controllers = eqx.filter_vmap(lambda k: controller_for(task, k))(
            jax.random.split(k_ctrl, n)
        )
        y0 = task.initial_state(params)
        ts = jax.random.uniform(k_t, (n,), y0.dtype)
        dy = eqx.filter_vmap(field, in_axes=(0, 0, None, None))(controllers, ts, y0, params)
        grads = eqx.filter_vmap(
            lambda c, t: eqx.filter_grad(lambda x: jnp.sum(field(x[0], t, x[1], x[2])))(
                (c, y0, params)
            )
        )(controllers, ts)
        init_sum = lambda p: jnp.sum(task.initial_state(p))  # noqa: E731
        # Again, unbatched, in traces of their own (see _discrete_contract).
        first = jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, controllers)
        alone = (task.initial_state(params), field(first, ts[0], y0, params))
        init_grad = eqx.filter_grad(init_sum)(params)
        return ts, y0, task.observe(y0), dy, grads, init_grad, alone

    try:
        ts, y0, obs, dy, grads, init_grad, alone = eqx.filter_jit(probe)(
            jax.random.PRNGKey(seed), params
        )
    except Exception as e:
        raise TaskCheckError(
            f"{name}.vector_field failed under jax.jit, jax.vmap or jax.grad: "
            f"{type(e).__name__}: {first_line(e)}"
        ) from e
    ts, y0, obs, dy = (np.asarray(x) for x in (ts, y0, obs, dy))
    if not np.all(np.isfinite(y0)):
        fail(f"{name}.initial_state returned a non-finite state {fmt(y0)}")
    if not np.all(np.isfinite(obs)):
        fail(f"{name}.observe returned a non-finite observation {fmt(obs)} for the state {fmt(y0)}")
    for i in _nonfinite_rows(dy)[:1]:
        fail(
            f"{name}.vector_field returned a non-finite dy/dt {fmt(dy[i])} at "
            f"t = {float(ts[i]):.4g} from {fmt(y0)}"
        )
    for what, g in zip(("controller's weights", "state", "parameters"), grads):
        for i in _nonfinite_rows(g)[:1]:
            fail(
                f"the gradient of {name}.vector_field with respect to the {what} is not finite "
                f"at t = {float(ts[i]):.4g} and the state {fmt(y0)}"
            )
    if _nonfinite_rows(jax.tree.map(lambda x: x[None], init_grad)).size:
        fail(f"the gradient of {name}.initial_state with respect to the parameters is not finite")
    if _all_zero(grads[0].layers):
        fail(
            f"{name}.vector_field ignores the controller: dy/dt does not depend on the force; "
            "take it from args: params, force_fn = args; force = force_fn(t, state)"
        )
    again, field0 = (np.asarray(x) for x in alone)
    if not np.array_equal(again, y0, equal_nan=True):
        fail(f"{name}.initial_state is not deterministic: it gave {fmt(y0)} and then {fmt(again)}")
    if not same(field0, dy[0]):
        fail(
            f"{name}.vector_field is not a pure function: at t = {float(ts[0]):.4g} it returns "
            f"{fmt(field0)} alone and {fmt(dy[0])} under jax.vmap"
        )
