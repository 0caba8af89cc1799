"""The run directory's life: claimed once, resumed from its own run.json, finished for good,
given back when nothing could be kept."""

from __future__ import annotations

import json
import threading

import pytest

from diffcontrol import _run_dir, runs
from diffcontrol.cli import main
from diffcontrol.errors import RunDirectoryError

from .conftest import TINY_CARTPOLE


def _files(d):
    return {p.name: p.read_bytes() for p in d.iterdir()}


@pytest.mark.slow
def test_resume_needs_only_the_directory(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runs._train, "save_run", interrupted)
    argv = ["train", "cartpole", "--out", str(out), "--quiet", *TINY_CARTPOLE]
    assert main([*argv, "--final-eval", "3", "--no-animation"]) == 130
    err = capsys.readouterr().err
    assert f"diffcontrol train --out {out} --resume" in err
    assert not (out / "metrics.json").exists()
    monkeypatch.undo()
    # the settings come from run.json: 3 evaluation episodes, no animation
    assert main(["train", "--out", str(out), "--resume", "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["gym_eval"]["episodes"] == 3
    assert not (out / "rollout.gif").exists()
    assert json.loads((out / "run.json").read_text())["complete"] is True


def test_resuming_a_finished_run_changes_nothing(cartpole_run, capsys):
    before = _files(cartpole_run)
    assert main(["train", "--out", str(cartpole_run), "--resume"]) == 0
    assert "finished run" in capsys.readouterr().out
    assert _files(cartpole_run) == before


@pytest.mark.slow
def test_a_run_that_fails_before_its_first_checkpoint_gives_the_directory_back(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "cartpole-swingup", "--out", str(out), "--quiet", "--updates", "2"]
    argv += ["--eval-every", "1", "--final-eval", "0", "--no-animation"]
    # a step budget too small for even the first solve: found after the directory is claimed
    assert main([*argv, "--max-steps", "2"]) == 2
    assert "max-steps" in capsys.readouterr().err
    assert not out.exists()
    assert main(argv) == 0  # the corrected command can use the directory


def test_a_resume_of_a_users_task_never_imports_what_run_json_names(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    run = {"format": "diffcontrol-run", "task": "x", "config": {}}
    run["invocation"] = {"task": "evil_module_that_must_not_load:Task"}
    (out / "run.json").write_text(json.dumps(run))
    assert main(["train", "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "not registered; name it" in err and len(err.strip().splitlines()) == 1


def test_of_two_processes_claiming_a_directory_one_wins(tmp_path):
    for trial in range(20):
        out = tmp_path / f"race{trial}"
        barrier = threading.Barrier(2)
        outcomes = []

        def claim(out=out, barrier=barrier, outcomes=outcomes):
            barrier.wait()
            try:
                _run_dir.prepare_run_dir(out, {"task": "t", "config": {"seed": 0}}, resume=False)
                outcomes.append("won")
            except RunDirectoryError:
                outcomes.append("refused")

        threads = [threading.Thread(target=claim) for _ in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert sorted(outcomes) == ["refused", "won"], outcomes


def test_a_claim_made_between_the_check_and_the_write_is_refused(tmp_path, monkeypatch):
    """The race above, made certain: another process writes ``run.json`` after this one's
    check found the directory empty. Without ``--resume`` the claim is refused (it was taken
    as a run to resume, so both processes trained into one directory)."""
    out = tmp_path / "race"
    run = {"task": "t", "config": {"seed": 0}}
    monkeypatch.setattr(_run_dir, "check_run_dir", lambda *args: None)  # the check passed earlier
    _run_dir.prepare_run_dir(out, run, resume=False)  # the other process's claim
    with pytest.raises(RunDirectoryError, match="another process has just claimed"):
        _run_dir.prepare_run_dir(out, run, resume=False)


def test_a_finished_run_refuses_the_library_resume(cartpole_run):
    doc = json.loads((cartpole_run / "run.json").read_text())
    with pytest.raises(RunDirectoryError, match="finished run"):
        _run_dir.prepare_run_dir(cartpole_run, doc, resume=True)


def test_result_save_never_overwrites_another_run(cartpole_run, tmp_path):
    """``result.save(DIR)`` (the README's call) refuses a directory that holds another run,
    keeps its files, writes into a new one, and writes again into the directory ``train``
    wrote (its own) or where told to with ``overwrite=True``."""
    import shutil

    import diffcontrol

    other = tmp_path / "other"
    shutil.copytree(cartpole_run, other)
    before = {p.name: p.read_bytes() for p in other.iterdir() if p.is_file()}
    task = diffcontrol.make("pendulum")
    config = task.default_config().replace(
        updates=2, eval_every=1, batch=4, window=10, eval_episodes=2
    )
    result = diffcontrol.train(task, config)
    with pytest.raises(RunDirectoryError, match="holds another run"):
        result.save(other, final_eval=0, animation=False)
    assert {p.name: p.read_bytes() for p in other.iterdir() if p.is_file()} == before
    assert "model.json" in result.save(tmp_path / "new", final_eval=0, animation=False)
    result.save(other, final_eval=0, animation=False, overwrite=True)
    assert json.loads((other / "model.json").read_text())["task"] == "pendulum"
    own = diffcontrol.train(task, config, out_dir=tmp_path / "own")
    assert "model.json" in own.save(tmp_path / "own", final_eval=0, animation=False)
