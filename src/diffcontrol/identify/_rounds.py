"""What one round of ``loop`` needs besides the library's steps: exploration by the current
controller with noise, the model's error on data it has not been fitted to, and the start of
a grey box that is not handed the truth."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ..errors import ConfigError
from .ensemble import mean_spread
from .fitted import fitted_model
from .kinds import kind
from .steps import prediction_errors


class NoisyPolicy:
    """The current controller with exploration noise, for recording (``record``'s ``policy``).

    For a ``Box`` action space: ``a = clip(policy(obs) + noise * (high - low) / 2 * N(0, 1),
    low, high)``, so ``noise`` is a fraction of the half range (0.1 on the Pendulum: a standard
    deviation of 0.2 N m). For a ``Discrete`` space: with probability ``noise`` an action drawn
    uniformly (epsilon-greedy). The draws come from ``numpy.random.default_rng(seed)``.
    """

    def __init__(self, policy: Any, space: Any, noise: float, seed: int):
        from gymnasium import spaces

        self.policy, self.space, self.noise = policy, space, float(noise)
        self.doc = getattr(policy, "doc", None)  # what record's policy check reads
        self._discrete = isinstance(space, spaces.Discrete)
        self._rng = np.random.default_rng(seed)

    def __call__(self, obs: np.ndarray) -> Any:
        action = self.policy(obs)
        if self._discrete:
            if self._rng.random() < self.noise:
                return int(self.space.start + self._rng.integers(self.space.n))
            return action
        low, high = np.asarray(self.space.low, np.float64), np.asarray(self.space.high, np.float64)
        a = np.asarray(action, np.float64)
        a = a + self.noise * (high - low) / 2 * self._rng.standard_normal(a.shape)
        return np.clip(a, low, high).astype(self.space.dtype)

    def reset(self) -> None:
        """A new episode: the wrapped policy's ``reset`` (a planner's warm start), if any."""
        if callable(getattr(self.policy, "reset", None)):
            self.policy.reset()

    def __repr__(self) -> str:
        return f"NoisyPolicy(noise={self.noise})"


def parse_start(task: Any, start: dict[str, float] | None) -> dict[str, float]:
    """Check the starting values of a grey box (names among the task's parameters, finite).

    Raises:
        ConfigError: an unknown name or a non-finite value (naming it and the choices).
    """
    known = [f.name for f in dataclasses.fields(task.default_params())]
    start = dict(start or {})
    for name, value in start.items():
        if name not in known:
            raise ConfigError(
                f"--start {name}={value}: {task.name!r} has no parameter {name!r}; choose among "
                f"{known}"
            )
        if not isinstance(value, int | float) or not math.isfinite(value):
            raise ConfigError(f"--start {name}={value!r} is not a finite number; e.g. g=8")
    return {n: float(v) for n, v in start.items()}


def predictor_of(task: Any, fit_doc: dict | None, model: str, start: dict[str, float]):
    """``(task, params)`` that predicts as the model did before the new data: the fitted file
    ``fit_doc`` of the previous round, or for the first round the start physics (a grey box, or
    a hybrid whose correction is still zero); ``None`` for a black box that has no model yet."""
    if fit_doc is None:
        return kind(model).first_predictor(task, start)
    return kind(fit_doc["model"]).predictor(task, fitted_model(task, fit_doc))


def model_error(predictor: Any, data: Any, horizons: tuple[int, ...] = (1, 10)) -> dict | None:
    """RMS error of ``predictor`` on ``data`` (``steps.prediction_errors``: open loop from every
    recorded state with the recorded actions), ``{"rmse_H": value}`` per horizon, and for an
    ensemble its members' mean spread on the data (``"spread"``: how unsure it was there);
    None without a predictor."""
    if predictor is None:
        return None
    errors = prediction_errors(*predictor, data, horizons)
    found = {f"rmse_{h}": _finite(errors[h]["rmse"]) for h in horizons}
    spread = mean_spread(predictor[0], predictor[1], data)
    return found if spread is None else {**found, "spread": _finite(spread)}


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None
