"""Hybrid and black-box (neural) models: fits, storage, and training through them."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import identify
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, InsufficientDataError, ModelFileError
from diffcontrol.identify.data import write_trajectories
from diffcontrol.runs._loop import kept_round

REAL = {"g": 12.0, "friction": 0.1}


@pytest.fixture(scope="module")
def task():
    return diffcontrol.make("pendulum")


@pytest.fixture(scope="module")
def data():
    """6 episodes of the mismatched real pendulum: 5 to fit (1000 transitions), 1 held out."""
    recorded = diffcontrol.record("diffcontrol/PendulumFriction-v0", 6, seed=3, env_kwargs=REAL)
    return recorded.split(5)


@pytest.fixture(scope="module")
def fits(task, data):
    return {
        kind: identify.fit_model(task, data[0], kind, steps=150, learning_rate=1e-2, hidden=(16,))
        for kind in identify.NETWORK_MODELS
    }


def test_correction_round_trips_through_json_and_refuses_malformed_networks():
    c = identify.Correction(
        jax.random.PRNGKey(1),
        4,
        2,
        (8,),
        in_scale=[1, 2, 3, 4],
        out_scale=[0.1, 0.2],
        zero_output=False,
    )
    doc = json.loads(json.dumps(identify.correction_to_dict(c)))
    back = identify.correction_from_dict(doc)
    x = jnp.arange(4.0)
    np.testing.assert_allclose(back(x), c(x), rtol=1e-6)
    assert float(jnp.max(jnp.abs(c(x)))) > 0
    zero = identify.Correction(jax.random.PRNGKey(1), 4, 2)
    assert np.all(np.asarray(zero(x)) == 0)  # a hybrid starts at exactly the physics
    bad = {**doc, "layers": doc["layers"][:1]}  # the output size no longer matches
    with pytest.raises(ModelFileError, match="shapes"):
        identify.correction_from_dict(bad, "f.json")
    nan = json.loads(json.dumps(doc))
    nan["layers"][0]["bias"][0] = float("nan")
    with pytest.raises(ModelFileError, match="non-finite"):
        identify.correction_from_dict(nan)
    with pytest.raises(ModelFileError, match="malformed"):
        identify.correction_from_dict({"layers": 3})


@pytest.mark.slow
def test_hybrid_and_neural_fits_beat_the_nominal_model_on_held_out_data(task, data, fits):
    held_out = data[1]
    nominal = identify.prediction_errors(task, task.default_params(), held_out)
    for kind, fit in fits.items():
        assert not fit.diverged and np.isfinite(fit.loss) and fit.loss < fit.nominal_loss
        errors = identify.prediction_errors(
            identify.model_task(task, fit.model), fit.model, held_out
        )
        factor = 0.5 if kind == "hybrid" else 0.8  # the black box learns everything: slower
        for h in (1, 10):
            assert errors[h]["rmse"] < factor * nominal[h]["rmse"], (kind, h)
    # the hybrid starts at the nominal physics: its first loss is the nominal model's
    hybrid = fits["hybrid"]
    np.testing.assert_allclose(hybrid.loss_history[0], hybrid.nominal_loss, rtol=1e-9)
    assert fits["neural"].loss_history[0] > hybrid.loss_history[0]


@pytest.mark.slow
def test_model_task_predicts_with_the_model_and_keeps_the_reward(task, fits):
    model = fits["hybrid"].model
    mt = identify.model_task(task, model)
    state, action = jnp.array([0.3, -1.0]), jnp.array([0.5])
    nxt, reward, _ = mt.step(mt.default_params(), state, action)
    physics, reward0, _ = task.step(model.params, state, action)
    np.testing.assert_allclose(reward, reward0)
    correction = model.correction(jnp.concatenate([task.observe(state), action]))
    np.testing.assert_allclose(nxt, physics + correction, rtol=1e-6)
    assert float(jnp.max(jnp.abs(correction))) > 0
    assert mt.name == task.name and mt.gym_id == task.gym_id


def test_too_little_data_and_bad_settings_are_refused(task, data):
    short = data[0].select([0])  # 200 transitions
    with pytest.raises(InsufficientDataError, match="200 recorded .* neural model: at least 1000"):
        identify.fit_model(task, short, "neural")
    with pytest.raises(ConfigError, match="unknown model kind 'lstm'"):
        identify.fit_model(task, short, "lstm")
    with pytest.raises(ConfigError, match="hidden"):
        identify.fit_model(task, short, "hybrid", hidden=(0,))


def test_the_model_kinds_are_one_registry_and_a_new_kind_is_one_class(task, data, monkeypatch):
    """Every module asks a kind (``identify.kinds``): the registry is the command line's
    choices, and a kind added to it is fitted with its own defaults, written and read back."""
    from diffcontrol.identify import kinds
    from diffcontrol.settings import MODELS

    assert tuple(identify.KINDS) == MODELS
    assert [k.network for k in identify.KINDS.values()] == [False, True, True]
    assert [k.physics for k in identify.KINDS.values()] == [True, True, False]
    with pytest.raises(ConfigError, match=r"unknown model kind 'grey'; choose one of \['params'"):
        identify.kind("grey")

    class QuickGreyBox(kinds.Params):
        name, label, defaults = "quick", "quick grey box", (7, 0.05)

    monkeypatch.setitem(kinds.KINDS, "quick", QuickGreyBox())
    result = identify.fit(task, data[0], "quick", lm_steps=0)
    assert result.model_type == "quick" and len(result.loss_history) == 7  # the kind's steps
    assert result.loss < result.nominal_loss


@pytest.mark.slow
def test_a_diverging_fit_keeps_the_best_weights_and_no_nan(task, data):
    fit = identify.fit_model(task, data[0], "neural", steps=30, learning_rate=1e6, hidden=(8,))
    leaves = jax.tree.leaves(fit.model)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in leaves)
    assert np.isfinite(fit.loss)
    if fit.diverged:
        assert "kept the best weights" in fit.message


@pytest.mark.slow
def test_cli_fit_hybrid_then_train_through_it_and_evaluate_on_the_real_system(
    tmp_path, data, capsys
):
    csv = tmp_path / "real.csv"
    both = data[0].select([0, 1])
    write_trajectories(csv, both)
    fit_dir = tmp_path / "fit"
    argv = ["fit", "pendulum", "--data", str(csv), "--model", "hybrid", "--out", str(fit_dir)]
    assert main([*argv, "--steps", "30", "--hidden", "8", "--holdout", "0.5", "--quiet"]) == 0
    doc = json.loads((fit_dir / "fitted.json").read_text())
    assert doc["model"] == "hybrid" and doc["network"]["parameters"] == 3 * 8 + 8 + 8 * 2 + 2 + 8
    assert doc["all_parameters"]["g"] == 10.0 and doc["data"]["env_kwargs"] == REAL
    e = doc["prediction_error"]
    assert e["fitted"]["10"]["rmse"] < e["nominal"]["10"]["rmse"]

    run = tmp_path / "run"
    train = ["train", "pendulum", "--model", str(fit_dir), "--out", str(run), "--quiet"]
    tiny = ["--updates", "4", "--eval-every", "2", "--eval-episodes", "4", "--final-eval", "2"]
    capsys.readouterr()
    assert main([*train, *tiny, "--no-animation"]) == 0
    assert "training through the hybrid model" in capsys.readouterr().out
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["model"]["kind"] == "hybrid"
    assert metrics["gym_eval"]["env_id"].startswith("diffcontrol/PendulumFriction-v0(g=12.0")
    assert (run / "model.json").exists() and (run / "rollout.png").exists()
    capsys.readouterr()
    assert main(["evaluate", str(run), "--episodes", "1", "--json"]) == 0  # the real system
    assert json.loads(capsys.readouterr().out)["env_id"].startswith("diffcontrol/PendulumFr")
    assert main(["evaluate", str(run), "--episodes", "1", "--json", "--env", "Pendulum-v1"]) == 0
    assert json.loads(capsys.readouterr().out)["env_id"] == "Pendulum-v1"

    # --param cannot change a hybrid's physics; another task's model is refused
    assert main([*train[:-2], str(tmp_path / "r2"), "--param", "g=9", *tiny]) == 2
    assert "--param cannot change the physics" in capsys.readouterr().err
    assert main(["train", "cartpole", "--model", str(fit_dir), "--out", str(tmp_path / "r3")]) == 2
    assert "fitted for task 'pendulum', not 'cartpole'" in capsys.readouterr().err
    assert main(["train", "pendulum", "--model", str(tmp_path), "--out", str(tmp_path / "r4")]) == 2
    assert "no fitted model at" in capsys.readouterr().err


@pytest.mark.slow
def test_train_with_a_grey_box_fit_uses_its_parameters(tmp_path, data, capsys):
    fit_dir = tmp_path / "fit"
    fit_dir.mkdir()
    doc = {
        "format": "diffcontrol-fitted-model",
        "version": 1,
        "task": "pendulum",
        "model": "params",
        "all_parameters": {"g": 11.5, "friction": 0.05},
        "data": {"env_id": "diffcontrol/PendulumFriction-v0", "env_kwargs": REAL},
    }
    (fit_dir / "fitted.json").write_text(json.dumps(doc))
    run = tmp_path / "run"
    argv = ["train", "pendulum", "--model", str(fit_dir), "--out", str(run), "--quiet"]
    tiny = ["--updates", "2", "--eval-every", "2", "--eval-episodes", "2", "--final-eval", "1"]
    assert main([*argv, *tiny, "--param", "friction=0.07", "--no-animation"]) == 0
    run_doc = json.loads((run / "run.json").read_text())
    assert dict(map(tuple, run_doc["config"]["params"])) == {"g": 11.5, "friction": 0.07}
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["model"]["kind"] == "params"

    doc["all_parameters"]["g"] = "heavy"
    (fit_dir / "fitted.json").write_text(json.dumps(doc))
    assert main([*argv[:-2], str(tmp_path / "r2"), *tiny]) == 2
    assert "finite numbers" in capsys.readouterr().err


def test_concat_renumbers_episodes_and_refuses_other_columns(data):
    from diffcontrol.identify.data import DataFileError, concat

    a, b = data[0].select([1, 3]), data[1]
    joined = concat([a, b])
    assert [e.id for e in joined.episodes()] == [0, 1, 2]
    assert joined.num_steps == a.num_steps + b.num_steps
    np.testing.assert_array_equal(joined.observations[: len(a.time)], a.observations)
    cartpole = diffcontrol.record("CartPole-v1", 1)
    with pytest.raises(DataFileError, match="cannot join"):
        concat([a, cartpole])


@pytest.mark.slow
def test_loop_records_fits_trains_and_resumes(tmp_path, capsys):
    out = tmp_path / "loop"
    argv = ["loop", "pendulum", "--env", "diffcontrol/PendulumFriction-v0", "--env-arg", "g=12"]
    argv += ["--env-arg", "friction=0.1", "--rounds", "2", "--episodes", "1", "--updates", "4"]
    argv += ["--eval-episodes", "2", "--out", str(out), "--quiet"]
    argv += ["--controller", "train"]  # the MLP's training, not the default planner
    assert main(argv) == 0
    doc = json.loads((out / "loop.json").read_text())
    assert [r["round"] for r in doc["rounds"]] == [1, 2]
    assert [r["episodes"] for r in doc["rounds"]] == [1, 2]  # one more episode each round
    for r in doc["rounds"]:  # the grey box finds the real g from one episode
        assert abs(r["fitted_parameters"]["g"] - 12.0) < 0.01
        assert np.isfinite(r["real_return"])
    # each round kept by the rule (runs._loop.kept_round), the last kept one handed back
    # (round 1 against round 0's: the nominal controller, judged on the same episodes)
    nominal = doc["nominal"]
    assert nominal["round"] == 0 and len(nominal["real_returns"]) == 2
    kept = [r["kept_round"] for r in doc["rounds"]]
    assert kept[0] == kept_round([nominal], doc["rounds"][0])
    assert kept[1] == kept_round([nominal, doc["rounds"][0]], doc["rounds"][1])
    assert doc["best_round"] == kept[1]
    assert f"round_{kept[1]}/run/model.json" in capsys.readouterr().out
    sources = json.loads((out / "data.csv").read_text().splitlines()[0][2:])["metadata"]
    # the evaluation's reset seeds (0 and 1, the default) are not recorded from
    first = json.loads((out / "round_0" / "recorded.csv").read_text().splitlines()[0][2:])
    assert first["metadata"]["skipped_seeds"] == [0, 2]
    assert sources["sources"][0] == "random actions"  # round 1 records with its controller:
    assert sources["sources"][1] == f"round {kept[0]} controller"  # or the one kept before
    assert (out / "round_2" / "run" / "model.json").exists() and (out / "loop.png").exists()
    capsys.readouterr()
    assert main(argv) == 2 and "pass --resume" in capsys.readouterr().err
    for name in ("model.json", "metrics.json"):  # as if interrupted in round 2's training
        (out / "round_2" / "run" / name).unlink()
    assert main([*argv, "--resume"]) == 0
    assert (out / "round_2" / "run" / "model.json").exists()
    assert main([*argv[:-3], "--model", "hybrid", "--out", str(out), "--resume"]) == 2
    assert "other settings" in capsys.readouterr().err
    # a run someone trained into the next round's directory is not adopted as that round's
    foreign = out / "round_3" / "run"
    tiny = ["--updates", "2", "--eval-every", "1", "--batch", "4", "--window", "10"]
    assert main(["train", "pendulum", "--out", str(foreign), *tiny, "--final-eval", "0"]) == 0
    capsys.readouterr()
    resume = [*argv, "--resume"]
    resume[resume.index("--rounds") + 1] = "3"
    assert main(resume) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "did not train" in err, err
    assert (foreign / "model.json").exists()  # left as it was


def test_the_real_system_of_a_fitted_model_comes_from_its_data():
    from diffcontrol.identify import as_env, real_params, real_system

    env = real_system({"data": {"env_id": "diffcontrol/PendulumFriction-v0", "env_kwargs": REAL}})
    assert as_env(env) == ("diffcontrol/PendulumFriction-v0", REAL)
    throws = {"data": {"kind": "throws", "metadata": {"params": {"drag_coefficient": 1.5}}}}
    real = real_system(throws)
    assert as_env(real) is None
    params = real_params(diffcontrol.make("trebuchet"), real)
    assert params.drag_coefficient == 1.5 and params.wind_factor == 1.0
    assert real_system({"data": {}}) is None and real_params(None, None) is None
