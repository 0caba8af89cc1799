"""Audit 3's unclear messages, each with a variant of its class: an integer refused by the rule
it breaks, an --out that is a dangling symbolic link, advice to --resume only where there is
something to resume, Ctrl-C that says what was kept and how to continue, and a setting given
twice. Every case runs in-process on tiny budgets, and fails before anything is trained."""

from __future__ import annotations

import errno
import json
import shlex
import shutil
from pathlib import Path

import pytest

from diffcontrol import _run_dir, runs
from diffcontrol.cli import main
from diffcontrol.config import TrainConfig
from diffcontrol.errors import ConfigError
from diffcontrol.runs import _sweep as runs_sweep

from ._cli import one_line

TINY = ["--updates", "20", "--eval-every", "10", "--final-eval", "2", "--no-animation"]


def _interrupted(capsys, argv, *needles):
    """``main(argv)`` exits 130 with a message holding every needle; returns its last line."""
    assert main([str(a) for a in argv]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and "nothing was written" not in err, err
    for needle in needles:
        assert needle in err, err
    return err.strip().splitlines()[-1]


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


# --- 1. an integer refused names the rule it breaks ------------------------------------------


@pytest.mark.parametrize(
    "argv, needle",
    [  # the audit's cases: a lower bound other than 1, a width's and a seed list's size
        (["plan", "pendulum", "--value-grid", "-1"], "must be an integer >= 0"),
        (["plan", "pendulum", "--value-levels", "1"], "must be an integer >= 2"),
        (["train", "pendulum", "--hidden", "10000000000000"], "at most 1,048,576"),
        (["sweep", "pendulum", "--seeds", "0-2147483647"], "more than 65,536 seeds"),
        # variants: the upper bound alone, a size's own bound, a seed, a range turned round
        (["plan", "pendulum", "--value-grid", "5000"], "must be at most 1,001, got 5000"),
        (["train", "pendulum", "--batch", "2000000"], "must be at most 1,048,576, got 2000000"),
        (["train", "pendulum", "--batch", "0"], "a positive integer (at most 1,048,576)"),
        (["train", "pendulum", "--hidden", "64,2000000"], "at most 1,048,576"),
        (["sweep", "pendulum", "--seeds", "5-2147483648"], "a seed must be in 0 ... 2,147,483,647"),
        (["sweep", "pendulum", "--seeds", "-3"], "a seed must be in 0"),
        (["sweep", "pendulum", "--seeds", "9-2"], "write it as 2-9"),
    ],
)
def test_an_integer_is_refused_by_the_rule_it_breaks(capsys, tmp_path, argv, needle):
    out = tmp_path / "out"
    one_line(capsys, [*argv, "--out", out, *TINY[:6]], needle, absent=["positive layer"])
    assert not out.exists()


def test_a_planners_value_grid_is_none_or_3_points_at_least():
    from diffcontrol.settings import PlanConfig

    with pytest.raises(ConfigError, match=r"value_grid must be 0 \(no terminal value\) or 3"):
        PlanConfig(value_grid=2)
    assert PlanConfig(value_grid=0).value_grid is None  # the command line's "none"
    assert PlanConfig(value_grid=0) == PlanConfig()


def test_a_config_names_the_bounds_of_a_size():
    with pytest.raises(ConfigError, match=r"batch must be in 1 \.\.\. 1,048,576"):
        TrainConfig(batch=2**21)
    with pytest.raises(ConfigError, match=r"at most 1,048,576 \(2\^20\) units each"):
        TrainConfig(hidden=(2**21,))
    assert len(runs_sweep.parse_seeds("0-65535")) == 2**16  # the most a sweep may have


# --- 2. an --out that is a symbolic link to nothing -------------------------------------------


@pytest.mark.parametrize("absolute", [True, False])
@pytest.mark.parametrize("command", ["train", "sweep", "loop"])
def test_an_out_that_is_a_dangling_link_is_named(capsys, tmp_path, monkeypatch, absolute, command):
    monkeypatch.chdir(tmp_path)
    target = tmp_path / "r" / "target" if absolute else "r/target"
    (tmp_path / "lnk").symlink_to(target)
    budget = {"train": TINY, "sweep": [*TINY[:6], "--seeds", "0-1"]}
    budget["loop"] = ["--rounds", "1", "--episodes", "1", "--updates", "20"]
    budget["loop"] += ["--controller", "train"]
    one_line(
        capsys,
        [command, "pendulum", "--out", "lnk", *budget[command]],
        f"--out lnk is a symbolic link to {target}, which does not exist; create",
        absent=["another process"],
    )
    assert not (tmp_path / "r").exists() and (tmp_path / "lnk").is_symlink()


def test_an_out_under_a_dangling_link_is_named(capsys, tmp_path):
    (tmp_path / "lnk").symlink_to(tmp_path / "gone")
    out = tmp_path / "lnk" / "run"
    one_line(capsys, ["train", "pendulum", "--out", out, *TINY], f"lies under {tmp_path / 'lnk'}")


# --- 3. --resume only where there is something to resume ---------------------------------------


def _fails_with(monkeypatch, error):
    def check_run_dir(out_dir, run, resume):  # where a parent without permissions fails
        raise error(out_dir)

    monkeypatch.setattr(_run_dir, "check_run_dir", check_run_dir)


def test_a_permission_error_before_a_run_starts_does_not_advise_resume(
    capsys, tmp_path, monkeypatch
):
    out = tmp_path / "locked" / "run"
    _fails_with(monkeypatch, lambda o: PermissionError(errno.EACCES, "Permission denied", o))
    one_line(
        capsys,
        ["train", "pendulum", "--out", out, *TINY],
        "Permission denied",
        "choose another place, then run the command again",
        absent=["--resume"],
    )


def test_a_full_disk_in_a_run_with_a_checkpoint_names_the_resume_command(
    capsys, tmp_path, monkeypatch
):
    out = tmp_path / "it's run"
    out.mkdir()
    (out / "run.json").write_text(json.dumps({"task": "pendulum", "config": {}}))
    (out / "checkpoint.npz").write_bytes(b"")
    _fails_with(monkeypatch, lambda o: OSError(errno.ENOSPC, "No space left on device", o))
    err = one_line(capsys, ["train", "pendulum", "--out", out, *TINY], "make room, then")
    again = shlex.split(err.split("continue with: ")[1])
    assert again == ["diffcontrol", "train", "pendulum", "--out", str(out), *TINY, "--resume"]


# --- 4. Ctrl-C says what was kept and prints the command that continues -----------------------


def test_ctrl_c_in_a_loops_first_round_names_what_was_kept(capsys, tmp_path, monkeypatch):
    out = tmp_path / "a loop"
    monkeypatch.setattr(runs._loop, "fit_dir", _interrupt)  # round 1's fit
    argv = ["loop", "pendulum", "--out", out, "--rounds", "2", "--episodes", "1"]
    argv += ["--updates", "20", "--fit-steps", "5", "--eval-episodes", "1", "--quiet"]
    argv += ["--controller", "train"]  # the MLP's training, not the default planner
    line = _interrupted(capsys, argv, f"kept in {out}")
    assert shlex.split(line.split("--resume: ")[1]) == ["diffcontrol", *map(str, argv), "--resume"]
    assert (out / "data.csv").is_file() and (out / "round_0" / "recorded.csv").is_file()


def test_ctrl_c_before_a_loop_records_anything_keeps_nothing(capsys, tmp_path, monkeypatch):
    out = tmp_path / "loop"
    monkeypatch.setattr(runs._loop, "record", _interrupt)
    argv = ["loop", "pendulum", "--out", out, "--rounds", "1", "--episodes", "1", "--quiet"]
    _interrupted(capsys, argv, "nothing was kept")
    assert not out.exists()


def test_ctrl_c_in_a_sweeps_final_evaluation_names_the_resume_command(
    capsys, cartpole_run, tmp_path, monkeypatch
):
    """Every member is written; the best member's final evaluation is cut short."""
    out = tmp_path / "a sweep"
    config = TrainConfig.from_json(json.loads((cartpole_run / "run.json").read_text())["config"])
    doc = {"format": runs_sweep.SWEEP_FORMAT, "task": "cartpole", "config": config.to_json()}
    doc |= {"seeds": [config.seed], "values": {}, "members": ["000-seed0"]}
    shutil.copytree(cartpole_run, out / "000-seed0")
    (out / "000-seed0" / "learning_curve.png").unlink()  # its final evaluation to come
    (out / "sweep.json").write_text(json.dumps(doc))
    monkeypatch.setattr(runs_sweep, "save_run", _interrupt)
    line = _interrupted(capsys, ["sweep", "--out", out, "--resume", "--quiet"], f"kept in {out}")
    assert shlex.split(line.split("with: ")[1]) == [
        "diffcontrol", "sweep", "--out", str(out), "--resume"
    ]  # fmt: skip
    assert not json.loads((out / "sweep.json").read_text()).get("complete")


def test_ctrl_c_in_a_planners_final_evaluation_leaves_what_it_says(capsys, tmp_path, monkeypatch):
    """plan has nothing to resume: interrupted after model.json, it gives the directory back,
    so that "nothing was written" is true and the same command runs again."""
    from diffcontrol import _run_files

    out = tmp_path / "plan"
    monkeypatch.setattr(_run_files, "evaluate_run", _interrupt)  # after model.json
    argv = ["plan", "pendulum", "--out", str(out), "--final-eval", "1", "--no-animation"]
    assert main([*argv, "--quiet"]) == 130
    assert "nothing was written" in capsys.readouterr().err
    assert not out.exists()


def test_ctrl_c_in_a_comparison_on_the_real_system_names_what_was_kept(
    capsys, tmp_path, monkeypatch
):
    import diffcontrol.compare as compare

    out = tmp_path / "real"

    def loops_then_interrupt(task, out_dir, **kwargs):  # a loop under way, as run_real's
        (Path(out_dir) / "loops").mkdir(parents=True)
        raise KeyboardInterrupt

    monkeypatch.setattr(compare, "run_real_comparison", loops_then_interrupt)
    argv = ["compare", "pendulum", "--real", "--out", out, "--seeds", "1", "--quiet"]
    line = _interrupted(capsys, argv, f"the loops under way in {out / 'loops'}")
    assert shlex.split(line.split("--resume: ")[1]) == ["diffcontrol", *map(str, argv), "--resume"]


# --- 5. a setting given twice ------------------------------------------------------------------


@pytest.mark.parametrize(
    "given, needle",
    [
        (["--set", "learning_rate=1e-3,3e-3", "--learning-rate", "0.1"], "--learning-rate 0.1 and"),
        (["--set", "hidden=8x8,16", "--hidden", "4,4"], "--hidden 4,4 and --set hidden="),
    ],
)
def test_a_setting_swept_and_given_by_its_own_option_is_refused(capsys, tmp_path, given, needle):
    out = tmp_path / "sweep"
    argv = ["sweep", "pendulum", "--out", out, "--seeds", "0-1", *given, *TINY[:6]]
    one_line(capsys, argv, needle, "give it once")
    assert not out.exists()


def test_a_resumed_sweep_refuses_settings_it_would_drop(capsys, tmp_path):
    out = tmp_path / "sweep"
    out.mkdir()
    doc = {"format": runs_sweep.SWEEP_FORMAT, "task": "pendulum", "config": {}, "seeds": [0]}
    (out / "sweep.json").write_text(json.dumps({**doc, "values": {}, "members": []}))
    one_line(
        capsys,
        ["sweep", "--out", out, "--resume", "--learning-rate", "0.1"],
        "drop --learning-rate",
    )


def test_a_resume_command_without_the_task_finds_a_built_in_one(monkeypatch):
    """A fresh process has made no built-in task yet: one that a file names is made then."""
    from diffcontrol import tasks

    monkeypatch.setattr(tasks, "_REGISTRY", {})
    assert tasks.named_by_file("cartpole", "sweep.json", "fix").name == "cartpole"


@pytest.mark.slow  # a fit and a training compiled: 10 s on one core
def test_a_loop_cut_short_before_its_first_checkpoint_resumes(capsys, tmp_path, monkeypatch):
    out = tmp_path / "loop"
    real_train = runs._loop.train

    def train_then_interrupt(*args, **kwargs):
        def progress(line):
            if not line.startswith("solving"):  # once the run is claimed, past the grid solve
                raise KeyboardInterrupt

        return real_train(*args, **{**kwargs, "progress": progress})

    monkeypatch.setattr(runs._loop, "train", train_then_interrupt)
    argv = ["loop", "pendulum", "--out", out, "--rounds", "1", "--episodes", "1"]
    argv += ["--updates", "4", "--fit-steps", "2", "--eval-episodes", "1", "--quiet"]
    argv += ["--controller", "train"]  # the MLP's training, not the default planner
    line = _interrupted(capsys, argv, f"kept in {out}")
    assert (out / "round_0" / "run" / "run.json").exists()  # the nominal controller's training
    monkeypatch.undo()
    assert main(shlex.split(line.split("--resume: ")[1])[1:]) == 0
    assert (out / "loop.json").exists()
