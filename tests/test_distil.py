"""Distillation of a planner into the MLP (``mpc.distil``, DAgger): the MLP learns the planner's
actions, later rounds label the MLP's own states, the result saves and loads like a trained
run, and bad settings are one-line errors."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import _timing, mpc
from diffcontrol.controllers import MLPController, apply_head, head_inverse
from diffcontrol.errors import ConfigError, SolverFailed
from diffcontrol.rollout import rollout
from diffcontrol.tasks import Pendulum, controller_kwargs

from .test_mpc import LinearQuadratic


class ShortLinearQuadratic(LinearQuadratic):
    """The double integrator of the planner's tests with short episodes (cheap to distil)."""

    name = "test-short-linear-quadratic"
    episode_length = 30

    def write_figures(self, run, out, animation=True):
        return []  # no Gymnasium environment to draw it in


def _planner(task):
    return mpc.make_planner(task, mpc.ILQR(iterations=3), horizon=10)


@pytest.fixture(scope="module")  # about 30 s: the tests that use it are slow
def distilled():
    task = ShortLinearQuadratic()
    planner = _planner(task)
    _timing.watch_compiles()
    programs = []  # compiled so far, at each progress line (the first is before any round)
    result = mpc.distil(
        task, planner, rounds=3, episodes_per_round=16, fit_steps=400, eval_episodes=16, seed=3,
        progress=lambda line: programs.append(_timing.compiled_programs()),
    )  # fmt: skip
    result.metrics["test_programs"] = programs
    return task, planner, result


def _labelled(planner, controller, beta, seed=7, episodes=8):
    task = planner.task
    starts = jax.vmap(task.reset, (0, None))(
        jax.random.split(jax.random.key(seed), episodes), planner.problem.params
    )
    keys = jax.random.split(jax.random.key(seed + 1), episodes)
    run = jax.jit(mpc.labelled_episodes, static_argnums=5)
    return starts, run(planner, controller, starts, keys, jnp.float32(beta), task.episode_length)


def _untrained(task, seed=0):
    return MLPController(jax.random.key(seed), hidden=(64, 64), **controller_kwargs(task))


@pytest.mark.slow
def test_the_distilled_mlp_acts_like_the_planner_on_its_own_states(distilled):
    task, planner, result = distilled
    controller = result.controller
    # States the distilled MLP visits itself (fresh starts), labelled by the planner.
    _, (obs, labels, valid, returns, finite) = _labelled(planner, controller, beta=0.0)
    assert bool(valid.all()) and bool(finite.all())
    span = planner.problem.high - planner.problem.low

    def error(ctrl):
        pred = jax.vmap(jax.vmap(ctrl))(obs)
        return float(jnp.sqrt(jnp.mean(((pred - labels) / span) ** 2)))

    assert error(controller) < 0.2 * error(_untrained(task))
    # and it drives nearly as well as the planner from the same starts
    starts, (_, _, _, planner_returns, _) = _labelled(planner, controller, beta=1.0)
    params, steps = planner.problem.params, task.episode_length
    mlp_returns = jax.vmap(lambda x: rollout(task, params, controller, x, steps).rewards.sum())(
        starts
    )
    untrained = _untrained(task)
    untrained = jax.vmap(lambda x: rollout(task, params, untrained, x, steps).rewards.sum())(starts)
    gap = float(planner_returns.mean() - mlp_returns.mean())
    assert gap < 0.1 * float(planner_returns.mean() - untrained.mean())


@pytest.mark.slow
def test_rounds_after_the_first_roll_out_the_mlp_and_label_with_the_planner():
    task = ShortLinearQuadratic()
    planner = _planner(task)
    controller = _untrained(task, seed=1)
    starts, (obs, labels, valid, returns, _) = _labelled(planner, controller, beta=0.0)
    params = planner.problem.params
    own = jax.vmap(lambda x: rollout(task, params, controller, x, task.episode_length))(starts)
    # beta 0: the states are the MLP's own closed loop ...
    np.testing.assert_allclose(np.asarray(obs), np.asarray(own.observations), atol=1e-5)
    np.testing.assert_allclose(np.asarray(returns), np.asarray(own.rewards.sum(-1)), rtol=1e-5)
    # ... the labels the planner's (not the MLP's) actions there
    first_plan, _ = jax.vmap(planner.plan, (0, None))(starts, planner.initial_plan())
    np.testing.assert_allclose(np.asarray(labels[:, 0]), np.asarray(first_plan[:, 0]), atol=1e-5)
    assert not np.allclose(np.asarray(labels), np.asarray(own.actions), atol=0.1)
    # beta 1: the planner drives (round 0)
    _, (p_obs, p_labels, _, _, _) = _labelled(planner, controller, beta=1.0)
    ep_states, ep_actions, _, _ = jax.vmap(planner.episode, (0, None))(starts, task.episode_length)
    np.testing.assert_allclose(np.asarray(p_obs), np.asarray(ep_states[:, :-1]), atol=1e-5)
    np.testing.assert_allclose(np.asarray(p_labels), np.asarray(ep_actions), atol=1e-5)


@pytest.mark.slow
def test_every_round_adds_its_episodes_and_is_on_the_curve(distilled):
    task, _, result = distilled
    curve = result.metrics["curve"]
    per_round = 16 * task.episode_length
    assert [p["labelled_states"] for p in curve] == [per_round, 2 * per_round, 3 * per_round]
    assert [p["planner_share"] for p in curve] == [1.0, 0.0, 0.0]
    info = result.metrics["distillation"]
    assert info["planner_calls"] == 3 * per_round and info["non_finite_solves"] == 0
    # the MLP's error on the states it visits, before each fit: the untrained one's (round 0)
    # against the learnt one's
    assert curve[-1]["on_policy_error"] < 0.2 * curve[0]["on_policy_error"]
    # the rounds after the first run the programs compiled for it: nothing new compiles
    programs = result.metrics["test_programs"]
    assert len(programs) == 4 and programs[3] == programs[2]
    hidden = [layer.out_features for layer in result.controller.layers[:-1]]
    assert tuple(hidden) == result.config.hidden


@pytest.mark.slow
def test_distilled_result_saves_and_loads_like_a_trained_run(distilled, tmp_path):
    task, _, result = distilled
    written = result.save(tmp_path / "run", final_eval=0, animation=False)
    assert "model.json" in written
    policy = diffcontrol.load(tmp_path / "run", task=task)
    obs = np.random.default_rng(0).uniform(-1, 1, (20, 2)).astype(np.float32)
    expected = np.asarray(jax.vmap(result.controller)(jnp.asarray(obs)))
    got = np.stack([np.asarray(policy(o), np.float32) for o in obs])
    np.testing.assert_allclose(got.reshape(expected.shape), expected, rtol=1e-4, atol=1e-4)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["distillation"]["method"] == "DAgger"
    assert metrics["distillation"]["planner"]["solver"] == "ILQR"


@pytest.mark.parametrize("head", ["linear", "tanh", "sigmoid"])
def test_head_inverse_undoes_the_head(head):
    low, high = jnp.array([-2.0]), jnp.array([3.0])
    u = jnp.linspace(-1.9, 2.9, 7)[:, None]
    z = head_inverse(head, u, low, high)
    np.testing.assert_allclose(np.asarray(apply_head(head, z, low, high)), np.asarray(u), atol=1e-5)
    assert bool(jnp.isfinite(head_inverse(head, high, low, high)).all())


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"rounds": 0}, "rounds=0"),
        ({"episodes_per_round": -1}, "episodes_per_round=-1"),
        ({"fit_steps": 2.5}, "fit_steps=2.5"),
        ({"beta": 1.5}, "beta=1.5"),
        ({"learning_rate": float("nan")}, "learning_rate=nan"),
        ({"seed": -3}, "seed=-3"),
    ],
)
def test_bad_settings_are_one_line_config_errors(kwargs, match):
    task = ShortLinearQuadratic()
    with pytest.raises(ConfigError, match=match) as err:
        mpc.distil(task, _planner(task), **kwargs)
    assert "\n" not in str(err.value)


def test_a_planner_of_another_task_or_a_discrete_head_is_refused():
    task = ShortLinearQuadratic()
    with pytest.raises(ConfigError, match="plans for task 'pendulum'"):
        mpc.distil(task, _planner(Pendulum()))
    sign = MLPController(jax.random.key(0), 2, 1, head="sign")
    with pytest.raises(ConfigError, match="'sign' head"):
        mpc.distil(task, _planner(task), sign)
    with pytest.raises(ConfigError, match="not a Planner"):
        mpc.distil(task, "ilqr")


@pytest.mark.slow
def test_a_planner_whose_every_solve_is_nan_is_reported_not_fitted():
    task = ShortLinearQuadratic()
    planner = mpc.make_planner(
        task, mpc.ILQR(iterations=2), horizon=5, terminal_cost=lambda x: jnp.nan * x[0]
    )
    with pytest.raises(SolverFailed, match="non-finite"):
        mpc.distil(task, planner, rounds=1, episodes_per_round=2, fit_steps=1, eval_episodes=1)
