"""A user's own task, in a file of theirs, gets what a built-in one gets: the CLI by import
path, a Gymnasium environment at registration, saving and loading, evaluation."""

from __future__ import annotations

import json
import textwrap

import gymnasium
import numpy as np
import pytest

import diffcontrol
from diffcontrol.cli import main
from diffcontrol.errors import UnknownTaskError

USER_FILE = """
import equinox as eqx
import jax
import jax.numpy as jnp

import diffcontrol


class RailParams(eqx.Module):
    mass: float = 1.0
    drag: float = 0.3
    dt: float = 0.05


class UserRail(diffcontrol.Task):
    name = "user-rail"
    summary = "stop a cart with drag at x = 0"
    episode_length = 40
    observation_size = 2
    action_size = 1
    action_head = "tanh"
    action_low, action_high = (-1.0,), (1.0,)
    losses = ("quadratic",)

    def default_params(self):
        return RailParams()

    def reset(self, key, params):
        return jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)

    def step(self, params, state, action):
        x, v = state
        v = v + (action[0] - params.drag * v) / params.mass * params.dt
        x = x + v * params.dt
        return jnp.stack([x, v]), -(x**2 + 0.1 * v**2), jnp.asarray(False)

    def observe(self, state):
        return state

    def step_loss(self, name):
        return lambda params, state, action, next_state, reward: -reward

    def default_config(self):
        return diffcontrol.TrainConfig(
            updates=4, batch=4, window=10, horizon=40, learning_rate=1e-2, hidden=(8,),
            eval_every=2, eval_episodes=4,
        )

    def frames(self, recording, every):
        from diffcontrol.animation import close, scene

        fig, ax = scene(3.0, 1.0, (-1.5, 1.5), (-0.5, 0.5))
        (cart,) = ax.plot([], [], "ks", ms=10)
        for i in range(0, recording.states.shape[0], every):
            cart.set_data([recording.states[i, 0]], [0.0])
            yield fig
        close(fig)


NOT_A_TASK = 3
"""


@pytest.fixture(scope="module")
def user_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("user")
    (d / "my_rail_tasks.py").write_text(textwrap.dedent(USER_FILE))
    return d


@pytest.fixture(scope="module")
def user_run(user_dir):
    """``diffcontrol train my_rail_tasks:UserRail`` from the user's directory."""
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(user_dir)
        out = user_dir / "run"
        argv = ["train", "my_rail_tasks:UserRail", "--out", str(out), "--quiet"]
        assert main([*argv, "--no-compile-cache"]) == 0
    return out


@pytest.mark.slow
def test_train_by_import_path_writes_a_loadable_run(user_run):
    doc = json.loads((user_run / "model.json").read_text())
    assert doc["task"] == "user-rail"
    assert doc["metadata"]["task_source"] == "my_rail_tasks:UserRail"
    metrics = json.loads((user_run / "metrics.json").read_text())
    assert metrics["updates"] == 4
    # registered on import: a Gymnasium environment at once, the final evaluation ran there
    assert metrics["gym_eval"]["env_id"] == "diffcontrol/UserRail-v0"
    assert (user_run / "rollout.gif").read_bytes()[:6] == b"GIF89a"
    policy = diffcontrol.load(user_run)
    env = gymnasium.make("diffcontrol/UserRail-v0")
    obs, _ = env.reset(seed=0)
    action = policy(obs)
    assert env.action_space.contains(action)
    env.step(action)


@pytest.mark.slow
def test_evaluate_and_animate_by_import_path(user_run, user_dir, capsys, monkeypatch):
    monkeypatch.chdir(user_dir)
    argv = ["evaluate", str(user_run), "--task", "my_rail_tasks:UserRail", "--episodes", "3"]
    assert main([*argv, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["task"] == "user-rail" and len(result["returns"]) == 3
    gif = user_dir / "again.gif"
    assert (
        main(["animate", str(user_run), "--task", "my_rail_tasks:UserRail", "--out", str(gif)]) == 0
    )
    assert gif.read_bytes()[:6] == b"GIF89a"
    # an existing file is never overwritten
    assert main(["animate", str(user_run), "--out", str(gif)]) == 2
    assert "already exists" in capsys.readouterr().err


def test_a_file_naming_an_unregistered_task_imports_nothing(user_run, tmp_path):
    doc = json.loads((user_run / "model.json").read_text())
    doc["task"] = "evil-task"
    doc["metadata"]["task_source"] = "evilmod:Evil"
    (tmp_path / "model.json").write_text(json.dumps(doc))
    with pytest.raises(UnknownTaskError, match="--task module:Class"):
        diffcontrol.runs.open_run(tmp_path)
    # load still works, on the file's format alone
    policy = diffcontrol.load(tmp_path)
    assert np.isfinite(policy.action(np.zeros(2))).all()


@pytest.mark.parametrize(
    "spec, needle",
    [
        ("no_such_module_xyz:Task", "cannot import 'no_such_module_xyz'"),
        ("my_rail_tasks:Missing", "has no 'Missing'"),
        ("my_rail_tasks:NOT_A_TASK", "not a diffcontrol Task"),
        ("my_rail_tasks", "unknown task"),
    ],
)
def test_bad_import_paths_get_one_line(spec, needle, user_dir, monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(user_dir)
    assert main(["train", spec, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x").exists()


def test_register_makes_a_gymnasium_environment_at_once():
    class Later(diffcontrol.tasks.Pendulum):
        name = "pendulum-registered-later"
        env_name = "PendulumRegisteredLater"

    diffcontrol.register(Later())
    env = gymnasium.make("diffcontrol/PendulumRegisteredLater-v0")
    obs, _ = env.reset(seed=1)
    assert obs.shape == (3,)
