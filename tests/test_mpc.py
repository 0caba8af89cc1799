"""The planning controller (diffcontrol.mpc): iLQR and shooting against exact LQR, on Pendulum,
and its refusals."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import diffcontrol
from diffcontrol import _gym, mpc
from diffcontrol.errors import ConfigError
from diffcontrol.tasks import Pendulum

A = np.array([[1.0, 0.1], [0.0, 1.0]])
B = np.array([[0.005], [0.1]])
Q = np.diag([1.0, 0.1])
R = 0.01


class _NoParams(eqx.Module):
    pass


class LinearQuadratic(diffcontrol.Task):
    """A double integrator with a quadratic cost: its plan is known in closed form (LQR)."""

    name = "test-linear-quadratic"
    summary = "double integrator, quadratic cost"
    episode_length = 50
    observation_size = 2
    action_size = 1
    action_head = "tanh"
    action_low, action_high = (-20.0,), (20.0,)
    losses = ("cost",)

    def default_params(self):
        return _NoParams()

    def default_config(self):
        return None

    def reset(self, key, params):
        return jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)

    def step(self, params, state, action):
        cost = state @ jnp.asarray(Q, state.dtype) @ state + R * action[0] ** 2
        nxt = jnp.asarray(A, state.dtype) @ state + jnp.asarray(B, state.dtype) @ action
        return nxt, -cost, jnp.asarray(False)

    def observe(self, state):
        return state

    def step_loss(self, name):
        return lambda params, state, action, next_state, reward: -reward


class TightLinearQuadratic(LinearQuadratic):
    action_low, action_high = (-0.5,), (0.5,)


def _lqr_plan(x0, horizon):
    """The exact finite-horizon LQR plan (Riccati recursion, float64, no terminal cost)."""
    p, gains = np.zeros((2, 2)), []
    for _ in range(horizon):
        k = np.linalg.solve(R + B.T @ p @ B, B.T @ p @ A)
        p = Q + A.T @ p @ (A - B @ k)
        gains.append(k)
    x, plan = np.asarray(x0, float), []
    for k in reversed(gains):
        u = -k @ x
        plan.append(u)
        x = A @ x + B @ u
    return np.array(plan)


X0 = jnp.array([1.0, -0.5])
H = 25


def _solve(task, solver):
    planner = mpc.make_planner(task, solver, horizon=H)
    return eqx.filter_jit(planner.plan)(X0, planner.initial_plan())


def test_ilqr_matches_exact_lqr():
    plan, info = _solve(LinearQuadratic(), mpc.ILQR(iterations=4))
    np.testing.assert_allclose(np.asarray(plan), _lqr_plan(np.asarray(X0), H), rtol=1e-3, atol=1e-4)
    assert bool(info.finite) and bool(info.converged)
    assert float(info.cost) < float(info.initial_cost)


def test_shooting_agrees_with_ilqr_roughly():
    exact, ilqr_info = _solve(LinearQuadratic(), mpc.ILQR(iterations=4))
    plan, info = _solve(LinearQuadratic(), mpc.Shooting(optax.lbfgs(), iterations=40))
    assert float(info.cost) == pytest.approx(float(ilqr_info.cost), rel=1e-3)
    np.testing.assert_allclose(np.asarray(plan), np.asarray(exact), atol=0.05)


def test_box_constrained_ilqr_matches_a_bounded_optimiser():
    from scipy.optimize import minimize

    task = TightLinearQuadratic()
    plan, info = _solve(task, mpc.ILQR(iterations=15))
    problem = mpc.make_planner(task, horizon=H).problem
    with jax.enable_x64(True):
        cost = jax.jit(lambda u: problem.cost(jnp.asarray(X0, float), u.reshape(H, 1)))
        grad = jax.jit(jax.grad(lambda u: problem.cost(jnp.asarray(X0, float), u.reshape(H, 1))))
        ref = minimize(lambda u: float(cost(u)), np.zeros(H), jac=lambda u: np.asarray(grad(u)),
                       bounds=[(-0.5, 0.5)] * H, method="L-BFGS-B", options={"ftol": 1e-14})  # fmt: skip
    assert np.all(np.abs(np.asarray(plan)) <= 0.5)
    assert np.abs(_lqr_plan(np.asarray(X0), H)).max() > 1.0  # the bounds bind
    assert float(info.cost) == pytest.approx(ref.fun, rel=1e-3)
    np.testing.assert_allclose(np.asarray(plan)[:, 0], ref.x, atol=2e-3)


@pytest.mark.slow
@pytest.mark.parametrize(
    "solver", [mpc.ILQR(iterations=5), mpc.Shooting(optax.adam(0.3), iterations=20)]
)
def test_planner_beats_zero_torque_on_pendulum(solver):
    task = Pendulum()
    params = task.default_params()
    starts = jax.vmap(task.reset, (0, None))(jax.random.split(jax.random.key(1), 4), params)
    planner = mpc.make_planner(task, solver, horizon=10)
    _, actions, rewards, info = jax.jit(jax.vmap(lambda x: planner.episode(x, 100)))(starts)

    def zero(x):
        step = lambda x, _: task.step(params, x, jnp.zeros(1))[:2]  # noqa: E731
        return jax.lax.scan(step, x, None, length=100)[1].sum()

    assert float(rewards.sum(1).mean()) > float(jax.vmap(zero)(starts).mean()) + 100
    assert bool(jnp.all(jnp.abs(actions) <= 2.0)) and bool(info.finite.all())


def test_non_finite_plan_falls_back_to_the_warm_start():
    planner = mpc.make_planner(Pendulum(), mpc.ILQR(iterations=2), horizon=5,
                               terminal_cost=lambda x: jnp.nan * x[0])  # fmt: skip
    warm = jnp.full((5, 1), 0.7)
    action, _, info = eqx.filter_jit(planner.control)(jnp.array([3.0, 0.0]), warm)
    assert not bool(info.finite)
    assert float(action[0]) == pytest.approx(0.7)


def test_policy_runs_in_gymnasium_and_reports_each_solve():
    import gymnasium

    policy = mpc.PlannerPolicy(mpc.make_planner(Pendulum(), mpc.ILQR(iterations=3), horizon=8))
    env = gymnasium.make("Pendulum-v1")
    obs, _ = env.reset(seed=0)
    for _ in range(15):
        action = policy(obs)
        assert action.shape == (1,) and action.dtype == np.float32 and abs(action[0]) <= 2
        obs, *_ = env.step(action)
    assert len(policy.reports) == 15 and "15 solves" in policy.summary()
    policy.reset()
    np.testing.assert_array_equal(np.asarray(policy._warm), 0.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(horizon=0), "horizon=0"),
        (dict(horizon=2.5), "horizon=2.5"),
        (dict(horizon=True), "horizon=True"),
        (dict(terminal_weight=-1.0), "terminal_weight=-1.0"),
        (dict(terminal_weight=float("nan")), "terminal_weight=nan"),
        (dict(terminal_weight=float("inf")), "terminal_weight=inf"),
        (dict(solver=mpc.ILQR(mu=-1.0)), "mu=-1.0"),
        (dict(solver=mpc.ILQR(iterations=0)), "iterations=0"),
        (dict(solver=mpc.Shooting(tol=float("nan"))), "tol=nan"),
        (dict(solver="adam"), "not a solver"),
        (dict(loss="nope"), "loss='nope'"),
        (dict(bounds=((1.0,), (-1.0,))), "low < high"),
        (dict(bounds=((-1.0, -1.0), (1.0, 1.0))), "1 finite numbers"),
        (dict(bounds=((-np.inf,), (1.0,))), "1 finite numbers"),
        (dict(bounds=(("a",), (1.0,))), "1 finite numbers"),
    ],
)
def test_bad_settings_are_one_line_config_errors(kwargs, match):
    with pytest.raises(ConfigError, match=match) as caught:
        mpc.make_planner(Pendulum(), **kwargs)
    assert "\n" not in str(caught.value)


def test_a_task_without_bounds_is_refused():
    with pytest.raises(ConfigError, match="action bounds.*bounds=") as caught:
        mpc.make_planner(diffcontrol.make("pendulum-unclipped"))
    assert "\n" not in str(caught.value)


@pytest.mark.slow
def test_a_sign_head_task_plans_its_relaxed_push_within_given_bounds():
    # CartPole: Discrete(2) pushes; the plan is the push u in [-1, 1] (force u * force_mag),
    # Gymnasium gets its sign. From a tilted start the planner keeps the pole up.
    task = diffcontrol.make("cartpole")
    planner = mpc.make_planner(task, mpc.ILQR(iterations=3), 10, loss="quadratic",
                               bounds=((-1,), (1,)))  # fmt: skip
    episode = jax.jit(lambda x0: planner.episode(x0, 200))
    states, actions, _, info = episode(jnp.array([0.0, 0.0, 0.15, 0.0]))
    assert bool(jnp.all(jnp.abs(states[:, 2]) < task.default_params().theta_threshold))
    assert bool(jnp.all(jnp.abs(actions) <= 1.0)) and bool(info.finite.all())
    assert _gym.gym_action(task, np.asarray(actions[0])) in (0, 1)
    default = mpc.make_planner(task, horizon=5).problem  # a sign head's relaxation: [-1, 1]
    assert (float(default.low[0]), float(default.high[0])) == (-1.0, 1.0)


@pytest.mark.slow
@pytest.mark.parametrize(
    "solver", [mpc.ILQR(iterations=3), mpc.Shooting(optax.sgd(0.02), iterations=30)]
)
def test_gradients_through_the_unrolled_solver_match_finite_differences(solver):
    # The planner is a pure JAX program, so reverse mode differentiates through the solver's
    # fixed iterations (the "unrolled" gradient of the plan); checked in float64.
    with jax.enable_x64(True):
        planner = mpc.make_planner(LinearQuadratic(), solver, horizon=6)

        def first_action(x0):
            return planner.plan(x0, jnp.zeros((6, 1)))[0][0, 0]

        x0 = jnp.array([0.8, -0.3])
        grad = np.asarray(jax.jit(jax.grad(first_action))(x0))
        f = jax.jit(first_action)
        eps = 1e-6
        fd = [(f(x0.at[i].add(eps)) - f(x0.at[i].add(-eps))) / (2 * eps) for i in range(2)]
        np.testing.assert_allclose(grad, np.asarray(fd), rtol=1e-5, atol=1e-7)
        assert np.all(np.abs(grad) > 1e-3)  # the plan does depend on the state


def test_evaluate_resets_a_stateful_policy_before_every_episode():
    """A planner's warm start belongs to one episode: evaluate() resets it each time."""
    import diffcontrol

    class Counting:
        def __init__(self):
            self.resets, self.steps_since_reset = 0, []

        def reset(self):
            self.resets += 1
            self.steps_since_reset.append(0)

        def __call__(self, obs):
            if self.steps_since_reset:
                self.steps_since_reset[-1] += 1
            return np.zeros(1)

    policy = Counting()
    diffcontrol.evaluate(policy, diffcontrol.make("pendulum"), episodes=3)
    assert policy.resets == 3 and policy.steps_since_reset == [200, 200, 200]


def _jacobian_and_fd(f, x, eps):
    """``jax.jacrev(f)(x)`` and the central finite differences of ``f`` along each of ``x``'s
    entries (columns), float64."""
    jac = np.asarray(jax.jit(jax.jacrev(f))(x))
    fj = jax.jit(f)
    fd = [(fj(x.at[i].add(eps)) - fj(x.at[i].add(-eps))) / (2 * eps) for i in range(x.size)]
    return jac, np.stack([np.asarray(c) for c in fd], -1)


@pytest.mark.parametrize(
    "solver", [mpc.ILQR(iterations=6), mpc.Shooting(optax.lbfgs(), iterations=60)],
    ids=["ilqr", "shooting-lbfgs"],
)  # fmt: skip
def test_implicit_gradient_of_the_plan_is_the_exact_lqr_gain(solver):
    # At the optimum of a linear-quadratic problem the plan is linear in the start, u = K x0;
    # the implicit derivative is K whatever the solver (L-BFGS's line search is a while_loop,
    # which cannot be unrolled in reverse mode: the implicit gradient does not need to).
    with jax.enable_x64(True):
        planner = mpc.make_planner(LinearQuadratic(), solver, horizon=6, gradient="implicit")
        jac = jax.jit(jax.jacrev(lambda x0: planner.plan(x0, jnp.zeros((6, 1)))[0][:, 0]))
        exact = np.stack([_lqr_plan(np.eye(2)[i], 6)[:, 0] for i in range(2)], 1)
        np.testing.assert_allclose(np.asarray(jac(jnp.array([0.8, -0.3]))), exact, atol=1e-8)


@pytest.mark.slow
def test_implicit_gradient_holds_actions_at_their_bounds_and_matches_finite_differences():
    with jax.enable_x64(True):
        planner = mpc.make_planner(
            TightLinearQuadratic(), mpc.ILQR(iterations=15), horizon=6, gradient="implicit"
        )
        x0 = jnp.array([0.8, -0.3])

        def plan_of(x):
            return planner.plan(x, jnp.zeros((6, 1)))[0][:, 0]

        plan = jax.jit(plan_of)(x0)  # one program, not op by op
        jac, fd = _jacobian_and_fd(plan_of, x0, 1e-4)
        held = np.abs(np.abs(np.asarray(plan)) - 0.5) < 1e-4
        assert 0 < held.sum() < 5  # some actions at a bound, some free
        np.testing.assert_array_equal(jac[held], 0.0)
        np.testing.assert_allclose(jac, fd, atol=1e-5 * np.abs(fd).max())  # the solve's tol
        assert np.abs(jac[~held]).max() > 0.1


@pytest.mark.slow
@pytest.mark.parametrize("gradient", ["unroll", "implicit"])
def test_plan_gradients_in_the_start_and_the_model_match_finite_differences(gradient):
    # Pendulum, a start from which the plan has free and held actions; the derivative in the
    # model's gravity is what a planner inside a trained controller passes back to the model.
    with jax.enable_x64(True):
        planner = mpc.make_planner(Pendulum(), mpc.ILQR(iterations=30), 12, gradient=gradient)

        def plan(z):  # z = (theta, theta_dot, g)
            p = eqx.tree_at(lambda p: p.problem.params.g, planner, z[2])
            return p.plan(z[:2], jnp.zeros((12, 1)))[0][:, 0]

        # A step of 1e-3: the solve is exact only to its tolerance, which a smaller step
        # would divide into the difference.
        jac, fd = _jacobian_and_fd(plan, jnp.array([0.5, -1.0, 10.0]), 1e-3)
        assert np.abs(jac).max() > 1.0
        np.testing.assert_allclose(jac, fd, atol=2e-5 * np.abs(fd).max())


@pytest.mark.slow
@pytest.mark.parametrize("gradient", ["unroll", "implicit"])
def test_closed_loop_gradient_through_the_planner_matches_finite_differences(gradient):
    # The return of a short closed-loop episode on the system (g = 10), differentiated through
    # every step's plan in the gravity of the planner's model (g = 9): the system does not
    # depend on it, so the whole derivative comes through the plans.
    with jax.enable_x64(True):
        planner = mpc.make_planner(Pendulum(), mpc.ILQR(iterations=10), 6, gradient=gradient)
        system = planner.problem.params

        def episode_return(g):
            p = eqx.tree_at(lambda p: p.problem.params.g, planner, g[0])
            return p.episode(jnp.array([-0.3, 0.5]), 4, system)[2].sum()

        jac, fd = _jacobian_and_fd(episode_return, jnp.array([9.0]), 1e-3)
        assert abs(float(jac[0])) > 1e-3
        np.testing.assert_allclose(jac, fd, rtol=1e-4)


def test_an_unknown_gradient_mode_is_refused():
    with pytest.raises(ConfigError, match="gradient='exact'"):
        mpc.make_planner(Pendulum(), gradient="exact")
