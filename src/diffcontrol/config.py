"""Training configuration: frozen, typed dataclasses whose field docs are the CLI help.

``TrainConfig`` is for discrete-time tasks (windowed BPTT), ``ODETrainConfig`` for
continuous-time ones (differentiation through an ODE solve). Both validate on construction,
so a bad value is caught where it is set, with a message that names it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from .errors import ConfigError

SCHEDULES = ("constant", "cosine", "warmup_cosine")


def _opt(doc: str, default: Any, metavar: str | None = None, **cli: Any) -> Any:
    """A config field: its help ``doc``, its ``default``, and how the command line reads it:
    the flag's ``metavar``, a number's bounds ``low`` (default 1) and ``high`` (default
    ``MAX_COUNT``), a float's ``form`` (``"fraction"``, ``"positive"``; ``"any"`` takes nan),
    text's ``choices``, or a ``flag`` named otherwise than the field."""
    meta = {"help": doc, "metavar": metavar, **cli}
    if isinstance(default, dict):
        return field(default_factory=dict, metadata=meta)
    return field(default=default, metadata=meta)


MAX_COUNT = 2**31 - 1
"""The largest count (updates, steps, seed): the trainer counts in 32-bit integers."""
MAX_HORIZON_S = 1e6
"""The longest closed-loop solve (s): float32 times lose the solver's steps beyond it."""
MAX_WIDTH = 2**20
"""The largest batch, population, layer width or number of episodes a run may ask for."""
MAX_VALUE_GRID = 1001
"""The finest grid of a terminal value (a planner's, a training window's): points per state
axis; its table is solved once per load or run (Pendulum: 0.8 GB)."""
_WIDE = ("batch", "eval_episodes", "population", "starts")


def int_bounds(f: dataclasses.Field) -> tuple[int, int]:
    """The bounds of the integer config field ``f``: its ``low`` (default 1) and ``high``
    (default ``MAX_WIDTH`` for the sizes of what runs side by side, else ``MAX_COUNT``), which
    the command line and the config's own checks both state."""
    high = MAX_WIDTH if f.name in _WIDE else MAX_COUNT
    return f.metadata.get("low", 1), f.metadata.get("high", high)


class _Config:
    """What every configuration shares: validation helpers, ``replace`` and JSON round trips."""

    def _check_types(self) -> None:
        """Every field has its declared type (numbers of the right kind, strings, a tuple of
        widths, (name, value) pairs), within the bounds a run can hold; integers given for
        floats and lists for tuples are converted."""
        for f in dataclasses.fields(self):
            value, declared = getattr(self, f.name), str(f.type)
            if declared == "int":
                if not isinstance(value, int) or isinstance(value, bool):
                    raise ConfigError(f"{f.name} must be an integer, got {value!r}")
                low, limit = int_bounds(f)
                if not (0 <= value <= limit):  # 0: a field's own check names its lower bound
                    raise ConfigError(f"{f.name} must be in {low} ... {limit:,}, got {value!r}")
            elif declared == "float":
                if not isinstance(value, int | float) or isinstance(value, bool):
                    raise ConfigError(f"{f.name} must be a number, got {value!r}")
                object.__setattr__(self, f.name, float(value))
            elif declared in ("str", "bool"):
                if type(value).__name__ != declared:
                    what = "text" if declared == "str" else "true or false"
                    raise ConfigError(f"{f.name} must be {what}, got {value!r}")
            elif declared == "tuple[int, ...]":
                object.__setattr__(self, f.name, layer_widths(f.name, value))
            elif f.name == "params":
                object.__setattr__(self, f.name, _pairs(value))

    def _check_common(self) -> None:
        from .controllers import ACTIVATIONS, HEADS  # JAX: config is read by --help

        if self.activation not in ACTIVATIONS:
            raise ConfigError(
                f"activation must be one of {', '.join(ACTIVATIONS)}, got {self.activation!r}"
            )
        if self.head and self.head not in HEADS:
            raise ConfigError(
                f"head must be empty (the task's) or one of {', '.join(HEADS)}, got {self.head!r}"
            )
        for name in ("updates", "eval_every"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
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

    def replace(self, **changes: Any) -> Any:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (tuples become lists, nan becomes None)."""
        out = dataclasses.asdict(self)
        out["hidden"] = list(self.hidden)
        out["params"] = [list(p) for p in self.params]
        for name, value in out.items():
            if isinstance(value, float) and math.isnan(value):
                out[name] = None
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Any:
        """Inverse of ``to_json``; unknown keys are an error."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = set(data) - set(fields)
        if unknown:
            raise ConfigError(f"unknown config keys {sorted(unknown)}")
        data = dict(data)
        if "hidden" in data:
            data["hidden"] = tuple(data["hidden"])
        if "params" in data:
            data["params"] = tuple((str(k), float(v)) for k, v in data["params"])
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


def _pairs(value: Any) -> tuple[tuple[str, float], ...]:
    """``params`` as ``((name, value), ...)``: names are text, values finite numbers."""
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
            f"params must be (name, value) pairs such as (('g', 9.81),), got {value!r}"
        )
    return tuple((name, float(v)) for name, v in value)


def _check_curriculum(config: Any) -> None:
    if not (0 < config.curriculum_start <= 1):
        raise ConfigError(
            f"curriculum_start must be a fraction in (0, 1] (1 turns the curriculum off), "
            f"got {config.curriculum_start!r}"
        )
    if not (0 < config.curriculum_fraction <= 1):
        raise ConfigError(
            f"curriculum_fraction must be a fraction in (0, 1], got {config.curriculum_fraction!r}"
        )


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

    seed: int = _opt("PRNG seed: a run is a function of this seed.", default=0, low=0)
    updates: int = _opt("Number of gradient updates (one per window).", default=500)
    batch: int = _opt("Simulations run side by side (initial states under vmap).", default=32)
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
    learning_rate: float = _opt(
        "Adam learning rate (peak value for schedules).", default=3e-3, metavar="LR"
    )
    lr_schedule: str = _opt(
        "Learning-rate schedule: constant, cosine (decay to lr_final_fraction), or "
        "warmup_cosine (5% linear warm-up, then cosine).",
        default="cosine",
    )
    lr_final_fraction: float = _opt("Final learning rate as a fraction of the peak.", default=0.05)
    grad_clip: float = _opt(
        "Clip the gradient's global norm to this; 0 disables.", default=1.0, metavar="NORM"
    )
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
        metavar="R",
        form="any",
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
    population: int = _opt(
        "Controllers trained side by side from different random initialisations (restarts "
        "against local optima, one compiled program); the best at each evaluation point is "
        "kept.",
        default=1,
    )
    curriculum_start: float = _opt(
        "Growing-horizon curriculum: training episodes first restart after this fraction of "
        "horizon, growing linearly to all of it over curriculum_fraction of the updates; 1 "
        "turns it off.",
        default=1.0,
    )
    curriculum_fraction: float = _opt(
        "Share of the updates over which the curriculum's horizon grows to the full one.",
        default=0.5,
    )
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
        "Share of the updates, at the end of the run, that use final_window.", default=0.25
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
    )
    value_time: bool = _opt(
        "With value_grid: the value with the steps the training episode has left (V_t) instead "
        "of a whole episode's (V_0), for tasks where waiting costs nothing under V_0 (the "
        "mountain car: a car at rest can still reach the flag in a whole episode); the "
        "training program then holds the whole table, horizon + 1 grids.",
        default=False,
    )

    def __post_init__(self) -> None:
        grid = self.value_grid  # its range before the generic bound, which would name 1 and 2
        if (
            isinstance(grid, int)
            and not isinstance(grid, bool)
            and not (grid == 0 or 3 <= grid <= MAX_VALUE_GRID)
        ):
            raise ConfigError(
                f"value_grid must be 0 (no terminal value) or 3 ... {MAX_VALUE_GRID} grid points "
                f"per state axis, got {grid!r}"
            )
        self._check_types()
        if math.isinf(self.target_return):
            raise ConfigError(
                f"target_return must be a finite return, or nan to never stop early, got "
                f"{self.target_return!r}"
            )
        for name in ("batch", "window", "eval_episodes", "population"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if not isinstance(self.horizon, int) or self.horizon < 0:
            raise ConfigError(
                f"horizon must be 0 (the task's) or a positive integer, got {self.horizon!r}"
            )
        _check_curriculum(self)
        if self.value_time and not self.value_grid:
            raise ConfigError(
                "value_time needs a value_grid: set one (--value-grid N, e.g. 101) or leave "
                "value_time off"
            )
        if not (0 < self.final_window_fraction <= 1):
            raise ConfigError(
                f"final_window_fraction must be a fraction in (0, 1], got "
                f"{self.final_window_fraction!r}"
            )
        self._check_common()

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


GRADIENT_METHODS = ("checkpoint", "backsolve", "forward")
SOLVER_NAMES = ("tsit5", "dopri5", "dopri8", "bosh3", "kvaerno5")


@dataclass(frozen=True)
class ODETrainConfig(_Config):
    """Settings of one training run through a continuous-time closed loop (a neural ODE).

    Every update solves the closed loop (the controller inside the ODE's right-hand side)
    from the task's initial state over ``horizon_s`` seconds with an adaptive solver, saves
    ``saves`` equally spaced points, differentiates the task's loss on that trajectory
    through the solve by ``gradient``, and takes one Adam step. ``population`` controllers
    from different initial weights train side by side under ``vmap``; the best is returned.
    """

    seed: int = _opt("PRNG seed: a run is a function of this seed.", default=0, low=0)
    updates: int = _opt("Number of gradient updates (one closed-loop solve each).", default=1000)
    horizon_s: float = _opt(
        "Length of the closed-loop solve (s).", default=1.0, metavar="S", form="positive"
    )
    saves: int = _opt(
        "Equally spaced saved points on [0, horizon_s] that the loss sees (both ends included).",
        default=50,
    )
    solver: str = _opt(
        "Adaptive ODE solver: tsit5, dopri5, dopri8, bosh3 or kvaerno5 (implicit, for stiff "
        "loops).",
        default="tsit5",
    )
    rtol: float = _opt(
        "Relative tolerance of the adaptive step-size controller.", 1e-3, "TOL", form="positive"
    )
    atol: float = _opt(
        "Absolute tolerance of the adaptive step-size controller.", 1e-6, "TOL", form="positive"
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
    )
    starts: int = _opt(
        "Initial states per update, drawn from the task's reset distribution "
        "(ContinuousTask.reset; by default the one initial state); the loss is their mean and "
        "the evaluation uses as many fixed starts.",
        default=1,
    )
    population: int = _opt(
        "Controllers from different initial weights trained side by side under vmap; the best "
        "is returned. Helps against local minima (a cart that never moves).",
        default=1,
    )
    curriculum_start: float = _opt(
        "Growing-horizon curriculum: the first update sees this fraction of horizon_s, growing "
        "linearly to all of it over curriculum_fraction of the updates; 1 turns it off.",
        default=1.0,
    )
    curriculum_fraction: float = _opt(
        "Share of the updates over which the curriculum's horizon grows to horizon_s.",
        default=0.5,
    )
    learning_rate: float = _opt(
        "Adam learning rate (peak value for schedules).", default=0.05, metavar="LR"
    )
    lr_schedule: str = _opt(
        "Learning-rate schedule: constant, cosine (decay to lr_final_fraction), or "
        "warmup_cosine (5% linear warm-up, then cosine).",
        default="constant",
    )
    lr_final_fraction: float = _opt("Final learning rate as a fraction of the peak.", default=0.05)
    grad_clip: float = _opt(
        "Clip the gradient's global norm to this; 0 disables.", default=0.0, metavar="NORM"
    )
    hidden: tuple[int, ...] = _opt("Hidden layer widths of the MLP controller.", default=(8,))
    activation: str = _opt("Hidden activation: tanh, relu, sigmoid or elu.", default="tanh")
    head: str = _opt(
        "Action head; empty means the task's (linear: an unbounded force).", default=""
    )
    loss: str = _opt("Training loss; empty means the task's default (see `list`).", default="")
    eval_every: int = _opt(
        "Updates between evaluation points; also the length of one compiled training chunk.",
        default=50,
    )
    keep_best: bool = _opt(
        "Return the controller (and population member) with the lowest loss over the "
        "evaluation points, each a full-horizon solve, instead of the last one.",
        default=True,
    )
    params: tuple[tuple[str, float], ...] = _opt(
        "Overrides of the simulator's physical parameters, as (name, value) pairs.",
        default=(),
    )

    def __post_init__(self) -> None:
        self._check_types()
        for name in ("saves", "max_steps", "population", "starts"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if self.saves < 2:
            raise ConfigError(
                f"saves must be at least 2 (both ends of the horizon), got {self.saves}"
            )
        if not (math.isfinite(self.horizon_s) and 0 < self.horizon_s <= MAX_HORIZON_S):
            raise ConfigError(
                f"horizon_s must be a positive number of seconds up to {MAX_HORIZON_S:g} (the "
                f"solve's times are float32), got {self.horizon_s!r}"
            )
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 < value < 1):  # a tolerance of 100 % or more
                raise ConfigError(  # lets the solver take any step: no solve at all
                    f"{name} must be a tolerance in (0, 1) such as 1e-3 or 1e-6, got {value!r}"
                )
        if self.solver not in SOLVER_NAMES:
            raise ConfigError(
                f"solver must be one of {', '.join(SOLVER_NAMES)}, got {self.solver!r}"
            )
        if self.gradient not in GRADIENT_METHODS:
            raise ConfigError(
                f"gradient must be one of {', '.join(GRADIENT_METHODS)}, got {self.gradient!r}"
            )
        _check_curriculum(self)
        self._check_common()

    @property
    def target_return(self) -> float:
        """No early stop for continuous-time runs (the driver asks every config)."""
        return math.nan
