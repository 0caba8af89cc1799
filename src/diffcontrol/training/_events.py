"""Training curves as TensorBoard event files (``--log-dir``), written with tensorboardX.

Per update: ``train/loss``, ``train/grad_norm`` and ``train/learning_rate``; per evaluation
point: ``eval/return`` and ``eval/return_std``; the step is the update. A run is one
directory of event files under the log directory (``tensorboard --logdir DIR`` shows each as
a run): the run itself, a sweep's members (``member_000``, ...) or its summary, a loop's
rounds (``round_1``, ...) beside the loop's own per-round figures.
"""

from __future__ import annotations

import atexit
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ._bptt import learning_rate_schedule


def learning_rates(config: Any, first: int, count: int, learning_rate: Any = None) -> np.ndarray:
    """The learning rates of updates ``first + 1 ... first + count`` under ``config``'s
    schedule (``learning_rate`` replaces the configured peak, as a sweep member's does)."""
    schedule = learning_rate_schedule(config, learning_rate)
    counts = np.arange(first, first + count)
    if not callable(schedule):
        return np.full(count, float(schedule))
    return np.asarray(schedule(counts), np.float64).reshape(count)


class EventLog:
    """TensorBoard event files under ``log_dir``, one directory per run name (``""``: the
    log directory itself).

    Raises:
        ConfigError: tensorboardX is not installed, or ``log_dir`` is a file.
    """

    def __init__(self, log_dir: str | Path):
        try:
            from tensorboardX import SummaryWriter
        except ImportError:
            raise ConfigError(
                '--log-dir needs the tensorboardX package: pip install "diffcontrol[tensorboard]"'
            ) from None
        self.dir = Path(log_dir)
        if self.dir.exists() and not self.dir.is_dir():
            raise ConfigError(f"--log-dir {self.dir} is a file; name a directory")
        self._writer_class = SummaryWriter
        self._writers: dict[str, Any] = {}
        atexit.register(self.close)  # an interrupted run keeps what it logged

    def _writer(self, run: str) -> Any:
        if run not in self._writers:
            path = self.dir / run if run else self.dir
            self._writers[run] = self._writer_class(logdir=str(path), flush_secs=30)
        return self._writers[run]

    def updates(
        self,
        first: int,
        losses: Sequence[float],
        grad_norms: Sequence[float],
        rates: Sequence[float],
        run: str = "",
    ) -> None:
        """The updates ``first + 1, first + 2, ...``: their losses, gradient norms and
        learning rates."""
        w = self._writer(run)
        for k, (loss, norm, rate) in enumerate(zip(losses, grad_norms, rates, strict=True)):
            step = first + k + 1
            w.add_scalar("train/loss", float(loss), step)
            w.add_scalar("train/grad_norm", float(norm), step)
            w.add_scalar("train/learning_rate", float(rate), step)

    def point(self, point: Mapping[str, Any], run: str = "") -> None:
        """An evaluation point of the learning curve (``eval_return`` at ``update``)."""
        self.scalars(
            {"eval/return": point["eval_return"], "eval/return_std": point["eval_return_std"]},
            int(point["update"]),
            run,
        )

    def scalars(self, values: Mapping[str, float | None], step: int, run: str = "") -> None:
        """Any figures at ``step`` (``None`` skipped)."""
        w = self._writer(run)
        for tag, value in values.items():
            if value is not None:
                w.add_scalar(tag, float(value), step)

    def close(self) -> None:
        """Flush and close the event files."""
        for w in self._writers.values():
            w.close()
        self._writers.clear()


def open_log(log_dir: str | Path | None) -> EventLog | None:
    """An ``EventLog`` for ``log_dir``, or ``None`` without one."""
    return None if log_dir is None else EventLog(log_dir)


def summary(values: np.ndarray) -> dict[str, float]:
    """The median, best and worst of the members' figures (non-finite ones left out)."""
    finite = values[np.isfinite(values)]
    if not finite.size:
        return {"median": math.nan, "max": math.nan, "min": math.nan}
    return {
        "median": float(np.median(finite)),
        "max": float(finite.max()),
        "min": float(finite.min()),
    }
