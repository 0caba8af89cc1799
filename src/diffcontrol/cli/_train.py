"""``diffcontrol train``: train a controller and write the run's files (``runs.train_run``)."""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from pathlib import Path
from typing import Any

from ..config import ODETrainConfig, TrainConfig, help_of
from . import _args as a
from ._args import FLAG, REQUIRED, add

# How the command line reads a config field, by its type; the exceptions by name. The fields
# themselves (and their help) come from the config dataclasses, so a new field is a new flag.
_BY_TYPE: dict[str, tuple[Any, str]] = {
    "int": (a.positive_int, "N"),
    "float": (a.finite_float, "X"),
    "str": (str, "NAME"),
    "bool": (a.yes_no, "yes|no"),
    "tuple[int, ...]": (a.widths, "W,W"),
}
_BY_NAME: dict[str, tuple[Any, str]] = {
    "seed": (int, "N"),
    "horizon": (a.nonneg_int, "STEPS"),
    "window": (a.positive_int, "STEPS"),
    "learning_rate": (a.finite_float, "LR"),
    "grad_clip": (a.finite_float, "NORM"),
    "target_return": (float, "R"),
    "horizon_s": (a.positive_float, "S"),
    "rtol": (a.positive_float, "TOL"),
    "atol": (a.positive_float, "TOL"),
    "gradient": (str, "METHOD"),
}


def _field_specs(config_cls: type, skip: set[str] = frozenset()) -> list[tuple]:
    """One ``--name`` spec per config field (``params`` is ``--param``), its help the field's."""
    specs = []
    for f in dataclasses.fields(config_cls):
        if f.name not in {*skip, "params"}:
            typ, metavar = _BY_NAME.get(f.name) or _BY_TYPE[str(f.type)]
            help = help_of(f.name, config_cls).replace("%", "%%")
            specs.append(("--" + f.name.replace("_", "-"), typ, None, metavar, help))
    return specs


_DISCRETE = {f.name for f in dataclasses.fields(TrainConfig)}
_SETTINGS = (_DISCRETE | {f.name for f in dataclasses.fields(ODETrainConfig)}) - {"params"}


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "train",
        help="train a controller and write model, metrics, plots and an animation",
        description=(
            "Train a controller for TASK by differentiating through its simulator, with the "
            "task's tuned defaults unless options change them: backpropagation through time "
            "for discrete-time tasks, through an adaptive ODE solve for continuous-time ones "
            "(cartpole-swingup*). Writes to DIR: model.json (the controller, runnable with "
            "NumPy alone), metrics.json (timings, simulated steps and episodes, learning "
            "curve, evaluation), learning_curve.png, rollout.png and rollout.gif (swing-ups: "
            "data.json with the time series, swingup.png with angle, position and force), "
            "and checkpoint.npz (for --resume)."
        ),
    )
    # fmt: off
    add(p,
        ("task", str, None, "TASK", "(optional with --resume: the run's own) " + a.TASK_HELP),
        ("--out", str, REQUIRED, "DIR", "output directory (new or empty)"),
        ("--recipe", str, None, "NAME",
         "start from a named set of settings, e.g. 'original' for the 2019 Flux recipe"),
        ("--resume", FLAG, False, None, "continue the interrupted run in DIR from its last "
         "checkpoint, with the settings of its run.json (a finished run is left as it is)"),
        ("--final-eval", a.episodes_or_0, None, "N", "evaluate after training: Gymnasium episodes "
         "on seeds 0..N-1 (default 100), or random targets for aiming tasks (default 1000); "
         "0 skips"),
        ("--no-animation", FLAG, False, None, "skip the GIF (saves a few seconds)"),
        ("--model", str, None, "FIT_DIR", "train through the model fitted by `diffcontrol fit` in "
         "FIT_DIR instead of the nominal simulator (fitted parameters, or the hybrid/neural "
         "model), and evaluate on the system its data was recorded from (e.g. "
         "diffcontrol/PendulumFriction-v0 with its arguments)"),
        ("--env", str, None, "ENV_ID", "with --model: the real system's Gymnasium id, where the "
         "fitted model's data names one in a module of yours (module:Env-v0); diffcontrol "
         "imports a module only when you name it"),
        a.NO_COMPILE_CACHE,
        a.QUIET,
    )
    group = p.add_argument_group(
        "training settings (defaults depend on the task; see `diffcontrol list`)")
    add(group, *_field_specs(TrainConfig))
    ode = p.add_argument_group(
        "continuous-time tasks only (cartpole-swingup*): the ODE solve and its gradient")
    add(ode, *_field_specs(ODETrainConfig, skip=_DISCRETE))
    add(group, ("--param", [a.param], None, "NAME=VALUE", "override a physical parameter of "
                "the simulator (repeatable), e.g. --param g=9.81"))
    # fmt: on


def cmd_train(args: argparse.Namespace) -> int:
    from ..errors import TrainingWarning
    from ..runs import train_run

    with warnings.catch_warnings():
        if not args.quiet:  # training warnings come as progress lines; not twice
            warnings.simplefilter("ignore", TrainingWarning)
        outcome = train_run(
            args.out,
            args.task,
            recipe=args.recipe,
            settings={name: getattr(args, name) for name in _SETTINGS},
            params=tuple(args.param or ()),
            model=args.model,
            env_id=args.env,
            resume=args.resume,
            final_eval=args.final_eval,
            animation=not args.no_animation,
            compile_cache=not args.no_compile_cache,
            progress=a.say(args),
            command=args.command_line,
        )
    print(outcome.summary)
    if outcome.files:
        print(f"wrote {', '.join(str(Path(args.out) / f) for f in outcome.files)}")
    return 0
