"""Gradients: the straight-through sign, finite-difference checks through rollouts and the
windowed-BPTT loss (float64), and a jit/vmap/grad contract battery over every registered task.

Finite differences: central differences ``(f(x + eps d) - f(x - eps d)) / (2 eps)`` with
``eps = 1e-6`` in float64. The truncation error is ``O(eps^2 f''') ~ 1e-12`` relative and the
rounding error ``~1e-16 |f| / eps ~ 1e-10`` relative for the well-scaled losses used here, so
``RTOL_FD = 1e-6`` has four orders of magnitude of room; a wrong or missing gradient term
(a stop_gradient in the wrong place, a dropped chain-rule factor) is off by O(1).

FD is only meaningful where the function is smooth along the perturbation. The non-smooth
points are documented in ``diffcontrol.systems``: the pendulum's torque clip (avoided with the
bounded ``tanh`` head, whose output never reaches the clip), its speed clip and the angle wrap
in its cost (each test asserts that its trajectory stays clear of them), CartPole's
termination (it only masks rewards, and the losses here do not use rewards) and its discrete
push (replaced by the smooth ``tanh`` head). The observation scaling and action bounds of
a controller are ``stop_gradient``-ed constants, so weight perturbations touch only ``layers``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol.tasks
from diffcontrol.controllers import MLPController, apply_head, straight_through_sign
from diffcontrol.rollout import rollout
from diffcontrol.tasks import controller_kwargs
from diffcontrol.training import make_trainer, resolve_config, task_params

from ._tasks import walked

EPS_FD = 1e-6
RTOL_FD = 1e-6
NUM_STEPS = 30


# --- (a) the straight-through sign -------------------------------------------------------------


def _sign_inputs(dtype) -> jnp.ndarray:
    rng = np.random.default_rng(0)
    edges = [0.0, -0.0, 1e-30, -1e-30, 1e-7, -1e-7, 0.5, -0.5, 1.0, -1.0, 1e6, -1e6]
    return jnp.asarray(np.concatenate([edges, rng.normal(0, 3, 200)]), dtype)


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
def test_straight_through_sign_forward_and_backward(x64):
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        x = _sign_inputs(dtype)
        y = jax.jit(straight_through_sign)(x)
        assert y.dtype == dtype
        # +1 for x >= 0 (0.0 and -0.0 included), -1 for x < 0: exactly, not approximately.
        np.testing.assert_array_equal(np.asarray(y), np.where(np.asarray(x) >= 0, 1.0, -1.0))
        assert y[0] == 1.0 and y[1] == 1.0
        # Backward is the identity: d/dx sum(f(x) w) = w, exactly.
        w = jnp.asarray(np.random.default_rng(1).normal(size=x.shape), dtype)
        grad = jax.jit(jax.grad(lambda x: jnp.sum(straight_through_sign(x) * w)))(x)
        np.testing.assert_array_equal(np.asarray(grad), np.asarray(w))


def test_straight_through_sign_large_and_infinite_inputs():
    """Exact at any magnitude: ``x + stop_gradient(hard - x)`` (an earlier version) returned 0
    for ``|x| >= 2**24`` in float32 and nan at infinity."""
    x = jnp.array([2.0**24, -(2.0**24), 1e8, -1e8, 3e38, -3e38, jnp.inf, -jnp.inf], jnp.float32)
    y = jax.jit(straight_through_sign)(x)
    np.testing.assert_array_equal(np.asarray(y), [1, -1, 1, -1, 1, -1, 1, -1])
    w = jnp.arange(1.0, 9.0)
    grad = jax.grad(lambda x: jnp.sum(straight_through_sign(x) * w))(x)
    np.testing.assert_array_equal(np.asarray(grad), np.asarray(w))


def test_sign_head_gradient_is_tanh_derivative():
    """The CartPole head: forward sign(tanh z), backward tanh'(z) = 1 - tanh(z)^2."""
    z = jnp.asarray(np.random.default_rng(2).normal(0, 2, 64), jnp.float32).at[0].set(0.0)
    low, high = -jnp.ones(64), jnp.ones(64)
    w = jnp.asarray(np.random.default_rng(3).normal(size=64), jnp.float32)
    head = jax.jit(lambda z: apply_head("sign", z, low, high))
    np.testing.assert_array_equal(np.asarray(head(z)), np.where(np.asarray(z) >= 0, 1.0, -1.0))
    grad = jax.grad(lambda z: jnp.sum(head(z) * w))(z)
    # float32: 1 - tanh(z)^2 cancels for large |z|, so allow an absolute ~ulp of 1 besides rtol.
    expected = np.asarray(w * (1 - jnp.tanh(z) ** 2))
    np.testing.assert_allclose(np.asarray(grad), expected, rtol=1e-6, atol=1e-7)


def test_cartpole_controller_sign_gradient():
    """Through a whole ``sign`` controller: d action / d (last bias) = tanh'(raw output)."""
    task = diffcontrol.tasks.make("cartpole")
    assert task.action_head == "sign"
    key = jax.random.key(4)
    kwargs = dict(controller_kwargs(task), final_scale=3.0)
    controller = MLPController(key, hidden=(8,), **kwargs)
    # The same weights (same key) with the raw output exposed.
    raw = MLPController(key, hidden=(8,), **dict(kwargs, head="linear"))
    obs = jnp.asarray(np.random.default_rng(5).normal(0, 0.5, (32, 4)), jnp.float32)

    z = jax.vmap(raw)(obs)[:, 0]
    actions = jax.vmap(controller)(obs)[:, 0]
    assert set(np.unique(np.asarray(actions))) <= {-1.0, 1.0}
    assert len(np.unique(np.asarray(actions))) == 2  # both pushes occur in this batch
    np.testing.assert_array_equal(np.asarray(actions), np.where(np.asarray(z) >= 0, 1.0, -1.0))

    def bias_grad(o):
        g = eqx.filter_grad(lambda c: c(o)[0])(controller)
        return g.layers[-1].bias[0]

    grads = jax.jit(jax.vmap(bias_grad))(obs)
    np.testing.assert_allclose(np.asarray(grads), np.asarray(1 - jnp.tanh(z) ** 2), rtol=1e-5)
    assert np.all(np.asarray(grads) > 0)  # a straight-through gradient, not sign's zero


# --- (b) finite differences through rollouts (float64) -----------------------------------------


def _random_like(tree, seed: int):
    """A random direction shaped like ``tree`` (NumPy: no eager JAX ops to compile)."""
    rng = np.random.default_rng(seed)
    return jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape), x.dtype), tree)


def _along(controller, direction, eps):
    """``controller`` with ``eps * direction`` added to its ``layers`` (nothing else)."""
    layers = jax.tree.map(lambda w, d: w + eps * d, controller.layers, direction)
    return eqx.tree_at(lambda c: c.layers, controller, layers)


def _check_fd(loss, controller, params, state0, param_names):
    """Compare ``jax.grad`` of ``loss(controller, params, state0)`` with central differences.

    ``loss`` returns ``(value, trajectory)``. One compiled value-and-grad serves both the
    analytic gradient and every FD evaluation (compile time dominates these tests). Returns
    the trajectory, for the caller's smoothness checks.
    """
    value_and_grad = jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2), has_aux=True))
    (_, traj), (g_ctrl, g_params, g_state) = value_and_grad(controller, params, state0)

    def f(controller, params, state0):
        return float(value_and_grad(controller, params, state0)[0][0])

    # The constants of the controller get no gradient.
    for name in ("obs_offset", "obs_scale", "action_low", "action_high"):
        np.testing.assert_array_equal(np.asarray(getattr(g_ctrl, name)), 0.0)

    # Weights: one directional derivative along a random direction in all of `layers`.
    direction = _random_like(controller.layers, seed=11)
    analytic = _dot(g_ctrl.layers, direction)
    fd = (f(_along(controller, direction, EPS_FD), params, state0)
          - f(_along(controller, direction, -EPS_FD), params, state0)) / (2 * EPS_FD)  # fmt: skip
    assert abs(analytic) > 1e-3  # a gradient that could be wrong
    np.testing.assert_allclose(fd, analytic, rtol=RTOL_FD)

    # Initial state: every component.
    fd_state = []
    for i in range(state0.shape[0]):
        e = np.zeros(state0.shape)
        e[i] = EPS_FD
        fd_state.append((f(controller, params, state0 + e) - f(controller, params, state0 - e))
                        / (2 * EPS_FD))  # fmt: skip
    g_state = np.asarray(g_state)
    np.testing.assert_allclose(
        np.array(fd_state), g_state, rtol=RTOL_FD, atol=RTOL_FD * np.abs(g_state).max()
    )

    # Physical parameters: each named field of the PyTree.
    for name in param_names:
        value = getattr(params, name)
        field = lambda p, name=name: getattr(p, name)  # noqa: E731
        plus = eqx.tree_at(field, params, value + EPS_FD)
        minus = eqx.tree_at(field, params, value - EPS_FD)
        fd = (f(controller, plus, state0) - f(controller, minus, state0)) / (2 * EPS_FD)
        analytic = float(getattr(g_params, name))
        assert abs(analytic) > 1e-6, name
        np.testing.assert_allclose(fd, analytic, rtol=RTOL_FD, err_msg=name)
    return traj


def _dot(tree_a, tree_b) -> float:
    return float(
        sum(np.vdot(a, b) for a, b in zip(jax.tree.leaves(tree_a), jax.tree.leaves(tree_b)))
    )


@pytest.mark.slow
@pytest.mark.parametrize("task_name", ["pendulum", "pendulum-unclipped"])
def test_pendulum_rollout_gradients_match_fd(task_name):
    """Total cost of a 30-step closed-loop rollout w.r.t. weights, initial state and g, m, l."""
    task = diffcontrol.tasks.make(task_name)
    with jax.enable_x64(True):
        params = task_params(task)
        assert params.g.dtype == jnp.float64
        controller = MLPController(
            jax.random.key(0), hidden=(8, 8), final_scale=1.0, **controller_kwargs(task)
        )
        state0 = jnp.array([2.0, 0.5])

        def loss(controller, params, state0):
            traj = rollout(task, params, controller, state0, NUM_STEPS)
            return -traj.total_return, traj

        traj = _check_fd(loss, controller, params, state0, ("g", "m", "l"))

    # The trajectory stayed clear of the non-smooth points (FD across one measures a kink).
    theta, theta_dot = np.asarray(traj.states[:-1]).T
    assert np.abs(theta_dot).max() < float(params.max_speed) - 0.1  # speed clip inactive
    wrapped = np.abs(np.mod(theta + np.pi, 2 * np.pi) - np.pi)  # |angle from upright|
    assert np.abs(wrapped - np.pi).min() > 1e-3  # the cost's wrap point (theta = pi) not hit
    actions = np.asarray(traj.actions)
    assert np.abs(actions).max() < 2.0 - 1e-3  # torque clip inactive
    assert np.ptp(actions) > 0.1  # and the controller matters: not a constant near zero


@pytest.mark.slow
def test_cartpole_rollout_gradients_match_fd():
    """A smooth function of the 30th state, with a continuous (``tanh``) push."""
    task = diffcontrol.tasks.make("cartpole")
    with jax.enable_x64(True):
        params = task_params(task)
        kwargs = dict(controller_kwargs(task), head="tanh", final_scale=5.0)
        controller = MLPController(jax.random.key(1), hidden=(8, 8), activation="tanh", **kwargs)
        state0 = jnp.array([0.1, -0.2, 0.05, 0.1])
        weights = jnp.array([1.0, 0.5, 10.0, 1.0])

        def loss(controller, params, state0):
            traj = rollout(task, params, controller, state0, NUM_STEPS)
            return jnp.sum(weights * traj.states[-1] ** 2), traj

        traj = _check_fd(
            loss, controller, params, state0, ("masspole", "length", "masscart", "gravity")
        )
    pushes = np.asarray(traj.actions)
    assert np.abs(pushes).max() < 1.0 and np.ptp(pushes) > 0.1


# --- (c) the windowed-BPTT loss (float64) ------------------------------------------------------


@pytest.mark.slow  # finite differences through 2 windows: 2-3 s each
@pytest.mark.parametrize(
    "task_name, overrides",
    [
        ("pendulum", dict()),
        # A continuous push and a smooth loss make CartPole's window loss differentiable.
        ("cartpole", dict(head="tanh", loss="quadratic", activation="tanh")),
    ],
)
def test_window_loss_gradient_matches_fd(task_name, overrides):
    task = diffcontrol.tasks.make(task_name)
    batch, window = 2, 10
    # horizon < window: every simulation restarts inside the window, so the gradient passes
    # through the explicit reset as well.
    config = resolve_config(task, batch=batch, window=window, horizon=6, hidden=(8, 8), **overrides)
    with jax.enable_x64(True):
        trainer = make_trainer(task, config)
        params = task_params(task)
        ts = trainer.init(jax.random.key(0), params)
        ctrl = ts.controller
        assert ctrl.layers[0].weight.dtype == jnp.float64
        keys = jax.random.split(jax.random.key(1), (window, batch))

        def loss(controller):
            return trainer.window_loss(
                controller, params, ts.env_state, ts.env_time, ts.episode_return, keys
            )

        value_and_grad = eqx.filter_jit(eqx.filter_value_and_grad(loss, has_aux=True))
        (value, (_, n_done, _)), grads = value_and_grad(ctrl)
        direction = _random_like(ctrl.layers, seed=3)
        plus = value_and_grad(_along(ctrl, direction, EPS_FD))[0][0]
        minus = value_and_grad(_along(ctrl, direction, -EPS_FD))[0][0]
    assert int(n_done) == batch  # each simulation hit the horizon once
    fd = (float(plus) - float(minus)) / (2 * EPS_FD)
    analytic = _dot(grads.layers, direction)
    assert np.isfinite(float(value)) and abs(analytic) > 1e-6
    np.testing.assert_allclose(fd, analytic, rtol=RTOL_FD)


# --- (d) the contract battery over every registered task ---------------------------------------


def _names_of(kind: type) -> list[str]:
    return [n for n in walked() if isinstance(diffcontrol.tasks.make(n), kind)]


@pytest.fixture(scope="module", params=_names_of(diffcontrol.tasks.Task))
def task(request):
    return diffcontrol.tasks.make(request.param)


@pytest.mark.slow
@pytest.mark.parametrize("name", _names_of(diffcontrol.tasks.ContinuousTask))
def test_continuous_task_contract(name):
    """Every continuous-time task: its vector field under jit, vmap and grad, its controller,
    its trajectory and every built-in loss on a short solve."""
    from diffcontrol.rollout import StateFeedback

    task = diffcontrol.tasks.make(name)
    params = jax.tree.map(jnp.asarray, task.default_params())
    y0 = task.initial_state(params)
    assert y0.ndim == 1 and np.all(np.isfinite(np.asarray(y0)))
    controller = MLPController(jax.random.key(0), hidden=(4,), **controller_kwargs(task))
    force = StateFeedback(controller, task.observe)
    field = jax.jit(task.vector_field)
    rng = np.random.default_rng(0)
    ys = jnp.asarray(rng.normal(size=(8, y0.size)), y0.dtype)
    dy = field(0.0, ys[0], (params, force))
    assert dy.shape == y0.shape and np.all(np.isfinite(np.asarray(dy)))
    np.testing.assert_allclose(
        np.asarray(task.vector_field(0.0, ys[0], (params, force))), np.asarray(dy), rtol=1e-5
    )
    batch = jax.jit(jax.vmap(task.vector_field, in_axes=(None, 0, None)))(0.0, ys, (params, force))
    for i in range(8):
        np.testing.assert_allclose(
            np.asarray(batch[i]),
            np.asarray(field(0.0, ys[i], (params, force))),
            rtol=1e-5,
            atol=1e-6,
        )

    def scalar(params, y, ctrl):
        return jnp.sum(task.vector_field(0.0, y, (params, StateFeedback(ctrl, task.observe))) ** 2)

    g_params, g_state, g_ctrl = eqx.filter_jit(eqx.filter_grad(lambda args: scalar(*args)))(
        (params, ys[1], controller)
    )
    leaves = [
        *jax.tree.leaves(g_params),
        g_state,
        *jax.tree.leaves(eqx.filter(g_ctrl.layers, eqx.is_array)),
    ]
    assert all(np.all(np.isfinite(np.asarray(g))) for g in leaves)
    assert np.any(np.asarray(g_state) != 0) and np.any(np.asarray(g_ctrl.layers[-1].bias) != 0)

    trainer = diffcontrol.training.make_ode_trainer(
        task, task.default_config().replace(horizon_s=0.3, saves=7)
    )
    sol = trainer.solve(controller, params, jnp.asarray(0.3), "checkpoint")
    assert bool(sol.ok) and sol.ys.shape == (7, y0.size)
    traj = task.trajectory(params, controller, sol.ts, sol.ys)
    for loss_name in task.losses:
        value = task.trajectory_loss(loss_name)(traj)
        assert value.shape == () and np.isfinite(float(value)), loss_name


def test_registry_is_not_empty():
    assert {"pendulum", "pendulum-unclipped", "cartpole"} <= set(diffcontrol.tasks.names())


@pytest.mark.slow
def test_task_contract(task):
    params = task.default_params()
    key = jax.random.key(42)
    reset = jax.jit(task.reset)
    step = jax.jit(task.step)
    observe = jax.jit(task.observe)

    # Same key, same state (jitted or not); another key, another state.
    state = reset(key, params)
    np.testing.assert_array_equal(np.asarray(state), np.asarray(reset(key, params)))
    # Eager against jitted: equal up to rounding (XLA may fuse a sampler's arithmetic).
    np.testing.assert_allclose(np.asarray(task.reset(key, params)), np.asarray(state), rtol=1e-6)
    assert not np.array_equal(np.asarray(state), np.asarray(reset(jax.random.key(43), params)))
    assert state.ndim == 1 and np.all(np.isfinite(np.asarray(state)))

    obs = observe(state)
    assert obs.shape == (task.observation_size,) and np.all(np.isfinite(np.asarray(obs)))
    # A valid action: 0.3 for unbounded tasks, the same fraction of the range for bounded ones
    # (0.3 N m for Pendulum-v1; 51 degrees and 271.5 lb for the trebuchet).
    if task.action_low is None:
        action = jnp.full((task.action_size,), 0.3)
    else:
        low, high = jnp.asarray(task.action_low), jnp.asarray(task.action_high)
        action = low + 0.575 * (high - low)
    next_state, reward, terminated = step(params, state, action)
    assert next_state.shape == state.shape and next_state.dtype == state.dtype
    assert reward.shape == () and terminated.shape == () and terminated.dtype == jnp.bool_
    assert np.all(np.isfinite(np.asarray(next_state))) and np.isfinite(float(reward))
    assert not np.array_equal(np.asarray(next_state), np.asarray(state))  # time moves on

    # vmap over a batch of keys, states and actions agrees with one-at-a-time.
    keys = jax.random.split(key, 8)
    states = jax.jit(jax.vmap(task.reset, in_axes=(0, None)))(keys, params)
    actions = jnp.linspace(-0.5, 0.5, 8)[:, None] * jnp.ones(task.action_size)
    b_next, b_reward, b_term = jax.jit(jax.vmap(task.step, in_axes=(None, 0, 0)))(
        params, states, actions
    )
    b_obs = jax.jit(jax.vmap(task.observe))(states)
    assert states.shape == (8, *state.shape) and b_obs.shape == (8, task.observation_size)
    assert b_next.shape == states.shape and b_reward.shape == (8,) and b_term.shape == (8,)
    for i in range(8):
        np.testing.assert_allclose(
            np.asarray(states[i]), np.asarray(reset(keys[i], params)), rtol=1e-6
        )
        np.testing.assert_allclose(
            np.asarray(b_next[i]), np.asarray(step(params, states[i], actions[i])[0]), rtol=1e-6
        )

    # grad of a scalar of the next state w.r.t. the action, the state and the parameters.
    def scalar(params, state, action):
        return jnp.sum(task.step(params, state, action)[0] ** 2)

    jparams = jax.tree.map(jnp.asarray, params)
    g_params, g_state, g_action = jax.jit(jax.grad(scalar, argnums=(0, 1, 2)))(
        jparams, state, action
    )
    assert g_action.shape == (task.action_size,) and g_state.shape == state.shape
    for g in (g_action, g_state, *jax.tree.leaves(g_params)):
        assert np.all(np.isfinite(np.asarray(g)))
    assert np.any(np.asarray(g_action) != 0) and np.any(np.asarray(g_state) != 0)

    # The task's controller fits its observation and action sizes.
    controller = MLPController(jax.random.key(0), hidden=(4,), **controller_kwargs(task))
    out = eqx.filter_jit(controller)(obs)
    assert out.shape == (task.action_size,) and np.all(np.isfinite(np.asarray(out)))
