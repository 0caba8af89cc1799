"""Sweeps: many whole runs as one vmapped program, their directories, and bad input."""

from __future__ import annotations

import json
import math

import jax
import numpy as np
import pytest

import diffcontrol as dc
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError
from diffcontrol.runs import _sweep as runs_sweep
from diffcontrol.training import grid, sweep

TASK = dc.make("cartpole")
TINY = dict(updates=20, eval_every=10, batch=4, window=10, eval_episodes=4, hidden=(8,))
BASE = TASK.default_config().replace(**TINY)


def _max_diff(a, b) -> float:
    pairs = zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
    return max(float(np.max(np.abs(np.asarray(x) - np.asarray(y)))) for x, y in pairs)


# What a member promises against the same run trained alone: its weights to rounding (the
# vmapped program sums in another order), not its CartPole losses and returns bit for bit.
# A push is the sign of the network's output, so where that output lies within rounding of
# zero the two runs push opposite ways once and their episodes part: on some CPUs a point of
# 4 evaluation episodes moved by a step per episode or more (144.25 against 145.25), and a
# chunk's mean training loss by 0.4 % (0.13185 against 0.13130) with the weights still within
# 1e-4. Losses are compared to 2 % and mean returns to 5 %: a few parted episodes pass, a
# member trained with another seed or learning rate (10-100 % apart) does not.
WEIGHTS_ATOL = 1e-4
LOSS_RTOL = 0.02
RETURN_RTOL = 0.05


@pytest.fixture(scope="module")
def swept():
    configs = grid(BASE, [0, 1], {"learning_rate": [1e-2, 3e-3]})
    return configs, sweep(TASK, configs)


def test_grid_orders_settings_outside_seeds():
    configs = grid(BASE, [5, 6], {"learning_rate": [1e-2, 3e-3]})
    assert [(c.seed, c.learning_rate) for c in configs] == [
        (5, 1e-2),
        (6, 1e-2),
        (5, 3e-3),
        (6, 3e-3),
    ]


@pytest.mark.slow
def test_each_member_is_the_run_train_would_make(swept):
    """Same keys, same updates, the member's own learning rate: the controller and curve of
    ``train(task, config)`` up to the order of floating-point sums."""
    configs, result = swept
    assert result.metrics["programs"] == 1 and result.metrics["swept"] == ["seed", "learning_rate"]
    for config, member in zip(configs, result.members, strict=True):
        alone = dc.train(TASK, config)
        assert member.config == config
        assert _max_diff(member.controller, alone.controller) < WEIGHTS_ATOL
        for key, rtol in (("loss", LOSS_RTOL), ("eval_return", RETURN_RTOL)):
            ours = [p[key] for p in member.curve]
            theirs = [p[key] for p in alone.curve]
            np.testing.assert_allclose(ours, theirs, rtol=rtol, err_msg=key)
        assert member.metrics["returned_update"] == alone.metrics["returned_update"]


@pytest.mark.slow
def test_members_differ_by_learning_rate(swept):
    configs, result = swept
    # the same seed with another learning rate: the same start, another controller
    assert _max_diff(result.members[0].controller, result.members[2].controller) > 1e-4
    first = [m.curve[0]["eval_return"] for m in result.members]
    assert first[0] == first[2] and first[1] == first[3]


@pytest.mark.slow
def test_a_shape_setting_makes_a_program_per_value():
    configs = grid(BASE.replace(updates=10), [0], {"hidden": [(8,), (4, 4)]})
    result = sweep(TASK, configs)
    assert result.metrics["programs"] == 2
    assert [m.controller.num_parameters for m in result.members] == [
        dc.train(TASK, c).controller.num_parameters for c in configs
    ]


@pytest.mark.slow
def test_each_member_stops_early_on_its_own():
    configs = grid(BASE.replace(target_return=20.0), [0, 1, 2, 3], {})
    result = sweep(TASK, configs)
    stopped = [m.metrics["stopped_early"] for m in result.members]
    assert any(stopped) and not all(stopped)  # the test means something
    for config, member in zip(configs, result.members, strict=True):
        alone = dc.train(TASK, config)
        assert member.metrics["stopped_early"] == alone.metrics["stopped_early"]
        assert member.metrics["updates"] == alone.metrics["updates"]


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: sweep(dc.make("cartpole-swingup"), [BASE]), "continuous-time"),
        (lambda: sweep(TASK, [BASE.replace(population=2)]), "population 1"),
        (lambda: sweep(TASK, []), "at least one"),
        (lambda: sweep(TASK, [BASE], devices=99), r"got 99"),
        (lambda: grid(BASE, [0], {"nope": [1]}), "cannot sweep 'nope'"),
        (lambda: grid(BASE, [0], {"learning_rate": []}), "non-empty list"),
        (lambda: grid(BASE, [], {}), "at least one seed"),
        (lambda: grid(BASE, range(70_000), {}), "more than 65,536"),
        (lambda: grid(BASE, [0], {"learning_rate": [-1.0]}), "learning_rate"),
    ],
)
def test_bad_sweeps_are_one_line(make, message):
    with pytest.raises(ConfigError, match=message) as e:
        make()
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    "text, seeds", [("0-3", [0, 1, 2, 3]), ("7", [7]), ("0,3,7", [0, 3, 7]), ("0-1,5", [0, 1, 5])]
)
def test_seed_lists(text, seeds):
    assert runs_sweep.parse_seeds(text) == seeds


@pytest.mark.parametrize("text", ["3-1", "a", "-1", "0,0", "1e23", "0-1e9", ""])
def test_bad_seed_lists(text):
    with pytest.raises(ConfigError, match="--seeds"):
        runs_sweep.parse_seeds(text)


def test_setting_values_have_their_types():
    values = runs_sweep.parse_values(
        ["learning_rate=1e-3,3e-3", "hidden=8x8,16", "keep_best=no"], BASE
    )
    assert values == {
        "learning_rate": [1e-3, 3e-3],
        "hidden": [(8, 8), (16,)],
        "keep_best": [False],
    }


@pytest.mark.parametrize(
    "item, message",
    [
        ("learning_rate=x", "takes a number"),
        ("learning_rate=-1", "learning_rate must be"),
        ("updates=1.5", "takes an integer"),
        ("hidden=8,a", "layer widths"),
        ("seed=1,2", "--seeds"),
        ("nope=1", "NAME one of"),
        ("learning_rate", "NAME=V1,V2"),
    ],
)
def test_bad_setting_values(item, message):
    with pytest.raises(ConfigError, match=message):
        runs_sweep.parse_values([item], BASE)


def _cli_tiny() -> list[str]:
    return ["--updates", "20", "--eval-every", "10", "--batch", "4", "--window", "10",
            "--eval-episodes", "4", "--hidden", "8", "--final-eval", "2", "--quiet"]  # fmt: skip


@pytest.mark.slow
def test_sweep_directory_resume_and_load(tmp_path):
    out = tmp_path / "sweep"
    args = [
        "sweep",
        "cartpole",
        "--out",
        str(out),
        "--seeds",
        "0-1",
        "--set",
        "learning_rate=1e-2,3e-3",
    ]
    assert main([*args, *_cli_tiny()]) == 0
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["complete"] and len(doc["members"]) == 4
    assert (out / "sweep.png").stat().st_size > 0
    table = (out / "sweep.txt").read_text()
    assert "best" in table and all(name in table for name in doc["members"])
    best = out / doc["best"]
    assert "evaluation" in json.dumps(json.loads((best / "metrics.json").read_text()))
    # every member loads and acts
    for name in doc["members"]:
        policy = dc.load(out / name)
        assert policy(np.zeros(4)) in (0, 1)
    # a lost member is trained again on resume, and only it; the others are untouched
    lost = out / doc["members"][3]
    before = json.loads((lost / "metrics.json").read_text())["final_eval_return"]
    weights_before = dc.load(lost)
    kept = (out / doc["members"][0] / "model.json").read_bytes()
    for f in lost.iterdir():
        f.unlink()
    lost.rmdir()
    assert main(["sweep", "--out", str(out), "--resume", "--quiet"]) == 0
    after = json.loads((lost / "metrics.json").read_text())["final_eval_return"]
    assert _max_diff(weights_before._layers, dc.load(lost)._layers) < WEIGHTS_ATOL
    assert math.isclose(before, after, rel_tol=RETURN_RTOL)
    assert (out / doc["members"][0] / "model.json").read_bytes() == kept
    # a member whose model.json is garbage (its run.json still complete) is trained again too
    damaged = out / doc["members"][2]
    weights_before = dc.load(damaged)
    (damaged / "model.json").write_text("garbage")
    stored = json.loads((out / "sweep.json").read_text())
    stored.pop("complete")
    (out / "sweep.json").write_text(json.dumps(stored))
    assert main(["sweep", "--out", str(out), "--resume", "--quiet"]) == 0
    assert _max_diff(weights_before._layers, dc.load(damaged)._layers) < WEIGHTS_ATOL
    # not a new sweep into a used directory
    assert main([*args, *_cli_tiny()]) == 2


def test_failed_sweep_gives_the_directory_back(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", "cartpole-swingup", "--out", str(out)]) == 2
    assert not out.exists()
    assert "continuous-time" in capsys.readouterr().err
    assert main(["sweep", "--out", str(out), "--resume"]) == 2
    assert "no sweep to resume" in capsys.readouterr().err


def test_the_library_sweep_caps_its_members_as_the_command_does():
    """More members than one program takes are refused before anything is built (the CLI's
    65,536, for the library's sweep() too)."""
    from diffcontrol.training import _sweep

    task = dc.make("pendulum")
    configs = [task.default_config()] * (_sweep.MAX_MEMBERS + 1)
    with pytest.raises(ConfigError, match="65,537 members is more than 65,536"):
        dc.sweep(task, configs)
