"""Compile once: a run compiles a fixed, small set of programs, and calling a compiled trainer
step again compiles nothing."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol import _timing
from diffcontrol.training import make_trainer, resolve_config, task_params

TINY = dict(updates=6, eval_every=3, eval_episodes=2, batch=4, window=5)


@pytest.mark.slow  # a trainer's start and chunk compiled: 2.6 s on one core
def test_second_call_of_a_jitted_trainer_step_does_not_recompile():
    _timing.watch_compiles()
    task = diffcontrol.make("cartpole")
    config = task.default_config().replace(**TINY)
    trainer = make_trainer(task, config)
    params = task_params(task)
    ts = jax.jit(trainer.init)(jax.random.PRNGKey(0), params)
    chunk = jax.jit(trainer.chunk)
    total = np.int32(config.updates)
    ts1, _ = chunk(ts, params, total)
    before = _timing.compiled_programs()
    ts2, stats = chunk(ts1, params, total)
    jax.block_until_ready(ts2)
    assert _timing.compiled_programs() == before
    assert int(ts2.update) == 2 * config.eval_every and np.all(np.isfinite(stats.loss))


@pytest.mark.slow  # two runs from a cold in-memory cache: about 2.5 s
@pytest.mark.filterwarnings("ignore::diffcontrol.errors.TrainingWarning")  # 6 updates
def test_a_discrete_run_compiles_three_programs_whatever_its_seed():
    """The start (keys, controller, simulations), the evaluation and the chunk; none for the
    checks between chunks, and as many for another seed (the seed is an argument)."""
    task = diffcontrol.make("pendulum")
    counts = []
    for seed in (0, 1):
        # the windows recipe: the defaults' grid value compiles its solve on a first run
        config = dataclasses.replace(resolve_config(task, "windows", **TINY), seed=seed)
        result = diffcontrol.train(task, config)
        counts.append(result.metrics["timings"]["compile_programs"])
        assert len(result.curve) == 3
    assert counts[0] <= 3 and counts[1] <= counts[0]
