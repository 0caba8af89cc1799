"""Discrete-time training with a population (restarts) and a growing-horizon curriculum."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol.training import make_trainer
from diffcontrol.training._bptt import PopulationTrainer, Trainer

TASK = diffcontrol.make("pendulum")
TINY = dict(updates=20, eval_every=10, batch=4, window=10, eval_episodes=4, hidden=(8,))


@pytest.fixture(scope="module")
def population_run():
    config = TASK.default_config().replace(**TINY, population=3)
    return config, diffcontrol.train(TASK, config)


def test_one_member_is_the_plain_trainer():
    assert type(make_trainer(TASK, TASK.default_config())) is Trainer
    assert type(make_trainer(TASK, TASK.default_config().replace(population=2))) is (
        PopulationTrainer
    )


@pytest.mark.slow
def test_the_best_member_is_the_runs_controller(population_run):
    config, result = population_run
    trainer = make_trainer(TASK, config)
    key = jax.random.split(jax.random.PRNGKey(config.seed))[1]  # the driver's evaluation key
    returns = np.asarray(trainer.evaluate(_stack(result.controller, 3), result.params, key))
    assert returns.shape == (3, config.eval_episodes)
    # the returned controller is one controller, and it scores what the curve says
    assert result.controller(jnp.zeros(3)).shape == (1,)
    chosen = max(result.curve, key=lambda p: p["eval_return"])
    assert returns[0].mean() == pytest.approx(chosen["eval_return"], rel=1e-5)
    assert all(0 <= p["best_member"] < 3 for p in result.curve)
    steps = config.updates * config.window * config.batch * 3
    assert result.metrics["simulated_steps"] == steps


@pytest.mark.slow
def test_members_differ_and_the_best_mean_is_reported():
    config = TASK.default_config().replace(**TINY, population=3)
    trainer = make_trainer(TASK, config)
    ts = trainer.init(jax.random.PRNGKey(0), diffcontrol.training.task_params(TASK))
    w = np.asarray(ts.controller.layers[0].weight)
    assert not np.allclose(w[0], w[1])  # different initialisations
    returns = np.array([[-3.0, -5.0], [-1.0, -1.0], [np.nan, np.nan]])
    assert trainer.summarize(returns)[0] == -1.0
    picked = trainer.pick(ts.controller, returns)
    np.testing.assert_array_equal(np.asarray(picked.layers[0].weight), w[1])


@pytest.mark.slow
def test_a_diverged_member_is_dropped_not_fatal():
    config = TASK.default_config().replace(**TINY, population=2)
    trainer = make_trainer(TASK, config)
    ts = trainer.init(jax.random.PRNGKey(0), diffcontrol.training.task_params(TASK))
    bad = eqx.tree_at(
        lambda s: s.members.controller.layers[0].weight,
        ts,
        ts.members.controller.layers[0].weight.at[1].set(jnp.nan),
    )
    notes = trainer.check(ts, bad, np.array([1.0]))
    assert notes == ["population member 1 diverged; the others train on"]
    both = eqx.tree_at(
        lambda s: s.members.controller.layers[0].weight,
        ts,
        jnp.full_like(ts.members.controller.layers[0].weight, jnp.nan),
    )
    with pytest.raises(diffcontrol.errors.TrainingDiverged):
        trainer.check(ts, both, np.array([np.nan]))


def test_the_curriculum_grows_the_training_horizon():
    config = TASK.default_config().replace(updates=100, curriculum_start=0.25)
    trainer = make_trainer(TASK, config)
    horizons = [int(trainer.horizon_at(jnp.asarray(u))) for u in (0, 25, 50, 99)]
    assert horizons == [50, 125, 200, 200]  # 200 steps, grown over half of the updates
    assert make_trainer(TASK, TASK.default_config()).horizon_at(jnp.asarray(0)) == 200
    with pytest.raises(diffcontrol.ConfigError, match="curriculum_start"):
        TASK.default_config().replace(curriculum_start=0.0)


def _stack(controller, n):
    """``n`` copies of one controller with a leading member axis."""
    return jax.tree.map(lambda x: jnp.stack([x] * n) if eqx.is_array(x) else x, controller)
