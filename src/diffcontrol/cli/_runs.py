"""``list``, and the commands on saved runs: ``evaluate``, ``animate``, ``aim`` (``runs``)."""

from __future__ import annotations

import argparse
import json
from typing import Any

import diffcontrol.cli._args as a

from .._registry import listing
from ._args import FLAG, REQUIRED, add


def add_parsers(sub: Any) -> None:
    sub.add_parser("list", help="list the tasks, one line each", description="List the tasks.")
    p = sub.add_parser(
        "evaluate",
        help="run a trained controller in Gymnasium's own environment",
        description=(
            "Run the controller saved in DIR in its task's Gymnasium environment on reset seeds "
            "S ... S+N-1 and print the return's mean and std. Aiming tasks: aim at "
            "N random targets drawn with seed S and print the miss statistics; continuous-time "
            "tasks: re-solve the closed loop with a float64 reference solver. A run trained "
            "with --model is evaluated on the real system its data came from."
        ),
    )
    # fmt: off
    add(p,
        a.RUN_DIR,
        ("--env", str, None, "ENV_ID", "evaluate in this Gymnasium environment instead (e.g. "
         "diffcontrol/PendulumFriction-v0)"),
        a.env_arg("a numeric argument of --env (repeatable), e.g. g=12"),
        ("--episodes", a.episodes, None, "N",
         "episodes (default 100), or random targets for aiming tasks (default 1000)"),
        ("--seed", a.nonneg_int, 0, "S",
         "first reset seed, or the seed of the random targets (default 0)"),
        ("--optimum", a.positive_int, None, "N", "also run the reference optimum (a dynamic "
         "program on an N x N state grid, e.g. 401; a task with a state grid: pendulum, or a "
         "continuous-time task of yours, held for its control period) and print the gap to it"),
        a.JSON,
        a.RUN_TASK,
    )
    p = sub.add_parser(
        "animate",
        help="re-render the animation of a saved controller",
        description="Record one Gymnasium episode of the controller in DIR (or re-solve a "
        "continuous-time task, or simulate an aiming task's throw) and write it as a GIF.",
    )
    add(p,
        a.RUN_DIR,
        ("--seed", a.nonneg_int, 0, "S", "reset seed of the episode (default 0)"),
        ("--out", str, None, "FILE", "GIF path (default DIR/rollout.gif)"),
        ("--target", a.finite_float, 80.0, "M", "aiming tasks: target (m)"),
        ("--wind", a.finite_float, -3.0, "MPS", "aiming tasks: wind (m/s)"),
        a.RUN_TASK,
    )
    p = sub.add_parser(
        "aim",
        help="aim a trained aiming controller at one target",
        description="Ask the aiming controller in DIR for the release angle and counterweight "
        "that hit a target at M metres in a wind of W m/s (+ toward the target), simulate the "
        "throw, and print the distance and the miss.",
    )
    add(p,
        ("run_dir", str, REQUIRED, "DIR", "a run of an aiming task (`diffcontrol train`)"),
        ("--target", a.finite_float, REQUIRED, "M", "target (m)"),
        ("--wind", a.finite_float, 0.0, "W", "wind (m/s)"),
        ("--direct", FLAG, False, None, "also aim by gradient descent on the simulator"),
        a.JSON,
    )
    # fmt: on


def cmd_list(args: argparse.Namespace) -> int:
    print("\n".join(listing()))
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from ..runs import evaluate_dir  # JAX: the library, when the command runs

    kw = a.pick(args, "task episodes seed optimum")
    run, ev = evaluate_dir(args.run_dir, env_id=args.env, env_kwargs=dict(args.env_arg), **kw)
    if args.json:
        print(json.dumps({"run_dir": str(args.run_dir), "task": run.task.name, **ev.to_json()}))
    else:
        where = " (on the real system of its fitted model)" if run.real and not args.env else ""
        print(f"{ev.summary()}{where}")
    return 0


def cmd_animate(args: argparse.Namespace) -> int:
    from ..runs import animate_dir  # JAX: the library, when the command runs

    kw = a.pick(args, "task seed target wind")
    path, what = animate_dir(args.run_dir, args.out, **kw)
    print(f"wrote {path} ({what})")
    return 0


def cmd_aim(args: argparse.Namespace) -> int:
    from ..runs import aim_dir  # JAX: the library, when the command runs

    result, lines = aim_dir(args.run_dir, args.target, args.wind, direct=args.direct)
    print(json.dumps(result) if args.json else "\n".join(lines))
    return 0
