"""Configuration: frozen, typed dataclasses whose fields are the command line's flags.

Every configuration (the training ones here, the settings of the work around training in
``settings``) is a ``_Config``: each field states its help, its default and its bounds in its
metadata (``_opt``), which both the command line (``cli._args.config_specs``) and the
configuration's own check on construction read, so a bad value is caught where it is set,
with a message that names it. ``TrainConfig`` is for discrete-time tasks (windowed BPTT),
``ODETrainConfig`` for continuous-time ones (differentiation through an ODE solve).

Importing this module imports no JAX.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError

SCHEDULES = ("constant", "cosine", "warmup_cosine")
ACTIVATION_NAMES = ("tanh", "relu", "sigmoid", "elu")
"""The controllers' hidden activations (``controllers.ACTIVATIONS``)."""
HEADS = ("linear", "tanh", "sigmoid", "sign", "argmax")
"""The controllers' action heads (``controllers.apply_head``)."""
GRADIENT_METHODS = ("checkpoint", "backsolve", "forward")
SOLVER_NAMES = ("tsit5", "dopri5", "dopri8", "bosh3", "kvaerno5")

MAX_COUNT = 2**31 - 1
"""The largest count (updates, steps, seed): the trainer counts in 32-bit integers."""
MAX_HORIZON_S = 1e6
"""The longest closed-loop solve (s): float32 times lose the solver's steps beyond it."""
MAX_WIDTH = 2**20
"""The largest batch, population, layer width or number of episodes a run may ask for."""
MAX_VALUE_GRID = 1001
"""The finest grid of a terminal value (a planner's, a training window's): points per state
axis; its table is solved once per load or run (Pendulum: 0.8 GB)."""


def _opt(doc: str, default: Any, metavar: str | None = None, **rule: Any) -> Any:
    """A config field: its help ``doc``, its ``default``, the flag's ``metavar``, and the rule
    its values follow: an integer's bounds ``low`` (default 1) and ``high`` (default
    ``MAX_COUNT``), and ``must``, the words for them where the bounds alone would mislead; a
    float's ``form`` (``FLOAT_FORMS``; default finite) and ``high``; text's ``choices``; a
    ``flag`` named otherwise than the field."""
    meta = {"help": doc, "metavar": metavar, **rule}
    if isinstance(default, dict):
        return field(default_factory=dict, metadata=meta)
    return field(default=default, metadata=meta)


FLOAT_FORMS = {
    "finite": (math.isfinite, "a finite number"),
    "any": (lambda v: not math.isinf(v), "a finite number, or nan"),
    "positive": (lambda v: 0 < v < math.inf, "a finite number > 0"),
    "nonneg": (lambda v: 0 <= v < math.inf, "a finite number >= 0"),
    "fraction": (lambda v: 0 <= v <= 1, "in [0, 1]"),
    "share": (lambda v: 0 < v <= 1, "a fraction in (0, 1]"),
    "tolerance": (lambda v: 0 < v < 1, "a tolerance in (0, 1) such as 1e-3 or 1e-6"),
}
"""The forms of a float field (``_opt(form=...)``): which values it takes, in words."""


def int_bounds(f: dataclasses.Field) -> tuple[int, int]:
    """The bounds of the integer config field ``f``: its ``low`` (default 1) and ``high``
    (default ``MAX_COUNT``), which the command line and the config's own check both state."""
    return f.metadata.get("low", 1), f.metadata.get("high", MAX_COUNT)


def _least(low: int) -> str:
    return {0: "an integer >= 0", 1: "a positive integer"}.get(low, f"an integer >= {low}")


def _checked(f: dataclasses.Field, value: Any) -> Any:
    """``value`` of the field ``f``, checked against the field's declared type and the rule in
    its metadata; integers given for floats and lists for tuples are converted.

    Raises:
        ConfigError: a value of another type or outside the rule, naming the field.
    """
    name, meta, declared = f.name, f.metadata, str(f.type).removesuffix(" | None")
    if declared == "int":
        low, high = int_bounds(f)
        if not isinstance(value, int) or isinstance(value, bool):
            raise ConfigError(f"{name} must be {_least(low)}, got {value!r}")
        if not low <= value <= high:
            must = meta.get("must") or (_least(low) if value < low else f"in {low} ... {high:,}")
            raise ConfigError(f"{name} must be {must}, got {value!r}")
    elif declared == "float":
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise ConfigError(f"{name} must be a number, got {value!r}")
        ok, must = FLOAT_FORMS[meta.get("form", "finite")]
        high = meta.get("high", math.inf)
        if not ok(value) or value > high:
            upto = f" up to {high:g}" if high < math.inf else ""
            raise ConfigError(f"{name} must be {must}{upto}, got {value!r}")
        return float(value)
    elif declared in ("str", "bool"):
        if type(value).__name__ != declared:
            what = "text" if declared == "str" else "true or false"
            raise ConfigError(f"{name} must be {what}, got {value!r}")
        choices = meta.get("choices", (value,))
        if value not in choices:
            empty = "empty or " if "" in choices else ""
            choose = ", ".join(c for c in choices if c)
            raise ConfigError(f"{name} must be {empty}one of {choose}, got {value!r}")
    elif declared == "tuple[int, ...]":
        return layer_widths(name, value)
    elif declared == "tuple[str, ...]":
        if not isinstance(value, tuple | list) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{name} must be names such as ('g',), got {value!r}")
        return tuple(value)
    elif declared == "tuple[tuple[str, float], ...]":
        return _pairs(name, value)
    return value


class _Config:
    """What every configuration shares: each field checked on construction against its type
    and the rule in its metadata (``_checked``), then the rules between fields (``_check``);
    ``replace`` and JSON round trips."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None and str(f.type).endswith("| None"):
                continue
            checked = _checked(f, value)
            if checked is not value:
                object.__setattr__(self, f.name, checked)
        self._check()

    def _check(self) -> None:
        """The rules between fields, where a configuration has any."""

    def replace(self, **changes: Any) -> Any:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (tuples become lists, nan becomes None)."""
        out = dataclasses.asdict(self)
        for name, value in out.items():
            if isinstance(value, float) and math.isnan(value):
                out[name] = None
            elif isinstance(value, tuple):
                out[name] = [list(v) if isinstance(v, tuple) else v for v in value]
        return out

    @classmethod
    def from_json(cls, data: Any) -> Any:
        """Inverse of ``to_json``; anything but an object of the fields is a ``ConfigError``."""
        if not isinstance(data, dict):
            raise ConfigError(f"{cls.__name__} must be an object, got {data!r}")
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = set(data) - set(fields)
        if unknown:
            raise ConfigError(f"unknown {cls.__name__} keys {sorted(unknown)}")
        data = dict(data)
        for name, value in list(data.items()):
            if value is None and isinstance(fields[name].default, float):
                data[name] = math.nan
        return cls(**data)


def layer_widths(name: str, value: Any) -> tuple[int, ...]:
    """``value`` as layer widths (positive, at most ``MAX_WIDTH``).

    Raises:
        ConfigError: anything else, naming the setting ``name``.
    """
    if not isinstance(value, tuple | list) or not all(
        isinstance(w, int) and not isinstance(w, bool) and w > 0 for w in value
    ):
        raise ConfigError(f"{name} must be positive layer widths such as (64, 64), got {value!r}")
    if any(w > MAX_WIDTH for w in value):  # the rule it breaks is the size, not the sign
        raise ConfigError(
            f"{name} must be layer widths of at most {MAX_WIDTH:,} (2^20) units each, got {value!r}"
        )
    return tuple(value)


def _pairs(name: str, value: Any) -> tuple[tuple[str, float], ...]:
    """``value`` as ``((name, value), ...)``: names are text, values finite numbers."""
    ok = isinstance(value, tuple | list) and all(
        isinstance(p, tuple | list)
        and len(p) == 2
        and isinstance(p[0], str)
        and isinstance(p[1], int | float)
        and not isinstance(p[1], bool)
        for p in value
    )
    if not ok:
        raise ConfigError(
            f"{name} must be (name, value) pairs such as (('g', 9.81),), got {value!r}"
        )
    for key, v in value:
        if not math.isfinite(v):
            raise ConfigError(f"parameter override {key}={v!r} is not a finite number")
    return tuple((key, float(v)) for key, v in value)


# The fields both training configurations have, with their help and rules; a configuration
# gives each its own default (and, where the two trainers differ, its own help).
_SHARED = {
    "seed": ("PRNG seed: a run is a function of this seed.", {"low": 0}),
    "learning_rate": (
        "Adam learning rate (peak value for schedules).",
        {"metavar": "LR", "form": "positive"},
    ),
    "lr_schedule": (
        "Learning-rate schedule: constant, cosine (decay to lr_final_fraction), or "
        "warmup_cosine (5% linear warm-up, then cosine).",
        {"choices": SCHEDULES},
    ),
    "lr_final_fraction": ("Final learning rate as a fraction of the peak.", {"form": "fraction"}),
    "grad_clip": (
        "Clip the gradient's global norm to this; 0 disables.",
        {"metavar": "NORM", "form": "nonneg"},
    ),
    "hidden": ("Hidden layer widths of the MLP controller.", {}),
    "activation": ("Hidden activation: tanh, relu, sigmoid or elu.", {"choices": ACTIVATION_NAMES}),
    "loss": ("Training loss; empty means the task's default (see `list`).", {}),
    "eval_every": (
        "Updates between evaluation points; also the length of one compiled training chunk.",
        {},
    ),
    "params": ("Overrides of the simulator's physical parameters, as (name, value) pairs.", {}),
    "curriculum_fraction": (
        "Share of the updates over which the curriculum's horizon grows to the full one.",
        {"form": "share"},
    ),
}


def _shared(name: str, default: Any, doc: str | None = None, **rule: Any) -> Any:
    """The shared training field ``name`` (``_SHARED``) with this ``default``."""
    help, own = _SHARED.get(name, ("", {}))
    return _opt(doc or help, default, **{**own, **rule})


_VALUE_GRID = f"0 (no terminal value) or 3 ... {MAX_VALUE_GRID} grid points per state axis"


def _head(doc: str) -> Any:
    return _opt(doc, "", "HEAD", choices=("", *HEADS))


@dataclass(frozen=True)
class TrainConfig(_Config):
    """Settings of one training run by backpropagation through time (BPTT).

    The trainer keeps ``batch`` copies of the simulator running side by side. Every
    ``window`` steps it differentiates the mean training loss of those steps through the
    simulator and the controller, takes one optimiser step, and carries the simulator states
    on without their gradient (truncated BPTT). An episode that terminates or reaches
    ``horizon`` steps restarts from the task's reset distribution. ``window == horizon`` is
    full BPTT over whole episodes.
    """

    seed: int = _shared("seed", 0)
    updates: int = _opt("Number of gradient updates (one per window).", default=500)
    batch: int = _opt(
        "Simulations run side by side (initial states under vmap).", default=32, high=MAX_WIDTH
    )
    window: int = _opt(
        "Simulated steps per update (the truncated-BPTT window).", default=200, metavar="STEPS"
    )
    horizon: int = _opt(
        "Training episode length in steps before a restart; 0 means the task's standard "
        "episode length.",
        default=0,
        metavar="STEPS",
        low=0,
    )
    learning_rate: float = _shared("learning_rate", 3e-3)
    lr_schedule: str = _shared("lr_schedule", "cosine")
    lr_final_fraction: float = _shared("lr_final_fraction", 0.05)
    grad_clip: float = _shared("grad_clip", 1.0)
    hidden: tuple[int, ...] = _shared("hidden", (64, 64))
    activation: str = _shared("activation", "tanh")
    head: str = _head("Action head; empty means the task's (tanh for torques, sign for pushes).")
    head_slope_floor: float = _opt(
        "Least slope of a tanh or sigmoid head in the backward pass, as a fraction of its "
        "slope at 0: an actuator held at its bound still gets a gradient (the forward pass "
        "is unchanged); 0 keeps the exact slope.",
        default=0.0,
        metavar="X",
        form="fraction",
    )
    loss: str = _shared("loss", "")
    eval_every: int = _shared("eval_every", 50)
    eval_episodes: int = _opt(
        "Episodes of the in-simulator evaluation at each evaluation point.",
        default=32,
        high=MAX_WIDTH,
    )
    target_return: float = _opt(
        "Stop early once the in-simulator evaluation return reaches this; nan disables.",
        default=math.nan,
        metavar="R",
        form="any",
    )
    keep_best: bool = _opt(
        "Return the controller of the evaluation point with the best in-simulator return "
        "(a held-out set of simulated starts, not the Gymnasium seeds) instead of the last one. "
        "It ranks by the task's return: turn it off when a custom loss aims at something else.",
        default=True,
    )
    params: tuple[tuple[str, float], ...] = _shared("params", ())
    population: int = _opt(
        "Controllers trained side by side from different random initialisations (restarts "
        "against local optima, one compiled program); the best at each evaluation point is "
        "kept.",
        default=1,
        high=MAX_WIDTH,
    )
    curriculum_start: float = _opt(
        "Growing-horizon curriculum: training episodes first restart after this fraction of "
        "horizon, growing linearly to all of it over curriculum_fraction of the updates; 1 "
        "turns it off.",
        default=1.0,
        form="share",
    )
    curriculum_fraction: float = _shared("curriculum_fraction", 0.5)
    final_window: int = _opt(
        "Window curriculum: the last final_window_fraction of the updates use windows of this "
        "many steps, so that an action is credited with what it does over a longer stretch once "
        "the short window has learned the basics (a long window from the start can settle in a "
        "poor local optimum); 0 keeps window throughout.",
        default=0,
        metavar="STEPS",
        low=0,
    )
    final_window_fraction: float = _opt(
        "Share of the updates, at the end of the run, that use final_window.",
        default=0.25,
        form="share",
    )
    value_grid: int = _opt(
        "Terminal cost of every window: minus the value V_0 (the best return of a whole "
        "episode from there) of the window's last state, from the task's grid dynamic program "
        "(diffcontrol.optimal) with this many points per state axis, so that a short window "
        "is credited with what comes after it; for a loss that is minus the reward, and tasks "
        "with a state grid (Pendulum). 0: none.",
        default=0,
        metavar="POINTS",
        low=0,
        high=MAX_VALUE_GRID,
        must=_VALUE_GRID,
    )
    value_time: bool = _opt(
        "With value_grid: the value with the steps the training episode has left (V_t) instead "
        "of a whole episode's (V_0), for tasks where waiting costs nothing under V_0 (the "
        "mountain car: a car at rest can still reach the flag in a whole episode); the "
        "training program then holds the whole table, horizon + 1 grids.",
        default=False,
    )

    def _check(self) -> None:
        if self.value_grid in (1, 2):
            raise ConfigError(f"value_grid must be {_VALUE_GRID}, got {self.value_grid!r}")
        if self.value_time and not self.value_grid:
            raise ConfigError(
                "value_time needs a value_grid: set one (--value-grid N, e.g. 101) or leave "
                "value_time off"
            )

    @property
    def final_window_start(self) -> int:
        """The first update whose window is ``final_window`` long (``updates`` when no update
        is: ``final_window`` is 0 or equal to ``window``)."""
        if self.final_window in (0, self.window):
            return self.updates
        return self.updates - round(self.final_window_fraction * self.updates)

    def simulated_steps(self, updates: int) -> int:
        """Simulator steps taken by the first ``updates`` updates of one run (one population
        member): ``batch`` simulations times the windows' lengths."""
        short = min(updates, self.final_window_start)
        return self.batch * (short * self.window + (updates - short) * self.final_window)


@dataclass(frozen=True)
class ODETrainConfig(_Config):
    """Settings of one training run through a continuous-time closed loop (a neural ODE).

    Every update solves the closed loop (the controller inside the ODE's right-hand side)
    from the task's initial state over ``horizon_s`` seconds with an adaptive solver, saves
    ``saves`` equally spaced points, differentiates the task's loss on that trajectory
    through the solve by ``gradient``, and takes one Adam step; with ``window_s``, one step
    per window of the horizon instead, each differentiated through its own window only.
    ``population`` controllers from different initial weights train side by side under
    ``vmap``; the best is returned.
    """

    seed: int = _shared("seed", 0)
    updates: int = _opt("Number of gradient updates (one closed-loop solve each).", default=1000)
    horizon_s: float = _opt(
        "Length of the closed-loop solve (s), at most 1e6 (the solve's times are float32).",
        default=1.0,
        metavar="S",
        form="positive",
        high=MAX_HORIZON_S,
    )
    saves: int = _opt(
        "Equally spaced saved points on [0, horizon_s] that the loss sees (both ends included).",
        default=50,
        low=2,
    )
    solver: str = _opt(
        "Adaptive ODE solver: tsit5, dopri5, dopri8, bosh3 or kvaerno5 (implicit, for stiff "
        "loops).",
        default="tsit5",
        choices=SOLVER_NAMES,
    )
    rtol: float = _opt(
        "Relative tolerance of the adaptive step-size controller.", 1e-3, "TOL", form="tolerance"
    )
    atol: float = _opt(
        "Absolute tolerance of the adaptive step-size controller.", 1e-6, "TOL", form="tolerance"
    )
    max_steps: int = _opt(
        "Step budget of one solve; a solve that needs more fails (and is reported).",
        default=4096,
    )
    gradient: str = _opt(
        "How the loss is differentiated through the solve: checkpoint (reverse mode through "
        "the solver's steps, exact for the discretised solve; default), backsolve (the "
        "continuous adjoint: O(1) memory but an APPROXIMATE gradient) or forward (forward "
        "mode, one tangent per weight; cheapest for a few dozen weights).",
        default="checkpoint",
        metavar="METHOD",
        choices=GRADIENT_METHODS,
    )
    starts: int = _opt(
        "Initial states per update, drawn from the task's reset distribution "
        "(ContinuousTask.reset; by default the one initial state); the loss is their mean and "
        "the evaluation uses as many fixed starts.",
        default=1,
        high=MAX_WIDTH,
    )
    window_s: float = _opt(
        "Truncated BPTT through the solve: each update cuts the horizon into about "
        "horizon_s / window_s consecutive windows (of the curriculum's horizon where it grows), "
        "differentiates each window's loss (the task's loss on that window's saved points, its "
        "end terms at every window's end) through that window's solve only and takes one "
        "optimiser step per window (a schedule spans them all); a window's end states start "
        "the next without gradient. Long chaotic solves give useless gradients; 0 (or "
        "window_s >= horizon_s) differentiates the whole horizon.",
        default=2.0,
        metavar="S",
        form="nonneg",
    )
    population: int = _opt(
        "Controllers from different initial weights trained side by side under vmap; the best "
        "is returned. Helps against local minima (a cart that never moves).",
        default=4,
        high=MAX_WIDTH,
    )
    curriculum_start: float = _opt(
        "Growing-horizon curriculum: the first update sees this fraction of horizon_s, growing "
        "linearly to all of it over curriculum_fraction of the updates; 1 turns it off.",
        default=1.0,
        form="share",
    )
    curriculum_fraction: float = _shared("curriculum_fraction", 0.5)
    learning_rate: float = _shared("learning_rate", 0.01)
    lr_schedule: str = _shared("lr_schedule", "constant")
    lr_final_fraction: float = _shared("lr_final_fraction", 0.05)
    grad_clip: float = _shared("grad_clip", 1.0)
    hidden: tuple[int, ...] = _shared("hidden", (32, 32))
    activation: str = _shared("activation", "tanh")
    head: str = _head("Action head; empty means the task's (linear: an unbounded force).")
    loss: str = _shared("loss", "")
    eval_every: int = _shared("eval_every", 50)
    keep_best: bool = _opt(
        "Return the controller (and population member) with the lowest loss over the "
        "evaluation points, each a full-horizon solve, instead of the last one.",
        default=True,
    )
    params: tuple[tuple[str, float], ...] = _shared("params", ())

    @property
    def target_return(self) -> float:
        """No early stop for continuous-time runs (the driver asks every config)."""
        return math.nan

    @classmethod
    def from_json(cls, data: Any) -> Any:
        """As ``_Config.from_json``; a configuration written before ``window_s`` existed
        differentiated its whole horizon, and resumes so (``window_s = 0``)."""
        if isinstance(data, dict) and "window_s" not in data:
            data = {**data, "window_s": 0.0}
        return super().from_json(data)
