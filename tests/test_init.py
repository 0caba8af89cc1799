"""``train --init RUN_DIR``: a run that starts from another run's trained controller."""

from __future__ import annotations

import json

import pytest

from diffcontrol.cli import main

from .conftest import TINY_CARTPOLE, TINY_SWINGUP

SAME_SETTINGS = {"cartpole_run": TINY_CARTPOLE, "swingup_run": TINY_SWINGUP}
"""The settings each shared run was trained with: the run from it compiles the same programs."""


@pytest.mark.parametrize(
    ("fixture", "task"),
    [
        ("cartpole_run", "cartpole"),
        # slow: with the swing-up's other tests, on the worker that has built its shared run
        pytest.param("swingup_run", "cartpole-swingup", marks=pytest.mark.slow),
    ],
)
def test_a_run_starts_where_the_run_it_names_ended(fixture, task, request, tmp_path):
    # discrete-time BPTT and the ODE trainer (whose controller has a population axis)
    source = request.getfixturevalue(fixture)
    out = tmp_path / "tuned"
    argv = ["train", task, "--init", str(source), "--out", str(out), "--quiet"]
    assert main([*argv, "--no-animation", *SAME_SETTINGS[fixture]]) == 0
    before = json.loads((source / "metrics.json").read_text())
    after = json.loads((out / "metrics.json").read_text())
    # the same evaluation (seed 0's starts) of the same weights: the source's returned point
    assert after["curve"][0]["eval_return"] == before["final_eval_return"]
    assert json.loads((out / "run.json").read_text())["invocation"]["init"] == str(source)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["cartpole", "--hidden", "8"], "is not the network this run makes (layers 4x8x1"),
        (["cartpole", "--population", "2"], "a population of 2 would start every member"),
        (["pendulum"], "holds a controller of observation size 4, but task 'pendulum'"),
    ],
)
def test_a_controller_that_cannot_start_the_run_is_one_line(
    cartpole_run, args, needle, tmp_path, capsys
):
    argv = ["train", *args, "--init", str(cartpole_run), "--out", str(tmp_path / "x")]
    assert main([*argv, "--quiet", *TINY_CARTPOLE]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "x").exists()  # the directory is given back


def test_init_names_a_missing_run(tmp_path, capsys):
    argv = ["train", "cartpole", "--init", str(tmp_path / "none"), "--out", str(tmp_path / "x")]
    assert main([*argv, "--quiet"]) == 2
    assert f"--init {tmp_path / 'none'}: " in capsys.readouterr().err


def test_a_resume_before_the_first_checkpoint_starts_from_the_same_controller(
    cartpole_run, tmp_path
):
    # a run killed before its first checkpoint leaves its run.json alone, which records --init:
    # its resume starts from the controller that names, read again, not from random weights
    out = tmp_path / "tuned"
    argv = ["train", "cartpole", "--init", str(cartpole_run), "--out", str(out), "--quiet"]
    assert main([*argv, "--no-animation", *TINY_CARTPOLE]) == 0
    run = json.loads((out / "run.json").read_text())
    for path in out.iterdir():
        path.unlink()
    del run["complete"]
    (out / "run.json").write_text(json.dumps(run))
    assert main(["train", "--resume", "--out", str(out), "--quiet"]) == 0
    before = json.loads((cartpole_run / "metrics.json").read_text())
    after = json.loads((out / "metrics.json").read_text())
    assert after["curve"][0]["eval_return"] == before["final_eval_return"]
