"""A planner's learned terminal value and warm-start policy (mpc.ValueNetwork, mpc.learn_value):
gradients through the planner against finite differences, learning on a fixed batch, files,
refusals."""

from __future__ import annotations

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffcontrol import mpc
from diffcontrol.controllers import MLPController
from diffcontrol.errors import ConfigError, ModelFileError
from diffcontrol.tasks import CartPole, Pendulum


def _value(task, key=0, hidden=(8,), gain=1.0, scale=30.0):
    """A small value network with a last layer ``gain`` times the default one (which is scaled
    by 0.01 to start near zero), so that it matters to the plan."""
    net = mpc.ValueNetwork(jax.random.PRNGKey(key), task, hidden, scale=scale)
    return eqx.tree_at(lambda n: n.layers[-1].weight, net, gain * net.layers[-1].weight)


def _weights(net):
    return eqx.filter(net, eqx.is_inexact_array)


@pytest.mark.slow
@pytest.mark.parametrize("gradient", ["unroll", "implicit"])
def test_closed_loop_gradient_in_the_value_weights_matches_finite_differences(gradient):
    # The loss of a short closed loop from two starts, differentiated in the value network's
    # weights through every step's plan, against a central difference along a random direction.
    with jax.enable_x64(True):
        task = Pendulum()
        value = _value(task, gain=100.0)
        planner = mpc.make_planner(
            task, mpc.ILQR(iterations=20), 4, terminal_cost=value, gradient=gradient
        )
        starts = jnp.array([[0.4, -0.5], [-0.7, 0.3]])
        params, static = eqx.partition(value, eqx.is_inexact_array)

        @eqx.filter_jit  # one program for the gradient, one for both differences
        def loss(p):
            net = eqx.combine(p, static)
            p_ = eqx.tree_at(lambda q: q.problem.terminal_cost, planner, net)
            return mpc.closed_loop_loss(p_, starts, 3)

        grads = jax.grad(loss)(params)
        leaves, tree = jax.tree.flatten(params)
        keys = jax.random.split(jax.random.PRNGKey(1), len(leaves))
        direction = [jax.random.normal(k, x.shape, x.dtype) for k, x in zip(keys, leaves)]
        along = sum(jnp.vdot(g, d) for g, d in zip(jax.tree.leaves(grads), direction))
        eps = 1e-4

        def shifted(sign):
            return jax.tree.unflatten(tree, [x + sign * eps * d for x, d in zip(leaves, direction)])

        fd = (loss(shifted(1)) - loss(shifted(-1))) / (2 * eps)
        assert abs(float(along)) > 1e-3  # the terminal value does move the plans
        np.testing.assert_allclose(float(along), float(fd), rtol=1e-3)


@pytest.mark.slow
def test_a_few_steps_through_the_planner_lower_the_closed_loop_loss_on_a_fixed_batch():
    task = Pendulum()
    planner = mpc.make_planner(task, mpc.ILQR(iterations=5), 5)
    value = _value(task, key=3, hidden=(16,), gain=10.0)
    starts = jax.vmap(task.reset, (0, None))(
        jax.random.split(jax.random.PRNGKey(0), 4), task.default_params()
    )
    before = float(mpc.closed_loop_loss(eqx.tree_at(lambda p: p.problem.terminal_cost, planner,
                                                    value, is_leaf=lambda x: x is None), starts, 30))  # fmt: skip
    result = mpc.learn_value(
        task, planner, value, init_rounds=0, steps=6, learning_rate=3e-2, starts=starts,
        window=30, eval_every=6, eval_episodes=2, keep_best=False,
    )  # fmt: skip
    after = float(mpc.closed_loop_loss(result.planner, starts, 30))
    assert np.isfinite(after) and after < before - 1.0, (before, after)
    assert result.metrics["curve"][-1]["stage"] == "through planner"


@pytest.mark.slow
def test_fitted_value_iteration_gives_a_planner_that_swings_up():
    # Two rounds of the initialisation alone at H = 5, where the planner without a terminal
    # cost cannot see a swing-up: the learned value must lift its simulated return.
    task = Pendulum()
    planner = mpc.make_planner(task, mpc.ILQR(iterations=5), 5, bound_starts=True)
    result = mpc.learn_value(
        task, planner, init_rounds=2, episodes=16, fit_steps=400, steps=0, eval_episodes=8
    )
    plain = mpc._learn._rollouts(planner, jax.vmap(task.reset, (0, None))(
        jax.random.split(jax.random.split(jax.random.PRNGKey(0), 3)[1], 8),
        task.default_params()), task.episode_length)[2]  # fmt: skip
    assert result.metrics["init_eval_return"] > float(np.mean(plain)) + 50.0


def test_a_value_network_round_trips_through_json(tmp_path):
    task = Pendulum()
    value = _value(task, key=5, hidden=(6, 4), gain=3.0)
    planner = mpc.make_planner(task, mpc.ILQR(iterations=3), 4, terminal_cost=value)
    result = mpc.ValueResult(planner, value, value, {})
    result.save(tmp_path / "value.json")
    back = mpc.load_value(task, tmp_path / "value.json")
    x = jnp.array([0.3, -1.2])
    assert float(back(x)) == pytest.approx(float(value(x)), rel=1e-6)
    assert back.hidden == (6, 4) and back.scale == value.scale
    doc = json.loads((tmp_path / "value.json").read_text())
    with pytest.raises(ModelFileError, match="of task 'pendulum', not 'cartpole'"):
        mpc.ValueNetwork.from_json(CartPole(), doc)
    doc["layers"][0]["weight"] = [[1.0]]
    with pytest.raises(ModelFileError, match="wrong shape"):
        mpc.ValueNetwork.from_json(task, doc)


@pytest.mark.slow
def test_a_warm_policy_is_one_more_start_and_only_the_unrolled_gradient_reaches_it():
    task = Pendulum()
    policy = MLPController(jax.random.PRNGKey(0), 3, 1, hidden=(8,), action_low=(-2.0,),
                           action_high=(2.0,), final_scale=1.0)  # fmt: skip
    x, warm = jnp.array([3.0, 0.0]), jnp.full((6, 1), 2.0)  # near the bottom; a poor guess
    solver = mpc.ILQR(iterations=1)
    plain = mpc.make_planner(task, solver, 6)
    with_policy = mpc.make_planner(task, solver, 6, warm_policy=policy)
    plan = eqx.filter_jit(lambda planner, guess: planner.plan(x, guess))  # not op by op
    _, info = plan(with_policy, warm)
    _, alone = plan(plain, warm)
    _, from_proposal = plan(plain, eqx.filter_jit(with_policy.proposal)(x))
    assert float(from_proposal.cost) < float(alone.cost) - 1.0  # the proposal is the better
    # the same solve from the same start, in two programs: equal up to float32 fusion's rounding
    assert float(info.cost) == pytest.approx(float(from_proposal.cost), rel=1e-5)

    def plan_sum(p, gradient):  # most actions are at a bound; the last is free
        planner = mpc.make_planner(task, solver, 6, warm_policy=p, gradient=gradient)
        return planner.plan(x, warm)[0].sum()

    for gradient, nonzero in (("unroll", True), ("implicit", False)):
        g = eqx.filter_jit(eqx.filter_grad(lambda p, gr=gradient: plan_sum(p, gr)))(policy)
        norm = float(sum(jnp.sum(leaf**2) for leaf in jax.tree.leaves(_weights(g))))
        assert (norm > 0) == nonzero, (gradient, norm)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"steps": -1}, "steps=-1"),
        ({"learning_rate": 0.0}, "learning_rate=0.0"),
        ({"gradient": "exact"}, "gradient='exact'"),
        ({"init_rounds": 0}, "init_rounds=0 needs a value network"),
        ({"window": 0}, "window=0"),
        ({"value": "net"}, "is not an mpc.ValueNetwork"),
    ],
)
def test_bad_settings_of_learn_value_are_one_line_config_errors(kwargs, match):
    task = Pendulum()
    planner = mpc.make_planner(task, mpc.ILQR(iterations=2), 3)
    with pytest.raises(ConfigError, match=match) as e:
        mpc.learn_value(task, planner, **kwargs)
    assert "\n" not in str(e.value)


def test_bad_value_networks_and_terminal_costs_are_refused():
    task = Pendulum()
    key = jax.random.PRNGKey(0)
    for kwargs, match in (({"hidden": (0,)}, "hidden"), ({"scale": -1.0}, "scale=-1.0"),
                          ({"activation": "relu"}, "activation='relu'")):  # fmt: skip
        with pytest.raises(ConfigError, match=match):
            mpc.ValueNetwork(key, task, **kwargs)
    with pytest.raises(ConfigError, match="terminal_cost=3 is not callable"):
        mpc.make_planner(task, terminal_cost=3)
    with pytest.raises(ConfigError, match="plans for task 'pendulum', not 'cartpole'"):
        mpc.learn_value(CartPole(), mpc.make_planner(task))


def test_a_planner_with_a_learned_value_round_trips_through_model_json(tmp_path):
    import diffcontrol
    from diffcontrol import runs
    from diffcontrol.settings import PlanConfig

    task = Pendulum()
    value = _value(task, key=7, hidden=(5,), gain=20.0)
    config = PlanConfig(horizon=3, iterations=2, bound_starts=False)
    runs.plan_run(tmp_path / "p", task, config, final_eval=0, animation=False, value=value)
    doc = json.loads((tmp_path / "p" / "model.json").read_text())
    assert doc["controller"]["value"]["hidden"] == [5]
    policy = diffcontrol.load(tmp_path / "p")
    back = policy.planner.problem.terminal_cost
    x = jnp.array([2.0, 0.5])
    assert float(back(x)) == pytest.approx(float(value(x)), rel=1e-6) and abs(float(value(x))) > 0
    with pytest.raises(ConfigError, match="two terminal costs"):
        mpc.planner_from_config(task, PlanConfig(value_grid=11), value=value)
    with pytest.raises(ConfigError, match="not an mpc.ValueNetwork of task 'pendulum'"):
        runs.plan_run(tmp_path / "q", task, config, final_eval=0, value=3)
    doc["controller"]["value"]["layers"] = []
    (tmp_path / "p" / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="malformed value network"):
        diffcontrol.load(tmp_path / "p")
