"""The one loop every training turns: evaluate, keep each run's best point, step a chunk of
updates, until each run has spent its updates or reached its target return.

It turns for one run of a trainer (``train``: ``_driver.TrainLoop``), for a sweep's members,
the same trainer under ``vmap`` (``_sweep.SweepLoop``: every array of their training state
leads with the member axis), and for a planner's distillation, one DAgger round a chunk
(``mpc._distil``). The hooks say how the runs sit in the state (their defaults: one run) and
what happens around each evaluation point and chunk; the loop, the keep-best rule and the
early stop are the same for all.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from jaxtyping import PyTree


class Loop:
    """The evaluation points and chunks of ``len(configs)`` runs trained side by side.

    Args:
        trainer: one run's trainer, whose hooks (``summarize``, ``counts``,
            ``point_extras``, ``pick``, ``check``) make and judge each run's points.
        configs: each run's settings (its budget of updates, its target return).
        params: the task's parameters, passed to every program.
        evaluate: the compiled evaluation, ``(controllers, params, key) -> returns``.
        eval_key: its key (a sweep's: one per member).
        chunks: ``(end update, compiled chunk)`` for each stage still to run
            (``Trainer.stages``); a chunk takes the update count each run stops at.
        say: called with progress lines and notes.
        curves, best_index, best: a resumed run's evaluation points, the index of its best
            and that point's controller.
        t_start: when the runs' clock started (``seconds``; default: now).
    """

    def __init__(
        self,
        trainer: Any,
        configs: Sequence[Any],
        params: PyTree,
        evaluate: Any,
        eval_key: Any,
        chunks: list[tuple[int, Any]],
        say: Callable[[str], None],
        *,
        curves: list[list[dict[str, Any]]] | None = None,
        best_index: Sequence[int] | None = None,
        best: Any = None,
        t_start: float | None = None,
    ) -> None:
        n = len(configs)
        self.trainer, self.configs, self.n, self.say = trainer, list(configs), n, say
        self.params, self.evaluate, self.eval_key, self.chunks = params, evaluate, eval_key, chunks
        self.curves = curves if curves is not None else [[] for _ in range(n)]
        self.best_index = np.zeros(n, int) if best_index is None else np.array(best_index)
        self.best = best
        self.budgets = np.array([c.updates for c in configs])
        self.targets = np.array([c.target_return for c in configs], float)
        self.stopped = np.zeros(n, bool)  # early: the target reached before the budget
        self.diverged = np.zeros(n, bool)
        self.eval_seconds = 0.0
        self.last_returns: np.ndarray | None = None
        self.t_start = time.perf_counter() if t_start is None else t_start

    # --- how the runs sit in the training state (defaults: one run) ------------------------

    def per_run(self, x: np.ndarray) -> Sequence[np.ndarray]:
        """An output of the programs (the returns, a chunk's losses), split into the runs'."""
        return [x]

    def updates(self, ts: Any) -> np.ndarray:
        """Each run's update count."""
        return np.atleast_1d(np.asarray(ts.update))

    def state_of(self, ts: Any, i: int) -> Any:
        """What the trainer's ``counts`` and ``point_extras`` read of run ``i``'s state."""
        return ts

    def keep(self, ts: Any, returns: np.ndarray, improved: np.ndarray) -> None:
        """Make ``self.best`` hold the controllers of the runs that ``improved``."""
        if improved[0]:
            self.best = self.trainer.pick(ts.controller, returns)

    def total(self, totals: np.ndarray) -> Any:
        """The chunk's argument: the update count each run stops at."""
        return np.int32(totals[0])

    def lost(self, old: Any, new: Any, losses: list[np.ndarray], means: np.ndarray) -> np.ndarray:
        """Which runs diverged in the chunk from ``old`` to ``new``; one run's trainer raises
        instead (``check``), or gives notes."""
        for note in self.trainer.check(old, new, losses[0]):
            self.say("note: " + note)
        return np.zeros(1, bool)

    # --- what happens around the points and chunks ------------------------------------------

    def point(
        self,
        ts: Any,
        i: int,
        update: int,
        returns: np.ndarray,
        loss: float,
        grad_norm: float,
        seconds: float,
    ) -> dict[str, Any]:
        """Run ``i``'s evaluation point (its curve's entry): from its ``returns``, the mean
        ``loss`` and ``grad_norm`` of the chunk before it and the trainer's hooks."""
        mean, std = self.trainer.summarize(returns)
        state = self.state_of(ts, i)
        return {
            "update": update,
            **self.trainer.counts(state),
            "seconds": seconds,
            "loss": loss,
            "grad_norm": grad_norm,
            "eval_return": mean,
            "eval_return_std": std,
            **self.trainer.point_extras(state, returns),
        }

    def seconds(self) -> float:
        """The runs' training time so far, for the points."""
        return time.perf_counter() - self.t_start

    def points_made(self, ts: Any, returns: np.ndarray, points: list[dict | None]) -> None:
        """After an evaluation point (``None`` for a run that took no part): progress, logs."""

    def chunk_done(
        self, updates: np.ndarray, done: np.ndarray, losses: list[np.ndarray], grads: list
    ) -> None:
        """After a chunk: each run's per-update losses and gradient norms, from ``updates``."""

    def saved(self, ts: Any) -> None:
        """After the point that follows a chunk (a checkpoint)."""

    # --- the loop -----------------------------------------------------------------------------

    def record(self, ts: Any, losses: np.ndarray, grads: np.ndarray, active: np.ndarray) -> None:
        """Evaluate every run, add a point to the curves of the ``active`` ones and keep the
        controller of each that did at least as well as its best so far (``>=``: among equal
        returns, CartPole's 500s, the later, longer-trained controller)."""
        t_eval = time.perf_counter()
        returns = np.asarray(self.evaluate(ts.controller, self.params, self.eval_key))
        self.eval_seconds += time.perf_counter() - t_eval
        self.last_returns = returns
        per_run, updates, seconds = self.per_run(returns), self.updates(ts), self.seconds()
        improved = np.zeros(self.n, bool)
        points: list[dict | None] = [None] * self.n
        for i in np.flatnonzero(active):
            point = points[i] = self.point(
                ts, i, int(updates[i]), per_run[i], float(losses[i]), float(grads[i]), seconds
            )
            mean = point["eval_return"]
            curve = self.curves[i]
            curve.append(point)
            so_far = curve[self.best_index[i]]["eval_return"]
            if len(curve) == 1 or math.isnan(so_far) or mean >= so_far:
                improved[i], self.best_index[i] = True, len(curve) - 1
        self.keep(ts, returns, improved)
        self.points_made(ts, returns, points)

    def run(self, ts: Any) -> Any:
        """Step chunks until every run has spent its updates, reached its target or
        diverged; returns the last training state."""
        while True:
            updates = self.updates(ts)
            last = np.array([c[-1]["eval_return"] if c else math.nan for c in self.curves])
            going = ~(self.stopped | self.diverged) & (updates < self.budgets)
            with np.errstate(invalid="ignore"):  # no target (NaN), or a NaN return
                self.stopped |= going & (last >= self.targets)
            totals = np.where(self.stopped | self.diverged, updates, self.budgets)
            if np.all(updates >= totals):
                return ts
            # the stage of the runs still training (they step together)
            first = np.min(updates[updates < totals])
            end, chunk = next((e, c) for e, c in self.chunks if first < e)
            totals = np.minimum(totals, end)  # a stage's last chunk may be short
            new, stats = chunk(ts, self.params, self.total(totals))
            done = self.updates(new) - updates  # updates past a run's total were skipped
            losses = [x[:k] for x, k in zip(self.per_run(np.asarray(stats.loss)), done)]
            grads = [x[:k] for x, k in zip(self.per_run(np.asarray(stats.grad_norm)), done)]
            with warnings.catch_warnings():  # a run whose updates all failed holds only nan
                warnings.simplefilter("ignore", RuntimeWarning)
                loss_mean = np.array([np.nanmean(x) if len(x) else math.nan for x in losses])
                grad_mean = np.array([np.nanmean(x) if len(x) else math.nan for x in grads])
            lost = self.lost(ts, new, losses, loss_mean) & (done > 0)
            self.diverged |= lost
            self.chunk_done(updates, done, losses, grads)
            ts = new
            self.record(ts, loss_mean, grad_mean, (done > 0) & ~lost)
            self.saved(ts)
