"""The re-audit of issue 12: new variants of each class of hostile input, in-process (the
CLI's ``main``, the library), on the shared tiny runs. Each gets one line and exit status 2,
imports nothing a file names, and changes nothing."""

from __future__ import annotations

import json
import re
import shutil
import sys

import numpy as np
import pytest

import diffcontrol
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, DiffcontrolError
from diffcontrol.tasks import check_params

from ._cli import one_line

EVIL = "evil_module_of_the_reaudit"


def _one_line(capsys, argv, *needles):
    one_line(capsys, argv, *needles)
    assert EVIL not in sys.modules


def _copy(run, tmp_path, name="run"):
    out = tmp_path / name
    shutil.copytree(run, out)
    return out


def _edit(path, change):
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


# --- corrupt-text generators, shared by every file kind ---------------------------------------

HOSTILE_TEXTS = {
    "deep nesting": "[" * 100_000 + "]" * 100_000,
    "huge integer": '{"version": ' + "9" * 5000 + "}",
    "truncated": '{"format": "diffcontrol-',
    "not UTF-8": "\udcff",
}


def _write_hostile(path, kind):
    text = HOSTILE_TEXTS[kind]
    if kind == "not UTF-8":
        path.write_bytes(b'{"a": "\xff"}')
    else:
        path.write_text(text)


@pytest.mark.parametrize("kind", list(HOSTILE_TEXTS))
@pytest.mark.parametrize("file", ["model.json", "metrics.json", "run.json"])
def test_hostile_text_in_every_run_file(capsys, pendulum_run, tmp_path, kind, file):
    out = _copy(pendulum_run, tmp_path)
    _write_hostile(out / file, kind)
    _one_line(capsys, ["evaluate", out, "--episodes", "1"], file)


@pytest.mark.parametrize("kind", list(HOSTILE_TEXTS))
def test_hostile_text_in_a_fitted_file_and_a_data_header(capsys, tmp_path, kind):
    fit = tmp_path / "fit"
    fit.mkdir()
    _write_hostile(fit / "fitted.json", kind)
    out = tmp_path / "out"
    _one_line(capsys, ["train", "pendulum", "--model", fit, "--out", out], "fitted.json")
    assert not out.exists()
    data = tmp_path / "data.csv"
    text = "\n# x" if kind == "not UTF-8" else HOSTILE_TEXTS[kind]
    data.write_text("# " + text + "\ntime,episode,obs.x [m],action.u [N]\n0,0,0,0\n")
    if kind == "not UTF-8":
        data.write_bytes(b"# {\xff}\n")
    _one_line(capsys, ["fit", "pendulum", "--data", data, "--model", "params", "--out", out])
    assert not out.exists()


# --- ids and arguments from files -------------------------------------------------------------


@pytest.mark.parametrize(
    "real, needle",
    [
        ({"env_id": f"{EVIL}:X-v0"}, "not import"),
        ({"env_id": "os:X:Y"}, "not an id"),
        ({"env_id": "CartPole-v1", "env_kwargs": "oops"}, "finite"),
        ({"env_id": "CartPole-v1", "env_kwargs": {"render_mode": 5}}, "to render"),
        ({"env_id": "CartPole-v1", "env_kwargs": {"sutton_barto": 5}}, "does not take"),
        ("oops", "not an object"),
    ],
)
def test_a_real_system_named_by_metrics_json(capsys, cartpole_run, tmp_path, real, needle):
    out = _copy(cartpole_run, tmp_path)
    _edit(out / "metrics.json", lambda m: m.update(model={"real_system": real}))
    _one_line(capsys, ["evaluate", out, "--episodes", "1"], needle)
    _one_line(capsys, ["animate", out, "--out", tmp_path / "a.gif"], needle)
    assert not (tmp_path / "a.gif").exists()


def test_a_real_system_that_fails_on_its_arguments_is_one_line(capsys, pendulum_run, tmp_path):
    """Text where the environment computes with a number: its TypeError, in one line that
    names the environment and the argument."""
    out = _copy(pendulum_run, tmp_path)
    real = {"env_id": "diffcontrol/PendulumFriction-v0", "env_kwargs": {"g": "12"}}
    _edit(out / "metrics.json", lambda m: m.update(model={"real_system": real}))
    _one_line(capsys, ["evaluate", out, "--episodes", "1"], "g='12') raised TypeError")
    _one_line(capsys, ["animate", out, "--out", tmp_path / "a.gif"], "raised TypeError")
    assert not (tmp_path / "a.gif").exists()


@pytest.fixture(scope="module")
def fitted_dir(tmp_path_factory):
    """A grey-box fitted.json of the pendulum (a few steps; only its fields matter here)."""
    d = tmp_path_factory.mktemp("fit")
    data = d / "data.csv"
    assert main(["record", "Pendulum-v1", "--episodes", "2", "--out", str(data), "--quiet"]) == 0
    argv = ["fit", "pendulum", "--data", str(data), "--model", "params", "--steps", "3"]
    assert main([*argv, "--lm-steps", "1", "--out", str(d / "fit"), "--quiet"]) == 0
    return d / "fit", data


@pytest.mark.parametrize(
    "change, needle",
    [
        (lambda f: f["data"].update(env_id="os:X:Y"), "not an id"),
        (lambda f: f["data"].update(env_kwargs=[1, 2]), "finite"),
        (lambda f: f.update(data=[1]), "'data'"),
        (lambda f: f["all_parameters"].update(max_speed=1e300), "float32"),
        (lambda f: f["all_parameters"].update(friction=-0.5), ">= 0"),
    ],
)
def test_a_damaged_fitted_file_trains_nothing(capsys, fitted_dir, tmp_path, change, needle):
    fit = tmp_path / "fit"
    shutil.copytree(fitted_dir[0], fit)
    _edit(fit / "fitted.json", change)
    out = tmp_path / "out"
    _one_line(capsys, ["train", "pendulum", "--model", fit, "--out", out], needle)
    assert not out.exists()


@pytest.mark.parametrize(
    "change, needle",
    [
        (lambda m: m.update(env_id=5), "env_id"),
        (lambda m: m.update(env_id="a:b:c"), "env_id"),
        (lambda m: m.update(env_kwargs="oops"), "env_kwargs"),
        (lambda m: m.update(params={"g": "x"}), "params"),
    ],
)
def test_bad_metadata_is_refused_by_the_first_reader(capsys, fitted_dir, tmp_path, change, needle):
    lines = fitted_dir[1].read_text().splitlines()
    header = json.loads(lines[0][2:])
    change(header["metadata"])
    data = tmp_path / "data.csv"
    data.write_text("# " + json.dumps(header) + "\n" + "\n".join(lines[1:]) + "\n")
    out = tmp_path / "out"
    _one_line(
        capsys, ["fit", "pendulum", "--data", data, "--model", "params", "--out", out], needle
    )
    assert not out.exists()


# --- physical parameters, model files -----------------------------------------------------------


@pytest.mark.parametrize(
    "task, param",
    [
        ("acrobot", "dt=0"),
        ("acrobot", "link_mass_1=-1"),
        ("pendulum", "max_speed=1e300"),
        ("mountain-car-continuous", "max_speed=1e300"),
        ("trebuchet", "projectile_mass=0"),
        ("trebuchet", "drag_coefficient=-1"),
    ],
)
def test_physical_parameters_of_other_tasks(capsys, tmp_path, task, param):
    out = tmp_path / "x"
    _one_line(capsys, ["train", task, "--out", out, "--param", param], param.split("=")[0])
    assert not out.exists()


def test_a_recorded_trebuchet_out_of_range(capsys, tmp_path):
    out = tmp_path / "t.csv"
    argv = ["record", "trebuchet", "--episodes", "2", "--env-arg", "sling_length=0"]
    _one_line(capsys, [*argv, "--out", out], "sling_length")
    assert not out.exists()


@pytest.mark.parametrize(
    "change, needle",
    [
        (lambda m: m["action"].update(size=True), "action size"),
        (lambda m: m["observation"].update(state="abcd", features="abcd"), "lists of names"),
        (
            lambda m: m["network"]["layers"][0].update(
                weight=[[1e300] * len(r) for r in m["network"]["layers"][0]["weight"]]
            ),
            "float32",
        ),
        (lambda m: m["observation"].update(scale=[0, 0, 0, 0]), "scale is 0"),
        (lambda m: m["observation"].update(scale=[0.0, -0.0, 0, 0.0]), "scale is 0"),
    ],
)
def test_model_file_fields_of_the_wrong_kind(cartpole_run, tmp_path, change, needle):
    out = _copy(cartpole_run, tmp_path)
    _edit(out / "model.json", change)
    with pytest.raises(DiffcontrolError, match=needle):
        diffcontrol.load(out)


# --- the fit's output is what the next command accepts -----------------------------------------


@pytest.mark.slow  # a grey-box fit compiled: 2.4 s on one core
def test_a_fit_never_writes_a_parameter_out_of_its_range(fitted_dir):
    from diffcontrol import identify, tasks
    from diffcontrol.identify.data import read_trajectories

    task = tasks.make("pendulum")
    data = read_trajectories(fitted_dir[1])
    # frictionless data: the fitted friction lands either side of 0; never below it
    result = identify.fit(task, data, "params", steps=3, lm_steps=1)
    assert result.values["friction"] >= 0
    check_params(task, result.params)


def test_library_inputs_of_the_wrong_kind(cartpole_run):
    task = diffcontrol.make("cartpole")
    for change in (dict(eval_every=True), dict(batch=2.5), dict(keep_best="no")):
        with pytest.raises(ConfigError):
            task.default_config().replace(**change)
    policy = diffcontrol.load(cartpole_run)
    for obs in (np.zeros((2, 5)), [[1.0, 2.0]], np.full(4, np.inf)):
        with pytest.raises(ValueError):
            policy(obs)


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda run: diffcontrol.make(5), "takes a task's name"),
        (lambda run: diffcontrol.make(None), "takes a task's name"),
        (lambda run: diffcontrol.train(5), "train() takes a task"),
        (lambda run: diffcontrol.register(5), "register() takes an instance"),
        (lambda run: diffcontrol.register("pendulum"), "register() takes an instance"),
        (lambda run: diffcontrol.check_task(5), "check_task() takes a task"),
        (lambda run: diffcontrol.load(run, task="pendulum"), "open it with its own task"),
        (lambda run: diffcontrol.fit(diffcontrol.make("pendulum"), run / "nope.csv"), "exist"),
        (lambda run: diffcontrol.fit(diffcontrol.make("pendulum"), {"x": 1}), "recorded data"),
    ],
)
def test_library_calls_with_the_wrong_kind_of_argument_say_what_they_take(
    cartpole_run, call, needle
):
    """One error of the library's own, naming what the call takes, never a raw TypeError or
    AttributeError from inside it (a CartPole run loaded as the Pendulum's included)."""
    with pytest.raises(DiffcontrolError, match=re.escape(needle)):
        call(cartpole_run)


def test_check_task_takes_a_name_as_make_does():
    assert diffcontrol.check_task("pendulum").task == "pendulum"


# --- integers on every command, races for a new file ------------------------------------------

HUGE = "1" + "0" * 13


@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "DIR", "--episodes", HUGE],
        ["evaluate", "DIR", "--seed", "1" + "0" * 30],
        ["animate", "DIR", "--seed", "-1"],
        ["record", "Pendulum-v1", "--episodes", HUGE, "--out", "x.csv"],
        ["record", "Pendulum-v1", "--episodes", "1", "--seed", "-1", "--out", "x.csv"],
        ["record", "Pendulum-v1", "--episodes", "1", "--max-steps", HUGE, "--out", "x.csv"],
        ["loop", "pendulum", "--out", "x", "--rounds", HUGE],
        ["loop", "pendulum", "--out", "x", "--seed", "1" + "0" * 30],
        ["loop", "pendulum", "--out", "x", "--eval-episodes", HUGE],
        ["fit", "pendulum", "--data", "x.csv", "--model", "params", "--out", "x", "--window", HUGE],
        ["train", "pendulum", "--out", "x", "--final-eval", HUGE],
        ["train", "cartpole-swingup", "--out", "x", "--population", HUGE],
        ["compare", "cartpole", "--out", "x", "--final-episodes", HUGE],
    ],
)
def test_huge_and_negative_integers_on_every_command(capsys, pendulum_run, tmp_path, argv):
    argv = [str(pendulum_run) if a == "DIR" else a for a in argv]
    argv = [str(tmp_path / a) if a in ("x", "x.csv") else a for a in argv]
    _one_line(capsys, argv, "at most")
    assert not (tmp_path / "x").exists() and not (tmp_path / "x.csv").exists()


def test_of_two_writers_racing_for_a_new_file_one_wins(tmp_path):
    import threading

    from diffcontrol import io
    from diffcontrol.errors import RunDirectoryError

    for trial in range(20):
        path = tmp_path / f"race{trial}.csv"
        barrier = threading.Barrier(2)
        outcomes = []

        def write(text, path=path, barrier=barrier, outcomes=outcomes):
            def writer(tmp):
                tmp.write_text(text)
                barrier.wait()  # both have checked and written: now both publish

            try:
                io.write_new(path, writer)
                outcomes.append(text)
            except RunDirectoryError:
                outcomes.append("refused")

        threads = [threading.Thread(target=write, args=(t,)) for t in ("a", "b")]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert sorted(outcomes)[-1] == "refused" and path.read_text() in outcomes, outcomes
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.slow
def test_a_run_that_diverges_after_a_checkpoint_names_a_fix_that_works(
    capsys, tmp_path, monkeypatch
):
    from diffcontrol.errors import TrainingDiverged
    from diffcontrol.training import _bptt

    calls = []
    check = _bptt.Trainer.check

    def diverge_second_chunk(self, old, new, losses):
        calls.append(1)
        if len(calls) == 2:
            raise TrainingDiverged("training diverged near update 3: lower --learning-rate")
        return check(self, old, new, losses)

    monkeypatch.setattr(_bptt.Trainer, "check", diverge_second_chunk)
    out = tmp_path / "run"
    argv = ["train", "cartpole", "--out", str(out), "--updates", "4", "--eval-every", "2"]
    argv += ["--eval-episodes", "2", "--final-eval", "1", "--no-animation", "--quiet"]
    _one_line(capsys, argv, "new --out", f"{out} keeps this run")
    assert (out / "checkpoint.npz").exists()
    monkeypatch.undo()
    new = tmp_path / "again"
    assert main([*argv[:3], str(new), *argv[4:], "--learning-rate", "0.001"]) == 0


@pytest.mark.slow
def test_a_users_real_system_is_imported_only_when_named_on_the_command_line(
    capsys, fitted_dir, tmp_path, monkeypatch
):
    module = "reaudit_user_env"
    (tmp_path / f"{module}.py").write_text(
        "import gymnasium\ngymnasium.register('ReauditPendulum-v0', "
        "entry_point='gymnasium.envs.classic_control.pendulum:PendulumEnv', "
        "max_episode_steps=200)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    fit = tmp_path / "fit"
    shutil.copytree(fitted_dir[0], fit)
    env = f"{module}:ReauditPendulum-v0"
    _edit(fit / "fitted.json", lambda f: f["data"].update(env_id=env, env_kwargs={}))
    out = tmp_path / "run"
    argv = ["train", "pendulum", "--model", str(fit), "--out", str(out), "--updates", "2"]
    argv += ["--eval-every", "1", "--final-eval", "1", "--no-animation", "--quiet"]
    try:
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2 and module not in sys.modules and f"pass --env {env}" in err, err
        assert not out.exists()
        # the suggested flag works: the user names the module, so it may be imported
        assert main([*argv, "--env", env]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["gym_eval"]["env_id"] == env
        assert json.loads((out / "run.json").read_text())["invocation"]["env"] == env
    finally:
        sys.modules.pop(module, None)


def test_a_model_of_another_size_than_its_task_is_refused_on_opening(
    capsys, cartpole_run, tmp_path
):
    out = _copy(cartpole_run, tmp_path)

    def three_inputs(m):
        m["observation"].update(size=3, offset=[0] * 3, scale=[1] * 3)
        m["network"]["layers"][0]["weight"] = [r[:3] for r in m["network"]["layers"][0]["weight"]]

    _edit(out / "model.json", three_inputs)
    _one_line(capsys, ["evaluate", out, "--episodes", "1"], "observation size 3")


def test_an_environment_a_fitted_model_names_is_made_before_training(capsys, fitted_dir, tmp_path):
    fit = tmp_path / "fit"
    shutil.copytree(fitted_dir[0], fit)
    _edit(fit / "fitted.json", lambda f: f["data"].update(env_kwargs={"nope": 1}))
    out = tmp_path / "out"
    _one_line(capsys, ["train", "pendulum", "--model", fit, "--out", out], "does not take")
    assert not out.exists()


def test_an_environment_of_another_size_or_a_missing_module_or_place(
    capsys, pendulum_run, tmp_path
):
    _one_line(capsys, ["evaluate", pendulum_run, "--env", "CartPole-v1"], "size 3")
    _one_line(
        capsys,
        ["record", "no_such_module_q:X-v0", "--episodes", "1", "--out", tmp_path / "q.csv"],
        "no_such_module_q",
    )
    _one_line(capsys, ["loop", "pendulum", "--out", "/proc/no/such", "--rounds", "1"], "/proc/no")


@pytest.mark.slow
def test_env_of_a_task_whose_evaluation_is_its_own(capsys, swingup_run):
    """--env runs Gymnasium episodes; a task that evaluates otherwise (a float64 reference
    solve) refuses it instead of ignoring it."""
    argv = ["evaluate", str(swingup_run), "--env", "Pendulum-v1"]
    _one_line(capsys, argv, "--env does not apply", "cartpole-swingup")


def test_a_horizon_beyond_float32_time_is_refused():
    from diffcontrol.config import ODETrainConfig

    with pytest.raises(ConfigError, match="up to 1e"):
        ODETrainConfig(horizon_s=1e300)


def test_an_unwritable_gif_names_the_file_asked_for(capsys, cartpole_run):
    _one_line(capsys, ["animate", str(cartpole_run), "--out", "/proc/x.gif"], "(/proc/x.gif)")


@pytest.mark.parametrize("damage", ["model [1]", "no model", "no metrics.json"])
def test_a_fitted_model_run_without_its_real_system_is_not_judged_on_the_nominal_one(
    capsys, pendulum_run, tmp_path, damage
):
    """A run that run.json says was trained through a fitted model is judged on the real
    system its metrics.json names; with that entry damaged or gone it is refused (not judged
    on the task's own system), and --env names the system instead."""
    run = tmp_path / "run"
    shutil.copytree(pendulum_run, run)
    doc = json.loads((run / "run.json").read_text())
    doc["invocation"] = {**doc.get("invocation", {}), "model": "fits/p"}
    (run / "run.json").write_text(json.dumps(doc))
    metrics = json.loads((run / "metrics.json").read_text())
    if damage == "no metrics.json":
        (run / "metrics.json").unlink()
    elif damage == "model [1]":
        (run / "metrics.json").write_text(json.dumps({**metrics, "model": [1]}))
    else:
        metrics.pop("model", None)
        (run / "metrics.json").write_text(json.dumps(metrics))
    _one_line(capsys, ["evaluate", run, "--episodes", "1"], "fitted model fits/p", "--env")
    assert main(["evaluate", str(run), "--episodes", "1", "--env", "Pendulum-v1"]) == 0


@pytest.mark.parametrize(
    ("sizes", "nan", "needle"),
    [
        ((4, 1), None, "gives 1 outputs, but this task's model needs 4 and 2"),
        ((3, 2), None, "takes 3 inputs"),
        ((4, 3), None, "gives 3 outputs"),
        ((4, 2), "in_scale", "in_scale is not finite"),
        ((4, 2), "out_scale", "out_scale is not finite"),
    ],
)
def test_a_fitted_network_that_does_not_fit_the_task_trains_and_plans_nothing(
    capsys, fitted_dir, tmp_path, sizes, nan, needle
):
    """A hybrid model's network must take the observation and action and give the state
    (the Pendulum's 3 + 1 -> 2), with finite scalings; one line names fitted.json."""
    import jax

    from diffcontrol.identify import Correction, correction_to_dict

    fit = tmp_path / "fit"
    shutil.copytree(fitted_dir[0], fit)
    doc = json.loads((fit / "fitted.json").read_text())
    network = correction_to_dict(Correction(jax.random.PRNGKey(0), sizes[0], sizes[1], (8,)))
    if nan:
        network[nan] = [float("nan")] * len(network[nan])
    (fit / "fitted.json").write_text(json.dumps({**doc, "model": "hybrid", "network": network}))
    for command in ("train", "plan"):
        out = tmp_path / command
        _one_line(capsys, [command, "pendulum", "--model", fit, "--out", out], "fitted", needle)
        assert not out.exists()


def test_a_terminal_value_needs_a_loss_that_is_minus_the_reward(capsys, tmp_path):
    """The value is a return to come, in reward units: a window's loss must be minus the
    reward to add up with it (a task's other loss, or a custom one, is refused)."""
    out = tmp_path / "run"
    argv = ["train", "pendulum", "--out", out, "--value-grid", "51", "--updates", "2"]
    _one_line(capsys, [*argv, "--loss", "squared_cost"], "--loss cost", "value_grid=51")
    assert not out.exists()
    task = diffcontrol.make("pendulum")
    config = task.default_config().replace(value_grid=51, updates=2, eval_every=1, batch=4)
    with pytest.raises(ConfigError, match="minus the reward"):
        diffcontrol.train(task, config, step_loss=lambda p, s, a, ns, r: -2.0 * r)


@pytest.mark.parametrize(
    ("column", "value", "needle"),
    [
        (2, "3.0", "obs.cos_theta [1] = 3"),  # |cos| > 1
        (3, "-1.5", "obs.sin_theta [1] = -1.5"),
        (4, "1e300", "obs.theta_dot [rad/s] = 1e+300"),  # beyond max_speed 8
        (5, "2.5", "action.torque [N m] = 2.5"),  # beyond the bounds +-2
        (5, "-9", "action.torque [N m] = -9"),
    ],
)
def test_data_the_system_cannot_produce_fits_nothing(
    capsys, fitted_dir, tmp_path, column, value, needle
):
    """Recorded values outside the system's observation or action space (its Gymnasium
    twin's bounds) are refused by fit in one line naming the row, the column and the value."""
    lines = fitted_dir[1].read_text().splitlines()
    cells = lines[10].split(",")
    cells[column] = value
    lines[10] = ",".join(cells)
    data = tmp_path / "bad.csv"
    data.write_text("\n".join(lines) + "\n")
    out = tmp_path / "fit"
    argv = ["fit", "pendulum", "--data", data, "--model", "params", "--out", out]
    _one_line(capsys, argv, "data row 9", needle, "never take")
    assert not out.exists()


@pytest.mark.parametrize(
    ("env_id", "needle"),
    [  # new-fit-envid_colon_number: a module named by the file is not imported
        ("Pendulum-v1:2", "pass --env Pendulum-v1:2 explicitly"),
        (f"{EVIL}:Pendulum-v1", "does not import modules named by files"),
    ],
)
def test_data_naming_a_module_imports_nothing_and_fits_nothing(
    capsys, fitted_dir, tmp_path, env_id, needle
):
    lines = fitted_dir[1].read_text().splitlines()
    header = json.loads(lines[0][2:])
    header["metadata"]["env_id"] = env_id
    data = tmp_path / "bad.csv"
    data.write_text("# " + json.dumps(header) + "\n" + "\n".join(lines[1:]) + "\n")
    out = tmp_path / "fit"
    argv = ["fit", "pendulum", "--data", data, "--model", "params", "--out", out]
    _one_line(capsys, argv, needle)
    assert not out.exists()


def test_a_task_that_cannot_read_its_state_is_not_planned(capsys, tmp_path):
    """new-plan-14: a task without state_from_observation (the trebuchet's aim) is refused
    before a planner is built, and no directory is left."""
    out = tmp_path / "plan"
    _one_line(capsys, ["plan", "trebuchet", "--out", out], "cannot be planned")
    assert not out.exists()


def test_data_naming_an_unknown_environment_fits_nothing(capsys, fitted_dir, tmp_path):
    lines = fitted_dir[1].read_text().splitlines()
    header = json.loads(lines[0][2:])
    header["metadata"]["env_id"] = "NoSuchEnv-v3"
    data = tmp_path / "bad.csv"
    data.write_text("# " + json.dumps(header) + "\n" + "\n".join(lines[1:]) + "\n")
    out = tmp_path / "fit"
    argv = ["fit", "pendulum", "--data", data, "--model", "params", "--out", out]
    _one_line(capsys, argv, "NoSuchEnv-v3")
    assert not out.exists()


def test_data_from_a_system_with_impossible_physics_fits_and_trains_nothing(
    capsys, fitted_dir, tmp_path
):
    """Environment arguments in a data file (or a fitted file) that name the task's physics
    with values its simulator has no meaning for are refused, not stored as the real system
    that train --model then judges on."""
    lines = fitted_dir[1].read_text().splitlines()
    header = json.loads(lines[0][2:])
    kwargs, needle = {"g": 1e308}, "g=1e+308"
    header["metadata"]["env_kwargs"] = kwargs
    data = tmp_path / "bad.csv"
    data.write_text("# " + json.dumps(header) + "\n" + "\n".join(lines[1:]) + "\n")
    out = tmp_path / "fit"
    argv = ["fit", "pendulum", "--data", data, "--model", "params", "--out", out]
    _one_line(capsys, argv, "Pendulum-v1", needle)
    assert not out.exists()
    fit = tmp_path / "copied"
    shutil.copytree(fitted_dir[0], fit)
    _edit(fit / "fitted.json", lambda f: f["data"].update(env_kwargs=kwargs))
    _one_line(capsys, ["train", "pendulum", "--model", fit, "--out", tmp_path / "run"], needle)
    assert not (tmp_path / "run").exists()


def test_a_sweep_larger_than_the_memory_is_refused_before_anything_is_allocated(
    capsys, tmp_path, monkeypatch
):
    """The members' training state is estimated from one member's shapes and refused, in one
    line that names how many fit, where it exceeds the memory the process may use."""
    from diffcontrol.training import _sweep

    monkeypatch.setattr(_sweep, "available_memory", lambda: 8 * 2**20)  # 8 MiB
    out = tmp_path / "sweep"
    argv = ["sweep", "pendulum", "--seeds", "0-15", "--updates", "2", "--out", out]
    one_line(capsys, argv, "a sweep of 16 members of 'pendulum' needs about", "members at once")
    monkeypatch.setattr(_sweep, "available_memory", lambda: 2**10)
    one_line(capsys, argv, "one member alone needs more")
    assert not out.exists()


@pytest.mark.parametrize(("suffix", "needle"), [(".csv", "larger than 1024 MiB"), (".npz", "")])
def test_a_data_file_past_its_size_limit_is_refused_unread(
    capsys, tmp_path, monkeypatch, suffix, needle
):
    """A file larger than diffcontrol reads (here 5 GiB, sparse: no disk is used) is refused
    by its size, not read up to the limit first."""
    from diffcontrol import io

    data = tmp_path / f"huge{suffix}"
    with open(data, "wb") as f:
        f.truncate(5 * 2**30)
    real_open = open

    def no_big_reads(*args, **kwargs):
        f = real_open(*args, **kwargs)
        read = f.read
        f.read = lambda n=-1: read(min(n, 2**20)) if 0 <= n else pytest.fail("read it all")
        return f

    monkeypatch.setattr(io, "open", no_big_reads, raising=False)
    argv = ["fit", "pendulum", "--data", data, "--model", "params", "--out", tmp_path / "fit"]
    one_line(capsys, argv, str(data), needle)


def test_a_long_read_and_fit_say_how_far_they_are(fitted_dir, tmp_path, monkeypatch):
    """A large data file's parsing and a long fit's Adam steps report as they go (every
    ``_progress.SECONDS``, here every time they may), and the fit is the same as a silent one."""
    from diffcontrol import identify
    from diffcontrol.identify import _progress

    task = diffcontrol.make("pendulum")
    monkeypatch.setattr(_progress, "SECONDS", 0.0)
    lines = []
    kw = {"window": 5, "steps": 100, "lm_steps": 0}
    said = identify.fit_dir(
        task, fitted_dir[1], "params", tmp_path / "a", progress=lines.append, **kw
    )
    quiet = identify.fit_dir(task, fitted_dir[1], "params", tmp_path / "b", **kw)
    assert any(line.startswith(f"parsing {fitted_dir[1]}: 0 of ") for line in lines), lines
    assert any(line.startswith("Adam step 50/100: best loss ") for line in lines), lines
    assert said.result.values == quiet.result.values


@pytest.mark.parametrize(("grid", "levels"), [(1001, 1001), (1001, 41), (401, 1001)])
def test_a_planner_file_asking_for_hours_of_grid_is_refused_at_once(capsys, tmp_path, grid, levels):
    """A downloaded planner's stored grid is solved again at every load: one within minutes
    is, one of hours is refused in one line (before anything is solved)."""
    from diffcontrol import io, policies
    from diffcontrol.settings import PlanConfig

    task = diffcontrol.make("pendulum")
    settings = PlanConfig(value_grid=grid, value_levels=levels).to_json()
    doc = policies.planner_document(task, settings, {"kind": "simulator"}, {"created": "now"})
    run = tmp_path / "planner"
    run.mkdir()
    io.write_json(run / "model.json", doc)
    _one_line(capsys, ["evaluate", run, "--episodes", "1"], "--value-grid 401 or less")
    argv = ["plan", "pendulum", "--value-grid", grid, "--value-levels", levels]
    _one_line(capsys, [*argv, "--out", tmp_path / "new"], "--value-grid 401 or less")
    assert not (tmp_path / "new").exists()  # the directory is given back


@pytest.mark.parametrize("episode", [str(2**70), "1e300", str(2**53 + 2)])
def test_an_episode_id_too_large_to_count_is_named(capsys, fitted_dir, tmp_path, episode):
    lines = fitted_dir[1].read_text().splitlines()
    for i in range(2, len(lines)):  # the first episode's rows: the header and the column names
        cells = lines[i].split(",")
        if cells[1] == "0":
            lines[i] = ",".join([cells[0], episode, *cells[2:]])
    data = tmp_path / "bad.csv"
    data.write_text("\n".join(lines) + "\n")
    argv = ["fit", "pendulum", "--data", data, "--model", "params", "--out", tmp_path / "fit"]
    _one_line(capsys, argv, "larger than 2^53")
