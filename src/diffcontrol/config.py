"""Training configuration: one frozen, typed dataclass whose field docs are the CLI help."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError

SCHEDULES = ("constant", "cosine", "warmup_cosine")


def _opt(doc: str, **kwargs: Any) -> Any:
    return field(metadata={"help": doc}, **kwargs)


@dataclass(frozen=True)
class TrainConfig:
    """Settings of one training run by backpropagation through time (BPTT).

    The trainer keeps ``batch`` copies of the simulator running side by side. Every
    ``window`` steps it differentiates the mean training loss of those steps through the
    simulator and the controller, takes one optimiser step, and carries the simulator states
    on without their gradient (truncated BPTT). An episode that terminates or reaches
    ``horizon`` steps restarts from the task's reset distribution. ``window == horizon`` is
    full BPTT over whole episodes.
    """

    seed: int = _opt("PRNG seed: a run is a function of this seed.", default=0)
    updates: int = _opt("Number of gradient updates (one per window).", default=500)
    batch: int = _opt("Simulations run side by side (initial states under vmap).", default=32)
    window: int = _opt("Simulated steps per update (the truncated-BPTT window).", default=200)
    horizon: int = _opt(
        "Training episode length in steps before a restart; 0 means the task's standard "
        "episode length.",
        default=0,
    )
    learning_rate: float = _opt("Adam learning rate (peak value for schedules).", default=3e-3)
    lr_schedule: str = _opt(
        "Learning-rate schedule: constant, cosine (decay to lr_final_fraction), or "
        "warmup_cosine (5% linear warm-up, then cosine).",
        default="cosine",
    )
    lr_final_fraction: float = _opt("Final learning rate as a fraction of the peak.", default=0.05)
    grad_clip: float = _opt("Clip the gradient's global norm to this; 0 disables.", default=1.0)
    hidden: tuple[int, ...] = _opt("Hidden layer widths of the MLP controller.", default=(64, 64))
    activation: str = _opt("Hidden activation: tanh, relu, sigmoid or elu.", default="tanh")
    head: str = _opt(
        "Action head; empty means the task's (tanh for torques, sign for pushes).", default=""
    )
    loss: str = _opt("Training loss; empty means the task's default (see `list`).", default="")
    eval_every: int = _opt(
        "Updates between evaluation points; also the length of one compiled training chunk.",
        default=50,
    )
    eval_episodes: int = _opt(
        "Episodes of the in-simulator evaluation at each evaluation point.", default=32
    )
    target_return: float = _opt(
        "Stop early once the in-simulator evaluation return reaches this; nan disables.",
        default=math.nan,
    )
    keep_best: bool = _opt(
        "Return the controller of the evaluation point with the best in-simulator return "
        "(a held-out set of simulated starts, not the Gymnasium seeds) instead of the last one. "
        "It ranks by the task's return: turn it off when a custom loss aims at something else.",
        default=True,
    )
    params: tuple[tuple[str, float], ...] = _opt(
        "Overrides of the simulator's physical parameters, as (name, value) pairs.",
        default=(),
    )

    def __post_init__(self) -> None:
        positive = ("updates", "batch", "window", "eval_every", "eval_episodes")
        for name in positive:
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if not isinstance(self.horizon, int) or self.horizon < 0:
            raise ConfigError(
                f"horizon must be 0 (the task's) or a positive integer, got {self.horizon!r}"
            )
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise ConfigError(
                f"learning_rate must be a positive finite number, got {self.learning_rate!r}"
            )
        if not isinstance(self.keep_best, bool):
            raise ConfigError(f"keep_best must be true or false, got {self.keep_best!r}")
        if not (math.isfinite(self.grad_clip) and self.grad_clip >= 0):
            raise ConfigError(f"grad_clip must be >= 0 (0 disables), got {self.grad_clip!r}")
        if not (0 <= self.lr_final_fraction <= 1):
            raise ConfigError(
                f"lr_final_fraction must be in [0, 1], got {self.lr_final_fraction!r}"
            )
        if self.lr_schedule not in SCHEDULES:
            raise ConfigError(
                f"lr_schedule must be one of {', '.join(SCHEDULES)}, got {self.lr_schedule!r}"
            )
        if not self.hidden or any((not isinstance(h, int)) or h <= 0 for h in self.hidden):
            raise ConfigError(f"hidden must be positive layer widths, got {self.hidden!r}")
        for name, value in self.params:
            if not math.isfinite(value):
                raise ConfigError(f"parameter override {name}={value!r} is not a finite number")

    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (tuples become lists, nan becomes None)."""
        out = dataclasses.asdict(self)
        out["hidden"] = list(self.hidden)
        out["params"] = [list(p) for p in self.params]
        if math.isnan(self.target_return):
            out["target_return"] = None
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of ``to_json``; unknown keys are an error."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ConfigError(f"unknown config keys {sorted(unknown)}")
        data = dict(data)
        if "hidden" in data:
            data["hidden"] = tuple(data["hidden"])
        if "params" in data:
            data["params"] = tuple((str(k), float(v)) for k, v in data["params"])
        if data.get("target_return") is None and "target_return" in data:
            data["target_return"] = math.nan
        return cls(**data)


def help_of(name: str) -> str:
    """The help text of a ``TrainConfig`` field."""
    for f in dataclasses.fields(TrainConfig):
        if f.name == name:
            return f.metadata["help"]
    raise KeyError(name)
