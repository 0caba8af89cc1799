"""``diffcontrol record``: record trajectories (or a task's own data) to CSV or NPZ."""

from __future__ import annotations

import argparse
import time
from typing import Any

from ._args import finite_float, param, positive_int


def nonneg_float(text: str) -> float:
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text!r}")
    return value


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record trajectories from a Gymnasium environment (CSV or NPZ)",
        description=(
            "Record N episodes of ENV_ID with the controller saved in DIR, or with random "
            "actions, and write them as a diffcontrol-trajectories file (CSV or NPZ by the "
            "extension of FILE; episode i is reset with seed S+i; the last row of an episode "
            "holds the final observation and no action). ENV_ID is a Gymnasium id (e.g. "
            "Pendulum-v1, my_module:MyEnv-v0) or a task's name, which records the task's own "
            "data: the trebuchet's throws (random inputs, or --controller aiming; --env-arg "
            "sets the real trebuchet's parameters, --noise-m the distance noise; a "
            "diffcontrol-throws file), a swing-up's full state under random forces (--env-arg "
            "sets its parameters). With --task, ENV_ID is the real system of TASK: its spaces "
            "must match the task's and the columns are named by the task."
        ),
    )
    p.add_argument("env_id", metavar="ENV_ID", help="a Gymnasium environment id or a task name")
    p.add_argument("--task", default=None, help="the task whose real system ENV_ID is")
    p.add_argument(
        "--episodes", type=positive_int, required=True, metavar="N", help="episodes (throws)"
    )
    p.add_argument(
        "--controller",
        metavar="DIR",
        default=None,
        help="a run directory (or model.json) of `diffcontrol train`; random actions if omitted",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="first reset seed (0)")
    p.add_argument(
        "--env-arg",
        type=param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a numeric keyword argument of gymnasium.make (e.g. g=9.0), or a parameter of a "
        "task's own system (e.g. drag_coefficient=1.5); repeatable",
    )
    p.add_argument(
        "--noise-m",
        type=nonneg_float,
        default=None,
        metavar="SD",
        help="trebuchet only: Gaussian noise (m) on the recorded distances (0)",
    )
    p.add_argument(
        "--max-steps", type=positive_int, default=None, metavar="N", help="cut episodes at N"
    )
    p.add_argument("--out", metavar="FILE", default=None, help="a .csv or .npz file")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--quiet", action="store_true", help="print only the final summary")


def cmd_record(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    task = tasks.resolve(args.task) if args.task else None
    say = (lambda line: None) if args.quiet else print
    t0 = time.perf_counter()
    data, out = identify.record_data(
        args.env_id,
        args.episodes,
        args.out,
        task=task,
        force=args.force,
        env_kwargs=dict(args.env_arg),
        controller=args.controller,
        seed=args.seed,
        max_steps=args.max_steps,
        noise_m=args.noise_m,
        progress=say,
    )
    print(f"wrote {out}: {identify.describe(data)} ({time.perf_counter() - t0:.1f} s)")
    return 0
