"""``diffcontrol train``: train a controller and write the run's files."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

from ..config import ODETrainConfig, TrainConfig, help_of
from ._args import (
    add_common,
    finite_float,
    nonneg_int,
    param,
    positive_float,
    positive_int,
    widths,
    yes_no,
)

# How the command line reads a config field, by its type; the exceptions by name. The fields
# themselves (and their help) come from the config dataclasses, so a new field is a new flag.
_BY_TYPE: dict[str, tuple[Any, str]] = {
    "int": (positive_int, "N"),
    "float": (finite_float, "X"),
    "str": (str, "NAME"),
    "bool": (yes_no, "yes|no"),
    "tuple[int, ...]": (widths, "W,W"),
}
_BY_NAME: dict[str, tuple[Any, str]] = {
    "seed": (int, "N"),
    "horizon": (nonneg_int, "STEPS"),
    "window": (positive_int, "STEPS"),
    "learning_rate": (finite_float, "LR"),
    "grad_clip": (finite_float, "NORM"),
    "target_return": (float, "R"),
    "horizon_s": (positive_float, "S"),
    "rtol": (positive_float, "TOL"),
    "atol": (positive_float, "TOL"),
    "gradient": (str, "METHOD"),
}


def _fields(config_cls: type) -> list[Any]:
    """The fields of a config that are command-line flags (``params`` is ``--param``)."""
    return [f for f in dataclasses.fields(config_cls) if f.name != "params"]


def _add_options(group: Any, config_cls: type, skip: set[str] = frozenset()) -> None:
    """One ``--name`` option per config field, its help the field's documentation."""
    for f in _fields(config_cls):
        if f.name in skip:
            continue
        typ, metavar = _BY_NAME.get(f.name) or _BY_TYPE[str(f.type)]
        group.add_argument(
            "--" + f.name.replace("_", "-"),
            dest=f.name,
            type=typ,
            metavar=metavar,
            default=None,
            help=help_of(f.name, config_cls).replace("%", "%%"),
        )


_SETTINGS = [f.name for f in _fields(TrainConfig)] + [
    f.name for f in _fields(ODETrainConfig) if f.name not in {g.name for g in _fields(TrainConfig)}
]


def add_parser(sub: Any) -> None:
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
    p.add_argument(
        "task",
        metavar="TASK",
        nargs="?",
        default=None,
        help="(optional with --resume: the run's own) a task name (`diffcontrol list`), or your own task as module:Class (from the current directory) or an entry point of the diffcontrol.tasks group",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (new or empty)")
    p.add_argument(
        "--recipe",
        metavar="NAME",
        help="start from a named set of settings, e.g. 'original' for the 2019 Flux recipe",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in DIR from its last checkpoint, with the settings "
        "of its run.json (a finished run is left as it is)",
    )
    p.add_argument(
        "--final-eval",
        type=nonneg_int,
        default=None,
        metavar="N",
        help="evaluate after training: Gymnasium episodes on seeds 0..N-1 (default 100), or "
        "random targets for aiming tasks (default 1000); 0 skips",
    )
    p.add_argument("--no-animation", action="store_true", help="skip the GIF (saves a few seconds)")
    p.add_argument(
        "--model",
        metavar="FIT_DIR",
        help="train through the model fitted by `diffcontrol fit` in FIT_DIR instead of the "
        "nominal simulator (fitted parameters, or the hybrid/neural model), and evaluate on "
        "the system its data was recorded from (e.g. diffcontrol/PendulumFriction-v0 with "
        "its arguments)",
    )
    add_common(p)
    group = p.add_argument_group(
        "training settings (defaults depend on the task; see `diffcontrol list`)"
    )
    _add_options(group, TrainConfig)
    ode = p.add_argument_group(
        "continuous-time tasks only (cartpole-swingup*): the ODE solve and its gradient"
    )
    _add_options(ode, ODETrainConfig, skip={f.name for f in _fields(TrainConfig)})
    group.add_argument(
        "--param",
        dest="params",
        type=param,
        action="append",
        metavar="NAME=VALUE",
        help="override a physical parameter of the simulator (repeatable), e.g. --param g=9.81",
    )


def cmd_train(args: argparse.Namespace) -> int:
    from ..runs import RunInterrupted, train_run

    say = (lambda line: None) if args.quiet else (lambda line: print(line, flush=True))
    if not args.quiet:  # training warnings come as progress lines; not twice
        import warnings

        from ..errors import TrainingWarning

        warnings.simplefilter("ignore", TrainingWarning)
    try:
        outcome = train_run(
            args.out,
            args.task,
            recipe=args.recipe,
            settings={name: getattr(args, name) for name in _SETTINGS},
            params=tuple(args.params or ()),
            model=args.model,
            resume=args.resume,
            final_eval=args.final_eval,
            animation=not args.no_animation,
            compile_cache=not args.no_compile_cache,
            progress=say,
            command=" ".join(["diffcontrol", *sys.argv[1:]]),
        )
    except RunInterrupted as e:
        print(f"\n{e}", file=sys.stderr)
        return 130
    print(outcome.summary)
    if outcome.files:
        print(f"wrote {', '.join(str(Path(args.out) / f) for f in outcome.files)}")
    return 0
