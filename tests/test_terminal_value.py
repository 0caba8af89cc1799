"""The windows' terminal value (``value_grid``): truncated BPTT credited with the return to go
that the task's grid dynamic program gives the state each window leaves."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol as dc
from diffcontrol import _run_dir, optimal
from diffcontrol.cli import main
from diffcontrol.errors import RunDirectoryError
from diffcontrol.mpc._config import default_plan_config, loop_planner
from diffcontrol.training import make_trainer, train
from diffcontrol.training._programs import _start

PENDULUM = dc.make("pendulum")
NAN = float("nan")
# 3 simulations, 5-step windows, 7-step episodes: started at times 0, 2 and 4, the first is
# mid-episode at the window's end, the second ends its episode at the window's last step and
# the third ends it at the window's third step (and goes on from a fresh start).
TINY = dict(batch=3, window=5, horizon=7, eval_episodes=2, hidden=(8,), target_return=NAN)


@pytest.mark.slow
@pytest.mark.parametrize("timed, episode", [(False, 7), (True, 7), (True, 6)])
def test_the_window_loss_adds_minus_the_value_of_the_state_left_per_step(timed, episode):
    """``episode`` below the horizon (7) is the horizon curriculum's: V_t then counts the
    steps of that shorter episode."""
    cfg = PENDULUM.default_config().replace(**TINY, value_grid=11, value_time=timed)
    params = PENDULUM.default_params()
    with_value = make_trainer(PENDULUM, cfg)
    plain = make_trainer(PENDULUM, cfg.replace(value_grid=0, value_time=False))
    ts, _ = _start(with_value, np.int32(0), params)
    times = jnp.array([0, 2, 4], jnp.int32)
    keys = jax.random.split(jax.random.PRNGKey(1), (cfg.window, cfg.batch))
    args = (ts.controller, params, ts.env_state, times, ts.episode_return, keys, episode)
    loss, (carry, n_done, _) = with_value.window_loss(*args)
    plain_loss, (plain_carry, plain_done, _) = plain.window_loss(*args)
    for a, b in zip(carry, plain_carry, strict=True):  # the same simulation
        np.testing.assert_array_equal(a, b)
    assert int(n_done) == int(plain_done) == 2
    steps = np.asarray(carry[1])
    # 7: the second restarts at its last step; 6: the second and third restart inside
    np.testing.assert_array_equal(steps, [5, 0, 2] if episode == 7 else [5, 1, 3])

    # solved apart: the same grid over the training horizon (7 steps), 41 torques
    table = optimal.solve(PENDULUM, 11, horizon=cfg.horizon)
    index = steps + (cfg.horizon - episode) if timed else np.zeros(3, int)
    value = np.array([float(table.value(t, x)) for t, x in zip(index, np.asarray(carry[0]))])
    to_go = value * (steps != 0)  # none for an episode that ended at the window's last step
    expected = float(plain_loss) - np.mean(to_go) / cfg.window
    assert abs(float(plain_loss) - expected) > 0.5  # the values are not negligible here
    np.testing.assert_allclose(float(loss), expected, rtol=1e-5)


@pytest.mark.parametrize(
    "task, grid, needle",
    [
        ("pendulum", 1, "value_grid must be 0"),
        ("pendulum", 2, "value_grid must be 0"),
        ("pendulum", 1002, "value_grid must be 0"),
        ("cartpole", 11, "value_grid=11 needs the task's grid optimum, but task 'cartpole'"),
        ("pendulum-unclipped", 11, "but task 'pendulum-unclipped' has no action bounds"),
    ],
)
def test_a_value_grid_the_task_cannot_have_is_refused_in_one_line(task, grid, needle):
    task = dc.make(task)
    with pytest.raises(dc.ConfigError) as exc:
        train(task, task.default_config().replace(updates=1, eval_every=1, value_grid=grid))
    assert needle in str(exc.value) and "\n" not in str(exc.value)
    if grid > 2 and grid < 1002:
        assert "--value-grid 0" in str(exc.value)


def test_tables_too_large_to_solve_or_hold_are_refused():
    from diffcontrol.training import resolve_config
    from diffcontrol.training._bptt import check_value_grid

    car = dc.make("mountain-car-continuous")
    recipe = resolve_config(car, "grid-value")
    check_value_grid(car, recipe)  # 1,000 grids of 101 x 101: held
    with pytest.raises(dc.ConfigError, match="held by the training program.* at most 183 points"):
        check_value_grid(car, recipe.replace(value_grid=201))
    check_value_grid(car, recipe.replace(value_grid=201, value_time=False))  # V_0 only held
    long = PENDULUM.default_config().replace(value_grid=201, horizon=100_000)
    with pytest.raises(dc.ConfigError, match="to be solved.* or a shorter horizon"):
        check_value_grid(PENDULUM, long)


def test_the_mountain_car_keeps_its_own_planner():
    """Its grid would give it the grid-valued planner of a task with a state grid, whose
    -V_0 makes waiting free there."""
    from diffcontrol.compare._planning import planning_methods

    car = dc.make("mountain-car-continuous")
    assert car.state_grid(car.default_params()) is not None
    assert loop_planner(car) == default_plan_config(car)
    assert planning_methods(car) == [] and planning_methods(PENDULUM) != []


def test_a_sweep_sets_value_time_against_the_recipes_grid(capsys, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    argv = ["sweep", "mountain-car-continuous", "--recipe", "grid-value", "--seeds", "0"]
    assert main([*argv, "--set", "value_time=yes,no", "--out", str(blocker)]) == 2
    err = capsys.readouterr().err
    assert "is not an empty directory" in err and "needs a value_grid" not in err, err


def test_value_time_needs_a_grid():
    with pytest.raises(dc.ConfigError, match="value_time needs a value_grid"):
        PENDULUM.default_config().replace(value_grid=0, value_time=True)


@pytest.mark.slow
def test_the_mountain_car_learns_from_its_own_reward_only_with_the_time_to_go():
    """The `cost` loss (minus Gymnasium's reward) alone teaches the car to stand still; with
    V_0 at the windows' ends too, since a whole episode is always ahead; with V_t, the value
    of the steps left, standing still loses the flag and the car learns to rock out."""
    from diffcontrol.training import resolve_config

    car = dc.make("mountain-car-continuous")
    cfg = resolve_config(car, "grid-value").replace(
        updates=100, batch=16, eval_every=50, eval_episodes=32, value_grid=41
    )
    timed = train(car, cfg).curve[-1]["eval_return"]
    with pytest.warns(UserWarning, match="keep_best returned the untrained controller"):
        whole = train(car, cfg.replace(value_time=False)).curve[-1]["eval_return"]
    assert timed > 90 and abs(whole) < 1, (timed, whole)


def test_the_range_is_named_as_it_is():
    for bad in (-1, 10**30):
        with pytest.raises(
            dc.ConfigError, match=r"value_grid must be 0 \(no terminal value\) or 3"
        ):
            PENDULUM.default_config().replace(value_grid=bad)


def test_too_many_grid_points_over_more_axes_are_refused_before_anything_is_solved():
    from diffcontrol.optimal import GridAxis
    from diffcontrol.training._bptt import check_value_grid

    class Cube:  # three state axes with bounds: only what the check reads
        name, action_low, action_high = "cube", (-1.0,), (1.0,)

        def default_params(self):
            return None

        def state_grid(self, params):
            return (GridAxis(0.0, 1.0),) * 3

        def reset(self, key, params):  # a state of three entries, one per axis
            return jnp.zeros(3)

    def config(points):  # one step: only the grid's points count
        return PENDULUM.default_config().replace(value_grid=points, horizon=1)

    check_value_grid(Cube(), config(100))  # 10^6 points: allowed
    with pytest.raises(dc.ConfigError, match="8,120,601 grid points .* at most 100 points"):
        check_value_grid(Cube(), config(201))


def test_a_run_stored_before_the_setting_existed_is_still_the_same_run(tmp_path):

    config = PENDULUM.default_config().replace(value_grid=0).to_json()
    old = {"task": "pendulum", "config": {k: v for k, v in config.items() if k != "value_grid"}}
    _run_dir.check_same_run(tmp_path, old, {"task": "pendulum", "config": config})  # no error
    changed = {"task": "pendulum", "config": {**config, "value_grid": 11}}
    with pytest.raises(RunDirectoryError, match="differs in: value_grid"):
        _run_dir.check_same_run(tmp_path, old, changed)


def test_a_directory_that_cannot_take_the_run_is_named_before_the_grid_is_solved(tmp_path):
    (tmp_path / "other").write_text("x")
    lines = []
    cfg = PENDULUM.default_config().replace(value_grid=401)
    with pytest.raises(RunDirectoryError, match="not empty"):
        train(PENDULUM, cfg, out_dir=tmp_path, progress=lines.append)
    assert not any("solving" in line for line in lines), lines


def test_make_trainer_solves_the_value_with_the_configs_physics():
    cfg = PENDULUM.default_config().replace(value_grid=5, params=(("g", 3.0),))
    assert float(make_trainer(PENDULUM, cfg).value.table.params.g) == 3.0
    with pytest.raises(dc.ConfigError, match="no terminal value"):
        from diffcontrol.training import Trainer

        plain = make_trainer(PENDULUM, cfg.replace(value_grid=0))
        Trainer(**{**vars(plain), "config": cfg})


def test_a_sweep_refuses_it_before_any_member_trains():
    from diffcontrol.training import grid, sweep

    cartpole = dc.make("cartpole")
    configs = grid(cartpole.default_config(), [0], {"value_grid": [0, 11]})
    lines = []
    with pytest.raises(dc.ConfigError, match="value_grid=11 needs the task's grid optimum"):
        sweep(cartpole, configs, progress=lines.append)
    assert not any("update" in line for line in lines), lines


def test_the_command_line_refuses_it_before_writing_anything(capsys, tmp_path):
    out = tmp_path / "run"
    for argv in (
        ["train", "cartpole", "--value-grid", "11", "--out", str(out)],
        ["sweep", "cartpole", "--seeds", "0", "--value-grid", "11", "--out", str(out)],
        ["sweep", "cartpole-swingup", "--seeds", "0", "--value-grid", "11", "--out", str(out)],
    ):
        assert main(argv) == 2, argv
        captured = capsys.readouterr()
        err = captured.err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert "value_grid=11" in err or "continuous-time" in err, err
        assert "solving" not in captured.out
        assert not out.exists()


@pytest.mark.slow
def test_short_windows_learn_the_swing_up_only_with_the_value():
    """10-step windows alone are too myopic for the swing-up (the windows recipe's 20 were
    chosen for that); with the grid's value at their end the same budget swings up and holds."""
    cfg = PENDULUM.default_config().replace(
        updates=1500, batch=16, window=10, learning_rate=5e-3, eval_every=500, eval_episodes=64,
        target_return=NAN, keep_best=False,
    )  # fmt: skip
    with_value = train(PENDULUM, cfg.replace(value_grid=51)).curve[-1]["eval_return"]
    plain = train(PENDULUM, cfg.replace(value_grid=0)).curve[-1]["eval_return"]
    assert with_value > -300 and plain < -500, (with_value, plain)


@pytest.mark.slow
def test_a_sweep_member_is_the_run_train_would_make():
    from diffcontrol.training import grid, sweep

    cfg = PENDULUM.default_config().replace(
        updates=4, eval_every=2, **{**TINY, "horizon": 0}, value_grid=11, keep_best=False
    )  # the last weights: those of every update
    member = sweep(PENDULUM, grid(cfg, [0, 1])).members[1]
    alone, plain = (
        train(PENDULUM, cfg.replace(seed=1)),
        train(PENDULUM, cfg.replace(seed=1, value_grid=0)),
    )
    weights = [_weights(r.controller) for r in (member, alone, plain)]
    for a, b in zip(weights[0], weights[1], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)
    assert not all(np.allclose(a, b) for a, b in zip(weights[1], weights[2], strict=True))


def _weights(controller):
    import equinox as eqx

    return [np.asarray(x) for x in jax.tree.leaves(eqx.filter(controller, eqx.is_inexact_array))]


def test_the_value_is_solved_once_per_task_grid_and_physics(monkeypatch):
    """Training the same task on the same physics again reuses the solved value; other
    physics, another grid or ``clear_compiled`` solve anew."""
    from diffcontrol.training import clear_compiled, resolve_config

    clear_compiled()
    solved = []
    real = optimal.solve
    monkeypatch.setattr(optimal, "solve", lambda *a, **k: solved.append(1) or real(*a, **k))
    cfg = resolve_config(PENDULUM, **TINY, updates=2, eval_every=1, value_grid=11)
    runs = [
        cfg,
        cfg.replace(updates=3),  # another trainer, the same value
        cfg.replace(params=(("g", 9.0),)),
        cfg.replace(value_grid=13),
        cfg.replace(updates=4),  # the first value again
    ]
    counts = []
    for c in runs:
        make_trainer(PENDULUM, c)  # solves its value (training would compile, not solve)
        counts.append(len(solved))
    assert counts == [1, 1, 2, 3, 3]
    clear_compiled()
    make_trainer(PENDULUM, cfg.replace(updates=5))
    assert len(solved) == 4


def test_a_step_loss_of_ones_own_is_named_as_such_when_the_default_value_refuses_it():
    cfg = PENDULUM.default_config().replace(**TINY, updates=1, eval_every=1)
    with pytest.raises(dc.ConfigError) as exc:
        train(PENDULUM, cfg, step_loss=lambda params, s, a, s2, reward: reward**2)
    assert "the step_loss given is not" in str(exc.value) and "--value-grid 0" in str(exc.value)
