"""Warnings about a run that finished but likely did not do what was meant.

Three symptoms that a run's own numbers show plainly and a user easily misses:

- the gradient is exactly zero at each of the first updates: the loss does not depend on the
  controller (a step loss that reads only ``state``, a trajectory loss of the initial state),
  so the weights never change;
- the training loss has not moved at all over the first updates: a constant loss, or a
  learning rate too small to change a float32 loss;
- ``keep_best`` returns the untrained controller: no later evaluation point beat update 0,
  because training never improved the task's return or the return became non-finite.

Each is said once: by ``warnings.warn`` (a ``TrainingWarning``), as a line ``warning: ...``
through the ``progress`` callback, and in ``metrics["warnings"]``.
"""

from __future__ import annotations

import math
import sys
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import TrainingWarning

ZERO_GRADIENT_UPDATES = 3
"""The zero-gradient warning needs an exactly zero gradient at each of this many first updates."""
STALL_UPDATES = 20
"""The unmoved-loss warning needs the same loss at each of this many first updates."""


class Diagnostics:
    """Watches a run's per-update statistics and its curve; collects the warnings.

    Args:
        say: the ``progress`` callback (or a no-op).
        updates: the run's budget of updates.
        start_update: the update the run starts from; the first-update checks only watch a
            run that starts from scratch (a resumed run did them before).
        previous: warnings of the run before a resume (from its checkpoint).
    """

    def __init__(
        self,
        say: Callable[[str], None],
        updates: int,
        start_update: int = 0,
        previous: list[str] | None = None,
    ):
        self.say = say
        self.warnings: list[str] = list(previous or [])
        self._watching = start_update == 0
        self._zero_needed = min(ZERO_GRADIENT_UPDATES, updates)
        self._stall_needed = min(STALL_UPDATES, updates)
        self._losses: list[float] = []
        self._grad_norms: list[float] = []

    def _warn(self, message: str) -> None:
        if message in self.warnings:
            return
        self.warnings.append(message)
        warnings.warn(message, TrainingWarning, stacklevel=_outside_training())
        self.say("warning: " + message)

    def after_chunk(self, losses: np.ndarray, grad_norms: np.ndarray, learning_rate: float) -> None:
        """The per-update losses and gradient norms of the chunk just run."""
        if not self._watching:
            return
        self._losses += [float(x) for x in losses]
        self._grad_norms += [float(x) for x in grad_norms]
        self._judge(learning_rate, final=False)

    def _judge(self, learning_rate: float, final: bool) -> None:
        norms, losses = self._grad_norms, self._losses
        if len(norms) >= self._zero_needed or (final and norms):
            first = norms[: self._zero_needed]
            if all(g == 0.0 for g in first):
                self._warn(
                    "the loss does not depend on the controller: its gradient with respect to "
                    f"the weights is exactly 0 at each of the first {len(first)} updates, so "
                    "training changes nothing; make the loss depend on what the controller does "
                    "(the action or the next state of a step, the solved trajectory)"
                )
                self._watching = False
                return
        if len(losses) >= self._stall_needed or (final and len(losses) >= 2):
            first = losses[: self._stall_needed]
            if len(first) >= 2 and math.isfinite(first[0]) and all(x == first[0] for x in first):
                self._warn(
                    f"the training loss has not moved: it is {first[0]:.6g} at each of the "
                    f"first {len(first)} updates; the loss may not change with the controller, "
                    f"or the learning rate ({learning_rate:g}) is too small to change it"
                )
            self._watching = False

    def finish(self, config: Any, curve: list[dict[str, Any]], returned_update: int) -> None:
        """At the end of a run: the first-update checks of a short run, and keep-best."""
        if self._watching:
            self._judge(config.learning_rate, final=True)
        trained = curve[-1]["update"] if curve else 0
        if not (config.keep_best and returned_update == 0 and trained > 0):
            return
        first = curve[0]["eval_return"]
        later = [p for p in curve[1:] if p["update"] > 0]
        if any(not math.isfinite(p["eval_return"]) for p in later):
            why = (
                "the evaluation return became non-finite after it (training diverged); lower "
                "the learning rate or set grad_clip"
            )
        else:
            best = max(later, key=lambda p: p["eval_return"])
            why = (
                f"no later evaluation point improved on its return {first:.6g} (the best "
                f"later one: {best['eval_return']:.6g} at update {best['update']}); training "
                "did not improve the task's return: check the loss (keep_best ranks by the task's "
                "return, not by a custom loss), or train longer or at another learning rate"
            )
        self._warn(
            f"keep_best returned the untrained controller (update 0 of {trained}): {why}; "
            "keep_best=False returns the last controller"
        )


def _outside_training() -> int:
    """The ``stacklevel`` of the first frame outside ``diffcontrol.training``: the warning
    points at the line that called ``train``."""
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_globals.get("__name__", "").startswith(__package__):
        frame, level = frame.f_back, level + 1
    return level
