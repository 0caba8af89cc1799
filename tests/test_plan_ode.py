"""A continuous-time task's planner as a saved controller: ``diffcontrol plan`` of a swing-up
(``mpc.discretise`` inside ``planner_from_config``), its reference solve with the planner in
the loop, ``diffcontrol.load`` / ``evaluate`` / ``animate`` of it; ``--value FILE``; refusals.

Small budgets: the 1 s swing-up (20 control periods), H = 4, one iLQR iteration. The run is
written once per module and the tests share its compiled programs."""

from __future__ import annotations

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import mpc, runs
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError
from diffcontrol.settings import PlanConfig

SETTINGS = dict(horizon=4, iterations=1, action_bound=20.0)  # bound_starts: the default


@pytest.fixture(scope="module")
def ode_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan-ode") / "run"
    runs.plan_run(out, "cartpole-swingup", settings=SETTINGS, animation=False)
    return out


def _benchmark_planner(params):
    """The planner ``benchmarks/mpc_swingup.py`` builds by hand, with this module's budget."""
    disc = mpc.discretise(diffcontrol.make("cartpole-swingup"), 0.05)
    return mpc.make_planner(
        disc,
        mpc.ILQR(iterations=1),
        horizon=4,
        params=params,
        bounds=((-20.0,), (20.0,)),
        terminal_cost=disc.terminal_cost("limited_hold", params),
        bound_starts=True,
    )


@pytest.mark.slow
def test_the_run_stores_the_discretised_planner_and_the_swingup_summary(ode_run):
    doc = json.loads((ode_run / "model.json").read_text())
    settings = doc["controller"]["settings"]
    assert settings["dt"] == 0.05 and settings["substeps"] == 1  # the task's dt, filled in
    assert settings["horizon"] == 4 and settings["action_bound"] == 20.0
    assert doc["action"]["low"] == [-20.0] and doc["action"]["high"] == [20.0]
    metrics = json.loads((ode_run / "metrics.json").read_text())
    swing = metrics["swingup"]  # as a trained swing-up run reports it
    assert swing["horizon_s"] == pytest.approx(1.0)
    assert 1.0 < swing["peak_force"] <= 20.0 + 1e-3 and np.isfinite(swing["loss"])
    assert (
        metrics["planner"]["solves"].startswith("20 solves")
        and "0 non-finite" in (metrics["planner"]["solves"])
    )
    data = json.loads((ode_run / "data.json").read_text())
    force = np.asarray(data["force"])
    assert len(data["t"]) == 101 and np.abs(force).max() == pytest.approx(swing["peak_force"])
    # held for 0.05 s: constant over the five 100 Hz samples of every control period
    assert np.all(force[:-1].reshape(20, 5) == force[:-1].reshape(20, 5)[:, :1])
    assert (ode_run / "swingup.png").stat().st_size > 0


@pytest.mark.slow
def test_load_rebuilds_the_planner_as_a_sampled_data_controller(ode_run):
    policy = diffcontrol.load(ode_run)
    assert isinstance(policy, mpc.SampledPlannerPolicy) and policy.dt == 0.05
    # the same planner as built by hand: discretised, bounded, the task's end cost (that it
    # acts the same is checked by evaluate reproducing the stored closed loop, below)
    params = policy.planner.problem.params
    assert bool(eqx.tree_equal(policy.planner, _benchmark_planner(params)))
    task = policy.task
    y = np.array([0.0, 0.0, 0.3, -0.5, 0.0, 0.0], np.float32)  # falling near the top
    got = []
    for k in range(6):  # the loop closed in float32 through the planner's own model
        got.append(policy(y[:4] if k % 2 else y))  # the physical state, or the ODE state
        y = np.asarray(mpc._discretise.rk4_hold(task, params, jnp.asarray(y),
                                                 jnp.array([got[-1]]), 0.05))  # fmt: skip
    assert all(isinstance(u, float) and abs(u) <= 20.0 for u in got)
    assert np.ptp(got) > 1.0 and len(policy.reports) == 6  # it acts; every solve reported
    with pytest.raises(ValueError, match="expected a state of 4 values"):
        policy(np.zeros(3))


@pytest.mark.slow
def test_evaluate_and_animate_take_the_run(ode_run, capsys):
    stored = json.loads((ode_run / "metrics.json").read_text())["swingup"]
    assert main(["evaluate", str(ode_run), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    for key in ("final_theta", "final_x", "peak_force", "loss"):  # the same closed loop
        assert again[key] == pytest.approx(stored[key], rel=1e-6, abs=1e-9), key
    assert again["planner_solves"].startswith("20 solves")
    gif = ode_run / "again.gif"
    assert main(["animate", str(ode_run), "--out", str(gif)]) == 0
    assert "peak |F|" in capsys.readouterr().out and gif.stat().st_size > 0


def test_old_planner_settings_load_unchanged():
    old = PlanConfig().to_json()
    for key in ("dt", "substeps", "action_bound"):  # a model.json written before these
        del old[key]
    assert PlanConfig.from_json(old) == PlanConfig()


@pytest.mark.parametrize(
    "change, match",
    [
        ({"dt": 0.0}, "dt must be"),
        ({"dt": float("nan")}, "dt must be"),
        ({"dt": float("inf")}, "dt must be"),
        ({"substeps": 0}, "substeps"),
        ({"action_bound": -1.0}, "action_bound"),
    ],
)
def test_bad_dt_substeps_and_bounds_are_config_errors(change, match):
    with pytest.raises(ConfigError, match=match) as e:
        PlanConfig(**change)
    assert "\n" not in str(e.value)


def test_refusals_on_the_command_line_are_one_line(tmp_path, capsys):
    out = str(tmp_path / "p")
    for argv, needle in [
        (["plan", "pendulum", "--out", out, "--dt", "0.05"], "discrete-time"),
        (["plan", "pendulum", "--out", out, "--substeps", "2"], "discrete-time"),
        (["plan", "cartpole-swingup", "--out", out], "--action-bound"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and needle in err, err
    for flag, bad in (("--dt", "0"), ("--dt", "nan"), ("--substeps", "0")):
        with pytest.raises(SystemExit) as exc:  # refused by the parser before anything runs
            main(["plan", "cartpole-swingup-limited", "--out", out, flag, bad])
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 2 and len(err.splitlines()) == 1 and flag in err, err
    assert not (tmp_path / "p").exists()  # every refused run gave its directory back


def _value_file(tmp_path, task_name="pendulum", key=7):
    task = diffcontrol.make(task_name)
    value = mpc.ValueNetwork(jax.random.PRNGKey(key), task, hidden=(5,), scale=20.0)
    last = value.layers[-1].weight  # scaled up: not near zero, as a fresh network starts
    value = eqx.tree_at(lambda v: v.layers[-1].weight, value, 100 * last)
    planner = mpc.make_planner(task, mpc.ILQR(iterations=1), 3, terminal_cost=value)
    path = tmp_path / f"value-{task_name}.json"
    mpc.ValueResult(planner, value, value, {}).save(path)
    return path, value


@pytest.mark.slow  # a grid value solved and planned through: about 2.2 s
def test_value_file_round_trips_through_the_command_line(tmp_path):
    path, value = _value_file(tmp_path)
    out = tmp_path / "p"
    argv = ["plan", "pendulum", "--out", str(out), "--horizon", "3", "--iterations", "1"]
    argv += ["--value", str(path), "--final-eval", "0", "--no-animation", "--quiet"]
    assert main(argv) == 0
    doc = json.loads((out / "model.json").read_text())
    assert doc["controller"]["value"] == json.loads(path.read_text())
    assert doc["controller"]["settings"]["value_grid"] is None  # in place of the default grid
    back = diffcontrol.load(out).planner.problem.terminal_cost
    x = jnp.array([2.0, 0.5])
    assert float(back(x)) == pytest.approx(float(value(x)), rel=1e-6) and abs(float(value(x))) > 1


def test_a_bad_value_file_is_one_line(tmp_path, capsys):
    cartpole, _ = _value_file(tmp_path, "cartpole")  # another task's network
    pendulum, _ = _value_file(tmp_path)
    shapes = tmp_path / "shapes.json"
    doc = json.loads(pendulum.read_text())
    doc["layers"][0]["weight"] = [[1.0]]
    shapes.write_text(json.dumps(doc))
    (tmp_path / "text.json").write_text("import os  # not JSON\n")
    out = str(tmp_path / "p")
    for file, needle in [
        (tmp_path / "missing.json", "does not exist"),
        (tmp_path / "text.json", "not valid JSON"),
        (cartpole, "of task 'cartpole', not 'pendulum'"),
        (shapes, "wrong shape"),
    ]:
        assert main(["plan", "pendulum", "--out", out, "--value", str(file)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and needle in err and str(file) in err, err
    assert not (tmp_path / "p").exists()
