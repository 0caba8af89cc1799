"""Nothing runs because a file says so: a task or an environment read from a file is found
among what is registered or installed, never looked up in the current directory; and every
command the library prints for the user to paste is shell-quoted.

The fixtures put modules that leave a mark when imported (``evilmod.py``, ``Box2D.py``,
``pygame.py``) in the working directory and on ``sys.path`` first, as ``python -m
diffcontrol.cli`` does, then hand the CLI files that name them."""

from __future__ import annotations

import json
import shlex
import shutil
import sys

import pytest

from diffcontrol._shell import command
from diffcontrol.cli import main
from diffcontrol.runs import _sweep as runs_sweep

EVIL = ("evilmod", "Box2D", "pygame")


@pytest.fixture
def booby_trapped(tmp_path, monkeypatch):
    """A working directory on ``sys.path`` whose modules write ``IMPORTED`` when imported."""
    for name in EVIL:
        (tmp_path / f"{name}.py").write_text(
            "import pathlib\n"
            f"pathlib.Path({str(tmp_path / 'IMPORTED')!r}).write_text({name!r})\n"
            "class Task: pass\n"
        )
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    saved = {name: sys.modules.pop(name) for name in EVIL if name in sys.modules}
    yield tmp_path
    for name in EVIL:
        sys.modules.pop(name, None)
    sys.modules.update(saved)
    assert not (tmp_path / "IMPORTED").exists(), (tmp_path / "IMPORTED").read_text()


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err


def _edit(path, change):
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize("task", ["evilmod:Task", "evilmod", "pygame:Task"])
def test_sweep_resume_never_imports_the_task_its_file_names(booby_trapped, capsys, task):
    out = booby_trapped / "s5"
    out.mkdir()
    doc = {"format": runs_sweep.SWEEP_FORMAT, "task": task, "config": {}, "seeds": [0]}
    (out / runs_sweep.SWEEP_FILE).write_text(json.dumps({**doc, "values": {}, "members": []}))
    assert main(["sweep", "--out", str(out), "--resume"]) == 2
    err = _one_line(capsys)
    assert "not registered; name it: diffcontrol sweep" in err and "never imports" in err


def test_train_resume_never_imports_the_task_its_file_names(booby_trapped, capsys):
    out = booby_trapped / "a b;$(touch PWNED)"
    out.mkdir()
    run = {"format": "diffcontrol-run", "task": "x", "config": {}}
    run["invocation"] = {"task": "evilmod:Task"}
    (out / "run.json").write_text(json.dumps(run))
    assert main(["train", "--out", str(out), "--resume"]) == 2
    err = _one_line(capsys)
    fix = err.split("name it: ")[1].split(" (diffcontrol never")[0]
    assert shlex.split(fix) == [
        "diffcontrol",
        "train",
        "evilmod:Task",
        "--out",
        str(out),
        "--resume",
    ]


@pytest.mark.parametrize(
    "real, message",
    [
        ({"env_id": "CarRacing-v3", "env_kwargs": {}}, "cannot be made here"),
        ({"env_id": "LunarLander-v3", "env_kwargs": {}}, "cannot be made here"),
        ({"env_id": "CartPole-v1", "env_kwargs": {"render_mode": "human"}}, "render"),
        ({"env_id": "Pendulum-v1", "env_kwargs": {"render_mode": "rgb_array"}}, "render"),
        ({"env_id": "evilmod:Pendulum-v0", "env_kwargs": {}}, "does not import modules"),
        ({"env_id": "NoSuchThing-v0", "env_kwargs": {}}, "does not know"),
    ],
)
def test_an_environment_a_run_file_names_imports_nothing_from_here(
    booby_trapped, capsys, pendulum_run, real, message
):
    """``metrics.json`` naming the real system: an id whose environment needs an optional
    package (Box2D) is made from the installed packages alone, and nothing renders."""
    out = booby_trapped / "run"
    shutil.copytree(pendulum_run, out)
    _edit(out / "metrics.json", lambda d: d.setdefault("model", {}).update(real_system=real))
    assert main(["evaluate", str(out), "--episodes", "1"]) == 2
    assert message in _one_line(capsys)


@pytest.mark.parametrize(
    "words",
    [
        ["train", "--out", "r/a b;$(touch PWNED)", "--resume"],
        ["sweep", "my_tasks:Task", "--out", "it's `here`", "--resume"],
        ["compare", "cartpole", "--out", "a\nb", "--seeds", "3"],
        ["train", "pendulum", "--out", "", "--set", "x=$HOME"],
    ],
)
def test_a_printed_command_reads_back_as_its_words(words):
    assert shlex.split(command(*words)) == ["diffcontrol", *words]


@pytest.mark.slow
def test_an_interrupted_run_prints_a_resume_command_that_pastes(tmp_path, monkeypatch):
    """Ctrl-C after the first checkpoint of a run whose ``--out`` is hostile: the printed
    command, split as a shell splits it, continues that run and runs nothing else."""
    from diffcontrol.runs import RunInterrupted, train_run

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "r" / "a b;$(touch PWNED)"
    updates = []

    def progress(line):  # Ctrl-C at the third evaluation point, after two checkpoints
        updates.extend([line] if line.startswith("[") else [])
        if len(updates) == 3:
            raise KeyboardInterrupt

    settings = dict(updates=40, eval_every=5, window=10, batch=4, eval_episodes=2)
    with pytest.raises(RunInterrupted) as caught:
        train_run(out, "pendulum", settings=settings, progress=progress, animation=False)
    printed = str(caught.value).split("Continue with: ")[1]
    assert shlex.split(printed) == ["diffcontrol", "train", "--out", str(out), "--resume"]
    assert main([*shlex.split(printed)[1:], "--quiet", "--final-eval", "0"]) == 0
    assert not (tmp_path / "PWNED").exists()
