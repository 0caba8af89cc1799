"""Fitting swing-up models (grey box, hybrid, neural) to recorded state data, and training
through them (``diffcontrol.identify.ode``, ``diffcontrol.builtin.swingup.fitted``).

Tiny budgets: 3 episodes of 3 s at 50 Hz (2 fitted, 1 held out), short windows, a few dozen
Adam steps. The full reproduction is ``benchmarks/fit_swingup.py``.
"""

from __future__ import annotations

import dataclasses
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol.builtin.swingup import fitted as of
from diffcontrol.builtin.swingup import system as cp
from diffcontrol.builtin.swingup.fitted import (
    FittedSwingUp,
    frictionless,
    generalized_force_accelerations,
)
from diffcontrol.errors import ConfigError, DataFileError, InsufficientDataError
from diffcontrol.identify.data import TrajectoryData

REAL = cp.SwingUpParams(cart_viscous=1.0, cart_coulomb=0.5, pole_viscous=0.1, pole_coulomb=0.05)


@pytest.fixture(scope="module")
def data():
    return of.record_swingup(REAL, 3, seed=1, duration_s=3.0)


@pytest.fixture(scope="module")
def split(data):
    return data.split(2)


@pytest.fixture(scope="module")
def hybrid_fit(split):
    return of.fit_swingup_model(
        split[0], "hybrid", window=5, steps=60, learning_rate=1e-2, hidden=(16, 16)
    )


def test_recorded_data_is_state_data_that_excites_friction(data):
    assert data.observation_columns == of.STATE_COLUMNS
    assert data.metadata["dt_s"] == 0.02 and data.num_episodes == 3 and data.num_steps == 450
    y = data.observations
    assert np.abs(y[:, 1]).max() > 2.0 and np.abs(y[:, 3]).max() > 4.0  # swing-up speeds


def test_generalized_forces_enter_like_the_systems_friction():
    key = jax.random.PRNGKey(0)
    for state, force in zip(jax.random.normal(key, (5, 4)) * 3, jnp.linspace(-20, 20, 5)):
        x_dot, theta, theta_dot = state[1], state[2], state[3]
        q_x = -REAL.cart_viscous * x_dot - REAL.cart_coulomb * jnp.tanh(x_dot / 0.05)
        q_t = -REAL.pole_viscous * theta_dot - REAL.pole_coulomb * jnp.tanh(theta_dot / 0.05)
        free = cp.accelerations(frictionless(REAL), state, force)
        dx, dt = generalized_force_accelerations(REAL, theta, q_x, q_t)
        x_acc, t_acc, power = cp.accelerations(REAL, state, force)
        np.testing.assert_allclose([free[0] + dx, free[1] + dt], [x_acc, t_acc], rtol=1e-5)
        np.testing.assert_allclose(-(q_x * x_dot + q_t * theta_dot), power, rtol=1e-5)


@pytest.mark.slow
def test_hybrid_starts_at_the_nominal_physics(split):
    unfitted = of.fit_swingup_model(split[0], "hybrid", window=2, steps=0, hidden=(8,))
    nominal = of.nominal_model(REAL)
    with jax.enable_x64(True):  # the fitted model is float64
        state, force = jnp.array([0.3, -1.0, 2.0, 4.0]), jnp.asarray(7.0)
        np.testing.assert_allclose(
            unfitted.model.accelerations(state, force), nominal.accelerations(state, force)
        )
    assert unfitted.loss_history.size == 0 and not unfitted.diverged


@pytest.mark.slow
def test_hybrid_fit_beats_the_nominal_model_on_held_out_data(split, hybrid_fit):
    held_out = split[1]
    nominal = of.prediction_errors(of.nominal_model(REAL), held_out, horizons=(1, 10))
    fitted = of.prediction_errors(hybrid_fit.model, held_out, horizons=(1, 10))
    assert hybrid_fit.loss < 0.5 * hybrid_fit.nominal_loss
    for h in (1, 10):
        assert fitted[h]["rmse"] < 0.5 * nominal[h]["rmse"], (h, fitted[h], nominal[h])
        assert np.isfinite(fitted[h]["rmse"])


@pytest.mark.slow
def test_grey_box_recovers_the_friction(split):
    r = of.fit_swingup_model(split[0], "params", window=5, steps=30, lm_steps=10)
    for name, value in r.values.items():
        assert value == pytest.approx(getattr(REAL, name), rel=0.05, abs=2e-3), name
        assert np.isfinite(r.standard_errors[name])


@pytest.mark.slow
def test_training_through_the_fitted_model(hybrid_fit):
    task = diffcontrol.make("cartpole-swingup-friction")
    wrapped = FittedSwingUp(task, hybrid_fit.model)
    y = jnp.array([0.1, 2.0, 2.5, -3.0, 0.0, 0.0])
    push = lambda t, s: jnp.array(5.0)  # noqa: E731
    nominal = cp.vector_field(0.0, y, (frictionless(REAL), push))
    fitted = wrapped.vector_field(0.0, y, (wrapped.default_params(), push))
    assert jnp.abs(fitted[1] - nominal[1]) > 0.1  # the learned friction slows the cart
    config = task.default_config().replace(
        updates=4, eval_every=2, population=1, horizon_s=1.0, saves=10
    )
    result = diffcontrol.train(wrapped, config)
    assert result.metrics["updates"] == 4
    assert np.isfinite(result.metrics["final_eval_return"])
    # A refit (here: three times the network's output) is an argument of the same programs:
    # its training compiles nothing and runs through its own network, not the first one's.
    model = hybrid_fit.model
    tripled = 3 * np.asarray(model.correction.out_scale)  # float64, as fitted
    refit = eqx.tree_at(lambda m: m.correction.out_scale, model, tripled)
    again = diffcontrol.train(FittedSwingUp(task, refit), config)
    assert again.metrics["timings"]["compile_programs"] == 0
    before, after = (r.curve[0]["eval_loss"] for r in (result, again))  # the same controller
    assert np.isfinite(after) and abs(after - before) > 1e-3 * abs(before)
    # an attribute set on the wrapper is read by the programs: its own trainer, its own head
    bounded = FittedSwingUp(task, refit)
    bounded.action_head, bounded.action_low, bounded.action_high = "tanh", (-1.0,), (1.0,)
    assert diffcontrol.train(bounded, config).controller.head == "tanh"
    # the network is the fit's, not a parameter to set
    with pytest.raises(ConfigError, match="correction"):
        diffcontrol.train(wrapped, config.replace(params=(("correction", 1.0),)))


def test_too_little_data_says_how_much_is_needed(data):
    short = data.select([0])  # 150 transitions
    with pytest.raises(InsufficientDataError, match=r"150 .* at least 250 .*5 s"):
        of.fit_swingup_model(short, "hybrid")
    with pytest.raises(InsufficientDataError, match="window of at most 150"):
        of.fit_swingup_model(data, "params", window=500)


def test_bad_data_and_settings_are_refused_by_name(data):
    renamed = dataclasses.replace(
        data, columns=(*data.columns[:3], "state.x_dot [km/h]", *data.columns[4:])
    )
    with pytest.raises(DataFileError, match=r"x_dot \[km/h\]"):
        of.fit_swingup_model(renamed, "hybrid")
    with pytest.raises(ConfigError, match="'grey'"):
        of.fit_swingup_model(data, "grey")
    with pytest.raises(ConfigError, match="window"):
        of.fit_swingup_model(data, "hybrid", window=0)
    stepped = TrajectoryData(
        np.arange(data.time.size, dtype=float),
        data.episode,
        data.observations,
        data.actions,
        ("time [step]", *data.columns[1:]),
        {},
    )
    with pytest.raises(DataFileError, match="seconds"):
        of.fit_swingup_model(stepped, "hybrid")


@pytest.mark.slow
def test_fitted_model_round_trips_through_json(hybrid_fit):
    doc = json.loads(json.dumps(of.model_to_dict(hybrid_fit.model)))
    back = of.model_from_dict(doc)
    state, force = jnp.array([0.3, -1.0, 2.0, 4.0]), jnp.asarray(7.0)
    with jax.enable_x64(True):
        np.testing.assert_allclose(
            back.accelerations(state, force),
            hybrid_fit.model.accelerations(state, force),
            rtol=1e-5,
        )


@pytest.mark.slow
def test_cli_fit_swingup_end_to_end(tmp_path, data, capsys):
    from diffcontrol.cli import main
    from diffcontrol.identify.data import write_trajectories

    path = tmp_path / "swingup.csv"
    write_trajectories(path, data)
    out = tmp_path / "fit"
    argv = [
        "fit",
        "cartpole-swingup-friction",
        "--data",
        str(path),
        "--model",
        "hybrid",
        "--out",
        str(out),
        # the settings of the hybrid_fit fixture, on the same two episodes: the same programs
        "--window",
        "5",
        "--steps",
        "60",
        "--learning-rate",
        "0.01",
        "--hidden",
        "16,16",
        "--holdout",
        "0.34",
        "--quiet",
    ]
    assert main(argv) == 0
    doc = json.loads((out / "fitted.json").read_text())
    assert doc["format"] == "diffcontrol-fitted-model" and doc["model"] == "hybrid"
    assert doc["network"]["inputs"] == ["x_dot [m/s]", "theta_dot [rad/s]"]
    assert set(doc["prediction_error"]["fitted"]) == {"1", "10", "50"}
    model = of.model_from_dict(doc, str(out / "fitted.json"))
    assert model.kind == "hybrid"
    assert "held-out RMS state error" in capsys.readouterr().out
    assert (out / "prediction.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # too little data: one line, exit status 2, says how much is needed
    short = tmp_path / "short.csv"
    write_trajectories(short, data.select([0]))
    assert main([*argv[:3], str(short), *argv[4:7], str(tmp_path / "f2"), "--holdout", "0"]) == 2
    assert "at least 250" in capsys.readouterr().err

    # train through the fitted hybrid, evaluated on the system the data came from
    run = tmp_path / "run"
    train = ["train", "cartpole-swingup-friction", "--model", str(out), "--out", str(run)]
    tiny = ["--updates", "4", "--eval-every", "2", "--population", "1", "--no-animation"]
    tiny += ["--horizon-s", "1", "--saves", "10"]  # test_training_through_the_fitted_model's
    assert main([*train, *tiny, "--quiet"]) == 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["model"]["kind"] == "hybrid"
    assert metrics["model"]["real_system"]["params"] == data.metadata["params"]
    assert json.loads((run / "model.json").read_text())["task"] == "cartpole-swingup-friction"

    # plan through it (the task's energy loss), judged on the same real system, and load it
    plan = tmp_path / "plan"
    argv = ["plan", "cartpole-swingup-friction", "--model", str(out), "--out", str(plan)]
    argv += ["--horizon", "4", "--iterations", "1", "--no-animation", "--quiet"]
    assert main([*argv, "--bound-starts", "no"]) == 0  # one plan a step, not three
    metrics = json.loads((plan / "metrics.json").read_text())
    assert metrics["model"]["kind"] == "hybrid" and np.isfinite(metrics["swingup"]["loss"])
    assert metrics["model"]["real_system"]["params"] == data.metadata["params"]
    assert metrics["swingup"]["peak_force"] <= 40.0 + 1e-3  # the task's planning bound
    policy = diffcontrol.load(plan)
    assert np.isfinite(policy(np.array([0.0, 0.0, np.pi, 0.0]))).all()


def test_cli_records_the_swingup_state(tmp_path, capsys):
    from diffcontrol.cli import main
    from diffcontrol.identify.data import read_trajectories

    out = tmp_path / "state.csv"
    argv = ["record", "cartpole-swingup", "--episodes", "1", "--env-arg", "cart_viscous=2"]
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    data = read_trajectories(out)
    assert data.observation_columns == of.STATE_COLUMNS
    assert data.metadata["params"]["cart_viscous"] == 2.0
    assert main([*argv, "--out", str(tmp_path / "x.csv"), "--controller", "runs/x"]) == 2
    assert "--controller does not apply" in capsys.readouterr().err
    assert main([*argv[:-1], "wind=3", "--out", str(tmp_path / "y.csv")]) == 2
    assert "no parameter 'wind'" in capsys.readouterr().err
