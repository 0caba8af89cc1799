"""``diffcontrol record``: record trajectories (or a task's own data) to CSV or NPZ."""

from __future__ import annotations

import argparse
import time
from typing import Any

from . import _args as a
from ._args import FLAG, REQUIRED, add


def add_parsers(sub: Any) -> None:
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
            "sets the real trebuchet's parameters, --noise-m the distance noise; a throw is "
            "a one-step episode), a swing-up's full state under random forces (--env-arg "
            "sets its parameters). With --task, ENV_ID is the real system of TASK: its spaces "
            "must match the task's and the columns are named by the task."
        ),
    )
    # fmt: off
    add(p,
        ("env_id", str, REQUIRED, "ENV_ID", "a Gymnasium environment id or a task name"),
        ("--task", str, None, "TASK", "the task whose real system ENV_ID is"),
        ("--episodes", a.episodes, REQUIRED, "N", "episodes (throws)"),
        ("--controller", str, None, "DIR",
         "a run directory (or model.json) of `diffcontrol train`; random actions if omitted"),
        ("--seed", a.seed, 0, "S", "first reset seed (0)"),
        a.env_arg("a numeric keyword argument of gymnasium.make (e.g. g=9.0), or a parameter of "
                  "a task's own system (e.g. drag_coefficient=1.5); repeatable"),
        ("--noise-m", a.nonneg_float, None, "SD",
         "trebuchet only: Gaussian noise (m) on the recorded distances (0)"),
        ("--max-steps", a.positive_int, None, "N", "cut episodes at N"),
        ("--out", str, None, "FILE", "a .csv or .npz file"),
        ("--force", FLAG, False, None, "overwrite FILE if it exists"),
        a.QUIET,
    )
    # fmt: on


def cmd_record(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    t0 = time.perf_counter()
    data, out = identify.record_data(
        args.env_id,
        args.episodes,
        args.out,
        task=tasks.resolve(args.task) if args.task else None,
        env_kwargs=dict(args.env_arg),
        progress=a.say(args),
        **a.pick(args, "force controller seed max_steps noise_m"),
    )
    print(f"wrote {out}: {identify.describe(data)} ({time.perf_counter() - t0:.1f} s)")
    return 0
