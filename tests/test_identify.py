"""``diffcontrol.identify`` with a user's own Gymnasium environment as the real system of a
task, and the rule that an environment id read from a file never imports a module."""

from __future__ import annotations

import json
import sys

import pytest

import diffcontrol
from diffcontrol import identify
from diffcontrol.cli import main
from diffcontrol.errors import ConfigError, DataFileError
from diffcontrol.identify._task import data_columns

USER_ENV = """
import gymnasium
from gymnasium.envs.classic_control.pendulum import PendulumEnv


class UserPendulum(PendulumEnv):
    pass


gymnasium.register("UserPendulum-v0", entry_point=UserPendulum, max_episode_steps=60)
"""

MARKER_ENV = """
import pathlib

pathlib.Path(__file__).with_name("imported.marker").write_text("imported")
"""


@pytest.fixture
def user_env(tmp_path, monkeypatch):
    (tmp_path / "user_pend_env.py").write_text(USER_ENV)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "user_pend_env:UserPendulum-v0"


@pytest.mark.slow
def test_a_user_env_id_records_as_the_real_system_of_a_task_with_its_columns(user_env, tmp_path):
    task = diffcontrol.make("pendulum")
    data = identify.record(user_env, 2, seed=1, task=task)
    assert (data.observation_columns, data.action_columns) == data_columns(task)
    assert data.env_id == user_env and data.metadata["dt_s"] == 0.05
    fit = identify.fit(task, data, "params", names=("g",), steps=5, lm_steps=0)
    assert fit.model_type == "params" and fit.names == ("g",) and not fit.diverged
    # without the task the columns are unknown, and the fit refuses them by name
    anonymous = identify.record(user_env, 1)
    assert anonymous.observation_columns[0] == "obs.0 [?]"
    with pytest.raises(DataFileError, match="has the columns"):
        identify.fit(task, anonymous, "params")
    # spaces that are not the task's are refused
    with pytest.raises(ConfigError, match="spaces"):
        identify.record("CartPole-v1", 1, task=task)


@pytest.mark.slow
def test_cli_record_fit_with_a_user_env_id(user_env, tmp_path, capsys):
    csv = tmp_path / "user.csv"
    argv = ["record", user_env, "--task", "pendulum", "--episodes", "2", "--out", str(csv)]
    assert main([*argv, "--quiet"]) == 0
    assert f"wrote {csv}: 2 episode(s), 120 steps" in capsys.readouterr().out
    out = tmp_path / "fit"
    fit = ["fit", "pendulum", "--data", str(csv), "--model", "params", "--params", "g"]
    assert main([*fit, "--steps", "5", "--lm-steps", "0", "--out", str(out), "--quiet"]) == 0
    doc = json.loads((out / "fitted.json").read_text())
    assert doc["data"]["env_id"] == user_env and doc["task"] == "pendulum"
    # the module is imported in this process: the id in the file may be used
    assert identify.real_system(identify.read_fitted(out))["env_id"] == user_env


def test_an_env_id_with_a_module_in_a_fitted_file_is_refused_without_import(
    tmp_path, monkeypatch, capsys
):
    (tmp_path / "marker_env.py").write_text(MARKER_ENV)
    monkeypatch.syspath_prepend(str(tmp_path))  # importing it would work: it must not happen
    fit_dir = tmp_path / "fit"
    fit_dir.mkdir()
    doc = {
        "format": "diffcontrol-fitted-model",
        "version": 1,
        "task": "pendulum",
        "model": "params",
        "all_parameters": {"g": 11.0},
        "data": {"env_id": "marker_env:Marker-v0", "env_kwargs": {}},
    }
    (fit_dir / "fitted.json").write_text(json.dumps(doc))
    with pytest.raises(ConfigError, match="pass --env marker_env:Marker-v0 explicitly"):
        identify.real_system(identify.read_fitted(fit_dir))
    argv = ["train", "pendulum", "--model", str(fit_dir), "--out", str(tmp_path / "run")]
    assert main([*argv, "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--env" in err
    assert not (tmp_path / "imported.marker").exists()
    assert "marker_env" not in sys.modules
    # an id without a module needs no import
    assert identify.checked_env_id("Pendulum-v1") == "Pendulum-v1"
