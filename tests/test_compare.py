"""`diffcontrol compare`: the evaluation protocol, the summary, the CLI end to end, bad input."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import diffcontrol
from diffcontrol.cli import main
from diffcontrol.compare import evaluate_batch, report
from diffcontrol.compare.run import first_reached, numpy_policy_act

TINY = ["--seeds", "1", "--eval-episodes", "2", "--final-episodes", "2", "--quiet"]


def test_batched_evaluation_is_the_evaluate_protocol(cartpole_run, pendulum_run):
    for run in (cartpole_run, pendulum_run):
        policy = diffcontrol.load(run)
        task = diffcontrol.make(policy.task)
        ours = evaluate_batch(numpy_policy_act(policy), task, episodes=3, seed=11)
        ref = diffcontrol.evaluate(policy, task, episodes=3, seed=11)
        np.testing.assert_allclose(ours, ref.returns, rtol=1e-12)


def _result(method, seed, curve, final):
    points = [
        {
            "env_steps": s,
            "episodes": s / 500,
            "episodes_finished": s // 100,
            "train_seconds": s / 1000,
            "mean_return": r,
            "std_return": 0.0,
        }
        for s, r in curve
    ]
    return {
        "method": method,
        "algo": method.upper(),
        "source": "test",
        "seed": seed,
        "env_steps": curve[-1][0],
        "train_seconds": curve[-1][0] / 1000,
        "curve": points,
        "final": {"episodes": 2, "mean_return": final, "std_return": 1.0, "returns": []},
    }


def test_summary_takes_the_first_point_at_the_threshold_and_medians_over_seeds():
    results = [
        _result("a", 0, [(1000, 100.0), (2000, 480.0), (3000, 300.0)], 300.0),
        _result("a", 1, [(1000, 490.0), (2000, 500.0)], 500.0),
        _result("a", 2, [(1000, 10.0), (4000, 476.0)], 476.0),
        _result("b", 0, [(1000, 10.0)], 10.0),
    ]
    assert first_reached(results[0]["curve"], 475.0)["env_steps"] == 2000
    assert first_reached(results[3]["curve"], 475.0) is None
    a, b = report.summarize(results, (475.0,))
    t = a["thresholds"][0]
    assert (t["reached"], t["of"]) == (3, 3)
    assert t["env_steps"] == {"median": 2000, "min": 1000, "max": 4000, "n": 3}
    assert a["final_mean_return"]["median"] == 476.0
    assert b["thresholds"][0]["reached"] == 0 and b["thresholds"][0]["env_steps"]["median"] is None
    text = report.table("t", [a, b])
    assert "2,000 [1,000–4,000]" in text and "3/3" in text and "0/1" in text


def test_on_point_sees_every_evaluation_point():
    task = diffcontrol.make("cartpole")
    config = task.default_config().replace(updates=20, eval_every=10, eval_episodes=2)
    seen = []
    result = diffcontrol.train(
        task, config, on_point=lambda p, c: seen.append((p["update"], c.num_parameters))
    )
    assert [u for u, _ in seen] == [p["update"] for p in result.curve] == [0, 10, 20]
    assert result.metrics["callback_seconds"] >= 0


@pytest.mark.slow
def test_compare_diffcontrol_alone_works_without_the_rl_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # as if not installed
    out = tmp_path / "cmp"
    args = ["compare", "cartpole", "--out", str(out), "--methods", "diffcontrol"]
    assert main([*args, "--updates", "10", *TINY]) == 0
    doc = json.loads((out / "comparison.json").read_text())
    assert [r["method"] for r in doc["runs"]] == ["diffcontrol"]
    assert doc["runs"][0]["env_steps"] == 10 * 8 * 4  # updates x window x batch
    # Asking for an RL method without the extra: one line naming the install command.
    code = main(["compare", "cartpole", "--out", str(tmp_path / "x"), "--methods", "ppo"])
    err = capsys.readouterr().err
    assert code == 2 and "pip install 'diffcontrol[rl]'" in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_compare_end_to_end_and_resume(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "cmp"
    args = ["compare", "cartpole", "--out", str(out), "--rl-steps", "256", "--updates", "10"]
    args += ["--eval-every", "128", *TINY]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "| ppo (PPO) |" in printed and "| dqn (DQN) |" in printed
    for name in ("compare.json", "comparison.json", "comparison.md", "comparison.png"):
        assert (out / name).stat().st_size > 0
    doc = json.loads((out / "comparison.json").read_text())
    assert [r["method"] for r in doc["runs"]] == ["diffcontrol", "ppo", "dqn"]
    for run in doc["runs"]:
        assert run["curve"] and run["final"]["episodes"] == 2
        assert all(np.isfinite(p["mean_return"]) for p in run["curve"])
        assert run["train_seconds"] > 0 and run["eval_seconds"] > 0
    ppo = doc["runs"][1]
    assert ppo["env_steps"] >= 256 and ppo["source"].endswith("hyperparams/ppo.yml, CartPole-v1")
    assert [p["env_steps"] for p in ppo["curve"]] == [128, 256]  # 8 envs step together
    assert doc["summary"][0]["thresholds"][0]["threshold"] == 475.0
    assert doc["machine"]["stable_baselines3"]

    # A finished run is kept on --resume; other settings are refused.
    before = (out / "runs" / "dqn-seed0.json").read_text()
    assert main([*args, "--resume"]) == 0
    assert (out / "runs" / "dqn-seed0.json").read_text() == before
    assert main([*args, "--resume", "--rl-steps", "512"]) == 2
    assert "other settings (rl_steps differ)" in capsys.readouterr().err
    assert main(args) == 2
    assert "--resume" in capsys.readouterr().err


@pytest.mark.slow
def test_compare_pendulum_td3_tiny(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "p"
    args = ["compare", "pendulum", "--out", str(out), "--methods", "td3", "--rl-steps", "200"]
    assert main([*args, "--eval-every", "100", *TINY]) == 0
    run = json.loads((out / "runs" / "td3-seed0.json").read_text())
    assert [p["env_steps"] for p in run["curve"]] == [100, 200]
    assert run["config"]["policy_kwargs"] == {"net_arch": [400, 300]}
    assert run["config"]["learning_starts"] == 10_000  # the zoo's, even past this tiny budget
    assert run["final"]["mean_return"] < 0


@pytest.mark.parametrize(
    "args, needle",
    [
        (["compare", "nope"], "unknown task 'nope'"),
        (["compare", "pendulum-unclipped"], "no RL baselines are defined"),
        (["compare", "cartpole", "--methods", "sac"], "unknown method 'sac'"),
        (["compare", "cartpole", "--seeds", "0"], "must be a positive integer"),
        (["compare", "cartpole", "--rl-steps", "-5"], "must be a positive integer"),
        (["compare", "cartpole", "--eval-every", "often"], "expected a positive integer"),
        (["compare", "cartpole", "--methods", ","], "expected comma-separated names"),
    ],
)
def test_compare_bad_input(capsys, tmp_path, args, needle):
    try:
        code = main([*args, "--out", str(tmp_path / "o")])
    except SystemExit as e:  # argparse's errors (one line, exit 2: see cli._Parser)
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_compare_refuses_a_directory_with_other_files(capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    code = main(["compare", "cartpole", "--out", str(tmp_path), "--methods", "diffcontrol"])
    assert code == 2 and "not empty" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_compare_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["compare", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for option in ("--seeds", "--rl-steps", "--updates", "--eval-every", "--resume", "--out"):
        assert option in out
    assert "leave out these evaluations" in " ".join(out.split())


@pytest.mark.slow
def test_compare_trebuchet_rl_in_the_diffcontrol_environment(tmp_path, monkeypatch):
    import tempfile

    pytest.importorskip("stable_baselines3")
    out = tmp_path / "t"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))  # where SB3's own logger would write
    args = ["compare", "trebuchet", "--out", str(out), "--methods", "sac,td3"]
    assert main([*args, "--rl-steps", "40", "--eval-every", "20", *TINY]) == 0
    assert not list(scratch.glob("SB3-*"))  # no empty SB3-<date> folder left per learn()
    doc = json.loads((out / "comparison.json").read_text())
    assert doc["eval_env"] == "diffcontrol/Trebuchet-v0" and doc["thresholds"] == [-2.0, -1.0]
    for run in doc["runs"]:
        assert [p["env_steps"] for p in run["curve"]] == [20, 40]
        assert run["episodes"] == run["env_steps"]  # one throw per episode
        assert all(r <= 0 for r in run["final"]["returns"])  # minus the miss in metres


@pytest.mark.slow
def test_compare_pendulum_has_the_planner_and_its_distilled_mlp(tmp_path, capsys, monkeypatch):
    from diffcontrol.compare import _planning, methods_for
    from diffcontrol.settings import PlanConfig

    assert methods_for(diffcontrol.make("pendulum"))[:3] == ["diffcontrol", "planner", "distilled"]
    assert "planner" not in methods_for(diffcontrol.make("cartpole"))  # no state grid
    small = PlanConfig(horizon=4, iterations=2, value_grid=9, value_levels=5)
    monkeypatch.setattr(_planning, "PLANNER", small)
    tiny = dict(rounds=1, episodes_per_round=4, fit_steps=10, batch_size=16, eval_episodes=4)
    monkeypatch.setattr(_planning, "DISTIL", tiny)
    out = tmp_path / "p"
    args = ["compare", "pendulum", "--out", str(out), "--methods", "planner,distilled"]
    assert main([*args, "--seeds", "1", "--eval-episodes", "2", "--final-episodes", "2"]) == 0
    planner = json.loads((out / "runs" / "planner-seed0.json").read_text())
    assert planner["env_steps"] == 0 and planner["config"] == small.to_json()
    assert len(planner["final"]["returns"]) == 2 and planner["final"]["mean_return"] < 0
    distilled = json.loads((out / "runs" / "distilled-seed0.json").read_text())
    assert distilled["env_steps"] == 4 * 200  # one round of four simulated episodes
    table = (out / "comparison.md").read_text()
    assert "planner" in table and "distilled" in table


def test_the_rl_baselines_are_the_tasks_own():
    """``compare.rl_setup`` of a task: the zoo's for CartPole and Pendulum, the trebuchet's
    from its folder, none for the unclipped Pendulum, and a user's task's own method."""
    from diffcontrol.compare import RLSetup, methods_for, rl_setup
    from diffcontrol.compare.baselines import Baseline

    setups = {n: rl_setup(diffcontrol.make(n)) for n in ("cartpole", "pendulum", "trebuchet")}
    baselines = [list(s.baselines) for s in setups.values()]
    assert baselines == [["ppo", "dqn"], ["sac", "td3"], ["sac", "td3"]]
    assert setups["cartpole"].thresholds == (475.0, 500.0)
    assert rl_setup(diffcontrol.make("pendulum-unclipped")) is None

    class Mine(type(diffcontrol.make("pendulum"))):
        name = "pendulum-mine"

        def rl_setup(self):
            return RLSetup({"a2c": Baseline("A2C", 1000)}, thresholds=(-300.0,))

    assert methods_for(Mine())[-1] == "a2c" and rl_setup(Mine()).thresholds == (-300.0,)
