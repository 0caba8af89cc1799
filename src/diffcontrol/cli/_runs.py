"""Commands on saved runs: ``list``, ``evaluate``, ``animate`` and ``aim``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..errors import DiffcontrolError
from ._args import finite_float, nonneg_int, param, positive_int


def _add_task_option(p: Any) -> None:
    p.add_argument(
        "--task",
        metavar="TASK",
        default=None,
        help="the run's task when it is not a built-in one: its import path (module:Class) "
        "or entry-point name; diffcontrol never imports code because a file names it",
    )


def add_parsers(sub: Any) -> None:
    sub.add_parser("list", help="list the tasks, one line each", description="List the tasks.")
    p = sub.add_parser(
        "evaluate",
        help="run a trained controller in Gymnasium's own environment",
        description=(
            "Run the controller saved in DIR in Gymnasium's own environment (Pendulum-v1, "
            "CartPole-v1) on seeds S ... S+N-1 and print the mean and std of the return. For "
            "an aiming task (trebuchet), aim at N random targets (20-100 m, wind ~ N(0, 5^2) "
            "m/s, drawn with seed S) and print the miss statistics over the reachable ones. "
            "For a continuous-time task (cartpole-swingup*), re-solve the closed loop with a "
            "float64 reference solver (dopri8 at 1e-9) and print the end state, the peak "
            "force and the swings. --env (with --env-arg) runs a discrete-time controller in "
            "another environment instead, e.g. the real system a fitted model came from "
            "(a run trained with --model is evaluated there by default)."
        ),
    )
    p.add_argument("run_dir", metavar="DIR", help="a directory written by `diffcontrol train`")
    p.add_argument(
        "--env",
        metavar="ENV_ID",
        default=None,
        help="evaluate in this Gymnasium environment instead (e.g. diffcontrol/PendulumFriction-v0)",
    )
    p.add_argument(
        "--env-arg",
        type=param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a numeric argument of --env (repeatable), e.g. g=12",
    )
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=None,
        metavar="N",
        help="episodes (default 100), or random targets for aiming tasks (default 1000)",
    )
    p.add_argument(
        "--seed",
        type=nonneg_int,
        default=0,
        metavar="S",
        help="first reset seed, or the seed of the random targets (default 0)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    _add_task_option(p)

    p = sub.add_parser(
        "animate",
        help="re-render the animation of a saved controller",
        description=(
            "Record one Gymnasium episode of the controller in DIR (or re-solve a swing-up, "
            "or simulate a trebuchet throw) and write it as a GIF."
        ),
    )
    p.add_argument("run_dir", metavar="DIR", help="a directory written by `diffcontrol train`")
    p.add_argument(
        "--seed",
        type=nonneg_int,
        default=0,
        metavar="S",
        help="reset seed of the episode (default 0)",
    )
    p.add_argument("--out", metavar="FILE", default=None, help="GIF path (default DIR/rollout.gif)")
    p.add_argument(
        "--target", type=finite_float, default=80.0, metavar="M", help="aiming tasks: target (m)"
    )
    p.add_argument(
        "--wind", type=finite_float, default=-3.0, metavar="MPS", help="aiming tasks: wind (m/s)"
    )
    _add_task_option(p)

    p = sub.add_parser(
        "aim",
        help="aim a trained trebuchet controller at one target",
        description=(
            "Ask the aiming controller in DIR for the release angle and counterweight that hit "
            "a target at M metres in a wind of W m/s (+ blows toward the target), simulate "
            "the throw, and print the distance and the miss. --direct also aims by gradient "
            "steps on the simulator alone, for comparison."
        ),
    )
    p.add_argument(
        "run_dir", metavar="DIR", help="a directory written by `diffcontrol train trebuchet`"
    )
    p.add_argument("--target", type=finite_float, required=True, metavar="M", help="target (m)")
    p.add_argument("--wind", type=finite_float, default=0.0, metavar="W", help="wind (m/s)")
    p.add_argument(
        "--direct", action="store_true", help="also aim by gradient descent on the simulator"
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def cmd_list(args: argparse.Namespace) -> int:
    from .. import tasks

    for name in tasks.names():
        task = tasks.make(name)
        losses = "/".join(task.losses)
        recipes = ", ".join(task.recipes()) or "-"
        print(f"{name:<26} {task.summary}  [losses: {losses}; recipes: {recipes}]")
    return 0


def _open(args: argparse.Namespace, real: Any = True) -> Any:
    from ..runs import open_run

    return open_run(args.run_dir, task=getattr(args, "task", None), real=real)


def cmd_aim(args: argparse.Namespace) -> int:
    run = _open(args)
    if not callable(getattr(run.task, "aim", None)):
        raise DiffcontrolError(
            f"{args.run_dir} holds a {run.task.name!r} controller; `aim` needs an aiming task "
            "(the trebuchet)"
        )
    result, lines = run.task.aim(run, args.target, args.wind, direct=args.direct)
    if args.json:
        print(json.dumps(result))
    else:
        print(f"target {args.target:g} m, wind {args.wind:+g} m/s")
        print("\n".join(lines))
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    real: Any = True  # the real system of a run trained through a fitted model
    if args.env:
        real = {"env_id": args.env, "env_kwargs": dict(args.env_arg)}
    elif args.env_arg:
        raise DiffcontrolError("--env-arg needs --env (the environment it applies to)")
    run = _open(args, real)
    ev = run.task.evaluate_run(run, episodes=args.episodes, seed=args.seed)
    if ev is None:
        raise DiffcontrolError(
            f"task {run.task.name!r} has no environment to evaluate in; name one with --env"
        )
    if args.json:
        print(json.dumps({"run_dir": str(args.run_dir), "task": run.task.name, **ev.to_json()}))
    else:
        where = " (on the real system of its fitted model)" if run.real and not args.env else ""
        print(f"{ev.summary()}{where}")
    return 0


def cmd_animate(args: argparse.Namespace) -> int:
    from ..io import check_new_file

    run = _open(args)
    path = Path(args.out) if args.out else Path(args.run_dir) / "rollout.gif"
    if args.out:
        check_new_file(path, ".gif")
    what = run.task.animate_run(run, path, seed=args.seed, target=args.target, wind=args.wind)
    print(f"wrote {path} ({what})")
    return 0
