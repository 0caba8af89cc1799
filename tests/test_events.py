"""``--log-dir``: training curves as TensorBoard event files, read back here record by record
(the TFRecord framing and tensorboardX's own ``Event`` protocol buffer)."""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
from tensorboardX.proto.event_pb2 import Event

from diffcontrol.cli import main
from diffcontrol.config import TrainConfig
from diffcontrol.training import _sweep
from diffcontrol.training._events import learning_rates

TINY = ["--updates", "6", "--window", "10", "--batch", "4", "--eval-every", "3"]
TINY += ["--eval-episodes", "2", "--final-eval", "0", "--quiet"]


def read_scalars(run_dir: Path) -> dict[str, dict[int, float]]:
    """Every scalar in the event files of ``run_dir``: tag -> {step: value}."""
    scalars: dict[str, dict[int, float]] = {}
    files = sorted(run_dir.glob("events.out.tfevents.*"))
    assert files, f"no event file in {run_dir}"
    for path in files:
        data, i = path.read_bytes(), 0
        while i < len(data):
            (length,) = struct.unpack("<Q", data[i : i + 8])
            event = Event.FromString(data[i + 12 : i + 12 + length])
            i += 12 + length + 4  # length, its CRC, the record, its CRC
            for value in event.summary.value:
                scalars.setdefault(value.tag, {})[event.step] = value.simple_value
    return scalars


def test_train_logs_every_update_and_evaluation_point(tmp_path):
    logs = tmp_path / "logs"
    out = tmp_path / "run"
    argv = ["train", "pendulum", "--out", str(out), "--log-dir", str(logs), "--no-animation"]
    assert main([*argv, *TINY]) == 0
    scalars = read_scalars(logs)
    for tag in ("train/loss", "train/grad_norm", "train/learning_rate"):
        assert sorted(scalars[tag]) == [1, 2, 3, 4, 5, 6], tag
    curve = json.loads((out / "metrics.json").read_text())["curve"]
    assert sorted(scalars["eval/return"]) == [p["update"] for p in curve] == [0, 3, 6]
    for point in curve:
        assert scalars["eval/return"][point["update"]] == pytest.approx(point["eval_return"])
    for point in curve[1:]:  # the curve's loss is the mean of its chunk's updates
        chunk = [scalars["train/loss"][u] for u in range(point["update"] - 2, point["update"] + 1)]
        assert np.mean(chunk) == pytest.approx(point["loss"], rel=1e-5)
    config = TrainConfig.from_json(json.loads((out / "run.json").read_text())["config"])
    rates = learning_rates(config, 0, 6)
    assert [scalars["train/learning_rate"][u] for u in range(1, 7)] == pytest.approx(rates)
    assert len(set(rates)) > 1, "the default schedule should change the rate"


@pytest.mark.slow
def test_a_sweep_logs_a_run_per_member_or_their_summary(tmp_path, monkeypatch):
    logs = tmp_path / "logs"
    argv = ["sweep", "pendulum", "--seeds", "0-1", "--out", str(tmp_path / "s"), *TINY]
    assert main([*argv, "--log-dir", str(logs)]) == 0
    members = sorted(p.name for p in logs.iterdir())
    assert members == sorted(p.name for p in (tmp_path / "s").iterdir() if p.is_dir())
    for name in members:
        scalars = read_scalars(logs / name)
        assert sorted(scalars["train/loss"]) == [1, 2, 3, 4, 5, 6]
        assert sorted(scalars["eval/return"]) == [0, 3, 6]
    monkeypatch.setattr(_sweep, "LOGGED_MEMBERS", 1)  # more members than logged one by one
    argv[-len(TINY) - 1] = str(tmp_path / "s2")
    assert main([*argv, "--log-dir", str(tmp_path / "logs2")]) == 0
    assert [p.name for p in (tmp_path / "logs2").iterdir()] == ["summary"]
    scalars = read_scalars(tmp_path / "logs2" / "summary")
    assert sorted(scalars["train/loss"]) == [1, 2, 3, 4, 5, 6]
    for tag in ("eval/return_median", "eval/return_max", "eval/return_min"):
        assert sorted(scalars[tag]) == [0, 3, 6]


@pytest.mark.slow
def test_the_loop_logs_each_round(tmp_path):
    logs, out = tmp_path / "logs", tmp_path / "loop"
    argv = ["loop", "pendulum", "--rounds", "2", "--episodes", "1", "--updates", "3"]
    argv += ["--eval-episodes", "2", "--out", str(out), "--quiet", "--log-dir", str(logs)]
    argv += ["--controller", "train"]  # the MLP's training, not the default planner
    assert main(argv) == 0
    doc = json.loads((out / "loop.json").read_text())
    rounds = [doc["nominal"], *doc["rounds"]]  # round 0: the nominal controller's
    scalars = read_scalars(logs)
    assert sorted(scalars["loop/real_return"]) == [0, 1, 2]
    for row in rounds:
        assert scalars["loop/real_return"][row["round"]] == pytest.approx(row["real_return"])
        assert scalars["loop/real_steps"][row["round"]] == row["real_steps"]
        assert sorted(read_scalars(logs / f"round_{row['round']}")["train/loss"]) == [1, 2, 3]


def test_without_tensorboardx_one_line_and_nothing_written(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "tensorboardX", None)  # as if not installed
    out = tmp_path / "run"
    argv = ["train", "pendulum", "--out", str(out), "--log-dir", str(tmp_path / "l"), *TINY]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'pip install "diffcontrol[tensorboard]"' in err
    assert not out.exists() and not (tmp_path / "l").exists()
