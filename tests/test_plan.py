"""The planner as a saved controller: ``diffcontrol plan`` / ``runs.plan_run`` write it,
``diffcontrol.load``, ``evaluate`` and ``animate`` take it back; bad settings are one line."""

from __future__ import annotations

import json

import equinox as eqx
import gymnasium
import numpy as np
import pytest

import diffcontrol
from diffcontrol import mpc, optimal, policies, runs
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, ModelFileError
from diffcontrol.settings import PlanConfig

SMALL = PlanConfig(horizon=5, iterations=3, value_grid=15, value_levels=9)


@pytest.fixture(scope="module")
def planner_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan") / "run"
    runs.plan_run(out, "pendulum", SMALL, final_eval=2, animation=False)
    return out


def _actions(policy, seed=3, steps=40):
    env = gymnasium.make("Pendulum-v1")
    obs, _ = env.reset(seed=seed)
    policy.reset()
    actions = []
    for _ in range(steps):
        actions.append(np.asarray(policy(obs)))
        obs, *_ = env.step(actions[-1])
    env.close()
    return np.stack(actions)


@pytest.mark.slow
def test_load_gives_the_same_actions_as_the_planner_in_memory(planner_run):
    task = diffcontrol.make("pendulum")
    table = optimal.solve(task, 15, 9)
    first = eqx.tree_at(lambda t: t.values, table, table.values[:1])
    planner = mpc.make_planner(
        task,
        mpc.ILQR(iterations=3),
        horizon=5,
        bound_starts=True,
        terminal_cost=lambda x: -first.value(0, x),
    )
    loaded = diffcontrol.load(planner_run)
    assert isinstance(loaded, mpc.PlannerPolicy)
    expected = _actions(mpc.PlannerPolicy(planner))
    np.testing.assert_allclose(_actions(loaded), expected, atol=1e-5)
    assert np.ptp(expected) > 0.5  # it acts: not a constant the two could share by accident


@pytest.mark.slow  # evaluate and animate a planner through the CLI: about 2 s
def test_the_run_is_a_run_like_a_trained_one(planner_run, capsys):
    doc = json.loads((planner_run / "model.json").read_text())
    assert doc["controller"] == {
        "type": "planner",
        "settings": SMALL.to_json(),
        "model": {"kind": "simulator"},
    }
    assert "network" not in doc  # the model and the settings, not a 100 MB table
    metrics = json.loads((planner_run / "metrics.json").read_text())
    stored = metrics["gym_eval"]["returns"]
    assert "0 non-finite" in metrics["planner"]["solves"]
    assert main(["evaluate", str(planner_run), "--episodes", "2", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(again["returns"], stored, rtol=1e-6)  # same seeds, same actions
    solves = again["planner_solves"]  # every control step's solve is counted and reported
    assert int(solves.split()[0]) >= 2 * 200 and "0 non-finite" in solves
    assert main(["animate", str(planner_run), "--out", str(planner_run / "a.gif")]) == 0
    assert (planner_run / "a.gif").stat().st_size > 0


def test_a_numpy_reader_refuses_a_planner_in_one_line(planner_run, capsys):
    with pytest.raises(ModelFileError, match="holds a planner"):
        policies.NumpyPolicy(policies.read_model(planner_run))
    assert main(["train", "--out", str(planner_run), "--resume"]) == 2  # not a training run
    assert "holds a planner" in capsys.readouterr().err


@pytest.mark.parametrize(
    "change, match",
    [
        ({"horizon": 0}, "horizon"),
        ({"terminal_weight": float("inf")}, "terminal_weight"),
        ({"terminal_weight": -1.0}, "terminal_weight"),
        ({"learning_rate": 0.0}, "learning_rate"),
        ({"solver": "newton"}, "solver"),
        ({"value_grid": 2}, "value_grid"),
        ({"bound_starts": "yes"}, "bound_starts"),
    ],
)
def test_bad_settings_are_one_line_config_errors(change, match):
    with pytest.raises(ConfigError, match=match):
        PlanConfig(**change)


def test_bad_input_on_the_command_line_is_one_line(tmp_path, capsys):
    def fails(argv, needle):
        with pytest.raises(SystemExit) as exc:  # argparse refuses it before anything runs
            main(argv)
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 2 and len(err.splitlines()) == 1 and needle in err, err

    out = str(tmp_path / "p")
    fails(["plan", "pendulum", "--out", out, "--horizon", "0"], "--horizon")
    fails(["plan", "pendulum", "--out", out, "--terminal-weight", "nan"], "--terminal-weight")
    for argv, needle in [
        (["plan", "pendulum", "--out", out, "--loss", "nope"], "nope"),
        (["plan", "pendulum-unclipped", "--out", out], "action bounds"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and needle in err, err
    assert not (tmp_path / "p").exists()  # the refused run gave its directory back


def _write_grey_box_fit(where, task: str, **parameters: float) -> None:
    """A minimal ``fitted.json`` of a grey-box fit of ``task`` in ``where``."""
    fit = {"format": "diffcontrol-fitted-model", "version": 1, "task": task, "model": "params"}
    (where / "fitted.json").write_text(json.dumps({**fit, "all_parameters": parameters}))


def test_a_model_file_of_another_task_is_refused(planner_run, tmp_path):
    _write_grey_box_fit(tmp_path, "cartpole", gravity=9.0)
    with pytest.raises(ModelFileError, match="cartpole"):
        runs.plan_run(tmp_path / "p", "pendulum", SMALL, model=tmp_path, final_eval=0)
    doc = json.loads((planner_run / "model.json").read_text())
    doc["task"] = "mountain-car"  # a planner file handed to another task
    with pytest.raises(ModelFileError):
        runs.load_policy(diffcontrol.make("pendulum"), doc)
    doc = json.loads((planner_run / "model.json").read_text())
    doc["controller"]["settings"]["horizon"] = 0  # an edited file
    (tmp_path / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="horizon"):
        diffcontrol.load(tmp_path)


@pytest.mark.slow
def test_a_grey_box_fit_is_planned_through(tmp_path):
    _write_grey_box_fit(tmp_path, "pendulum", g=9.0)
    config = PlanConfig(horizon=5, iterations=2)
    run, _ = runs.plan_run(tmp_path / "p", "pendulum", config, model=tmp_path, final_eval=0)
    loaded = diffcontrol.load(tmp_path / "p")
    assert float(loaded.planner.problem.params.g) == 9.0
    assert json.loads((tmp_path / "p" / "model.json").read_text())["controller"]["model"]["fitted"][
        "all_parameters"
    ] == {"g": 9.0}


@pytest.mark.slow
def test_a_hybrid_fit_is_planned_through_and_judged_on_its_real_system(tmp_path, capsys):
    data, fit, plan = (str(tmp_path / n) for n in ("data.csv", "fit", "plan"))
    real = "diffcontrol/PendulumFriction-v0"
    assert main(["record", real, "--task", "pendulum", "--episodes", "2", "--out", data]) == 0
    argv = ["fit", "pendulum", "--data", data, "--model", "hybrid", "--steps", "5", "--out", fit]
    assert main([*argv, "--quiet"]) == 0
    argv = ["plan", "pendulum", "--model", fit, "--out", plan, "--horizon", "4", "--iterations"]
    assert main([*argv, "2", "--value-grid", "9", "--final-eval", "1", "--no-animation"]) == 0
    doc = json.loads((tmp_path / "plan" / "model.json").read_text())
    assert doc["controller"]["model"]["fitted"]["model"] == "hybrid"  # networks inside
    capsys.readouterr()
    assert main(["evaluate", plan, "--episodes", "1"]) == 0
    assert real in capsys.readouterr().out  # judged where the data came from


def test_a_recorder_asking_for_action_and_gym_action_solves_once(planner_run):
    policy = diffcontrol.load(planner_run)
    obs = np.array([1.0, 0.0, 0.0], np.float32)  # upright at rest: the same obs every step
    u = policy.action(obs)
    assert np.asarray(policy(obs)) == pytest.approx(u) and len(policy.reports) == 1
    policy(obs), policy(obs)  # plain calls always solve, even on an unchanged observation
    assert len(policy.reports) == 3


@pytest.mark.slow
def test_a_three_way_choice_is_planned_relaxed_and_acted_on_as_its_heaviest_choice(tmp_path):
    """The Acrobot's argmax head: the planner plans each torque's weight in [0, 1] (the
    one-hot choice relaxed, as CartPole's sign is planned in [-1, 1]) and Gymnasium gets the
    heaviest choice; ``plan acrobot`` needs no bounds."""
    out = tmp_path / "acrobot"
    small = PlanConfig(horizon=4, iterations=2)
    runs.plan_run(out, "acrobot", small, final_eval=1, animation=False)
    assert json.loads((out / "metrics.json").read_text())["gym_eval"]["env_id"] == "Acrobot-v1"
    policy = diffcontrol.load(out)
    env = gymnasium.make("Acrobot-v1")
    obs, _ = env.reset(seed=0)
    relaxed = np.asarray(policy.action(obs)).reshape(-1)
    assert relaxed.shape == (3,) and np.all((relaxed >= 0) & (relaxed <= 1))
    assert policy(obs) == int(np.argmax(relaxed)) and env.action_space.contains(policy(obs))
    env.close()


def test_the_acrobot_plans_with_the_goal_weighted_past_the_power():
    """``plan acrobot`` plans with ``reach``: ``pump`` with the goal indicator weighted 30
    instead of 2 (docs/benchmarks.md: -66.9 against -86.7 in Acrobot-v1); training keeps
    ``pump``, its first loss."""
    from diffcontrol.mpc._config import default_plan_config
    from diffcontrol.systems import acrobot as ac

    task = diffcontrol.make("acrobot")
    assert default_plan_config(task).loss == "reach" and task.losses[0] == "pump"
    params = task.default_params()
    state, choice = np.array([0.3, -0.2, 1.0, 2.0]), np.array([0.0, 0.0, 1.0])
    after, *_ = task.step(params, state, choice)
    losses = {n: float(task.step_loss(n)(params, state, choice, after, -1.0)) for n in task.losses}
    below = 1 / (1 + np.exp(-(ac.GOAL_HEIGHT - float(ac.tip_height(after))) / 0.5))
    assert losses["pump"] == pytest.approx(losses["power"] + 2 * below, rel=1e-5)
    assert losses["reach"] == pytest.approx(losses["power"] + 30 * below, rel=1e-5)


def test_the_pendulum_plans_with_its_grid_value_by_default_and_without_it_on_request(tmp_path):
    """``plan pendulum``'s defaults are its best planner (H = 10, the 201-point grid value);
    ``--value-grid 0`` drops the value and keeps the rest."""
    from diffcontrol.mpc._config import default_plan_config

    assert default_plan_config(diffcontrol.make("pendulum")) == PlanConfig(
        horizon=10, value_grid=201
    )
    assert default_plan_config(diffcontrol.make("pendulum-unclipped")) == PlanConfig()
    out = tmp_path / "p"
    argv = ["plan", "pendulum", "--out", str(out), "--value-grid", "0", "--final-eval", "0"]
    assert main([*argv, "--no-animation", "--quiet"]) == 0
    settings = json.loads((out / "model.json").read_text())["controller"]["settings"]
    assert settings["value_grid"] is None and settings["horizon"] == 10
