"""The one training loop (``training._loop``), on a stand-in trainer whose programs are plain
NumPy: the early stop, the keep-best rule, a sweep member that diverges, and the trainer
interface that the library's trainers implement."""

from __future__ import annotations

import inspect
import math
from types import SimpleNamespace

import numpy as np
import pytest

from diffcontrol.training import ODETrainer, Trainer
from diffcontrol.training._bptt import PopulationTrainer
from diffcontrol.training._interface import TrainerInterface
from diffcontrol.training._loop import Loop
from diffcontrol.training._sweep import SweepLoop

EVERY = 2  # updates per chunk


class Counting:
    """A trainer whose controller is a number: each update adds the run's ``step`` to it, and
    an evaluation returns the controller (a NaN step makes the loss and weights NaN)."""

    episode_length = 1

    def __init__(self, config):
        self.config = config

    def summarize(self, returns):
        return float(np.mean(returns)), 0.0

    def pick(self, controller, returns):
        return controller

    def counts(self, ts):
        return {"simulated_steps": int(ts.update)}

    def point_extras(self, ts, returns):
        return {}

    def check(self, old, new, losses):
        return []


def _chunk(steps):
    """A sweep chunk over members with these per-update ``steps``."""

    def chunk(ts, params, totals):
        go = np.clip(np.asarray(totals) - ts.update, 0, EVERY)
        grid = np.arange(EVERY)[None, :] < go[:, None]  # which of the chunk's updates run
        loss = np.where(grid, np.asarray(steps)[:, None], np.nan)
        new = SimpleNamespace(
            update=ts.update + go,
            controller=ts.controller + go * np.asarray(steps),
            finished_episodes=ts.finished_episodes,
            finished_return_sum=ts.finished_return_sum,
        )
        return new, SimpleNamespace(loss=loss, grad_norm=np.abs(loss))

    return chunk


def _state(n):
    zeros = np.zeros(n)
    return SimpleNamespace(
        update=np.zeros(n, int),
        controller=zeros,
        finished_episodes=zeros,
        finished_return_sum=zeros,
    )


def _evaluate(controller, params, key):
    return np.asarray(controller, float)[..., None]  # one episode per run


def _sweep(steps, configs):
    n = len(configs)
    loop = SweepLoop(
        Counting(configs[0]),
        configs,
        None,
        _evaluate,
        None,
        [(configs[0].updates, _chunk(steps))],
        lambda line: None,
        shard=lambda x: x,
        logged=None,
    )
    nan = np.full(n, math.nan)
    loop.record(_state(n), nan, nan, np.ones(n, bool))
    return loop, loop.run(_state(n))


def _config(updates=6, target=math.nan):
    return SimpleNamespace(updates=updates, target_return=target, seed=0, learning_rate=1.0)


def test_members_stop_at_their_target_or_budget_and_a_diverged_one_stops_alone():
    configs = [_config(), _config(target=4.0), _config(), _config(target=6.0)]
    loop, ts = _sweep([1.0, 1.0, math.nan, 1.0], configs)
    # member 1 reaches 4 at update 4 and stops; member 3 reaches 6 only with its last update,
    # which is not an early stop; member 2 diverges in its first chunk and trains no more
    assert ts.update.tolist() == [6, 4, 2, 6]
    assert loop.stopped.tolist() == [False, True, False, False]
    assert loop.diverged.tolist() == [False, False, True, False]
    assert [len(c) for c in loop.curves] == [4, 3, 1, 4]
    assert [p["update"] for p in loop.curves[0]] == [0, 2, 4, 6]
    assert loop.curves[0][1]["loss"] == 1.0  # the mean over the chunk's updates
    np.testing.assert_array_equal(loop.best, [6.0, 4.0, 0.0, 6.0])


def test_a_tie_keeps_the_later_point_and_a_worse_one_keeps_the_best():
    loop = Loop(
        Counting(_config()),
        [_config()],
        None,
        lambda controller, params, key: np.asarray([min(controller, 2.0) - (controller > 3)]),
        None,
        [],
        lambda line: None,
    )
    nan = np.full(1, math.nan)
    for value in (0.0, 2.0, 3.0, 4.0):  # returns 0, 2, 2 (a tie), 1 (worse)
        loop.record(SimpleNamespace(update=value, controller=value), nan, nan, np.ones(1, bool))
    assert loop.best_index.tolist() == [2]
    assert loop.best == 3.0


@pytest.mark.parametrize("trainer", [Trainer, PopulationTrainer, ODETrainer])
def test_each_trainer_implements_the_interface(trainer):
    for name, member in vars(TrainerInterface).items():
        if name.startswith("_") or not callable(member):
            continue
        ours = getattr(trainer, name, None)
        assert callable(ours), f"{trainer.__name__} has no {name}"
        arity = len(inspect.signature(member).parameters)  # the driver passes them by position
        assert len(inspect.signature(ours).parameters) == arity, (trainer.__name__, name)
    fields = getattr(trainer, "__dataclass_fields__", {})
    for name in ("episode_length", "config"):
        assert name in fields or hasattr(trainer, name), (trainer.__name__, name)


@pytest.mark.parametrize(
    "task, given, message",
    [
        ("cartpole", "trajectory_loss", "is discrete-time: pass step_loss"),
        ("cartpole-swingup", "step_loss", "is continuous-time: pass trajectory_loss"),
    ],
)
def test_train_takes_the_loss_its_registered_trainer_takes(task, given, message):
    """``train`` asks the trainer registered for the config's class which loss it takes, and
    refuses the other by name before anything compiles."""
    import diffcontrol
    from diffcontrol.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        diffcontrol.train(diffcontrol.make(task), **{given: lambda *args: 0.0})
