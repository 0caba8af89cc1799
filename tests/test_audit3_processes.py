"""Audit 3's cases that need a process of their own: an environment module typed on the
command line and found in the current directory (the console script, unlike ``python -m``,
does not put it on ``sys.path``), a file-size limit while ``plan`` writes, and SIGKILL while a
loop's planner is being built. The command of each case runs as ``python -P -m
diffcontrol.cli`` (``-P`` keeps the current directory off ``sys.path``, as the console script
does); what follows it runs in this process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from diffcontrol.cli import main

from ._cli import one_line

REAL_ENVS = """
import gymnasium
from gymnasium.envs.classic_control.pendulum import PendulumEnv

gymnasium.register("Raising-v0", entry_point=PendulumEnv, max_episode_steps=20)
"""


def _cli(*argv, cwd: Path, check: bool = True, **kwargs) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-P", "-m", "diffcontrol.cli", *map(str, argv)]
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, **kwargs)
    if check:
        assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


@pytest.mark.slow  # a recording in a process of its own, a fit: about 8 s on one core
def test_an_environment_module_typed_on_the_command_line_is_found_in_the_current_directory(
    tmp_path, capsys
):
    """new-loop-04: ``record my_module:Env-v0`` as the docs show it, run from the directory
    that holds ``my_module.py``; the id read back from the data file alone imports nothing
    (the file names it, the user did not), and ``fit --env`` names it as the user trusts it."""
    (tmp_path / "realenvs.py").write_text(REAL_ENVS)
    env = "realenvs:Raising-v0"
    _cli("record", env, "--task", "pendulum", "--episodes", "10", "--out", "d.csv", cwd=tmp_path)
    data = tmp_path / "d.csv"
    assert json.loads(data.read_text().splitlines()[0][2:])["metadata"]["env_id"] == env
    fit = ["fit", "pendulum", "--data", data, "--model", "params", "--steps", "2"]
    fit += ["--lm-steps", "1", "--quiet", "--out"]
    one_line(capsys, [*fit, tmp_path / "f0"], f"pass --env {env} explicitly")
    one_line(capsys, [*fit, tmp_path / "f0", "--env", "Pendulum-v1"], "is not the environment")
    assert not (tmp_path / "f0").exists() and "realenvs" not in sys.modules
    assert main([str(a) for a in [*fit, tmp_path / "f1", "--env", env]]) == 0
    assert json.loads((tmp_path / "f1" / "fitted.json").read_text())["data"]["env_id"] == env


@pytest.mark.slow  # a plan cut short and run again: about 10 s on one core
def test_a_file_size_limit_while_plan_writes_leaves_nothing_and_the_command_runs_again(
    tmp_path,
):
    """new-disk-06: EFBIG while ``plan`` writes its pictures gives the directory back, says
    to run the command again, and that command succeeds."""
    argv = ["plan", "pendulum", "--out", "plan", "--final-eval", "2", "--horizon", "5"]
    cmd = " ".join([sys.executable, "-P", "-m", "diffcontrol.cli", *argv])
    proc = subprocess.run(
        ["bash", "-c", f"ulimit -f 40; exec {cmd}"], cwd=tmp_path, capture_output=True, text=True
    )
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "run the command again" in lines[0], proc.stderr
    assert not (tmp_path / "plan").exists()
    out = tmp_path / "plan"
    assert main([*argv[:2], "--out", str(out), *argv[4:], "--quiet", "--no-animation"]) == 0
    assert (out / "model.json").exists()


@pytest.mark.slow  # a loop killed while its planner is built, then resumed: about 25 s
def test_a_loop_killed_while_its_planner_is_built_resumes(tmp_path):
    """new-loop-28: SIGKILL leaves round 1's run.json and nothing else of its planner;
    ``loop --resume`` builds the planner and finishes. The real pendulum is heavier than the
    nominal one, so that round 1's planner solves its terminal value anew (a planner of the
    nominal physics is already solved in the process, by round 0, and is built at once)."""
    argv = ["loop", "pendulum", "--out", "lp", "--controller", "plan", "--rounds", "1"]
    argv += ["--episodes", "1", "--fit-steps", "2", "--eval-episodes", "1", "--quiet"]
    argv += ["--env", "diffcontrol/PendulumFriction-v0", "--env-arg", "g=12"]
    cmd = [sys.executable, "-P", "-m", "diffcontrol.cli", *argv]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    claim = tmp_path / "lp" / "round_1" / "run" / "run.json"
    deadline = time.monotonic() + 240
    while not claim.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert claim.exists() and proc.poll() is None, "the planner was not being built"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (claim.parent / "model.json").exists()
    out = str(tmp_path / "lp")
    assert main([*argv[:2], "--out", out, *argv[4:], "--resume"]) == 0
    loop = json.loads((tmp_path / "lp" / "loop.json").read_text())
    assert [r["round"] for r in loop["rounds"]] == [1]
    assert json.loads((claim.parent / "model.json").read_text())["controller"]["type"] == "planner"
