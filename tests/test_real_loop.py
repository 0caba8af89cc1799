"""The loop counted in real steps (issue 14): its bookkeeping, a grey box that starts wrong,
exploration with noise, a budget of real steps per round, bad input, and ``compare --real``'s
runs (on CartPole-v1 end to end)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces

import diffcontrol
from diffcontrol import _gym, identify
from diffcontrol.cli import main
from diffcontrol.compare.real import _as_run, _rl_runs, run_real_comparison
from diffcontrol.errors import ConfigError
from diffcontrol.identify._rounds import NoisyPolicy, model_error, predictor_of
from diffcontrol.tasks import Pendulum


class _BrokenPendulum(gymnasium.Env):
    """Pendulum-shaped spaces; from step 3: NaN observations ("nan"), an exception ("raise"),
    an observation of 4 numbers ("shape") or an infinite reward ("inf")."""

    observation_space = spaces.Box(-np.inf, np.inf, (3,), np.float32)
    action_space = spaces.Box(-2.0, 2.0, (1,), np.float32)

    def __init__(self, how: str = "nan"):
        self.how, self.t = how, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.array([1.0, 0.0, 0.0], np.float32), {}

    def step(self, action):
        self.t += 1
        if self.t == 3 and self.how == "raise":
            raise RuntimeError("motor driver fault")
        broken = self.t >= 3
        obs = np.array([1.0, 0.0, np.nan if broken and self.how == "nan" else 0.0], np.float32)
        if broken and self.how == "shape":
            obs = np.zeros(4, np.float32)
        reward = np.inf if broken and self.how == "inf" else 0.0
        return obs, reward, False, self.t >= 10, {}


gymnasium.register("test/BrokenPendulum-v0", entry_point=_BrokenPendulum, max_episode_steps=10)


@pytest.mark.parametrize(
    "how, match",
    [
        ("nan", "non-finite observation"),
        ("raise", "raised"),
        ("shape", r"observation of shape \(4,\)"),
        ("inf", "the reward inf"),
    ],
)
def test_record_refuses_a_system_that_breaks_its_space(how, match):
    task = diffcontrol.make("pendulum")
    with pytest.raises(ConfigError, match=match) as e:
        identify.record("test/BrokenPendulum-v0", 1, env_kwargs={"how": how}, task=task)
    assert "\n" not in str(e.value) and "episode 0 at step 3" in str(e.value)


class _Blind(Pendulum):
    """A Pendulum that cannot reconstruct its state from observations (the default hook)."""

    name = "blind-pendulum"
    state_from_observation = _gym.state_from_observation.dispatch(object)


def test_loop_refuses_other_spaces_and_unknown_start_before_writing(tmp_path, capsys):
    out = tmp_path / "loop"
    assert main(["loop", "pendulum", "--env", "CartPole-v1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "CartPole-v1 has the spaces" in err
    assert main(["loop", "pendulum", "--start", "gravity=8", "--out", str(out)]) == 2
    assert "no parameter 'gravity'" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="cannot fit a model of 'blind-pendulum'"):
        diffcontrol.runs.loop(_Blind(), out)  # a task that cannot reconstruct its state
    for flag in ("--explore-noise", "0.1"), ("--real-steps", "100"):
        assert main(["loop", "trebuchet", *flag, "--out", str(out)]) == 2
        assert f"{flag[0]} applies to Gymnasium episodes" in capsys.readouterr().err
    assert main(["compare", "trebuchet", "--real", "--out", str(out)]) == 2
    err = capsys.readouterr().err  # the tasks that can (the MuJoCo ones among them)
    assert "not 'trebuchet'; choose cartpole or " in err and " pendulum or " in err
    assert main(["compare", "pendulum", "--real", "--models", "pid", "--out", str(out)]) == 2
    assert "unknown model(s) ['pid']" in capsys.readouterr().err
    assert not out.exists()


def test_noisy_policy_stays_in_the_action_space_and_explores():
    box = spaces.Box(-2.0, 2.0, (1,), np.float32)
    policy = NoisyPolicy(lambda obs: np.array([1.9], np.float32), box, 0.5, seed=0)
    actions = np.array([policy(np.zeros(3)) for _ in range(500)])
    assert np.all((actions >= -2.0) & (actions <= 2.0))
    assert 0.5 < actions.std() < 1.2 and np.any(actions < 1.9)  # noise of 0.5 * 2 N m, clipped
    assert np.array_equal(NoisyPolicy(lambda o: [0.5], box, 0.0, 0)(np.zeros(3)), [0.5])
    discrete = NoisyPolicy(lambda obs: 1, spaces.Discrete(2), 0.3, seed=0)
    picks = np.array([discrete(np.zeros(4)) for _ in range(2000)])
    assert abs(np.mean(picks == 0) - 0.15) < 0.03  # random with p 0.3, half of those are 0


def test_model_error_before_the_fit_is_that_of_the_start_physics():
    task = diffcontrol.make("pendulum")
    data = identify.record("Pendulum-v1", 1, seed=0, task=task)
    truth = model_error(predictor_of(task, None, "params", {}), data)
    wrong = model_error(predictor_of(task, None, "hybrid", {"g": 8.0}), data)
    assert truth["rmse_1"] < 1e-5 < 1e-3 < wrong["rmse_1"] < wrong["rmse_10"]
    assert predictor_of(task, None, "neural", {}) is None


@pytest.mark.slow
def test_the_nominal_controller_is_handed_back_when_no_round_beats_it(
    tmp_path, capsys, monkeypatch
):
    """Round 0 (the task's own physics) against rounds that do worse on the real system: both
    rounds keep it, round 2 records with it, and the loop hands it back."""
    from diffcontrol.runs import _loop

    real_evaluate = _loop._evaluate

    def judged(task, here, episodes, seed, real, policy_of):
        doc = real_evaluate(task, here, episodes, seed, real, policy_of)
        if here.name != "round_0":  # every later round 50 worse on each episode
            doc = {**doc, "returns": [r - 50.0 for r in doc["returns"]]}
            doc["mean_return"] = float(np.mean(doc["returns"]))
        return doc

    monkeypatch.setattr(_loop, "_evaluate", judged)
    out = tmp_path / "loop"
    argv = ["loop", "cartpole", "--rounds", "2", "--real-steps", "200", "--updates", "2"]
    argv += ["--eval-episodes", "2", "--eval-seed", "1000", "--out", str(out), "--quiet"]
    assert main(argv) == 0  # CartPole: a trained MLP (no planner does better there)
    doc = json.loads((out / "loop.json").read_text())
    assert doc["nominal"]["real_returns"] and doc["nominal"]["real_steps"] == 0
    assert [r["kept_round"] for r in doc["rounds"]] == [0, 0] and doc["best_round"] == 0
    printed = capsys.readouterr().out
    assert "round 0: the nominal controller" in printed
    assert "round_0/run/model.json (round 0's: the nominal controller" in printed
    recorded = identify.read_trajectories(out / "round_1" / "recorded.csv")
    assert recorded.metadata["source"] == "round 0 controller"
    assert (out / "round_0" / "run" / "model.json").exists()


@pytest.mark.slow
def test_loop_counts_real_steps_starts_wrong_and_resumes(tmp_path, capsys):
    out = tmp_path / "loop"
    argv = ["loop", "pendulum", "--rounds", "2", "--episodes", "1", "--updates", "2"]
    argv += ["--eval-episodes", "2", "--eval-seed", "1000", "--start", "g=8"]
    argv += ["--explore-noise", "0.1", "--out", str(out), "--quiet"]
    argv += ["--controller", "train"]  # the MLP's training, not the default planner
    assert main(argv) == 0
    doc = json.loads((out / "loop.json").read_text())
    assert doc["settings"]["start"] == {"g": 8.0} and "g = 8 (nominal 10)" in doc["start"]["note"]
    rounds = doc["rounds"]
    assert [r["real_steps"] for r in rounds] == [200, 400]  # evaluation episodes not counted
    first, second = (r["model_error_on_new_data"] for r in rounds)
    assert first["rmse_1"] > 1e-3 > second["rmse_1"]  # g = 8 was wrong; the fit of round 1 not
    assert all(abs(r["fitted_parameters"]["g"] - 10.0) < 0.01 for r in rounds)
    evaluated = json.loads((out / "round_1" / "eval.json").read_text())
    assert (
        evaluated["seeds"] == [1000, 1001] and rounds[0]["real_return"] == evaluated["mean_return"]
    )
    sources = json.loads((out / "data.csv").read_text().splitlines()[0][2:])["metadata"]["sources"]
    kept = rounds[0]["kept_round"]  # round 1's, or the nominal one (round 0) if it did better
    assert sources == ["random actions", f"round {kept} controller with action noise 0.1"]
    before = (out / "round_1" / "recorded.csv").read_bytes()
    (out / "round_2" / "run" / "model.json").unlink()  # as if interrupted in round 2's training
    assert main([*argv, "--resume"]) == 0
    assert (out / "round_1" / "recorded.csv").read_bytes() == before  # nothing recorded twice
    assert identify.read_trajectories(out / "data.csv").num_episodes == 2


def test_a_loop_becomes_a_compare_run_on_real_steps(tmp_path):
    rounds = [
        {"round": 1, "episodes": 1, "real_steps": 200, "real_return": -400.0,
         "real_return_std": 50.0, "eval_episodes": 100, "model_error_on_new_data": None,
         "work_seconds": {"record": 0.1, "fit": 2.0, "train": 3.0}},
        {"round": 2, "episodes": 2, "real_steps": 400, "real_return": -140.0,
         "real_return_std": 80.0, "eval_episodes": 100, "model_error_on_new_data": {"rmse_1": 0.1},
         "work_seconds": {"record": 0.1, "fit": 1.0, "train": None}},
    ]  # fmt: skip
    run = _as_run("grey box", 3, {"settings": {}, "rounds": rounds, "start": {}}, 9.0, 100)
    assert run["method"] == "diffcontrol (grey box)" and run["seed"] == 3
    assert [p["env_steps"] for p in run["curve"]] == [200, 400]
    # as compare counts them: real steps in standard episodes (here of 100 steps); recorded ones
    assert [(p["episodes"], p["episodes_finished"]) for p in run["curve"]] == [(2.0, 1), (4.0, 2)]
    assert run["curve"][-1]["train_seconds"] == pytest.approx(6.2)
    assert run["final"]["mean_return"] == -140.0 and run["env_steps"] == 400
    other = tmp_path / "c.json"
    other.write_text(json.dumps({"task": "pendulum", "eval_seed": 0, "runs": []}))
    with pytest.raises(ConfigError, match="--eval-seed 0"):
        _rl_runs(other, "pendulum", 1000)


def _first_observations(data) -> list:
    return [e.observations[0] for e in data.episodes()]


def test_record_skips_the_seeds_it_is_told_to():
    data = identify.record("CartPole-v1", 4, seed=998, skip_seeds=range(999, 1001))
    assert data.metadata["skipped_seeds"] == [999, 1001]
    assert "skipped_seeds" not in identify.record("CartPole-v1", 1, seed=0).metadata
    firsts = _first_observations(data)
    for first, seed in zip(firsts, (998, 1001, 1002, 1003)):  # 999 and 1000 skipped
        alone = identify.record("CartPole-v1", 1, seed=seed)
        np.testing.assert_array_equal(first, _first_observations(alone)[0])
    skipped = identify.record("CartPole-v1", 1, seed=999)
    assert not np.array_equal(firsts[1], _first_observations(skipped)[0])


def test_record_spends_a_budget_of_real_steps():
    task = diffcontrol.make("cartpole")
    data = identify.record("CartPole-v1", None, seed=0, task=task, total_steps=100)
    ends = data.metadata["ends"]
    assert data.num_steps == 100 and data.num_episodes == len(ends) > 2  # random: ~20 steps
    assert ends[-1] == "truncated" and set(ends[:-1]) == {"terminated"}  # the last cut short
    pendulum = diffcontrol.make("pendulum")  # 200-step episodes: 200 steps are one of them
    one = identify.record("Pendulum-v1", 1, seed=0, task=pendulum)
    budget = identify.record("Pendulum-v1", None, seed=0, task=pendulum, total_steps=200)
    assert np.array_equal(one.observations, budget.observations) and budget.num_episodes == 1
    few = identify.record("CartPole-v1", 2, seed=0, task=task, total_steps=1000)
    assert few.num_episodes == 2 and few.num_steps < 1000  # episodes bound it first
    with pytest.raises(ConfigError, match="total_steps must be a positive integer, got 0"):
        identify.record("CartPole-v1", None, total_steps=0)
    with pytest.raises(ConfigError, match="a number of episodes or a budget of steps"):
        identify.record("CartPole-v1", None)


@pytest.mark.slow
def test_compare_real_cartpole_counts_the_loops_real_steps(tmp_path):
    rl = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "compare.json"
    out = tmp_path / "real"
    kw = dict(seeds=1, models=["params"], max_rounds=2, steps={"params": 150}, updates=2)
    doc = run_real_comparison("cartpole", out, final_episodes=3, rl_results=rl, **kw)
    assert doc["threshold"] == 500.0 and doc["steps_per_round"] == {"params": 150}
    assert doc["start"] == {"gravity": 12.0, "length": 0.8, "force_mag": 7.0}  # the task's
    for name in ("comparison.json", "comparison.md", "comparison.png", "runs/params-seed0.json"):
        assert (out / name).stat().st_size > 0
    loop = json.loads((out / "loops" / "params-seed0" / "loop.json").read_text())
    assert "gravity = 12 (nominal 9.8)" in loop["start"]["note"]
    rounds = sorted(loop["rounds"], key=lambda r: r["round"])
    # 2 updates balance nothing: both rounds run, each recording exactly its 150 real steps
    # (random pushes, then round 1's controller with noise, cut at the budget)
    assert [r["real_steps"] for r in rounds] == [150, 300]
    data = identify.read_trajectories(out / "loops" / "params-seed0" / "data.csv")
    assert data.num_steps == 300
    # round 1 records from reset seeds 1000... but skips the evaluation's 1000-1002
    recorded = [out / "loops" / "params-seed0" / f"round_{k}" / "recorded.csv" for k in (0, 1)]
    metadata = [identify.read_trajectories(f).metadata for f in recorded]
    assert [m["skipped_seeds"] for m in metadata] == [[1000, 1003]] * 2
    assert (
        rounds[0]["model_error_on_new_data"]["rmse_1"]
        > 10 * (rounds[1]["model_error_on_new_data"]["rmse_1"])
    )  # the wrong start, then the fit of round 1 on the controller's steps
    assert abs(rounds[-1]["fitted_parameters"]["gravity"] - 9.8) < 0.05
    # the evaluation episodes (a CartPole return is its steps) are not counted
    evaluated = json.loads((out / "loops" / "params-seed0" / "round_2" / "eval.json").read_text())
    assert evaluated["seeds"] == [1000, 1002] and len(evaluated["returns"]) == 3  # first, last
    assert sum(evaluated["returns"]) >= 3  # steps taken on the real system, not in real_steps
    run = next(r for r in doc["runs"] if r["method"] == "diffcontrol (grey box)")
    assert [p["env_steps"] for p in run["curve"]] == [150, 300] and run["env_steps"] == 300
    assert [p["episodes"] for p in run["curve"]] == [0.3, 0.6]  # in 500-step episodes
    ppo = next(r for r in doc["summary"] if r["method"] == "ppo")  # read from --rl-results
    assert [t["threshold"] for t in ppo["thresholds"]] == [475.0, 500.0]
    assert "| ppo (PPO) |" in doc["table"] and "| diffcontrol (grey box)" in doc["table"]
    before = (out / "runs" / "params-seed0.json").read_text()
    again = run_real_comparison("cartpole", out, final_episodes=3, rl_results=rl, resume=True, **kw)
    assert (out / "runs" / "params-seed0.json").read_text() == before  # nothing run twice
    assert (
        again["real_steps_to_threshold"]
        == doc["real_steps_to_threshold"]
        == {"diffcontrol (grey box)": {0: None}}
    )


@pytest.mark.slow
def test_compare_real_fits_ensembles_for_the_network_models_only(tmp_path):
    out = tmp_path / "real"
    kw = dict(seeds=1, max_rounds=1, steps={"params": 150, "hybrid": 250}, updates=2)
    doc = run_real_comparison(
        "cartpole", out, models=["params", "hybrid"], members=2, final_episodes=1,
        fit_steps=50, **kw
    )  # fmt: skip
    assert doc["members"] == 2 and doc["fit_steps"] == 50
    loops = out / "loops"
    hybrid = json.loads((loops / "hybrid-seed0" / "loop.json").read_text())["settings"]
    assert (
        hybrid["members"] == 2
        and "members"
        not in json.loads((loops / "params-seed0" / "loop.json").read_text())["settings"]
    )  # a grey box has no network
    fitted = json.loads((loops / "hybrid-seed0" / "round_1" / "fit" / "fitted.json").read_text())
    assert len(fitted["network"]["members"]) == 2
    assert len(fitted["fit"]["loss_history"]) == 50  # the fit took the steps asked for


class _QuickPlanPendulum(Pendulum):
    """Pendulum whose loop planner is tiny (H = 4, 2 iLQR iterations, no grid): cheap to build;
    its training has no terminal value either, so no round solves a grid (a test's class is
    solved anew for every physics)."""

    def default_config(self):
        return super().default_config().replace(value_grid=0)

    def loop_planner(self):
        from diffcontrol.settings import PlanConfig

        return PlanConfig(horizon=4, iterations=2, bound_starts=False)


def test_a_recording_resets_a_policy_that_has_a_reset_before_every_episode():
    class Counting:
        resets = 0

        def reset(self):
            self.resets += 1

        def __call__(self, obs):
            return np.zeros(1, np.float32)

    counting = Counting()
    noisy = NoisyPolicy(counting, spaces.Box(-2.0, 2.0, (1,), np.float32), 0.1, seed=0)
    identify.record("Pendulum-v1", 3, policy=noisy, max_steps=5)
    assert counting.resets == 3  # through the noise wrapper


def test_compare_real_refuses_an_unknown_controller(tmp_path):
    with pytest.raises(ConfigError, match="--controllers mpc: choose among train,plan"):
        run_real_comparison("pendulum", tmp_path / "r", controllers=("mpc",))


@pytest.mark.slow
def test_compare_real_runs_a_planner_through_the_fitted_model_as_its_own_row(tmp_path):
    out = tmp_path / "real"
    doc = run_real_comparison(
        _QuickPlanPendulum(), out, seeds=1, models=["params"], controllers=("train", "plan"),
        max_rounds=2, steps={"params": 100}, updates=2, final_episodes=2,
    )  # fmt: skip
    assert doc["controllers"] == ["train", "plan"]
    methods = {r["method"] for r in doc["runs"]}
    assert methods == {"diffcontrol (grey box)", "diffcontrol (grey box, planner)"}
    where = out / "loops" / "params-plan-seed0"
    loop = json.loads((where / "loop.json").read_text())
    assert loop["settings"]["controller"] == "plan"
    assert (
        "controller"
        not in json.loads((out / "loops" / "params-seed0" / "loop.json").read_text())["settings"]
    )  # the default is not written: a loop from before it still resumes
    for k in (1, 2):
        doc_k = json.loads((where / f"round_{k}" / "run" / "model.json").read_text())
        assert diffcontrol.policies.is_planner(doc_k)  # a planner, not an MLP, acted
        assert doc_k["controller"]["model"]["kind"] == "fitted"  # through the round's fit
        assert doc_k["controller"]["settings"]["horizon"] == 4  # the task's loop planner
    recorded = identify.read_trajectories(where / "round_1" / "recorded.csv")
    kept = min(loop["rounds"], key=lambda r: r["round"])["kept_round"]  # 1, or 0: nominal
    assert recorded.metadata["source"].startswith(f"round {kept} controller")  # a planner
    rounds = sorted(loop["rounds"], key=lambda r: r["round"])
    assert [r["real_steps"] for r in rounds] == [100, 200]
    assert all(len(r["real_returns"]) == 2 for r in rounds)  # judged on the real system
    assert abs(rounds[-1]["fitted_parameters"]["g"] - 10.0) < 0.05  # from g = 8
    assert rounds[0]["work_seconds"]["train"] > 0  # the planner's build time


def test_evaluation_refuses_a_system_whose_rewards_are_not_numbers(pendulum_run):
    """No return is judged from infinite rewards (a loop's round on such a system included):
    one line naming the environment, the episode and the return."""
    policy, task = diffcontrol.load(pendulum_run), diffcontrol.make("pendulum")
    real = ("test/BrokenPendulum-v0", {"how": "inf"})
    with pytest.raises(ConfigError, match="rewards are not finite numbers") as e:
        diffcontrol.evaluate(policy, task, episodes=2, real=real)
    assert "\n" not in str(e.value) and "episode 0 (reset seed 0)" in str(e.value)


def test_the_pendulums_loop_plans_by_default_and_refuses_a_training_setting(tmp_path, capsys):
    """Where the task's planner does best (the Pendulum) it acts in the loop unless the MLP is
    asked for; ``--updates`` then does not apply, and says so. CartPole and the mountain car
    keep the trained MLP."""
    from diffcontrol.mpc._config import plans_best

    assert [plans_best(diffcontrol.make(n)) for n in ("pendulum", "cartpole")] == [True, False]
    assert not plans_best(diffcontrol.make("mountain-car-continuous"))
    out = tmp_path / "loop"
    argv = ["loop", "pendulum", "--rounds", "1", "--episodes", "1", "--eval-episodes", "2"]
    argv += ["--fit-steps", "5", "--out", str(out), "--quiet"]
    assert main([*argv, "--updates", "3"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("(--controller plan, the default for pendulum): add --controller train, "
                        "or drop --updates") and "\n" not in err, err  # fmt: skip
    assert not out.exists()
    assert main(argv) == 0
    assert json.loads((out / "loop.json").read_text())["settings"]["controller"] == "plan"
    doc = json.loads((out / "round_1" / "run" / "model.json").read_text())
    assert doc["controller"]["type"] == "planner"


def test_a_loop_resumed_without_a_controller_keeps_its_own(tmp_path):
    """A loop that does not name its controller was trained (the default before the planner);
    resumed without --controller it stays so, and a new one plans (the Pendulum)."""
    from diffcontrol.runs._loop import _controller
    from diffcontrol.settings import LoopConfig

    task, unset = diffcontrol.make("pendulum"), LoopConfig()
    (tmp_path / "loop.json").write_text(json.dumps({"settings": {"task": "pendulum"}}))
    assert _controller(task, unset, tmp_path, resume=True) == "train"
    assert _controller(task, unset, tmp_path, resume=False) == "plan"
    (tmp_path / "loop.json").write_text(json.dumps({"settings": {"controller": "plan"}}))
    assert _controller(task, unset, tmp_path, resume=True) == "plan"
    assert _controller(task, LoopConfig(controller="train"), tmp_path, resume=True) == "train"
    (tmp_path / "loop.json").write_text("[1]")  # not a loop's: _start refuses it later
    assert _controller(task, unset, tmp_path, resume=True) == "train"


def test_train_names_the_planner_where_it_does_better(tmp_path):
    """``train`` ends with the planning command where the task's planner beats its MLP (the
    Pendulum), on the physics the MLP was trained for; nothing elsewhere."""
    from diffcontrol.runs._train import _advice

    out = tmp_path / "my run"
    line = _advice(diffcontrol.make("pendulum"), out, ())
    plan = f"diffcontrol plan pendulum --out '{out}-plan'"
    assert line.startswith("a planner does better on pendulum") and line.endswith(plan), line
    assert _advice(diffcontrol.make("pendulum"), out, (("g", 9.0),)) == ""
    for other in ("cartpole", "mountain-car-continuous", "cartpole-swingup"):
        assert _advice(diffcontrol.make(other), out, ()) == "", other


def test_a_round_worse_than_the_kept_one_by_more_than_a_standard_error_is_not_kept():
    """The loop keeps the newer controller unless, on the same evaluation episodes, it does
    worse than the one kept before by more than the standard error of the paired differences;
    the next round is compared with the kept one, not the rejected one."""
    from diffcontrol.runs._loop import kept_round

    def row(k, returns, kept=None):
        return {"round": k, "real_returns": returns, **({"kept_round": kept} if kept else {})}

    first = row(1, [-150.0, -160.0, -140.0])
    assert kept_round([], first) == 1
    assert kept_round([first], row(2, [-151.0, -161.0, -139.0])) == 2  # within noise
    assert kept_round([first], row(2, [-140.0, -150.0, -130.0])) == 2  # better
    worse = row(2, [-250.0, -240.0, -260.0])
    assert kept_round([first], worse) == 1
    rejected = {**worse, "kept_round": 1}
    assert kept_round([first, rejected], row(3, [-155.0, -159.0, -141.0])) == 3
    assert kept_round([first, rejected], row(3, [-200.0, -200.0, -200.0])) == 1
    assert kept_round([first], row(2, None)) == 2  # nothing to compare: the newer
    assert kept_round([first], row(2, [-1.0])) == 2  # other episodes: the newer
    assert kept_round([{"round": 1}], row(2, [-1.0])) == 2  # a row written before the rule
