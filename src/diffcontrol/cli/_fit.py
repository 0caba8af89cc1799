"""``diffcontrol fit``: fit a model of a task's system to recorded data (``identify.fit_dir``)."""

from __future__ import annotations

import argparse
from typing import Any

from ._args import finite_float, names, nonneg_int, positive_float, positive_int, widths

MODELS = ("params", "hybrid", "neural")


def holdout_fraction(text: str) -> float:
    value = finite_float(text)
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be a fraction in [0, 1), got {text!r}")
    return value


TASK_HELP = (
    "a task name (`diffcontrol list`), or your own task as module:Class (from the current "
    "directory) or an entry point of the diffcontrol.tasks group"
)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "fit",
        help="fit a model of the task's system to recorded trajectories (or throws)",
        description=(
            "Fit a model of TASK's system to FILE (recorded by `diffcontrol record`) by "
            "differentiating it through short windows: from every recorded state, predict "
            "WINDOW steps with the recorded actions and minimise the squared error. --model "
            "params fits physical parameters of TASK's simulator (grey box, with standard "
            "errors); hybrid adds a network to the nominal physics; neural learns the dynamics "
            "alone. The last episodes (a fraction F) are held out to measure the prediction "
            "error 1, 10 and 50 steps ahead. Writes DIR/fitted.json and DIR/prediction.png; "
            "`diffcontrol train TASK --model DIR` trains through it. For the trebuchet, FILE "
            "holds recorded throws and the distances are fitted."
        ),
    )
    p.add_argument("task", metavar="TASK", help=TASK_HELP)
    p.add_argument("--data", required=True, metavar="FILE", help="recorded trajectories/throws")
    p.add_argument("--model", required=True, choices=MODELS, help="grey box, hybrid or neural")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--params",
        type=names,
        default=None,
        metavar="NAMES",
        help="--model params: the parameters to fit (default: the task's, e.g. g,friction)",
    )
    p.add_argument("--hidden", type=widths, default=(32, 32), metavar="W,W", help="(32,32)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="the network's initial weights (0)")
    p.add_argument("--window", type=positive_int, default=10, metavar="N", help="steps (10)")
    p.add_argument("--steps", type=nonneg_int, default=None, metavar="N", help="Adam steps")
    p.add_argument(
        "--lm-steps", type=nonneg_int, default=20, metavar="N", help="Levenberg-Marquardt (20)"
    )
    p.add_argument("--learning-rate", type=positive_float, default=None, metavar="LR")
    p.add_argument(
        "--holdout",
        type=holdout_fraction,
        default=0.2,
        metavar="F",
        help="fraction of the episodes (throws) held out, the last ones (0.2; 0 for none)",
    )
    p.add_argument("--force", action="store_true", help="replace DIR/fitted.json if it exists")
    p.add_argument("--quiet", action="store_true", help="print only the final summary")


def cmd_fit(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    done = identify.fit_dir(
        tasks.resolve(args.task),
        args.data,
        args.model,
        args.out,
        holdout=args.holdout,
        force=args.force,
        progress=None if args.quiet else print,
        names=args.params,
        window=args.window,
        steps=args.steps,
        learning_rate=args.learning_rate,
        lm_steps=args.lm_steps,
        hidden=args.hidden,
        seed=args.seed,
    )
    print("\n".join(done.lines))
    return 0
