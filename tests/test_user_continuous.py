"""A user's own continuous-time task, in a file of theirs: trained from the command line,
judged by reference solves of its closed loop (checked against SciPy's DOP853), and planned
at its own control period."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import diffcontrol
from diffcontrol.cli import main

from ._cli import one_line

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
USER_FILE = EXAMPLES / "damped_pendulum.py"

SPEC = "damped_pendulum:DampedPendulum"
TINY = ["--updates", "4", "--eval-every", "2", "--starts", "2", "--horizon-s", "1"]
TINY += ["--saves", "11", "--hidden", "4", "--population", "1"]


@pytest.fixture(scope="module")
def user_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("user-continuous")
    shutil.copy(USER_FILE, d / "damped_pendulum.py")
    shutil.copy(EXAMPLES / "gridded_pendulum.py", d / "gridded_pendulum.py")  # with a state grid
    return d


@pytest.mark.slow
def test_train_and_evaluate_without_an_environment(user_dir, monkeypatch, capsys):
    """No Gymnasium environment: the final evaluation and ``evaluate`` solve the closed loop
    with the task's own vector field from held-out starts of its reset distribution, and
    report the loss and where each start ends, as SciPy's DOP853 integrates it."""
    from scipy.integrate import solve_ivp

    monkeypatch.chdir(user_dir)
    out = user_dir / "run"
    # 2 starts everywhere: one compiled evaluation, shared with the test below
    assert main(["train", SPEC, "--out", str(out), "--quiet", *TINY, "--final-eval", "2"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["final_evaluation"] == "closed_loop"
    assert metrics["closed_loop"]["starts"] == 2 and metrics["closed_loop"]["horizon_s"] == 1.0

    capsys.readouterr()
    assert main(["evaluate", str(out), "--task", SPEC, "--episodes", "2", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["starts"] == 2 and ev["loss"] == "upright"
    assert main(["evaluate", str(out), "--task", SPEC, "--episodes", "2"]) == 0
    assert "final state, mean over the starts: phi" in capsys.readouterr().out

    # the same closed loop, integrated by SciPy with the NumPy policy that `load` gives
    task = diffcontrol.tasks.resolve(SPEC)
    policy = diffcontrol.load(out)
    import jax

    for i, final in enumerate(ev["final_states"]):
        y0 = np.asarray(task.reset(jax.random.PRNGKey(i), task.default_params()), np.float64)

        def f(t, y):
            u = float(policy(y))  # a StatePolicy: the state in, the force out
            return [y[1], 9.81 * np.sin(y[0]) - 0.1 * y[1] + u]

        sol = solve_ivp(f, (0.0, 1.0), y0, method="DOP853", rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(
            [final["phi"], final["phidot"]], sol.y[:, -1], rtol=1e-4, atol=1e-5
        )

    # the grid optimum from the same starts: refused without a state grid, else the grid's
    # controller judged as the run is, with the gap to it
    one_line(capsys, ["evaluate", out, "--task", SPEC, "--optimum", "21"], "define state_grid")
    gridded = ["evaluate", str(out), "--task", "gridded_pendulum:GriddedPendulum"]
    assert main([*gridded, "--episodes", "2", "--optimum", "21", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    opt = ev["optimum"]
    assert (opt["grid_points"], opt["dt"], opt["starts"], opt["seed"]) == ([21, 21], 0.1, 2, 0)
    assert len(opt["losses"]) == len(opt["final_states"]) == 2
    assert ev["gap_to_optimum"] == pytest.approx(ev["mean_loss"] / opt["mean_loss"] - 1)
    assert main([*gridded, "--episodes", "2", "--optimum", "21"]) == 0
    assert "grid optimum (grid 21 x 21, 41 actions, each held 0.1 s)" in capsys.readouterr().out

    # a run stored before window_s existed resumes, with the whole horizon it was trained on
    doc = json.loads((out / "run.json").read_text())
    del doc["config"]["window_s"], doc["complete"]
    (out / "run.json").write_text(json.dumps(doc))
    (out / "model.json").unlink()
    assert main(["train", SPEC, "--out", str(out), "--resume", "--quiet"]) == 0
    assert json.loads((out / "metrics.json").read_text())["config"]["window_s"] == 0.0


def test_a_continuous_task_plans_at_its_own_control_period(user_dir, monkeypatch):
    """``plan`` needs no ``--dt``: a continuous task's control period is the interval between
    the saved points of its training configuration."""
    from diffcontrol.mpc._config import default_plan_config, for_task
    from diffcontrol.settings import PlanConfig

    monkeypatch.chdir(user_dir)
    task = diffcontrol.tasks.resolve(SPEC)
    assert default_plan_config(task).dt == pytest.approx(8 / 80)
    assert for_task(PlanConfig(), task).dt == pytest.approx(0.1)
    assert for_task(PlanConfig(dt=0.02), task).dt == 0.02  # one given wins


@pytest.mark.slow
def test_a_controller_that_ends_where_doing_nothing_ends_is_warned_of(user_dir, monkeypatch):
    """The closed-loop evaluation says when the controller's loop ends where a controller
    that does nothing ends (a pendulum left hanging), and not when it moves the system."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from diffcontrol.controllers import MLPController
    from diffcontrol.evaluation import evaluate_closed_loop

    monkeypatch.chdir(user_dir)
    task = diffcontrol.tasks.resolve(SPEC)
    config = task.default_config().replace(horizon_s=1.0, saves=11, hidden=(4,))
    ctrl = MLPController(
        jax.random.PRNGKey(0),
        3,
        1,
        hidden=(4,),
        head="tanh",
        action_low=(-3.0,),
        action_high=(3.0,),
    )
    idle = eqx.tree_at(lambda c: c.layers[-1].bias, ctrl, replace_fn=jnp.zeros_like)
    idle = eqx.tree_at(lambda c: c.layers[-1].weight, idle, replace_fn=jnp.zeros_like)
    pushing = eqx.tree_at(lambda c: c.layers[-1].bias, idle, jnp.full((1,), 5.0))
    hanging = evaluate_closed_loop(task, idle, config=config, starts=2)
    assert len(hanging.warnings) == 1 and "does nothing" in hanging.warnings[0]
    assert "warning: the controller ends where" in hanging.summary()
    moved = evaluate_closed_loop(task, pushing, config=config, starts=2)
    assert moved.warnings == [] and moved.to_json()["warnings"] == []


def test_a_vector_field_that_misreads_the_action_is_one_line_naming_its_shape(
    user_dir, monkeypatch
):
    """``force_fn(t, y)`` gives a one-action task's action as a scalar; a vector field that
    indexes it, or returns the wrong shape, is refused before training, saying so."""
    import jax.numpy as jnp

    monkeypatch.chdir(user_dir)
    base = type(diffcontrol.tasks.resolve(SPEC))

    class Indexing(base):
        def vector_field(self, t, y, args):
            p, force_fn = args
            u = force_fn(t, y)[0]  # as if it were controller(obs), shape (1,)
            return jnp.stack([y[1], p.g * jnp.sin(y[0]) + u])

    class Flat(base):
        def vector_field(self, t, y, args):
            return jnp.zeros(3)

    config = base().default_config().replace(updates=1, eval_every=1, horizon_s=1.0, saves=11)
    with pytest.raises(diffcontrol.ConfigError, match=r"force_fn\(t, y\) gives a scalar") as e:
        diffcontrol.train(Indexing(), config)
    assert "\n" not in str(e.value) and "state of shape (2,)" in str(e.value)
    with pytest.raises(diffcontrol.ConfigError, match=r"of shape \(3,\) for a state of shape"):
        diffcontrol.train(Flat(), config)


def test_windows_take_one_step_each_through_their_own_solve(user_dir, monkeypatch):
    """``window_s`` cuts each update's horizon into consecutive windows: one optimiser step
    per window, each window's loss on its own share of the saved points; 0, or a window as
    long as the horizon, is the whole horizon in one step. A configuration written before
    ``window_s`` existed resumes as it was trained: the whole horizon."""
    import jax
    import optax

    from diffcontrol.config import ODETrainConfig
    from diffcontrol.training import make_ode_trainer, task_params

    monkeypatch.chdir(user_dir)
    task = diffcontrol.tasks.resolve(SPEC)
    params = task_params(task)
    config = task.default_config().replace(
        horizon_s=1.0, saves=11, starts=2, population=1, hidden=(4,), window_s=0.25
    )
    seen = []  # the saved points of each trajectory the loss is traced on

    def recording(trajectory):
        seen.append(trajectory.phi.shape)
        return task.trajectory_loss("upright")(trajectory)

    trainer = make_ode_trainer(task, config, trajectory_loss=recording)
    assert trainer.windows() == 4
    state, stats = trainer.update(trainer.init(jax.random.PRNGKey(0), params), params)
    assert int(optax.tree_utils.tree_get(state.opt_state, "count")[0]) == 4
    # the checks of the loss on a whole horizon (11 points) and a window (10 / 4 intervals: 3
    # points), then one trace inside the scan over the windows
    assert seen == [(11,), (3,), (3,)]
    assert bool(jax.numpy.isfinite(stats.loss))
    for whole in (0.0, 1.0):
        assert make_ode_trainer(task, config.replace(window_s=whole)).windows() == 1
    old = {k: v for k, v in config.to_json().items() if k != "window_s"}
    assert ODETrainConfig.from_json(old).window_s == 0.0
    assert ODETrainConfig().window_s == 2.0  # a new run of a user's task: 2 s windows


def test_a_continuous_task_without_planning_losses_is_planned_by_its_trajectory_loss(
    user_dir, monkeypatch, capsys
):
    """A task that declares no running cost is planned with its trajectory loss of a
    trajectory that stays at the state and action (here 6 x (1 - cos phi + 0.01 phidot^2));
    its one action reaches the vector field as the scalar that training gives, and ``plan``
    ends with the loss of its closed loop: a reference for the trained controller."""
    import jax.numpy as jnp

    from diffcontrol.mpc._discretise import DwellingCost, planning_losses, running_cost

    monkeypatch.chdir(user_dir)
    task = diffcontrol.tasks.resolve(SPEC)
    assert planning_losses(task) == ("upright",)
    rate = running_cost(task, "upright")
    assert rate == DwellingCost(task, "upright")  # equal planners compile once
    y = jnp.array([0.5, 2.0])
    expected = 6 * (1 - np.cos(0.5) + 0.01 * 2.0**2)
    assert float(rate(task.default_params(), y, jnp.array([1.0]))) == pytest.approx(expected)
    out = user_dir / "plan"
    argv = ["plan", SPEC, "--out", str(out), "--horizon", "3", "--iterations", "1"]
    assert main([*argv, "--final-eval", "2", "--quiet", "--no-animation"]) == 0
    assert "(2 starts)" in capsys.readouterr().out  # the loss of its closed loop from 2 starts
    assert diffcontrol.policies.is_planner(json.loads((out / "model.json").read_text()))


@pytest.mark.slow
def test_the_grid_optimum_of_a_continuous_task_answers_whether_it_is_feasible(
    user_dir, monkeypatch
):
    """``mpc.closed_loop_optimum`` of the user's pendulum with a state grid: the grid's
    controller, each action held for 0.1 s, swings it up from held-out starts in the float64
    reference solve of the task's own ODE (a coarse 41 x 41 grid suffices), and keeps it at
    rest upright to the end."""
    import jax.numpy as jnp

    from diffcontrol.mpc import closed_loop_optimum

    monkeypatch.chdir(user_dir)
    task = diffcontrol.tasks.resolve("gridded_pendulum:GriddedPendulum")
    opt = closed_loop_optimum(task, 41, starts=2, seed=1000)
    phi = (opt.result.final_states[:, 0] + np.pi) % (2 * np.pi) - np.pi
    assert np.all(np.abs(phi) < 0.1) and np.all(np.abs(opt.result.final_states[:, 1]) < 0.5)
    assert opt.result.horizon_s == 8.0 and opt.dt == pytest.approx(0.1)
    assert opt.mean < 1.0  # hanging for 8 s costs 2 + 5 * 2

    # where the plan ends counts: from upright rest it stays there to the last instant, over a
    # horizon that is not a whole number of periods too (the last period cut short)
    base = type(task)

    class AtRest(base):
        name = "user-damped-pendulum-at-rest"

        def reset(self, key, params):
            return jnp.zeros(2)

    config = task.default_config().replace(horizon_s=1.04, saves=14)
    rest = closed_loop_optimum(AtRest(), 41, starts=1, config=config)
    assert rest.mean == 0.0 and np.all(rest.result.final_states == 0.0)
    assert rest.gap(0.5) is None  # a gap to a loss of 0 is no fraction
    judged = dataclasses.replace(rest.result, optimum=rest)  # a controller as good as it
    assert "the controller's loss is 0 above it" in judged.summary()

    # a grid that does not fit the state, or a table too large to hold, is one line
    class ThreeAxes(base):
        name = "user-damped-pendulum-3-axes"

        def state_grid(self, params):
            return (*task.state_grid(params), task.state_grid(params)[1])

    with pytest.raises(diffcontrol.ConfigError, match="3 axes for a state of 2 entries"):
        closed_loop_optimum(ThreeAxes(), 21)
    long = task.default_config().replace(horizon_s=2000.0)
    with pytest.raises(diffcontrol.ConfigError, match="more than 201,402,201; choose fewer"):
        closed_loop_optimum(task, 1001, config=long)


def test_each_window_starts_where_and_when_the_last_one_ended():
    """A clock (``y' = 1`` from ``y = 0``) over 1 s in 4 windows: the windows' first saved
    points are at t = 0, 0.25, 0.5, 0.75, each with the state the last window ended in."""
    import jax
    import jax.numpy as jnp

    from diffcontrol.training import make_ode_trainer

    class Clock(diffcontrol.ContinuousTask):
        name = "clock"
        observation_size = action_size = 1
        action_head = "linear"
        losses = ("late",)
        state_names = ("y",)

        def default_params(self):
            return ()

        def default_config(self):
            return diffcontrol.ODETrainConfig(horizon_s=1.0, saves=9, window_s=0.25)

        def initial_state(self, params):
            return jnp.zeros(1)

        def vector_field(self, t, y, args):
            return jnp.ones(1)

        def observe(self, state):
            return state

        def trajectory(self, params, controller, ts, ys):
            return (ts, ys[:, 0])

        def trajectory_loss(self, name):
            def late(trajectory):
                ts, ys = trajectory
                jax.debug.callback(lambda t, y: seen.append((t, y)), ts[0], ys[0])
                return jnp.mean(ys)

            return late

    seen = []
    task = Clock()
    config = task.default_config().replace(population=1, hidden=(2,))
    trainer = make_ode_trainer(task, config)
    trainer.update(trainer.init(jax.random.PRNGKey(0), ()), ())
    starts = np.asarray([np.ravel(np.asarray(x)) for pair in seen for x in pair]).reshape(-1, 2)
    np.testing.assert_allclose(starts, [[0.0, 0.0], [0.25, 0.25], [0.5, 0.5], [0.75, 0.75]])
