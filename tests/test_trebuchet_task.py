"""The trebuchet aiming task: reachability, direct aiming, learning, and the CLI end to end."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol import policies
from diffcontrol.builtin.trebuchet import system as tb
from diffcontrol.builtin.trebuchet import task as aim
from diffcontrol.builtin.trebuchet.judge import evaluate_aiming
from diffcontrol.builtin.trebuchet.task import RefinedAimingPolicy, shoot_in_chunks
from diffcontrol.cli import main
from diffcontrol.errors import ModelFileError
from diffcontrol.training import resolve_config, train

shoot = jax.jit(tb.shoot)
aim_directly = jax.jit(aim.aim_directly)
TINY = ["--updates", "20", "--final-eval", "50"]


@pytest.fixture(scope="module")
def trebuchet_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "trebuchet"
    assert main(["train", "trebuchet", "--out", str(out), "--quiet", *TINY]) == 0
    return out


def test_reset_draws_the_original_situations():
    task = diffcontrol.make("trebuchet")
    keys = jax.random.split(jax.random.key(0), 4000)
    states = np.asarray(jax.jit(jax.vmap(task.reset, in_axes=(0, None)))(keys, None))
    target, wind, distance = states.T
    assert target.min() >= 20 and target.max() <= 100
    assert abs(np.mean(target) - 60) < 1.5 and abs(np.std(target) - 80 / np.sqrt(12)) < 1.0
    assert abs(np.mean(wind)) < 0.3 and abs(np.std(wind) - 5.0) < 0.2
    assert np.all(np.abs(wind) <= 20) and np.all(distance == 0)


@pytest.mark.slow
def test_reachable_range_brackets_what_the_heads_can_throw():
    winds = np.array([-12.0, -3.0, 0.0, 4.0, 10.0])
    shortest, longest = (np.asarray(x) for x in aim.reachable_range(winds))
    assert np.all(shortest < 20) and np.all(np.diff(longest) > 0)  # a tail wind carries further
    # No angle/weight inside the bounds beats the longest throw (a coarse grid, all winds).
    a, w = np.meshgrid(np.linspace(5, 85, 33), np.linspace(30, 450, 15), indexing="ij")
    grid = np.asarray(shoot(winds[:, None, None], a[None], w[None]))
    assert np.all(grid.max(axis=(1, 2)) <= longest + 1e-3)
    assert np.all(grid.max(axis=(1, 2)) >= longest - 0.5)  # and the search is not far off
    assert np.all(grid.min(axis=(1, 2)) >= shortest - 0.5)


@pytest.mark.slow  # compiles a throw program of its own: about 5 s
def test_evaluation_throws_share_one_compiled_program(monkeypatch):
    """``shoot_in_chunks`` keeps the broadcast shape, pads without leaking, and every batch
    size and the reachability search trace (so compile) one program."""
    traces = []

    def counted(*args):
        traces.append(jax.tree.map(np.shape, args))
        return tb.shoot(*args)

    monkeypatch.setattr(aim, "_SHOOT", jax.jit(counted))
    rng = np.random.default_rng(3)
    wind, angle = rng.normal(0, 5, (7, 1)), rng.uniform(20, 60, 150)
    distance = aim.shoot_in_chunks(wind, angle, 250.0)  # 1,050 throws: a padded second call
    assert distance.shape == (7, 150) and distance.dtype == np.float64
    np.testing.assert_allclose(distance, np.asarray(shoot(wind, angle, 250.0)), atol=0.01)
    assert aim.shoot_in_chunks(wind[0, 0], angle[0], 250.0).shape == ()
    shortest, longest = aim.reachable_range(np.array([-3.0, 0.0, 4.0]))
    assert shortest.shape == longest.shape == (3,) and np.all(np.diff(longest) > 0)
    assert len(traces) == 1, traces


@pytest.mark.slow
def test_direct_aiming_hits_reachable_targets():
    target = np.array([25.0, 50.0, 80.0, 95.0])
    wind = np.array([3.0, -5.0, -2.0, 4.0])
    # one target a call, as `diffcontrol aim --direct` calls it: the same compiled program
    aims = [aim_directly(float(t), float(w)) for t, w in zip(target, wind, strict=True)]
    angle, weight, miss = np.asarray(aims, np.float64).T
    assert np.all(np.abs(miss) < 0.01), miss
    assert np.all((angle >= 5) & (angle <= 85) & (weight >= 30) & (weight <= 450))
    np.testing.assert_allclose(np.asarray(shoot(wind, angle, weight)), target, atol=0.01)


@pytest.mark.slow
def test_aiming_network_learns_on_a_small_budget():
    """300 updates of 64 throws (a seventh of the default) take the mean miss over the
    reachable targets from tens of metres to under a metre."""
    task = diffcontrol.make("trebuchet")
    result = train(task, resolve_config(task, updates=300))  # the CLI tests' programs
    assert result.curve[0]["eval_return"] < -10
    policy = policies.AimingPolicy(policies.controller_to_dict(result.controller, task))
    stats = evaluate_aiming(policy, task, targets=300, seed=1).stats
    assert stats["reachable"] > 250 and stats["mean_miss_m"] < 1.0, stats


@pytest.mark.slow
def test_check_target_names_the_reachable_range():
    aim.check_target(60.0, 0.0)
    with pytest.raises(diffcontrol.ConfigError, match=r"out of reach.*reaches"):
        aim.check_target(150.0, -10.0)
    with pytest.raises(diffcontrol.ConfigError, match="positive"):
        aim.check_target(-5.0, 0.0)
    with pytest.raises(diffcontrol.ConfigError, match="finite"):
        aim.check_target(60.0, float("nan"))


@pytest.mark.slow
def test_cli_train_writes_everything_and_load_aims(trebuchet_run):
    for name in ("model.json", "metrics.json", "learning_curve.png", "rollout.png", "rollout.gif"):
        assert (trebuchet_run / name).stat().st_size > 0, name
    metrics = json.loads((trebuchet_run / "metrics.json").read_text())
    ev = metrics["aim_eval"]
    assert ev["targets"] == 50 and ev["reachable"] + ev["unreachable"] == 50
    assert ev["median_miss_m"] <= ev["p95_miss_m"] <= ev["worst_miss_m"]
    assert metrics["simulated_episodes"] == 20 * resolve_config(diffcontrol.make("trebuchet")).batch

    policy = diffcontrol.load(trebuchet_run)
    assert isinstance(policy, diffcontrol.policies.AimingPolicy)
    angle, weight = policy(80.0, -3.0)
    assert isinstance(angle, float) and 5 <= angle <= 85 and 30 <= weight <= 450
    angles, weights = policy(np.array([30.0, 60.0, 90.0]), np.array([0.0, 2.0, -2.0]))
    assert angles.shape == weights.shape == (3,)
    assert (angles[1], weights[1]) == pytest.approx(policy(60.0, 2.0))
    # The network (NumPy) is the JAX controller; the policy refines its aim through the
    # simulator (two Gauss-Newton steps), which lands the throw closer than the network's aim
    assert isinstance(policy, RefinedAimingPolicy) and policy.iterations == 2
    network = policy.network_action(np.array([80.0, -3.0]))
    controller = policies.controller_from_dict(policies.read_model(trebuchet_run))
    np.testing.assert_allclose(np.asarray(controller(np.array([80.0, -3.0]))), network, rtol=1e-5)
    miss = lambda aim: abs(float(shoot_in_chunks(-3.0, *aim)) - 80.0)  # noqa: E731
    assert miss((angle, weight)) < min(0.05, miss(network)), (miss((angle, weight)), network)


@pytest.mark.slow
def test_the_throws_gif_plays_in_real_time_and_holds_the_landing(trebuchet_run):
    from PIL import Image

    with Image.open(trebuchet_run / "rollout.gif") as gif:
        durations = []
        for i in range(gif.n_frames):
            gif.seek(i)
            durations.append(gif.info["duration"])
    # 30 frames a second (GIF stores centiseconds), the landing held for about 1 s
    assert len(durations) > 30 and set(durations[:-1]) <= {30, 40}, durations
    assert 950 <= durations[-1] <= 1100, durations[-1]


@pytest.mark.slow
def test_cli_aim_evaluate_animate(trebuchet_run, capsys, tmp_path):
    assert main(["aim", str(trebuchet_run), "--target", "70", "--wind", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    angle, weight = diffcontrol.load(trebuchet_run)(70.0, 2.0)
    assert out["angle_deg"] == pytest.approx(angle) and out["weight_lb"] == pytest.approx(weight)
    distance = float(shoot(2.0, angle, weight))
    assert out["miss_m"] == pytest.approx(distance - 70.0, abs=1e-3)

    assert main(["aim", str(trebuchet_run), "--target", "70", "--direct"]) == 0
    text = capsys.readouterr().out
    assert "network:" in text and "direct:" in text

    assert main(["evaluate", str(trebuchet_run), "--episodes", "40", "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    ref = evaluate_aiming(diffcontrol.load(trebuchet_run), diffcontrol.make("trebuchet"), 40)
    assert ev["targets"] == 40 and ev["mean_miss_m"] == pytest.approx(ref.stats["mean_miss_m"])

    gif = tmp_path / "throw.gif"
    assert main(["animate", str(trebuchet_run), "--out", str(gif), "--target", "50"]) == 0
    assert gif.stat().st_size > 0


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--target", "150", "--wind", "-10"], "out of reach"),
        (["--target", "-3"], "positive"),
        (["--target", "nan"], "--target"),
    ],
)
@pytest.mark.slow
def test_cli_aim_bad_targets(trebuchet_run, capsys, argv, needle):
    try:
        status = main(["aim", str(trebuchet_run), *argv])
    except SystemExit as e:  # argparse rejects non-numbers before the command runs
        status = e.code
    assert status == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_cli_aim_needs_an_aiming_run(cartpole_run, capsys):
    assert main(["aim", str(cartpole_run), "--target", "50"]) == 2
    assert "needs an aiming task" in capsys.readouterr().err


@pytest.mark.parametrize(
    "refine",
    [{"method": "newton", "iterations": 2}, {"method": "gauss-newton", "iterations": 99}, 2],
)
def test_a_bad_refinement_in_the_file_is_refused_by_name(trebuchet_run, tmp_path, refine):
    doc = json.loads((trebuchet_run / "model.json").read_text())
    (tmp_path / "model.json").write_text(json.dumps({**doc, "refine": refine}))
    with pytest.raises(ModelFileError, match="refine .* is not Gauss-Newton with 0-50 iterations"):
        diffcontrol.load(tmp_path)
    doc["metadata"]["config"]["params"] = [["drag_coefficient", "much"]]
    (tmp_path / "model.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="training params .* not \\(name, number\\) pairs"):
        diffcontrol.load(tmp_path)


def test_the_export_is_the_network_and_says_the_refinement_is_left_out(
    trebuchet_run, tmp_path, capsys
):
    assert main(["export", str(trebuchet_run), "--out", str(tmp_path / "aim.onnx")]) == 0
    assert "the network alone: its refinement through the simulator" in capsys.readouterr().out
