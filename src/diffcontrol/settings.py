"""Settings of the work around training: a recording (``identify.record_data``), a model fit
(``identify.fit_dir``), a loop on a real system (``runs.loop``), a comparison with RL
(``compare.run_comparison``) and a planning controller (``runs.plan_run``).
Configurations (``config._Config``), as the training ones are: frozen, typed dataclasses that
validate on construction, whose fields are the command line's flags (``diffcontrol
record/fit/loop/compare/plan``: the name, the default, the bounds and the help).

Importing this module imports no JAX.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .config import _VALUE_GRID, MAX_VALUE_GRID, MAX_WIDTH, _Config, _opt
from .errors import ConfigError

MODELS = ("params", "hybrid", "neural")
"""The names of the model kinds ``identify.fit`` learns (``identify.kinds``, their registry):
grey box, hybrid (physics plus a network), neural."""
CONTROLLERS = ("train", "plan")
"""What acts on the real system in a loop: an MLP trained through the fitted model, or a
planner through it (``mpc._config.loop_planner``)."""


@dataclass(frozen=True)
class RecordConfig(_Config):
    """Settings of ``identify.record_data``: episodes of a real system (or a task's own
    data), as a task's ``record_data`` hook takes them."""

    episodes: int = _opt("episodes (throws)", dataclasses.MISSING, "N", high=MAX_WIDTH)
    controller: str | None = _opt(
        "a run directory (or model.json) of `diffcontrol train`; random actions if omitted",
        None,
        "DIR",
    )
    seed: int = _opt("first reset seed", 0, "S", low=0)
    env_kwargs: dict[str, float] = _opt(
        "a numeric keyword argument of gymnasium.make (e.g. g=9.0), or a parameter of a task's "
        "own system (e.g. drag_coefficient=1.5); repeatable",
        {},
        "NAME=VALUE",
        flag="env_arg",
    )
    noise_m: float | None = _opt(
        "aiming tasks only: Gaussian noise (m) on the recorded distances (0)",
        None,
        "SD",
        form="nonneg",
    )
    max_steps: int | None = _opt("cut episodes at N", None, "N")


@dataclass(frozen=True)
class FitConfig(_Config):
    """Settings of ``identify.fit_dir``: a model of a task's system fitted to recorded data
    (``identify.fit`` takes them as keywords; Adam's ``steps`` and ``learning_rate`` default
    to the task's route's for the model type)."""

    names: tuple[str, ...] | None = _opt(
        "--model params: the parameters to fit (default: the task's, e.g. g,friction)",
        None,
        "NAMES",
        flag="params",
    )
    hidden: tuple[int, ...] = _opt("hidden layer widths of a network", (32, 32), "W,W")
    seed: int = _opt("the network's initial weights", 0, "S", low=0)
    members: int = _opt(
        "hybrid/neural: networks of an ensemble, fitted together from their own initial "
        "weights; the model is their mean and their spread its uncertainty (5 is usual)",
        1,
        "K",
        high=64,
    )
    bootstrap: bool = _opt(
        "an ensemble's members each fit a resample (with replacement) of the data", False
    )
    uncertainty_penalty: float = _opt(
        "an ensemble's weight of its members' spread (in units of the typical state change) "
        "in every step's loss when training through it",
        1.0,
        "W",
        form="nonneg",
    )
    window: int = _opt("steps predicted from every recorded state", 10, "N")
    steps: int | None = _opt("Adam steps", None, "N", low=0)
    lm_steps: int = _opt("Levenberg-Marquardt steps of a grey box", 20, "N", low=0)
    learning_rate: float | None = _opt("Adam learning rate", None, "LR", form="positive")
    holdout: float = _opt(
        "fraction of the episodes (throws) held out, the last ones (0 for none)",
        0.2,
        "F",
        form="fraction",
    )


@dataclass(frozen=True)
class LoopConfig(_Config):
    """Settings of ``runs.loop``: record -> fit -> train on a real system, a few rounds."""

    model: str = _opt("what to fit", "params", choices=MODELS)
    names: tuple[str, ...] | None = _opt(
        "the parameters a grey box fits (default: the task's)", None, "NAMES", flag="params"
    )
    rounds: int = _opt("rounds", 3, "R", high=MAX_WIDTH)
    episodes: int = _opt("real episodes recorded per round", 2, "N", high=MAX_WIDTH)
    real_steps: int | None = _opt(
        "real steps recorded per round instead of whole --episodes: episodes until N steps, "
        "the last cut short (a CartPole episode of random pushes lasts ~20 steps, one of a "
        "good controller 500)",
        None,
        "N",
    )
    updates: int | None = _opt("gradient updates of each round (default: the task's)", None, "N")
    fit_steps: int | None = _opt(
        "Adam steps of each round's fit (default: the model's, 2000 for a network)",
        None,
        "N",
        low=0,
    )
    seed: int = _opt("seed of training and recording", 0, "S", low=0)
    eval_episodes: int = _opt(
        "evaluation episodes of each round's controller on the real system", 20, "N", high=MAX_WIDTH
    )
    eval_seed: int = _opt(
        "first reset seed of the evaluation episodes on the real system; compare uses 1000",
        0,
        "S",
        low=0,
    )
    start: dict[str, float] = _opt(
        "a parameter the grey box or hybrid starts from instead of the nominal one "
        "(repeatable), e.g. g=8, so that it is not handed the truth",
        {},
        "NAME=VALUE",
    )
    members: int = _opt(
        "hybrid/neural: networks of an ensemble (their mean is the model, their spread its "
        "uncertainty; 5 is usual)",
        1,
        "K",
        high=64,
    )
    uncertainty_penalty: float = _opt(
        "an ensemble's weight of its members' spread in every step's training loss",
        1.0,
        "W",
        form="nonneg",
    )
    explore_noise: float = _opt(
        "noise on the controller's actions while it records, a fraction of the action's half "
        "range (0: none; 0.1 suits the Pendulum)",
        0.0,
        "F",
        form="fraction",
    )
    controller: str | None = _opt(
        "what acts each round: 'train' an MLP through the fitted model, or 'plan' through it "
        "(MPC with the task's loop planner; needs JAX to act; docs/planning.md); default: "
        "plan where the task's planner does best (the Pendulum), else train",
        None,
        choices=CONTROLLERS,
    )


@dataclass(frozen=True)
class CompareConfig(_Config):
    """Settings of ``compare.run_comparison``: diffcontrol and the RL baselines on one task,
    trained on seeds ``0 ... seeds-1`` and evaluated alike; the ``--real`` fields are those of
    the comparison in the real system's steps (``run_comparison(real=True)``)."""

    seeds: int = _opt("training seeds", 3, "N", high=MAX_WIDTH)
    methods: tuple[str, ...] | None = _opt(
        "a subset of the methods, e.g. diffcontrol,ppo (default: all for the task)", None, "M,M"
    )
    rl_steps: int | None = _opt(
        "RL budget in environment steps (default: each baseline's zoo budget)", None, "N"
    )
    updates: int | None = _opt(
        "diffcontrol's gradient updates (default: the task's default config)", None, "N"
    )
    eval_every: int | None = _opt(
        "RL evaluation interval in environment steps (default: the task's, compare.rl_setup); "
        "diffcontrol is evaluated at its own evaluation points",
        None,
        "STEPS",
    )
    eval_episodes: int = _opt("episodes per evaluation point", 20, "N", high=MAX_WIDTH)
    final_episodes: int = _opt(
        "episodes for each method's returned controller", 100, "N", high=MAX_WIDTH
    )
    eval_seed: int = _opt("first reset seed of the evaluation episodes", 1000, "S", low=0)
    torch_threads: int | None = _opt(
        "PyTorch threads for the RL baselines (None: PyTorch's own number)", 1, "N"
    )
    models: tuple[str, ...] | None = _opt(
        "--real: a subset of params,hybrid,neural (default all)", None, "M,M"
    )
    max_rounds: int = _opt(
        "--real: the most rounds of a loop; it stops at the first controller that reaches the "
        "task's threshold",
        3,
        "R",
    )
    start: dict[str, float] = _opt(
        "--real: the wrong physics the grey box and hybrid start from (repeatable; default "
        "the task's: pendulum g=8, friction=0.1; cartpole gravity=12, length=0.8, "
        "force_mag=7)",
        {},
        "NAME=VALUE",
    )
    members: int = _opt(
        "--real: networks of the hybrid's and the neural model's ensembles (1: one network)",
        1,
        "K",
        high=64,
    )
    explore_noise: float = _opt(
        "--real: action noise while a controller records, a fraction of the half range",
        0.1,
        "F",
        form="fraction",
    )
    controllers: tuple[str, ...] = _opt(
        "--real: what acts each round, rows of their own: train, plan (a planner through the "
        "fitted model), or train,plan",
        ("train",),
        "C,C",
    )
    rl_results: str | None = _opt(
        "--real: a comparison (comparison.json, or benchmarks/results/compare.json) whose RL "
        "runs are drawn beside",
        None,
        "FILE",
    )


SOLVERS = ("ilqr", "shooting")
"""The planner's solvers (``mpc.ILQR``, ``mpc.Shooting`` with Adam)."""


@dataclass(frozen=True)
class PlanConfig(_Config):
    """Settings of a planning controller (``mpc.planner_from_config``, ``diffcontrol plan``):
    what ``model.json`` stores of a planner, with the model it plans through. Pendulum's best
    (docs/planning.md): ``PlanConfig(horizon=10, value_grid=401)``. A task's defaults are its
    ``default_plan_config()`` (the swing-ups': ``dt=0.05``, ``horizon=40``, ``iterations=5``;
    the actuator-limited one's force within 5 N, the friction one's within 40 N with 10
    iterations); a continuous-time task is planned through
    ``mpc.discretise(task, dt, substeps)``."""

    solver: str = _opt("the solver of every step's plan", "ilqr", choices=SOLVERS)
    horizon: int = _opt(
        "H, the actions planned at every step (default 20, or the task's own)",
        20,
        "H",
        high=10_000,
    )
    iterations: int | None = _opt(
        "solver iterations per step (default 10 for ilqr, 30 for shooting, or the task's own)",
        None,
        "N",
        high=10_000,
    )
    learning_rate: float = _opt("shooting: Adam's learning rate", 0.3, "LR", form="positive")
    bound_starts: bool = _opt(
        "also solve from the constant plans at both action bounds every step and keep the best "
        "(three times the work; escapes plans that do not swing)",
        True,
    )
    value_grid: int | None = _opt(
        "terminal cost -V_0 of the task's grid optimum with N points per state axis (tasks "
        "with a state grid; 401: about 35 s per load on one core); 0: none (default: none, or "
        "the task's own: pendulum 201)",
        None,
        "N",
        low=0,
        high=MAX_VALUE_GRID,
        must=_VALUE_GRID,
    )
    value_levels: int = _opt("actions per action dimension of that grid", 41, "N", low=2, high=1001)
    terminal_weight: float = _opt("weight of the terminal cost", 1.0, "W", form="nonneg")
    loss: str | None = _opt(
        "the task's step loss to plan with (default the task's planning default, else its first)",
        None,
        "NAME",
    )
    action_bound: float | None = _opt(
        "plan actions within +-B (default: the task's bounds, or its planning default)",
        None,
        "B",
        form="positive",
    )
    dt: float | None = _opt(
        "continuous-time tasks: the control period (s); each action is held for it, and the "
        "planner's model integrates the ODE over it by RK4 (default: the task's)",
        None,
        "S",
        form="positive",
    )
    substeps: int = _opt("continuous-time tasks: RK4 steps per control period", 1, "N", high=1000)

    def _check(self) -> None:
        if self.value_grid in (1, 2):
            raise ConfigError(f"value_grid must be {_VALUE_GRID}, got {self.value_grid!r}")
        if self.value_grid == 0:  # the command line's "none"
            object.__setattr__(self, "value_grid", None)

    @property
    def solver_iterations(self) -> int:
        """``iterations``, or the solver's default."""
        return self.iterations or (10 if self.solver == "ilqr" else 30)
