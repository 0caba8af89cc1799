"""One interrupt path: SIGTERM at each phase of a small ``diffcontrol train`` behaves as
Ctrl-C does (one line, exit 130, a resume command that works and gives the uninterrupted
result, no partial file), and a full disk ends with one line, exit 2 and a resume that works
once there is room."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from diffcontrol.cli import main

SMALL = ["--updates", "40", "--eval-every", "10", "--batch", "4", "--window", "20"]
SMALL += ["--hidden", "8", "--eval-episodes", "2", "--no-animation"]
SMALL += ["--recipe", "windows"]  # no grid solve in each of the processes signalled
SRC = str(Path(__file__).resolve().parents[1] / "src")


def _weights(out: Path) -> list:
    return json.loads((out / "model.json").read_text())["network"]["layers"]


def _no_partial_files(out: Path) -> None:
    if out.exists():
        assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


def _cli(*argv: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen(
        [sys.executable, "-m", "diffcontrol.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted run that every resumed one must reproduce."""
    out = tmp_path_factory.mktemp("sigterm") / "reference"
    assert (
        main(["train", "pendulum", "--out", str(out), "--quiet", *SMALL, "--final-eval", "2"]) == 0
    )
    return _weights(out)


@pytest.mark.slow
@pytest.mark.parametrize(
    "phase, after_lines",
    [("import", 0), ("compile", 1), ("train", 3), ("final evaluation", 6)],
)
def test_sigterm_at_each_phase_then_resume(tmp_path, reference, phase, after_lines):
    out = tmp_path / "run"
    final_eval = "300" if phase == "final evaluation" else "2"
    proc = _cli("train", "pendulum", "--out", str(out), *SMALL, "--final-eval", final_eval)
    for _ in range(after_lines):  # the progress lines before the phase
        if not proc.stdout.readline():
            break
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=300)
    _no_partial_files(out)
    assert "Traceback" not in err and "Segmentation" not in err, err
    if proc.returncode == 0:  # it finished before the signal: nothing to check here
        pytest.skip(f"the run ended before SIGTERM reached the {phase} phase")
    if proc.returncode == -signal.SIGTERM:  # during the import, before diffcontrol's handler
        assert phase == "import" and not (out / "run.json").exists()
        resume = ["train", "pendulum", "--out", str(out), *SMALL, "--final-eval", final_eval]
    else:
        assert proc.returncode == 130, err
        lines = [line for line in err.strip().splitlines() if line.strip()]
        assert len(lines) == 1, err
        if "nothing was kept" in lines[0] or "nothing was written" in lines[0]:
            assert not (out / "run.json").exists()
            resume = ["train", "pendulum", "--out", str(out), *SMALL, "--final-eval", final_eval]
        else:
            command = lines[0].split("Continue with: ")[-1].split("finish them with: ")[-1]
            assert command.startswith("diffcontrol train") and command.endswith("--resume"), err
            resume = shlex.split(command)[1:]
    assert main([*resume, "--quiet"] if "--resume" in resume else [*resume, "--quiet"]) == 0
    assert _weights(out) == reference
    assert json.loads((out / "run.json").read_text())["complete"] is True


@pytest.mark.parametrize("write", ["write_json", "write_json_new"])
def test_an_interrupt_just_after_the_temporary_file_is_created_removes_it(
    tmp_path, monkeypatch, write
):
    """The instant the SIGTERM test above hit at random: the temporary file exists, and the
    call that created it has not returned."""
    from diffcontrol import io

    real_open = os.open

    def interrupted(path, flags, mode=0o777, **kw):
        os.close(real_open(path, flags, mode, **kw))
        raise KeyboardInterrupt

    target = tmp_path / "run.json"
    if write == "write_json":
        target.write_text("{}")
    monkeypatch.setattr(io.os, "open", interrupted)
    with pytest.raises(KeyboardInterrupt):
        getattr(io, write)(target, {"a": 1})
    monkeypatch.undo()
    assert [p.name for p in tmp_path.iterdir()] == (["run.json"] if write == "write_json" else [])
    if write == "write_json":
        assert target.read_text() == "{}"


def _tmpfs(path: Path, size: str) -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    path.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True
    )
    return done.returncode == 0


@pytest.mark.slow
def test_a_full_disk_ends_with_one_line_and_resumes(tmp_path, reference, capsys):
    disk = tmp_path / "disk"
    if not _tmpfs(disk, "256k"):
        pytest.skip("mounting a small tmpfs needs root and a kernel that allows it")
    try:
        filler = disk / "filler"
        with open(filler, "wb") as f:  # leave a little room: run.json fits, more does not
            try:
                f.write(b"\0" * (256 * 1024 - 12 * 1024))
            except OSError:
                pass
        out = disk / "run"
        argv = ["train", "pendulum", "--out", str(out), "--quiet", *SMALL, "--final-eval", "2"]
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2, err
        lines = [line for line in err.strip().splitlines() if line.strip()]
        assert len(lines) == 1 and "Traceback" not in err, err
        assert "No space left" in lines[0]
        # --resume is advised where there is something to resume, and only there
        assert ("--resume" in lines[0]) == (out / "run.json").exists(), err
        _no_partial_files(out)
        for p in out.iterdir() if out.exists() else ():
            if p.suffix == ".json":
                json.loads(p.read_text())  # whole, never half-written
        filler.unlink()  # room again: the suggested command completes the run
        again = ["train", "--out", str(out), "--resume", "--quiet"]
        if not (out / "run.json").exists():  # nothing was kept: the command itself again
            again = argv
        assert main(again) == 0
        assert _weights(out) == reference
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_a_sigterm_inside_a_garbage_collection_callback_is_sent_again(monkeypatch):
    """Python drops an exception raised in a GC callback (JAX has one): inside a command
    (``terminate_as_interrupt``, the CLI's) the handler must not raise there but deliver the
    signal again, and raise anywhere else."""
    import gc
    import threading

    from diffcontrol import _interrupts

    frames = []

    def callback(phase, info):
        frames.append(sys._getframe())

    sent, again = [], threading.Event()

    def kill(pid, signum):
        sent.append((pid, signum))
        again.set()

    monkeypatch.setattr(_interrupts.os, "kill", kill)
    before = signal.getsignal(signal.SIGTERM)
    with _interrupts.terminate_as_interrupt():
        assert signal.getsignal(signal.SIGTERM) is _interrupts.interrupt
        gc.callbacks.append(callback)
        try:
            gc.collect()  # the callback's frame, as a signal landing in it would see it
            try:
                _interrupts.interrupt(signal.SIGTERM, frames[0])
            except KeyboardInterrupt:
                pytest.fail("raised inside a GC callback, where Python would drop it")
        finally:
            gc.callbacks.remove(callback)
        assert again.wait(10)
        with pytest.raises(KeyboardInterrupt):
            _interrupts.interrupt(signal.SIGTERM, sys._getframe())
    assert sent == [(os.getpid(), signal.SIGTERM)]
    assert signal.getsignal(signal.SIGTERM) == before
