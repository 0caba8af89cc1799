"""Ensembles of networks (``identify.ensemble``): fitted together, their mean as the model,
their spread as its uncertainty and a penalty in the training loss through it."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import identify
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, ModelFileError
from diffcontrol.identify.data import write_trajectories
from diffcontrol.identify.ensemble import (
    ensemble_from_dict,
    ensemble_to_dict,
    make_ensemble,
    stack,
)
from diffcontrol.settings import FitConfig, LoopConfig

REAL = {"g": 12.0, "friction": 0.1}


def _exit_code(argv):
    """``main(argv)``'s exit status (argparse's refusals exit by SystemExit)."""
    try:
        return main(argv)
    except SystemExit as e:
        return e.code


@pytest.fixture(scope="module")
def task():
    return diffcontrol.make("pendulum")


@pytest.fixture(scope="module")
def data():
    """6 episodes of the mismatched real pendulum: 5 to fit (1000 transitions), 1 held out."""
    recorded = diffcontrol.record("diffcontrol/PendulumFriction-v0", 6, seed=3, env_kwargs=REAL)
    return recorded.split(5)


def _ensemble(penalty=1.0, key=1):
    # 3 members with non-zero outputs from their own keys: they disagree everywhere
    return make_ensemble(
        jax.random.PRNGKey(key), 3, 4, 2, (8,), penalty=penalty, out_scale=[0.5, 2.0],
        zero_output=False,
    )  # fmt: skip


def test_members_differ_and_the_model_is_their_mean():
    e = _ensemble()
    x = jnp.array([0.1, 0.9, -0.4, 1.5])
    outs = e.all(x)
    assert outs.shape == (3, 2) and e.num_members == 3
    assert float(jnp.min(jnp.abs(outs[0] - outs[1]))) > 1e-4  # own keys, own weights
    np.testing.assert_allclose(e(x), jnp.mean(outs, axis=0), rtol=1e-6)
    np.testing.assert_allclose(e.member(2)(x), outs[2], rtol=1e-6)
    assert e.num_parameters == 3 * e.member(0).num_parameters
    # the spread: the members' std over the output scale, root mean square over components
    std = np.std(np.asarray(outs), axis=0) / np.array([0.5, 2.0])
    np.testing.assert_allclose(float(e.spread(x)), np.sqrt(np.mean(std**2)), rtol=1e-4)


@pytest.mark.slow
def test_the_penalty_is_zero_where_members_agree_and_positive_where_they_differ(task):
    one = _ensemble().member(0)
    agree = stack([one, one, one], penalty=10.0)
    differ = _ensemble(penalty=10.0)
    model_of = lambda c: identify.NeuralModel(task.default_params(), c)  # noqa: E731
    state, action = jnp.array([2.5, -1.0]), jnp.array([0.7])
    x = jnp.concatenate([task.observe(state), action])
    base = task.step_loss("cost")
    for ensemble, positive in ((agree, False), (differ, True)):
        model = model_of(ensemble)
        mt = identify.model_task(task, model)
        nxt, reward, _ = mt.step(model, state, action)
        np.testing.assert_allclose(nxt, state + ensemble(x), rtol=1e-6)  # the members' mean
        loss = mt.step_loss("cost")(model, state, action, nxt, reward)
        plain = base(task.default_params(), state, action, nxt, reward)
        spread = float(ensemble.spread(x))
        np.testing.assert_allclose(float(loss - plain), 10.0 * spread, rtol=1e-4, atol=1e-6)
        assert (spread > 1e-3) == positive and (spread < 1e-5) == (not positive)
        # the spread's gradient is finite even where the members agree exactly
        g = jax.grad(mt.step_loss("cost"), argnums=2)(model, state, action, nxt, reward)
        assert bool(jnp.all(jnp.isfinite(g)))
    # a penalty of 0: the task's own loss
    model = model_of(_ensemble(penalty=0.0))
    mt = identify.model_task(task, model)
    nxt, reward, _ = mt.step(model, state, action)
    loss = mt.step_loss("cost")(model, state, action, nxt, reward)
    np.testing.assert_allclose(loss, base(task.default_params(), state, action, nxt, reward))


def test_an_ensemble_round_trips_through_json_and_refuses_malformed_members():
    e = _ensemble(penalty=2.5)
    doc = json.loads(json.dumps(ensemble_to_dict(e)))
    back = ensemble_from_dict(doc, "f.json")
    x = jnp.array([0.3, -0.2, 0.8, 1.0])
    np.testing.assert_allclose(back.all(x), e.all(x), rtol=1e-6)
    assert back.penalty == 2.5
    with pytest.raises(ModelFileError, match="'members', a list"):
        ensemble_from_dict({"members": "three"}, "f.json")
    with pytest.raises(ModelFileError, match="'members', a list"):
        ensemble_from_dict({"members": []}, "f.json")
    other = json.loads(json.dumps(ensemble_to_dict(make_ensemble(
        jax.random.PRNGKey(0), 1, 4, 2, (5,), zero_output=False))))  # fmt: skip
    mixed = {**doc, "members": doc["members"][:2] + other["members"]}
    with pytest.raises(ModelFileError, match="differ in shape"):
        ensemble_from_dict(mixed, "f.json")
    with pytest.raises(ModelFileError, match="member 1"):
        ensemble_from_dict({**doc, "members": [doc["members"][0], {"layers": 3}]}, "f.json")
    with pytest.raises(ModelFileError, match="uncertainty_penalty"):
        ensemble_from_dict({**doc, "uncertainty_penalty": -1}, "f.json")


def test_bad_members_are_refused_in_one_line(task, data, tmp_path, capsys):
    for bad in (0, 65, 2.5, True):
        with pytest.raises(ConfigError, match="members"):
            identify.fit_model(task, data[0], "neural", members=bad)
        with pytest.raises(ConfigError, match="members"):
            FitConfig(members=bad)
        with pytest.raises(ConfigError, match="members"):
            LoopConfig(members=bad)
    with pytest.raises(ConfigError, match="uncertainty_penalty"):
        identify.fit_model(task, data[0], "neural", members=3, uncertainty_penalty=-1.0)
    path = tmp_path / "d.csv"
    write_trajectories(path, data[0])
    for argv, said in (
        (["--model", "neural", "--members", "0"], "--members"),
        (["--model", "neural", "--members", "many"], "--members"),
        (["--model", "params", "--members", "3"], "grey box"),
    ):
        code = _exit_code(["fit", "pendulum", "--data", str(path), "--out", str(tmp_path / "f"),
                           *argv])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert code == 2 and said in err and len(err.splitlines()) == 1, err
        assert not (tmp_path / "f" / "fitted.json").exists()


@pytest.mark.slow
def test_a_fitted_ensemble_predicts_and_knows_where_it_has_no_data(task, data):
    fit = identify.fit_model(
        task, data[0], "neural", steps=150, learning_rate=1e-2, hidden=(16,), members=3
    )
    assert not fit.diverged and fit.loss < fit.nominal_loss
    model = fit.model
    assert isinstance(model.correction, identify.Ensemble) and model.correction.num_members == 3
    nominal = identify.prediction_errors(task, task.default_params(), data[1])
    errors = identify.prediction_errors(identify.model_task(task, model), model, data[1])
    for h in (1, 10):  # better than the wrong physics on episodes it was not fitted to
        assert errors[h]["rmse"] < 0.8 * nominal[h]["rmse"], h
    on_data = identify.mean_spread(task, model, data[1])
    assert on_data > 0  # the members differ ...
    far = jnp.array([1.0, 0.0, 40.0, 2.0])  # ... and more where nothing was recorded (40 rad/s)
    assert float(model.correction.spread(far)) > 2 * on_data


@pytest.mark.slow
def test_cli_fits_an_ensemble_whose_file_predicts_as_the_fit_did(task, data, tmp_path, capsys):
    path = tmp_path / "d.csv"
    recorded = identify.concat([data[0], data[1]])
    write_trajectories(path, recorded)
    out = tmp_path / "fit"
    argv = ["fit", "pendulum", "--data", str(path), "--model", "neural", "--out", str(out)]
    argv += ["--members", "3", "--steps", "40", "--hidden", "8", "--uncertainty-penalty", "4"]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "ensemble of 3: mean spread of the members" in said and "(held-out)" in said
    doc = identify.read_fitted(out)
    assert len(doc["network"]["members"]) == 3 and doc["network"]["uncertainty_penalty"] == 4
    assert doc["fit"]["mean_spread"]["held_out"] > 0
    model = identify.fitted_model(task, doc)
    again = identify.fit_model(
        task,
        recorded.split(5)[0],
        "neural",
        steps=40,
        hidden=(8,),
        members=3,
        uncertainty_penalty=4.0,
    )  # fmt: skip: the same fit in memory
    x = jnp.array([0.2, 0.98, 1.5, -0.3])
    np.testing.assert_allclose(model.correction.all(x), again.model.correction.all(x), rtol=1e-5)
    assert model.correction.penalty == 4.0
    doc["network"]["members"][1]["layers"] = doc["network"]["members"][1]["layers"][:1]
    (out / "fitted.json").write_text(json.dumps({k: v for k, v in doc.items() if k != "_path"}))
    argv = [
        "train",
        "pendulum",
        "--model",
        str(out),
        "--updates",
        "2",
        "--out",
        str(tmp_path / "r"),
    ]
    code = _exit_code(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and "member 1" in err and len(err.splitlines()) == 1, err


@pytest.mark.slow
def test_the_loop_fits_ensembles_and_books_their_spread_on_the_new_data(tmp_path, capsys):
    out = tmp_path / "loop"
    argv = ["loop", "pendulum", "--env", "diffcontrol/PendulumFriction-v0", "--env-arg", "g=12"]
    argv += ["--env-arg", "friction=0.1", "--rounds", "2", "--episodes", "1", "--updates", "4"]
    argv += ["--eval-episodes", "2", "--fit-steps", "30", "--out", str(out), "--quiet"]
    argv += ["--model", "hybrid"]
    argv += ["--controller", "train"]  # the MLP's training, not the default planner
    assert _exit_code([*argv, "--members", "2", "--model", "params"]) == 2
    assert "grey box has no network" in capsys.readouterr().err
    assert not (out / "loop.json").exists()
    assert _exit_code([*argv, "--members", "2"]) == 0
    doc = json.loads((out / "loop.json").read_text())
    assert doc["settings"]["members"] == 2
    first, second = doc["rounds"]
    assert "spread" not in first["model_error_on_new_data"]  # the start physics: no members
    assert second["model_error_on_new_data"]["spread"] > 0  # round 1's ensemble, before refit
    assert "the members' spread there" in capsys.readouterr().out
    fitted = json.loads((out / "round_2" / "fit" / "fitted.json").read_text())
    assert len(fitted["network"]["members"]) == 2
