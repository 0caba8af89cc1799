"""Training diagnostics: a loss that ignores the controller, a loss that never moves, and
``keep_best`` returning the untrained controller are warned about, sent to ``progress`` and
listed in ``metrics["warnings"]``."""

from __future__ import annotations

import math
import re

import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol.errors import TrainingWarning
from diffcontrol.training._diagnostics import STALL_UPDATES, ZERO_GRADIENT_UPDATES, Diagnostics

from .test_checks import Rail

ZERO_GRADIENT = "the loss does not depend on the controller"
STALLED = "the training loss has not moved"
UNTRAINED = r"keep_best returned the untrained controller \(update 0"


class Config:
    keep_best = True
    learning_rate = 0.01


def _diagnostics(updates=100):
    lines = []
    return Diagnostics(lines.append, updates), lines


def test_zero_gradient_at_the_first_updates():
    diag, lines = _diagnostics()
    zeros = np.zeros(ZERO_GRADIENT_UPDATES)
    with pytest.warns(TrainingWarning, match=ZERO_GRADIENT):
        diag.after_chunk(np.arange(ZERO_GRADIENT_UPDATES), zeros, 0.01)
    assert len(diag.warnings) == 1 and lines == ["warning: " + diag.warnings[0]]
    assert "\n" not in diag.warnings[0]

    diag, lines = _diagnostics()
    almost = zeros.copy()
    almost[-1] = 1e-30  # not exactly zero: the loss does depend on the controller
    diag.after_chunk(np.arange(ZERO_GRADIENT_UPDATES), almost, 0.01)
    assert diag.warnings == [] and lines == []


def test_zero_gradient_waits_for_enough_updates_or_the_end():
    diag, _ = _diagnostics()
    diag.after_chunk(np.ones(1), np.zeros(1), 0.01)  # one update per chunk (eval_every=1)
    assert diag.warnings == []
    with pytest.warns(TrainingWarning, match=ZERO_GRADIENT):
        diag.after_chunk(
            np.ones(ZERO_GRADIENT_UPDATES - 1), np.zeros(ZERO_GRADIENT_UPDATES - 1), 0.01
        )
    diag, _ = _diagnostics(updates=1)  # a run shorter than the window of the check
    with pytest.warns(TrainingWarning, match="at each of the first 1 updates"):
        diag.after_chunk(np.ones(1), np.zeros(1), 0.01)


def test_a_loss_that_never_moves():
    diag, _ = _diagnostics()
    n = STALL_UPDATES
    diag.after_chunk(np.full(n - 1, 0.25), np.ones(n - 1), 1e-30)
    assert diag.warnings == []  # not yet
    with pytest.warns(TrainingWarning, match=rf"{STALLED}: it is 0.25 at each of the first {n} "):
        diag.after_chunk(np.full(5, 0.25), np.ones(5), 1e-30)
    assert "learning rate (1e-30)" in diag.warnings[0]

    diag, _ = _diagnostics()
    losses = np.full(n, 0.25)
    losses[-1] = np.nextafter(0.25, 1.0)
    diag.after_chunk(losses, np.ones(n), 0.01)
    assert diag.warnings == []


def test_a_resumed_run_is_not_rechecked_and_keeps_its_warnings():
    diag = Diagnostics(lambda line: None, 100, start_update=50, previous=["earlier"])
    diag.after_chunk(np.ones(10), np.zeros(10), 0.01)
    assert diag.warnings == ["earlier"]


def _point(update, eval_return):
    return {"update": update, "eval_return": eval_return}


def test_keep_best_returning_the_untrained_controller():
    diag, lines = _diagnostics()
    curve = [_point(0, -10.0), _point(50, -30.0), _point(100, -20.0)]
    with pytest.warns(TrainingWarning, match=UNTRAINED) as record:
        diag.finish(Config(), curve, returned_update=0)
    message = str(record.pop(TrainingWarning).message)
    assert "never" not in message and "improved on its return -10" in message
    assert "(the best later one: -20 at update 100)" in message and lines

    diag, _ = _diagnostics()
    curve = [_point(0, -10.0), _point(50, -math.inf)]
    with pytest.warns(TrainingWarning, match=r"became non-finite after it \(training diverged\)"):
        diag.finish(Config(), curve, returned_update=0)

    # Not when training found better, when keep_best is off, or when nothing was trained.
    for curve, returned in (([_point(0, -10.0), _point(50, -5.0)], 50), ([_point(0, -1.0)], 0)):
        diag, _ = _diagnostics()
        diag.finish(Config(), curve, returned)
        assert diag.warnings == []
    off = Config()
    off.keep_best = False
    diag.finish(off, [_point(0, -10.0), _point(50, -30.0)], 0)
    assert diag.warnings == []


# --- through train ------------------------------------------------------------------------


class FixedStartRail(Rail):
    """The rail, always from the same state: with window = horizon every window is the same
    episode, so the loss changes only if the controller does."""

    name = "test-rail-fixed-start"

    def reset(self, key, params):
        return jnp.array([0.5, -0.2])


def _config(**changes):
    cfg = diffcontrol.TrainConfig(
        updates=6, batch=2, window=2, horizon=20, eval_every=3, eval_episodes=2
    )
    return cfg.replace(**changes)


@pytest.mark.slow
def test_train_warns_when_the_loss_ignores_the_action(tmp_path):
    """A loss of the state a step starts from: over one-step windows, no action reaches it."""
    lines = []

    def state_cost(params, state, action, next_state, reward):
        return jnp.sum(state**2)

    cfg = _config(window=1, keep_best=False)
    with pytest.warns(TrainingWarning, match=ZERO_GRADIENT) as record:
        result = diffcontrol.train(
            Rail(), cfg, step_loss=state_cost, progress=lines.append, out_dir=tmp_path / "run"
        )
    (warned,) = [w for w in record if issubclass(w.category, TrainingWarning)]
    assert warned.filename == __file__  # points at the line that called train
    (message,) = result.metrics["warnings"]
    assert message.startswith(ZERO_GRADIENT) and "warning: " + message in lines
    assert all(p["grad_norm"] == 0.0 for p in result.curve[1:])
    # The warning is part of the run: a resumed (here: finished) run still reports it.
    again = diffcontrol.train(
        Rail(), cfg, step_loss=state_cost, out_dir=tmp_path / "run", resume=True
    )
    assert again.metrics["warnings"] == [message]


@pytest.mark.slow
def test_train_warns_when_the_loss_never_moves():
    cfg = _config(updates=STALL_UPDATES, eval_every=STALL_UPDATES, window=20, learning_rate=1e-30)
    cfg = cfg.replace(keep_best=False)
    with pytest.warns(TrainingWarning, match=STALLED):
        result = diffcontrol.train(FixedStartRail(), cfg)
    assert result.metrics["warnings"][0].startswith(STALLED)


@pytest.mark.slow
def test_train_warns_when_keep_best_returns_the_untrained_controller():
    """Trained to maximise the cost: every later evaluation point is worse than the first."""

    def wrong_way(params, state, action, next_state, reward):
        return reward

    cfg = _config(learning_rate=0.1, window=5, eval_episodes=8)
    with pytest.warns(TrainingWarning, match=UNTRAINED):
        result = diffcontrol.train(Rail(), cfg, step_loss=wrong_way)
    assert result.metrics["returned_update"] == 0
    assert re.match(UNTRAINED, result.metrics["warnings"][-1])
    returns = [p["eval_return"] for p in result.curve]
    assert returns[0] > max(returns[1:])


@pytest.mark.slow
def test_a_healthy_run_has_no_warnings(recwarn):
    result = diffcontrol.train(Rail(), _config(keep_best=False, learning_rate=0.05))
    assert result.metrics["warnings"] == []
    assert not [w for w in recwarn if issubclass(w.category, TrainingWarning)]
    assert np.isfinite(result.curve[-1]["loss"])
