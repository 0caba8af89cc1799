"""``diffcontrol export``: the controller as an ONNX model, run by ONNX Runtime, gives the
actions ``diffcontrol.load`` gives: within 1e-5 for continuous actions, exactly for discrete
ones (the graph computes in float64, as ``load`` does), for every built-in task's network
controller, a user's own task, and runs trained by the CLI."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import jax
import numpy as np
import onnx
import onnxruntime as ort
import pytest

import diffcontrol
from diffcontrol import deploy, io, policies, tasks
from diffcontrol.cli import main
from diffcontrol.controllers import MLPController
from diffcontrol.errors import ConfigError
from diffcontrol.settings import PlanConfig
from diffcontrol.tasks import controller_kwargs

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
N = 4096


def _network_doc(task, activation: str | None = None, seed: int = 0) -> dict:
    """A network controller of ``task`` with the task's own settings (sizes, head, bounds,
    observation scaling), its weights spread so that actions reach their bounds."""
    cfg = task.default_config()
    kwargs = controller_kwargs(task)
    if getattr(cfg, "head", None):
        kwargs["head"] = cfg.head
    key = jax.random.key(seed)
    net = MLPController(key, hidden=cfg.hidden, activation=activation or cfg.activation, **kwargs)
    doc = policies.controller_to_dict(net, task)
    for layer in doc["network"]["layers"]:
        layer["weight"] = (3 * np.asarray(layer["weight"])).tolist()
    return doc


def _observations(doc: dict, seed: int = 1) -> np.ndarray:
    """Random float32 observations around the ones the controller is scaled for."""
    obs = doc["observation"]
    rng = np.random.default_rng(seed)
    spread = 2.0 / np.asarray(obs["scale"], float)
    x = np.asarray(obs["offset"], float) + spread * rng.standard_normal((N, obs["size"]))
    return x.astype(np.float32)


def _save(doc: dict, directory: Path) -> Path:
    directory.mkdir(parents=True)
    io.write_json(directory / "model.json", doc)
    return directory


def _onnx_actions(path: Path, obs: np.ndarray) -> np.ndarray:
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run(["action"], {"observation": obs})[0]


def _loaded_actions(policy, obs: np.ndarray) -> np.ndarray:
    """The Gymnasium actions of what ``diffcontrol.load`` returns, for a batch of
    observations (``obs`` as the float64 values the float32 ones are)."""
    x = obs.astype(np.float64)
    if isinstance(policy, policies.AimingPolicy):  # (target, wind) -> (angle, weight)
        return np.stack(policy(x[:, 0], x[:, 1]), axis=-1)
    if isinstance(policy, policies.StatePolicy):  # its network, on the observation features
        return policy.action(x)
    return policy(x)


def _assert_same(onnx_actions: np.ndarray, loaded: np.ndarray, doc: dict) -> None:
    discrete = doc["action"]["gym"] != "box"
    if discrete:
        assert onnx_actions.dtype == np.int64 and onnx_actions.shape == (N,)
        np.testing.assert_array_equal(onnx_actions, loaded)
        assert len(np.unique(loaded)) > 1, "the test should see more than one action"
    else:
        size = doc["action"]["size"]
        assert onnx_actions.dtype == np.float32 and onnx_actions.shape == (N, size)
        # Gymnasium's Box actions are float32, as are NumpyPolicy's: compared as such
        np.testing.assert_allclose(onnx_actions, loaded.astype(np.float32), rtol=0, atol=1e-5)
        if doc["action"]["low"] is not None:  # the bounds are reached and kept
            low, high = (np.asarray(doc["action"][k], np.float32) for k in ("low", "high"))
            assert np.all(onnx_actions >= low) and np.all(onnx_actions <= high)


@pytest.mark.parametrize("name", tasks.names())
def test_every_builtin_tasks_network_exports_to_the_actions_load_gives(name, tmp_path):
    task = tasks.make(name)
    doc = _network_doc(task)
    run = _save(doc, tmp_path / "run")
    path = diffcontrol.export(run, tmp_path / f"{name}.onnx")
    obs = _observations(doc)
    _assert_same(_onnx_actions(path, obs), _loaded_actions(diffcontrol.load(run), obs), doc)


@pytest.mark.parametrize("activation", ["relu", "sigmoid", "elu"])
def test_each_hidden_activation_exports_exactly(activation, tmp_path):
    doc = _network_doc(tasks.make("acrobot"), activation=activation, seed=2)  # discrete: exact
    run = _save(doc, tmp_path / "run")
    path = diffcontrol.export(run, tmp_path / "a.onnx")
    obs = _observations(doc)
    _assert_same(_onnx_actions(path, obs), _loaded_actions(diffcontrol.load(run), obs), doc)


def _example_task(module: str, cls: str):
    if module not in sys.modules:  # as tests/test_examples.py loads them
        spec = importlib.util.spec_from_file_location(module, EXAMPLES / f"{module}.py")
        sys.modules[module] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[module])
    return getattr(sys.modules[module], cls)()


@pytest.mark.parametrize(
    ("module", "cls"), [("custom_task", "Rail"), ("continuous_task", "Spring")]
)
def test_a_users_own_task_exports(module, cls, tmp_path):
    task = _example_task(module, cls)
    doc = _network_doc(task)
    run = _save(doc, tmp_path / "run")
    path = diffcontrol.export(run, tmp_path / "own.onnx")
    obs = _observations(doc)
    loaded = diffcontrol.load(run, task=task)
    _assert_same(_onnx_actions(path, obs), _loaded_actions(loaded, obs), doc)


@pytest.mark.slow  # the runs are trained by the command line (the session's shared runs)
@pytest.mark.parametrize("fixture", ["pendulum_run", "cartpole_run", "swingup_run"])
def test_runs_trained_by_the_cli_export_from_the_command_line(fixture, request, tmp_path, capsys):
    run = request.getfixturevalue(fixture)
    out = tmp_path / "controller.onnx"
    assert main(["export", str(run), "--out", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    doc = policies.read_model(run)
    obs = _observations(doc, seed=3)
    _assert_same(_onnx_actions(out, obs), _loaded_actions(diffcontrol.load(run), obs), doc)


def test_the_model_says_what_it_controls(cartpole_run, tmp_path):
    path = diffcontrol.export(cartpole_run, tmp_path / "cartpole.onnx")
    model = onnx.load(str(path))
    onnx.checker.check_model(model)
    assert [(o.domain, o.version) for o in model.opset_import] == [("", deploy.OPSET)]
    assert model.ir_version == deploy.IR_VERSION and model.producer_name == "diffcontrol"
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["task"] == "cartpole" and meta["gym_id"] == "CartPole-v1"
    assert meta["diffcontrol_version"] == diffcontrol.__version__
    assert json.loads(meta["observation_space"]) == {"shape": [4], "dtype": "float32"}
    assert json.loads(meta["action_space"]) == {"kind": "discrete", "n": 2, "dtype": "int64"}
    (inp,), (out,) = model.graph.input, model.graph.output
    assert inp.name == "observation" and out.name == "action"

    pendulum = deploy.metadata(policies.read_model(_save(_network_doc(tasks.make("pendulum")),
                                                         tmp_path / "p")))  # fmt: skip
    space = json.loads(pendulum["action_space"])
    assert space == {"kind": "box", "shape": [1], "dtype": "float32", "low": [-2.0], "high": [2.0]}
    swingup = deploy.metadata(policies.read_model(_save(_network_doc(tasks.make(
        "cartpole-swingup")), tmp_path / "s")))  # fmt: skip
    observation = json.loads(swingup["observation_space"])
    assert observation["features"] == list(tasks.make("cartpole-swingup").feature_names)


def test_a_planner_is_refused_with_the_way_to_distil_it(tmp_path, capsys):
    task = tasks.make("pendulum")
    doc = policies.planner_document(
        task, PlanConfig().to_json(), {"kind": "simulator"}, {"created": "now"}
    )
    run = _save(doc, tmp_path / "planner")
    with pytest.raises(ConfigError, match="mpc.distil"):
        diffcontrol.export(run, tmp_path / "p.onnx")
    assert main(["export", str(run), "--out", str(tmp_path / "p.onnx")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "holds a planner" in err
    assert not (tmp_path / "p.onnx").exists()


def test_an_existing_file_is_kept_unless_forced(pendulum_run, tmp_path, capsys):
    out = tmp_path / "kept.onnx"
    out.write_bytes(b"someone's work")
    assert main(["export", str(pendulum_run), "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err and out.read_bytes() == b"someone's work"
    assert main(["export", str(pendulum_run), "--out", str(out), "--force", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["task"] == "pendulum"
    assert onnx.load(str(out)).graph.output[0].name == "action"


def test_the_deploy_pages_python_snippet_runs_the_exported_pendulum(
    pendulum_run, tmp_path, monkeypatch
):
    """docs/deploy.md's ONNX Runtime loop gives the return diffcontrol.load's policy gives."""
    import contextlib
    import io as _io
    import re

    import gymnasium

    page = (Path(__file__).resolve().parents[1] / "docs" / "deploy.md").read_text()
    snippet = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    diffcontrol.export(pendulum_run, tmp_path / "pendulum.onnx")
    monkeypatch.chdir(tmp_path)
    with contextlib.redirect_stdout(_io.StringIO()) as printed:
        exec(compile(snippet, "docs/deploy.md", "exec"), {})
    policy, env = diffcontrol.load(pendulum_run), gymnasium.make("Pendulum-v1")
    obs, _ = env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        total, done = total + reward, terminated or truncated
    assert printed.getvalue().strip() == f"return {total:.1f}"
