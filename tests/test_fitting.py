"""Grey-box fitting (``diffcontrol.fitting``, ``diffcontrol fit``) on a mismatched "real" pendulum.

The data is recorded from Gymnasium's own ``Pendulum-v1`` with ``g = 12`` (the nominal model
has 10) and the ``PendulumFriction`` wrapper's joint friction 0.1 N m s/rad (the nominal has
none), with random torques in [-2, 2] N m: 10 episodes of 200 steps, the first 8 fitted, the
last 2 held out. "Noisy" adds Gaussian sensor noise to every recorded observation: standard
deviation 0.01 on cos(theta) and sin(theta), 0.05 rad/s on theta_dot.
"""

from __future__ import annotations

import dataclasses
import json

import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol import _gym, identify
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, DataFileError, InsufficientDataError
from diffcontrol.identify.data import write_trajectories
from diffcontrol.wrappers import PENDULUM_FRICTION_ID

from ._monitoring import listening

TRUTH = {"g": 12.0, "friction": 0.1}
NOISE = np.array([0.01, 0.01, 0.05])  # cos, sin (1), theta_dot (rad/s)
FIT = dict(steps=100, lm_steps=20)


def _record(episodes, seed=0, **kw):
    return diffcontrol.record(PENDULUM_FRICTION_ID, episodes, seed=seed, env_kwargs=TRUTH, **kw)


@pytest.fixture(scope="module")
def task():
    return diffcontrol.make("pendulum")


@pytest.fixture(scope="module")
def clean():
    return _record(10).split(8)


@pytest.fixture(scope="module")
def noisy(clean):
    rng = np.random.default_rng(1)

    def add_noise(d):
        obs = d.observations + rng.normal(size=d.observations.shape) * NOISE
        return dataclasses.replace(d, observations=obs)

    return tuple(add_noise(d) for d in clean)


@pytest.fixture(scope="module")
def clean_fit(task, clean):
    return identify.fit_parameters(task, clean[0], ("g", "friction"), **FIT)


@pytest.fixture(scope="module")
def noisy_fit(task, noisy):
    return identify.fit_parameters(task, noisy[0], ("g", "friction"), **FIT)


def _relative_errors(result):
    return {n: abs(result.values[n] - TRUTH[n]) / TRUTH[n] for n in TRUTH}


@pytest.mark.slow
def test_recovers_g_and_friction_from_noise_free_data(clean_fit):
    errors = _relative_errors(clean_fit)
    assert all(e < 0.02 for e in errors.values()), errors
    assert not clean_fit.diverged and clean_fit.loss < 1e-3 * clean_fit.nominal_loss
    assert all(np.isfinite(list(clean_fit.standard_errors.values())))
    assert all(se > 0 for se in clean_fit.standard_errors.values())
    assert np.all(np.isfinite(clean_fit.loss_history))


@pytest.mark.slow
def test_recovers_with_sensor_noise_and_the_errors_cover_the_truth(noisy_fit):
    errors = _relative_errors(noisy_fit)
    assert all(e < 0.10 for e in errors.values()), errors
    for n, truth in TRUTH.items():
        se = noisy_fit.standard_errors[n]
        assert np.isfinite(se) and 0 < se < 0.02 * truth, (n, se)  # informative, not vacuous
        assert abs(noisy_fit.values[n] - truth) < 3 * se, (n, noisy_fit.values[n], se)


@pytest.mark.slow
def test_fitted_model_predicts_held_out_episodes_better(task, clean, noisy, clean_fit, noisy_fit):
    for (_, held_out), result, factor in ((clean, clean_fit, 0.01), (noisy, noisy_fit, 0.5)):
        nominal = identify.prediction_errors(task, task.default_params(), held_out)
        fitted = identify.prediction_errors(task, result.params, held_out)
        assert set(fitted) == {1, 10, 50} and fitted[10]["starts"] == 2 * (200 - 10 + 1)
        assert fitted[10]["rmse"] < factor * nominal[10]["rmse"], (fitted[10], nominal[10])
        assert fitted[50]["rmse"] < nominal[50]["rmse"]


@pytest.mark.slow
def test_parameters_the_data_cannot_separate_get_infinite_errors(task, clean):
    # g, m and l enter the Pendulum only as g / l and 1 / (m l^2): one direction is flat
    result = identify.fit_parameters(task, clean[0], ("g", "m", "l"), steps=5, lm_steps=0)
    assert all(se == np.inf for se in result.standard_errors.values())
    assert all(np.isfinite(v) for v in result.values.values())


@pytest.mark.slow
def test_divergence_is_reported_and_the_best_parameters_kept(task, clean):
    result = identify.fit_parameters(task, clean[0], learning_rate=1000.0, steps=5, lm_steps=0)
    assert result.diverged and "non-finite" in result.message
    assert all(np.isfinite(v) for v in result.values.values())
    assert np.isfinite(result.loss) and result.loss <= result.nominal_loss


def test_too_little_data_says_how_much_is_needed(task, monkeypatch):
    short = _record(1, max_steps=60)
    with pytest.raises(InsufficientDataError, match="60 recorded transitions .* at least 100"):
        identify.fit_parameters(task, short, ("g", "friction"))
    with pytest.raises(InsufficientDataError, match="no episode has 80 steps"):
        identify.fit_parameters(task, short, ("g",), window=80)
    # a task with physical parameters to fit is pointed at them; one without is not
    with pytest.raises(InsufficientDataError, match=r"at least 1000 .*\(--model params\)"):
        identify.fit_model(task, short, "neural")
    monkeypatch.setattr(type(task), "fit_parameter_names", ())
    with pytest.raises(InsufficientDataError, match="record more episodes$"):
        identify.fit_model(task, short, "neural")


def test_unknown_names_and_other_systems_are_refused(task, clean):
    with pytest.raises(ConfigError, match=r"\['mass'\].*'max_torque', 'friction'"):
        identify.fit_parameters(task, clean[0], ("g", "mass"))
    cartpole = diffcontrol.record("CartPole-v1", 2)
    with pytest.raises(DataFileError, match="CartPole-v1 has the columns"):
        identify.fit_parameters(task, cartpole, ("g",))


@pytest.mark.slow
def test_cli_fit_end_to_end(tmp_path, capsys):
    data = tmp_path / "real.csv"
    write_trajectories(data, _record(3, seed=7, max_steps=100))
    out = tmp_path / "fit"
    args = ["fit", "pendulum", "--data", str(data), "--model", "params", "--out", str(out)]
    tiny = ["--steps", "40", "--lm-steps", "10", "--holdout", "0.3", "--quiet"]
    assert main([*args, *tiny]) == 0
    doc = json.loads((out / "fitted.json").read_text())
    assert (doc["format"], doc["version"], doc["model"]) == (
        "diffcontrol-fitted-model",
        1,
        "params",
    )
    assert abs(doc["parameters"]["g"]["value"] - 12.0) < 0.24  # 2 %
    assert (
        doc["parameters"]["g"]["nominal"] == 10.0 and doc["parameters"]["g"]["standard_error"] > 0
    )
    assert doc["data"]["fit_episodes"] == [0, 1] and doc["data"]["held_out_episodes"] == [2]
    errors = doc["prediction_error"]
    assert errors["fitted"]["10"]["rmse"] < 0.01 * errors["nominal"]["10"]["rmse"]
    assert (out / "prediction.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    capsys.readouterr()
    assert main([*args, *tiny]) == 2  # fitted.json exists
    assert "pass --force" in capsys.readouterr().err
    assert main([*args[:-4], "--model", "neural", "--out", str(tmp_path / "n")]) == 2
    err = capsys.readouterr().err
    assert "200 recorded transitions are too few for a neural model: at least 1000" in err
    assert not (tmp_path / "n").exists()
    assert main([*args, "--force", "--params", "g,wind", *tiny]) == 2
    assert "unknown parameter(s) ['wind']" in capsys.readouterr().err


def test_cli_fit_refuses_bad_data_in_one_line(tmp_path, capsys):
    def fit(data, *extra):
        argv = ["fit", "pendulum", "--data", str(data), "--model", "params"]
        code = main([*argv, "--out", str(tmp_path / "out"), "--quiet", *extra])
        return code, capsys.readouterr().err

    code, err = fit(tmp_path / "missing.csv")
    assert code == 2 and "missing.csv" in err and len(err.strip().splitlines()) == 1
    broken = tmp_path / "broken.csv"
    broken.write_text("time [s],episode\n0.0,0\n")
    code, err = fit(broken)
    assert code == 2 and "broken.csv" in err
    cartpole = tmp_path / "cartpole.csv"
    write_trajectories(cartpole, diffcontrol.record("CartPole-v1", 2))
    code, err = fit(cartpole)
    assert code == 2 and "CartPole-v1 has the columns" in err and "pendulum" in err
    one = tmp_path / "one.csv"
    write_trajectories(one, _record(1, max_steps=120))
    code, err = fit(one)  # --holdout 0.2 of one episode
    assert code == 2 and "leaves none to fit" in err and "--holdout 0" in err
    code, err = fit(one, "--holdout", "0", "--params", "g,friction,m")
    assert code == 2 and "at least 150 are needed" in err
    assert not (tmp_path / "out").exists()  # nothing created for a refused fit


@pytest.mark.slow
def test_cartpole_grey_box_from_a_wrong_start_recovers_gymnasiums_physics():
    """CartPole's observation is its state, so its model can be fitted to Gymnasium's own
    episodes: from gravity 12, length 0.8 and force 7 the default names come back to 9.8, 0.5
    and 10 (random pushes, 10 episodes)."""
    task = diffcontrol.make("cartpole")
    data = diffcontrol.record("CartPole-v1", 10, seed=0)
    start = {"gravity": 12.0, "length": 0.8, "force_mag": 7.0}
    fit = identify.fit_parameters(task, data, None, init=start, **FIT)
    assert tuple(fit.values) == task.fit_parameter_names
    truth = {"gravity": 9.8, "length": 0.5, "force_mag": 10.0}
    assert all(abs(fit.values[n] - v) < 1e-3 * v for n, v in truth.items()), fit.values


@pytest.mark.slow
def test_data_sets_of_one_step_budget_share_the_fits_compiled_programs():
    """CartPole's episodes end early, so 250 recorded steps are 10 or 15 episodes, and the
    10-step windows 160 or 115: padded to one size, the second fit and its prediction errors
    compile nothing (the loop fits every seed's round to such a budget), nor does the hybrid's
    fit, whose data scalings differ; and the padding counts for nothing in the result."""
    task = diffcontrol.make("cartpole")
    first, second = (
        diffcontrol.record("CartPole-v1", None, seed=s, total_steps=250) for s in (0, 4)
    )
    assert first.num_episodes != second.num_episodes
    settings = dict(steps=20, lm_steps=2, init={"gravity": 12.0, "length": 0.8, "force_mag": 7.0})
    identify.fit_parameters(task, first, **settings)
    identify.prediction_errors(task, task.default_params(), first, (1, 10))
    identify.fit_model(task, first, "hybrid", steps=5)
    events = []  # the session's persistent cache (conftest): a miss is a program compiled
    with listening("event", lambda event, **kw: events.append(event)):
        fit = identify.fit_parameters(task, second, **settings)
        errors = identify.prediction_errors(task, task.default_params(), second, (1, 10))
        hybrid = identify.fit_model(task, second, "hybrid", steps=5)
    assert "/jax/compilation_cache/cache_hits" in events  # programs were looked up
    assert "/jax/compilation_cache/cache_misses" not in events
    # the padding rows count for nothing: the result is that of the recorded windows alone
    windows = sum(max(len(e.actions) - 9, 0) for e in second.episodes())
    assert fit.windows == hybrid.windows == windows and errors[10]["starts"] == windows
    assert fit.loss == pytest.approx(_window_loss(task, fit.params, second), rel=1e-9)


def _window_loss(task, params, data, window=10):
    """The mean squared window error over the recorded windows alone, computed plainly."""
    starts, actions, targets = [], [], []
    for ep in data.episodes():
        acts = identify.steps.task_actions(task, ep.actions)
        for t in range(len(ep.actions) - window + 1):
            starts.append(ep.observations[t])
            actions.append(acts[t : t + window])
            targets.append(ep.observations[t + 1 : t + window + 1])
    with jax.enable_x64(True):
        params = jax.tree.map(np.float64, params)
        states = jax.vmap(_gym.state_from_observation.bound(task))(np.stack(starts))
        predict = jax.vmap(identify.steps.predict, in_axes=(None, None, 0, 0))
        pred = np.asarray(predict(task, params, states, np.stack(actions)))
    return float(np.mean((pred - np.stack(targets)) ** 2))


def test_standard_errors_are_ordinary_least_squares_ones_and_inf_where_singular():
    """``sigma^2 (X^T X)^-1`` for a linear model, with the padded residuals left out of the
    degrees of freedom; ``inf`` for an unidentifiable parameter or a non-finite Jacobian."""
    from diffcontrol.identify._shooting import standard_errors

    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 3))
    y = x @ np.array([1.0, -2.0, 0.5]) + 0.1 * rng.normal(size=40)
    beta = np.linalg.lstsq(x, y, rcond=None)[0]
    sigma2 = np.sum((x @ beta - y) ** 2) / (40 - 3)
    expected = np.sqrt(np.diag(sigma2 * np.linalg.inv(x.T @ x)))
    with jax.enable_x64(True):
        got = standard_errors(lambda v, x, y: x @ v - y, jax.numpy.asarray(beta), x, y)
        # 10 zero rows of padding: the same residuals and Jacobian, not counted
        padded = np.vstack([x, np.zeros((10, 3))]), np.concatenate([y, np.zeros(10)])
        got_padded = standard_errors(
            lambda v, x, y: x @ v - y, jax.numpy.asarray(beta), *padded, size=40
        )
        twin = np.column_stack([x[:, 0], x[:, 0]])  # two columns that cannot be told apart
        singular = standard_errors(lambda v: twin @ v - y, jax.numpy.zeros(2))
        broken = standard_errors(lambda v: v * np.array([np.nan, 1.0]), jax.numpy.ones(2))
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(got_padded, expected, rtol=1e-12)
    assert np.all(np.isinf(singular)) and np.all(np.isinf(broken))
