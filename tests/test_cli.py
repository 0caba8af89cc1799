"""The command line end to end on tiny budgets, and every bad input it must refuse cleanly."""

from __future__ import annotations

import json
import os

import gymnasium
import numpy as np
import pytest

import diffcontrol
from diffcontrol._jax_setup import GC_THRESHOLDS
from diffcontrol.cli import main

from .conftest import TINY_CARTPOLE


def test_list_names_every_task(capsys):
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == diffcontrol.list_tasks()
    assert {"pendulum", "cartpole"} <= set(diffcontrol.list_tasks())


def test_help_explains_each_command(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("list", "train", "evaluate", "animate"):
        assert command in out
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    for option in (
        "--window",
        "--horizon",
        "--batch",
        "--grad-clip",
        "--lr-schedule",
        "--resume",
        "--seed",
    ):
        assert option in out


@pytest.mark.slow
@pytest.mark.parametrize("run", ["cartpole_run", "pendulum_run"])
def test_train_writes_every_output(run, request):
    out = request.getfixturevalue(run)
    for name in (
        "model.json",
        "metrics.json",
        "learning_curve.png",
        "rollout.png",
        "rollout.gif",
        "run.json",
    ):
        assert (out / name).stat().st_size > 0, name
    metrics = json.loads((out / "metrics.json").read_text())
    cfg = metrics["config"]
    assert metrics["simulated_steps"] == cfg["updates"] * cfg["window"] * cfg["batch"]
    assert metrics["simulated_episodes"] == pytest.approx(
        metrics["simulated_steps"] / metrics["episode_length"]
    )
    assert metrics["train_seconds"] >= metrics["compile_seconds"] > 0
    assert [p["update"] for p in metrics["curve"]][0] == 0
    assert metrics["curve"][-1]["update"] == cfg["updates"]
    assert metrics["gym_eval"]["episodes"] == len(metrics["gym_eval"]["returns"])
    assert (out / "rollout.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "rollout.gif").read_bytes()[:6] == b"GIF89a"


@pytest.mark.slow
def test_evaluate_prints_json_on_gymnasium_seeds(cartpole_run, capsys):
    assert main(["evaluate", str(cartpole_run), "--episodes", "3", "--seed", "5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["env_id"] == "CartPole-v1"
    assert result["seeds"] == [5, 7] and len(result["returns"]) == 3
    # The same seeds by hand in Gymnasium's own environment give the same returns.
    policy = diffcontrol.load(cartpole_run)
    env = gymnasium.make("CartPole-v1")
    for i, expected in enumerate(result["returns"]):
        obs, _ = env.reset(seed=5 + i)
        total, done = 0.0, False
        while not done:
            obs, r, term, trunc, _ = env.step(policy(obs))
            total += r
            done = term or trunc
        assert total == expected
    assert result["mean_return"] == pytest.approx(np.mean(result["returns"]))


@pytest.mark.slow
def test_evaluate_human_readable(pendulum_run, capsys):
    assert main(["evaluate", str(pendulum_run), "--episodes", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Pendulum-v1: return") and "±" in out


def test_animate_rerenders(cartpole_run, tmp_path, capsys):
    gif = tmp_path / "again.gif"
    assert main(["animate", str(cartpole_run), "--out", str(gif), "--seed", "3"]) == 0
    assert gif.read_bytes()[:6] == b"GIF89a"
    assert str(gif) in capsys.readouterr().out


# --- bad input: one line naming the problem, exit status 2, nothing overwritten -----------------


def _fails_cleanly(capsys, argv, *needles):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err
    return err


def _usage_fails_cleanly(capsys, argv, *needles):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2
    assert len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err


def test_unknown_task(capsys, tmp_path):
    _fails_cleanly(
        capsys, ["train", "pendulm", "--out", str(tmp_path / "x")], "'pendulm'", "pendulum"
    )
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "option, value, needle",
    [
        ("--window", "0", "--window"),
        ("--window", "-3", "--window"),
        ("--horizon", "-1", "--horizon"),
        ("--updates", "many", "--updates"),
        ("--learning-rate", "nan", "--learning-rate"),
        ("--learning-rate", "inf", "--learning-rate"),
        ("--hidden", "64,x", "--hidden"),
        ("--param", "g", "--param"),
        ("--keep-best", "maybe", "--keep-best"),
        ("--final-window", "-1", "--final-window"),
        ("--value-grid", "1002", "--value-grid"),
        ("--learning-rate", "-0.1", "--learning-rate"),
        ("--lr-schedule", "wavy", "--lr-schedule"),
        ("--final-window-fraction", "0", "--final-window-fraction"),
    ],
)
def test_bad_option_values(capsys, tmp_path, option, value, needle):
    _usage_fails_cleanly(
        capsys, ["train", "pendulum", "--out", str(tmp_path / "x"), option, value], needle
    )
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--loss", "nope"], "'nope'"),
        (["--param", "gravity=3"], "'gravity'"),
        (["--recipe", "fancy"], "'fancy'"),
        (["--value-grid", "2"], "value_grid"),
    ],
)
def test_bad_settings(capsys, tmp_path, args, needle):
    _fails_cleanly(capsys, ["train", "pendulum", "--out", str(tmp_path / "x"), *args], needle)
    assert not (tmp_path / "x").exists()


def test_missing_and_corrupt_model(capsys, tmp_path):
    _fails_cleanly(capsys, ["evaluate", str(tmp_path)], "model.json", "does not exist")
    (tmp_path / "model.json").write_text("{not json")
    _fails_cleanly(capsys, ["evaluate", str(tmp_path)], "not valid JSON")
    (tmp_path / "model.json").write_text(json.dumps({"format": "diffcontrol-model", "version": 99}))
    _fails_cleanly(capsys, ["animate", str(tmp_path)], "version 99")


def test_out_dir_not_writable(capsys, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    _fails_cleanly(capsys, ["train", "cartpole", "--out", str(blocker / "sub")], "--out")
    _fails_cleanly(capsys, ["train", "cartpole", "--out", str(blocker)], "is a file")
    assert blocker.read_text() == "x"


def test_out_dir_with_a_different_run_is_left_alone(capsys, cartpole_run):
    before = {p.name: p.read_bytes() for p in cartpole_run.iterdir()}
    _fails_cleanly(
        capsys, ["train", "cartpole", "--out", str(cartpole_run)], "already holds a run", "--resume"
    )
    _fails_cleanly(
        capsys,
        ["train", "cartpole", "--out", str(cartpole_run), "--resume", "--window", "4"],
        "different run",
        "window",
    )
    _fails_cleanly(
        capsys, ["train", "pendulum", "--out", str(cartpole_run), "--resume"], "different run"
    )
    after = {p.name: p.read_bytes() for p in cartpole_run.iterdir()}
    assert before == after


def test_out_dir_with_other_files(capsys, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    _fails_cleanly(capsys, ["train", "cartpole", "--out", str(tmp_path)], "not empty")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_resume_without_a_run(capsys, tmp_path):
    _fails_cleanly(
        capsys,
        ["train", "cartpole", "--out", str(tmp_path / "new"), "--resume"],
        "nothing to resume",
    )


def test_resume_of_a_finished_run_keeps_its_result(capsys, tmp_path):
    out = tmp_path / "run"
    assert (
        main(["train", "cartpole", "--out", str(out), "--quiet", "--no-animation", *TINY_CARTPOLE])
        == 0
    )
    model = (out / "model.json").read_text()
    capsys.readouterr()
    assert (
        main(["train", "cartpole", "--out", str(out), "--resume", "--quiet", "--no-animation"]) == 0
    )
    assert json.loads((out / "model.json").read_text())["network"] == json.loads(model)["network"]


def test_files_are_written_with_normal_permissions(cartpole_run):
    mode = (cartpole_run / "model.json").stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask


@pytest.mark.slow  # three fresh interpreters that import diffcontrol: 1.3 s on one core
def test_the_console_script_freezes_the_collector_then_exits_normally(tmp_path):
    """``cli.run`` (the console script) runs the command with the collector at
    ``GC_THRESHOLDS``, freezes the objects made so far out of it, so that the shutdown's last
    collections skip them, and leaves the exit itself to Python: the status, the output and a
    failed write of it are as before."""
    import resource
    import signal
    import subprocess
    import sys

    script = tmp_path / "script.py"
    script.write_text(
        "import atexit, gc, sys\n"
        "from diffcontrol import cli\n"
        "atexit.register(lambda: print('frozen:', gc.get_freeze_count() > 0))\n"
        "atexit.register(lambda: print('thresholds:', *gc.get_threshold()))\n"
        "sys.argv = ['diffcontrol', 'list']\n"
        "sys.exit(cli.run())\n"
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[0] == diffcontrol.list_tasks()[0]
    # the thresholds it ran under (the atexit functions run last registered, first)
    thresholds = " ".join(map(str, GC_THRESHOLDS))
    assert done.stdout.endswith(f"thresholds: {thresholds}\nfrozen: True\n")
    cmd = [sys.executable, "-m", "diffcontrol.cli"]
    bad = subprocess.run([*cmd, "train", "no-such-task", "--out", str(tmp_path / "r")],
                         capture_output=True, text=True)  # fmt: skip
    assert bad.returncode == 2
    assert "no-such-task" in bad.stderr and "Traceback" not in bad.stderr

    def no_room():  # the output's file may not grow: its write fails, as on a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    with open(tmp_path / "listing.txt", "w") as out:
        full = subprocess.run([*cmd, "list"], stdout=out, stderr=subprocess.PIPE,
                              preexec_fn=no_room, env=env, text=True)  # fmt: skip
    assert full.returncode != 0, "a lost output must not end with status 0"
