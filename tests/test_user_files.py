"""The two newest systems, written as a user's own files outside the package (their system
and task modules copied out, the package-relative imports made public ones), go through the
command line by import path: train, save, load, evaluate and the record -> fit -> train
loop, as the built-in ones do."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import diffcontrol
from diffcontrol.cli import main

SRC = Path(diffcontrol.__file__).parent
PUBLIC_IMPORTS = {
    "from ..config import TrainConfig": "from diffcontrol import TrainConfig",
    "from ..settings import PlanConfig": "from diffcontrol.settings import PlanConfig",
    "from ._base import StepLoss, Task": "from diffcontrol.tasks import StepLoss, Task",
    "from ._scene import close, scene": "from diffcontrol.animation import close, scene",
    "from ._grid import GridAxis": "from diffcontrol.optimal import GridAxis",
}


def _user_files(directory: Path, system: str, alias: str, cls: str) -> str:
    """Write ``user_<system>.py`` (the system) and ``user_<system>_task.py`` (its task under
    a name of its own); returns the import path of the task."""
    dynamics = (SRC / "systems" / f"{system}.py").read_text()
    dynamics = dynamics.replace("from .draws import", "from diffcontrol.systems.draws import")
    (directory / f"user_{system}.py").write_text(dynamics)
    task = (SRC / "tasks" / f"{system}.py").read_text()
    task = task.replace(
        f"from ..systems import {system} as {alias}", f"import user_{system} as {alias}"
    )
    for old, new in PUBLIC_IMPORTS.items():
        task = task.replace(old, new)
    assert "from ." not in task, "a package-relative import is left"
    task += f"\n\nclass User{cls}({cls}):\n    name = 'user-{system}'\n    env_name = 'User{cls}'\n"
    (directory / f"user_{system}_task.py").write_text(task)
    return f"user_{system}_task:User{cls}"


@pytest.fixture(scope="module")
def user_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("user-files")
    specs = {
        "mountain_car": _user_files(d, "mountain_car", "mc", "MountainCarContinuous"),
        "acrobot": _user_files(d, "acrobot", "ac", "Acrobot"),
    }
    return d, specs


TINY = ["--updates", "2", "--eval-every", "1", "--batch", "2", "--window", "10"]
TINY += ["--eval-episodes", "2", "--hidden", "8", "--final-eval", "2", "--no-animation"]


@pytest.mark.slow
@pytest.mark.parametrize(
    "system, gym_id", [("mountain_car", "MountainCarContinuous-v0"), ("acrobot", "Acrobot-v1")]
)
def test_user_files_train_save_load_evaluate_and_loop(
    user_dir, system, gym_id, monkeypatch, capsys
):
    d, specs = user_dir
    spec = specs[system]
    monkeypatch.chdir(d)
    out = d / f"run-{system}"
    assert main(["train", spec, "--out", str(out), "--quiet", *TINY]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["gym_eval"]["env_id"] == gym_id and metrics["gym_eval"]["episodes"] == 2
    policy = diffcontrol.load(out)
    import gymnasium

    env = gymnasium.make(gym_id)
    obs, _ = env.reset(seed=0)
    assert env.action_space.contains(policy(obs))
    capsys.readouterr()
    assert main(["evaluate", str(out), "--task", spec, "--episodes", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["env_id"] == gym_id
    loop = d / f"loop-{system}"
    argv = ["loop", spec, "--env", gym_id, "--model", "neural", "--rounds", "1"]
    argv += ["--episodes", "2", "--updates", "2", "--fit-steps", "20", "--eval-episodes", "1"]
    assert main([*argv, "--out", str(loop), "--quiet"]) == 0
    assert (loop / "round_1" / "run" / "model.json").exists()
    assert json.loads((loop / "loop.json").read_text())["settings"]["fit_steps"] == 20
    fitted = json.loads((loop / "round_1" / "fit" / "fitted.json").read_text())
    assert len(fitted["fit"]["loss_history"]) == 20  # the fit took the steps asked for
