"""The reference optimum (diffcontrol.optimal): a grid dynamic program on Pendulum's state."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import _gym, optimal
from diffcontrol.errors import ConfigError
from diffcontrol.tasks import Pendulum

TASK = Pendulum()
PARAMS = TASK.default_params()


@pytest.fixture(scope="module")
def coarse():
    """A coarse table: 121 x 121 states, 21 torques, the whole 200-step episode."""
    return optimal.solve(TASK, points=121, levels=21)


def _starts(n=12, seed=0):
    keys = jax.random.split(jax.random.key(seed), n)
    return jax.vmap(TASK.reset, (0, None))(keys, PARAMS)


def _constant_returns(starts, torque):
    def episode(x):
        def one(x, _):
            nxt, reward, _ = TASK.step(PARAMS, x, jnp.array([torque]))
            return nxt, reward

        return jax.lax.scan(one, x, None, length=200)[1].sum()

    return jax.vmap(episode)(starts)


def test_interpolation_is_exact_at_grid_points_and_wraps_the_angle(coarse):
    v = coarse.values[0]
    theta = -np.pi + 2 * np.pi * 7 / 121
    speed = -8.0 + 16.0 * 30 / 120
    at = float(coarse.value(0, jnp.array([theta, speed])))
    assert at == pytest.approx(float(v[7, 30]), abs=1e-4)
    wrapped = float(coarse.value(0, jnp.array([theta + 2 * np.pi, speed])))
    assert wrapped == pytest.approx(at, abs=1e-3)
    beyond = float(coarse.value(0, jnp.array([theta, 50.0])))  # clamped to the speed clip
    assert beyond == pytest.approx(float(v[7, -1]), abs=1e-4)


def test_values_are_nonincreasing_in_time_to_go(coarse):
    # Every reward is <= 0, so more steps to go can only cost more.
    assert float(coarse.values[-1].max()) == 0.0
    assert bool(jnp.all(coarse.values[0] <= coarse.values[100] + 1e-4))


def test_greedy_controller_beats_constant_torques_and_matches_its_value(coarse):
    starts = _starts()
    greedy = optimal.greedy_rollout(coarse, starts)
    for torque in (0.0, 2.0, -2.0):
        assert float(greedy.mean()) > float(_constant_returns(starts, torque).mean()) + 100
    # The table's prediction V_0(x_0) against the return its greedy controller achieves on the
    # exact dynamics. Bilinear interpolation on a coarse grid is pessimistic where the value
    # is steep (a start close to a swing-left/swing-right boundary), so on a 121 x 121 grid
    # they agree to 2 on the median start and to 15 % on the mean (the error shrinks with the
    # grid: -132.5 vs -133.0 at 401 x 401 on Gymnasium's seeds 0-99).
    predicted = jax.vmap(coarse.value, (None, 0))(0, starts)
    assert float(jnp.median(jnp.abs(predicted - greedy))) < 2.0
    assert float(jnp.abs(predicted.mean() - greedy.mean())) < 0.15 * abs(float(greedy.mean()))
    assert bool(jnp.all(predicted <= greedy + 2.0))  # achievable: the table never promises more


def test_gymnasium_episodes_match_the_simulator(coarse):
    import gymnasium

    seeds = [0, 1, 2]
    result = optimal.optimal_return(TASK, seeds, table=coarse)
    starts = []
    for s in seeds:
        env = gymnasium.make("Pendulum-v1")
        env.reset(seed=s)
        starts.append(np.array(env.unwrapped.state, np.float32))
    simulated = np.asarray(optimal.greedy_rollout(coarse, jnp.asarray(np.stack(starts))))
    assert result.returns.shape == (3,)
    np.testing.assert_allclose(result.returns, simulated, rtol=0.02, atol=1.0)
    assert result.gap(result.mean) == 0.0
    assert "seeds 0-2" in result.summary()


def test_tasks_without_a_grid_or_bounds_are_refused():
    with pytest.raises(ConfigError, match="state_grid"):
        optimal.solve(diffcontrol.make("cartpole"), points=11, levels=3)
    with pytest.raises(ConfigError, match="action bounds"):
        optimal.solve(diffcontrol.make("pendulum-unclipped"), points=11, levels=3)
    with pytest.raises(ConfigError, match="points"):
        optimal.solve(TASK, points=2, levels=3)
    with pytest.raises(ConfigError, match="levels"):
        optimal.solve(TASK, points=11, levels=1)
    with pytest.raises(ConfigError, match="horizon"):
        optimal.solve(TASK, points=11, levels=3, horizon=0)
    assert diffcontrol.make("cartpole").state_grid(None) is None


def test_evaluate_reports_the_gap_to_the_optimum(pendulum_run, cartpole_run, capsys):
    import json

    from diffcontrol.cli import main

    argv = ["evaluate", str(pendulum_run), "--episodes", "3", "--optimum", "41", "--json"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    opt = doc["optimum"]
    assert opt["seeds"] == [0, 2] and opt["grid_points"] == [41, 41]
    # the tiny run is barely trained: the optimum on the same seeds is far better
    assert opt["mean_return"] > doc["mean_return"]
    gap = (opt["mean_return"] - doc["mean_return"]) / abs(opt["mean_return"])
    assert doc["gap_to_optimum"] == pytest.approx(gap) and gap > 0
    assert main(["evaluate", str(cartpole_run), "--episodes", "1", "--optimum", "41"]) == 2
    err = capsys.readouterr().err
    assert "state grid" in err and len(err.strip().splitlines()) == 1


REAL = ("diffcontrol/PendulumFriction-v0", {"g": 12.0, "friction": 0.1})


@pytest.mark.slow
def test_the_optimum_of_a_real_system_is_solved_on_its_physics():
    import gymnasium

    params = _gym.params_of_env(TASK, *REAL)
    assert (float(params.g), float(params.friction)) == (12.0, 0.1)
    assert _gym.params_of_env(TASK, "Pendulum-v1", {}) == PARAMS
    # environments or arguments whose physics the task does not know
    assert _gym.params_of_env(TASK, "diffcontrol/Pendulum-v0", {}) is None
    assert _gym.params_of_env(TASK, REAL[0], {"g": 12.0, "render_mode": "rgb_array"}) is None

    table = optimal.solve(TASK, points=61, levels=11, params=params)
    seeds = [0, 1, 2]
    result = optimal.optimal_return(TASK, seeds, table=table, real=REAL)
    assert result.env_id.startswith(REAL[0])
    starts = []
    for s in seeds:
        env = gymnasium.make(REAL[0], **REAL[1])
        env.reset(seed=s)
        starts.append(np.array(env.unwrapped.state, np.float32))
    # the greedy controller in the real environment does what it does on the real physics
    simulated = np.asarray(optimal.greedy_rollout(table, jnp.asarray(np.stack(starts))))
    np.testing.assert_allclose(result.returns, simulated, rtol=0.02, atol=1.0)
    # and it is not the nominal physics' table (which values the same starts otherwise)
    nominal = optimal.optimal_return(TASK, seeds, points=61, levels=11, real=REAL)
    assert float(np.abs(nominal.predicted - result.predicted).max()) > 3.0


def test_evaluate_on_another_system_reports_that_systems_optimum(pendulum_run, capsys):
    import json

    from diffcontrol.cli import main

    env = ["--env", REAL[0], "--env-arg", "g=12", "--env-arg", "friction=0.1"]
    argv = ["evaluate", str(pendulum_run), "--episodes", "3", "--optimum", "41", "--json", *env]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["env_id"].startswith(REAL[0]) and doc["optimum"]["env_id"] == doc["env_id"]
    real = optimal.optimal_return(
        TASK, [0, 1, 2], 41, params=_gym.params_of_env(TASK, *REAL), real=REAL
    )
    nominal = optimal.optimal_return(TASK, [0, 1, 2], 41)
    assert doc["optimum"]["mean_return"] == pytest.approx(real.mean, abs=1e-6)
    assert doc["optimum"]["predicted_mean"] == pytest.approx(real.predicted_mean, abs=1e-4)
    assert abs(doc["optimum"]["predicted_mean"] - nominal.predicted_mean) > 3.0
    # an environment whose physics the task does not know: one line, exit 2
    argv = ["evaluate", str(pendulum_run), "--episodes", "1", "--optimum", "41"]
    assert main([*argv, "--env", "diffcontrol/Pendulum-v0"]) == 2
    err = capsys.readouterr().err
    assert "physics" in err and len(err.strip().splitlines()) == 1


def test_the_first_values_are_kept_for_a_builtin_task_and_its_physics():
    """``solve_first`` (the planners' and the training windows' terminal value) solves a
    built-in task once per grid, horizon and physics, for any instance of its class; a user's
    task (a class defined outside diffcontrol) is solved every time."""
    first = optimal.solve_first(TASK, 21, 5, horizon=3)
    assert optimal.solve_first(TASK, 21, 7, horizon=3) is not first  # other actions
    assert optimal.solve_first(Pendulum(), 21, 5, PARAMS, horizon=3) is first
    np.testing.assert_array_equal(first.values, optimal.solve(TASK, 21, 5, horizon=3).values[:1])
    heavier = eqx.tree_at(lambda p: p.g, PARAMS, 12.0)
    assert optimal.solve_first(TASK, 21, 5, heavier, horizon=3) is not first

    class Mine(Pendulum):
        pass

    mine = Mine()
    assert optimal.solve_first(mine, 21, 5, horizon=3) is not optimal.solve_first(
        mine, 21, 5, horizon=3
    )
