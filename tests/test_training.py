"""The trainer: learning with real thresholds, exact resume, one compilation, the cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import policies
from diffcontrol.evaluation import evaluate
from diffcontrol.training import (
    TrainingDiverged,
    clear_compiled,
    make_trainer,
    resolve_config,
    train,
)

from ._monitoring import listening


def _weights(controller):
    return jax.tree.leaves(eqx.filter(controller, eqx.is_inexact_array))


@pytest.mark.slow
def test_cartpole_defaults_learn_to_balance():
    """The default CartPole recipe (<= 10 simulated episodes) balances on Gymnasium seeds."""
    task = diffcontrol.make("cartpole")
    result = train(task)
    assert result.metrics["simulated_episodes"] <= 10
    policy = policies.NumpyPolicy(policies.controller_to_dict(result.controller, task))
    ev = evaluate(policy, task, episodes=20, seed=0)
    assert ev.mean >= 475, ev.returns


@pytest.mark.slow
def test_pendulum_learns_on_a_small_budget():
    """600 updates of the windows recipe (a fifth of its budget) take the return from about
    -1300 to the swing-up, and the returned controller is the best evaluation point's
    (``keep_best``). The defaults' value needs more updates: test_terminal_value."""
    task = diffcontrol.make("pendulum")
    cfg = resolve_config(task, "windows", updates=600, eval_every=150, eval_episodes=64)
    cfg = cfg.replace(target_return=float("nan"))
    result = train(task, cfg)
    returns = [p["eval_return"] for p in result.curve]
    assert returns[0] < -1000
    assert max(returns) > -300, returns

    # keep_best: the returned controller is the one at the best evaluation point, and its
    # in-simulator evaluation reproduces that point's figure.
    best = int(np.argmax(returns))
    assert result.metrics["returned_update"] == result.curve[best]["update"]
    assert result.metrics["final_eval_return"] == returns[best]
    trainer = make_trainer(task, cfg)
    k_eval = jax.random.split(jax.random.PRNGKey(cfg.seed))[1]
    again = float(jnp.mean(trainer.evaluate(result.controller, result.params, k_eval)))
    assert again == pytest.approx(returns[best], rel=1e-4)

    # And in Gymnasium's own Pendulum-v1.
    policy = policies.NumpyPolicy(policies.controller_to_dict(result.controller, task))
    assert evaluate(policy, task, episodes=10, seed=0).mean > -400


@pytest.mark.slow
def test_resume_continues_exactly(tmp_path):
    """A run interrupted after a checkpoint and resumed ends with the same weights."""
    task = diffcontrol.make("cartpole")
    cfg = resolve_config(task, updates=30, eval_every=10, eval_episodes=2)
    whole = train(task, cfg)

    calls = []

    def interrupt_at_third_point(line):
        calls.append(line)
        if len(calls) == 3:  # points at updates 0, 10, 20: checkpoint at 10 exists
            raise KeyboardInterrupt

    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train(task, cfg, out_dir=out, progress=interrupt_at_third_point)
    with np.load(out / "checkpoint.npz", allow_pickle=False) as data:
        meta = json.loads(bytes(data["header"]).decode())["meta"]
    assert meta["curve"][-1]["update"] == 10
    resumed = train(task, cfg, out_dir=out, resume=True)
    for a, b in zip(_weights(whole.controller), _weights(resumed.controller), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert [p["update"] for p in resumed.curve] == [0, 10, 20, 30]
    assert resumed.metrics["simulated_steps"] == whole.metrics["simulated_steps"]


@pytest.mark.slow
def test_same_seed_same_run_and_different_seed_differs():
    task = diffcontrol.make("pendulum")
    cfg = resolve_config(task, updates=4, batch=2, window=5, eval_every=2, eval_episodes=2)
    a, b = train(task, cfg), train(task, cfg)
    c = train(task, cfg.replace(seed=1))
    wa, wb, wc = (np.concatenate([np.ravel(x) for x in _weights(r.controller)]) for r in (a, b, c))
    np.testing.assert_array_equal(wa, wb)
    assert not np.allclose(wa, wc)


@pytest.mark.slow
def test_chunks_are_compiled_once():
    """After the first chunk, further chunks compile nothing: one compiled chunk is reused."""
    task = diffcontrol.make("pendulum")
    compiles = []
    at_point = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    cfg = resolve_config(task, updates=12, batch=2, window=3, eval_every=3, eval_episodes=2)
    with listening("event_duration", listener):
        # on_point: one call per evaluation point (progress also carries warnings).
        train(task, cfg.replace(hidden=(7,)), on_point=lambda p, c: at_point.append(len(compiles)))
    assert len(at_point) == 5  # updates 0, 3, 6, 9, 12
    assert at_point[0] > 0  # the chunk was compiled (a shape no other test uses)
    assert at_point[2:] == [at_point[1]] * 3, at_point


@pytest.mark.slow
def test_divergence_is_reported_not_hidden():
    """A non-finite loss stops the run with a message naming the fix."""
    task = diffcontrol.make("pendulum")
    cfg = resolve_config(task, "windows", updates=4, batch=2, window=3, eval_every=2)
    cfg = cfg.replace(eval_episodes=2)

    def nan_loss(params, state, action, next_state, reward):
        return jnp.sqrt(-1.0 - reward**2)  # nan

    with pytest.raises(TrainingDiverged, match="learning-rate"):
        train(task, cfg, step_loss=nan_loss)


@pytest.mark.slow
def test_user_loss_changes_what_is_learned():
    """A user-supplied loss from Python replaces the task's (here: push the cart right)."""
    task = diffcontrol.make("cartpole")
    cfg = resolve_config(task, updates=20, eval_every=20, eval_episodes=2, learning_rate=0.05)
    cfg = cfg.replace(keep_best=False)  # the best *return* would be the untrained controller

    def go_right(params, state, action, next_state, reward):
        return -next_state[1]  # maximise the cart's speed to the right

    result = train(task, cfg, step_loss=go_right)
    obs = jax.vmap(lambda k: task.reset(k, None))(jax.random.split(jax.random.PRNGKey(0), 64))
    pushes = jax.vmap(result.controller)(obs)
    assert float(jnp.mean(pushes)) > 0.9


def test_load_drops_into_a_plain_gymnasium_loop(cartpole_run, pendulum_run):
    for run, env_id in ((cartpole_run, "CartPole-v1"), (pendulum_run, "Pendulum-v1")):
        policy = diffcontrol.load(run)
        env = gymnasium.make(env_id)
        obs, _ = env.reset(seed=0)
        for _ in range(20):
            action = policy(obs)
            assert env.action_space.contains(action), action
            obs, _, term, trunc, _ = env.step(action)
            if term or trunc:
                break


def test_numpy_policy_matches_the_jax_controller(pendulum_run, cartpole_run):
    for run in (pendulum_run, cartpole_run):
        doc = policies.read_model(run)
        ctrl = policies.controller_from_dict(doc)
        policy = policies.NumpyPolicy(doc)
        obs = np.random.default_rng(0).normal(size=(50, doc["observation"]["size"]))
        with jax.default_matmul_precision("highest"):  # a GPU would use TF32 otherwise
            want = np.asarray(jax.vmap(ctrl)(jnp.asarray(obs, jnp.float32)))
        np.testing.assert_allclose(policy.action(obs), want, atol=1e-5)


@pytest.mark.slow
def test_corrupt_checkpoint_is_a_clear_error(tmp_path):
    task = diffcontrol.make("cartpole")
    cfg = resolve_config(task, updates=2, eval_every=2, eval_episodes=2)
    out = tmp_path / "run"
    train(task, cfg, out_dir=out)
    (out / "checkpoint.npz").write_bytes(b"garbage")
    with pytest.raises(diffcontrol.errors.ModelFileError, match="corrupt"):
        train(task, cfg, out_dir=out, resume=True)


@pytest.mark.slow
@pytest.mark.parametrize("task", ["cartpole", "cartpole-swingup"])
def test_persistent_compile_cache_hits_on_a_second_run(tmp_path, task):
    """A second identical command loads every program from the cache and compiles nothing.

    JAX refuses to cache programs with host callbacks (such as Equinox's runtime checks, in
    every Diffrax solve unless the command line turns them into NaN), so this also guards
    against one sneaking into the training programs, of a discrete-time task and of an ODE.
    """
    env = dict(os.environ, DIFFCONTROL_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("EQX_ON_ERROR", None)  # what the command sets itself, not the test session's
    args = ["train", task, "--updates", "4", "--eval-every", "2", "--final-eval", "1"]
    args += ["--no-animation", "--quiet", "--hidden", "5,5"]
    args += ["--eval-episodes", "2"] if task == "cartpole" else []
    caches = []
    for i in range(2):
        cmd = [sys.executable, "-m", "diffcontrol.cli", *args, "--out", str(tmp_path / f"r{i}")]
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        caches.append(
            json.loads((tmp_path / f"r{i}" / "metrics.json").read_text())["compile_cache"]
        )
    # JAX does not even look up a program with a host callback: such a program shows as a
    # request neither hit nor missed, so every request must be a miss, then a hit
    assert caches[0]["misses"] >= 2 and caches[0]["hits"] == 0
    assert caches[0]["misses"] == caches[0]["requests"]
    assert caches[1]["misses"] == 0 and caches[1]["hits"] == caches[1]["requests"]
    if task != "cartpole":
        return
    # Entries swapped among themselves (each another program's valid executable) are not run
    # as this program's: every one is a miss, compiled again, and the run is the same.
    entries = sorted((tmp_path / "cache").glob("*-cache"))  # JAX's file cache: KEY-cache
    contents = [p.read_bytes() for p in entries]
    assert len(contents) >= 2
    for path, content in zip(entries, contents[1:] + contents[:1], strict=True):
        path.write_bytes(content)
    cmd = [sys.executable, "-m", "diffcontrol.cli", *args, "--out", str(tmp_path / "r2")]
    subprocess.run(cmd, check=True, env=env, capture_output=True)
    swapped = json.loads((tmp_path / "r2" / "metrics.json").read_text())["compile_cache"]
    assert swapped["hits"] == 0 and swapped["misses"] == swapped["requests"] >= 2
    models = [json.loads((tmp_path / r / "model.json").read_text()) for r in ("r0", "r2")]
    assert models[0]["network"] == models[1]["network"]


@pytest.mark.slow  # three to six small trainings: 3-6 s
def test_the_next_seed_in_a_process_reuses_the_compiled_programs():
    """A second run of the same settings (another seed) compiles nothing; a setting that
    changes the training program (the window) compiles its start and chunk again, but not the
    evaluation, which the window does not change."""
    task = diffcontrol.make("cartpole")
    cfg = resolve_config(task, updates=4, batch=2, window=3, eval_every=2, eval_episodes=2)
    first = train(task, cfg)
    second = train(task, cfg.replace(seed=1))
    other = train(task, cfg.replace(seed=1, window=4))
    assert second.metrics["timings"]["compile_programs"] == 0  # the seed is an argument
    assert other.metrics["timings"]["compile_programs"] == 2  # the start and the chunk
    assert _weights(first.controller)[0].shape == _weights(second.controller)[0].shape
    assert not np.array_equal(_weights(first.controller)[0], _weights(second.controller)[0])
    clear_compiled()  # the kept programs let go: the next run compiles (or loads) all three
    assert train(task, cfg.replace(seed=2)).metrics["timings"]["compile_programs"] == 3


@pytest.mark.slow  # three to six small trainings: 3-6 s
def test_a_kept_trainer_runs_what_a_fresh_one_runs_and_a_changed_task_gets_its_own(monkeypatch):
    """The next seed reuses the kept trainer and traces nothing, with the weights a fresh
    process would give; an attribute of the task changed in between is a new trainer, and a
    custom loss is never kept (it could read a global changed since)."""
    task = diffcontrol.make("cartpole")  # the process's shared instance: changed by monkeypatch
    cfg = resolve_config(task, updates=4, batch=2, window=3, eval_every=2, eval_episodes=2)
    train(task, cfg)
    kept = train(task, cfg.replace(seed=1))
    assert kept.metrics["timings"]["compile_programs"] == 0
    clear_compiled()
    fresh = train(task, cfg.replace(seed=1))
    for a, b in zip(_weights(kept.controller), _weights(fresh.controller)):
        np.testing.assert_array_equal(a, b)
    monkeypatch.setattr(task, "episode_length", 7)  # the evaluation's episodes
    short = train(task, cfg.replace(seed=1))
    assert short.metrics["timings"]["compile_programs"] >= 2
    assert short.metrics["curve"][0]["eval_return"] <= 7
    scale = [1.0]

    def loss(params, state, action, next_state, reward):
        return -scale[0] * reward

    train(task, cfg, step_loss=loss)
    scale[0] = 0.0  # a zero loss: the weights cannot move
    still = train(task, cfg, step_loss=loss)
    assert still.metrics["timings"]["compile_programs"] >= 1


@pytest.mark.slow  # three to six small trainings: 3-6 s
def test_a_program_that_calls_back_into_python_is_not_reused():
    """Two runs whose losses call back into Python (each its own list) each call their own."""
    task = diffcontrol.make("cartpole")
    cfg = resolve_config(task, updates=2, batch=2, window=3, eval_every=2, eval_episodes=2)
    seen: list[list] = [[], []]
    for i in range(2):

        def loss(params, state, action, next_state, reward, calls=seen[i]):
            jax.debug.callback(lambda r: calls.append(1), reward)
            return -reward

        train(task, cfg, step_loss=loss)
    assert len(seen[0]) == len(seen[1]) > 0
