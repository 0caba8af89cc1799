"""``diffcontrol record``, ``fit`` and ``loop``: trajectories recorded to CSV or NPZ
(``identify.record_data``), a model of a task's system learnt from them (``identify.fit_dir``),
and record -> fit -> train on a real system (``runs.loop``)."""

from __future__ import annotations

import argparse
import time
from typing import Any

from ..settings import MODELS, FitConfig, LoopConfig, RecordConfig
from ._args import (
    FLAG,
    LOG_DIR,
    QUIET,
    REQUIRED,
    TASK,
    add,
    config_of,
    config_specs,
    env_arg,
    say,
)


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record trajectories from a Gymnasium environment (CSV or NPZ)",
        description=(
            "Record N episodes of ENV_ID with the controller saved in DIR, or with random "
            "actions, to a diffcontrol-trajectories file (CSV or NPZ by FILE's extension; "
            "episode i is reset with seed S+i). ENV_ID is a Gymnasium id (e.g. Pendulum-v1, "
            "my_module:MyEnv-v0) or a task's name, which records the task's own data (an aiming "
            "task's throws, a continuous-time task's full state). With --task, ENV_ID is the "
            "real system of TASK: its spaces must match and the columns are named by the task."
        ),
    )
    # fmt: off
    add(p,
        ("env_id", str, REQUIRED, "ENV_ID", "a Gymnasium environment id or a task name"),
        ("--task", str, None, "TASK", "the task whose real system ENV_ID is"),
        *config_specs(RecordConfig),
        ("--out", str, None, "FILE", "a .csv or .npz file"),
        ("--force", FLAG, False, None, "overwrite FILE if it exists"),
        QUIET,
    )
    p = sub.add_parser(
        "fit",
        help="fit a model of the task's system to recorded trajectories (or throws)",
        description=(
            "Fit a model of TASK's system to FILE (from `diffcontrol record`) by predicting "
            "WINDOW steps from every recorded state and minimising the squared error: params "
            "fits the simulator's physical parameters (grey box), hybrid adds a network to "
            "the nominal physics, neural learns the dynamics alone. Writes DIR/fitted.json "
            "(with held-out prediction errors) and DIR/prediction.png; `diffcontrol train "
            "TASK --model DIR` trains through it."
        ),
    )
    add(p,
        TASK,
        ("--data", str, REQUIRED, "FILE", "recorded trajectories/throws"),
        ("--model", MODELS, REQUIRED, None, "grey box, hybrid or neural"),
        ("--out", str, REQUIRED, "DIR", "output directory"),
        *config_specs(FitConfig),
        ("--env", str, None, "ENV_ID", "the environment the data came from, where its module "
         "is yours (my_envs:MyPendulum-v0): imported because you name it, never because the "
         "file does"),
        ("--force", FLAG, False, None, "replace DIR/fitted.json if it exists"),
        QUIET,
    )
    p = sub.add_parser(
        "loop",
        help="alternate record -> fit -> train (or plan) on a real system for a few rounds",
        description=(
            "Learn a controller for a system you can only run, in R rounds of: record N "
            "episodes of the real environment ENV_ID (random actions at first, then the kept "
            "controller's), fit a model of TASK's system to all data so far, train or plan "
            "through it (--controller), evaluate on the real environment; a round's controller "
            "is kept unless it does worse there than the one kept before (round 0: the nominal "
            "controller, of TASK's own physics). Writes DIR/data.csv, DIR/round_K/{fit,run}/, "
            "DIR/loop.json and DIR/loop.png."
        ),
    )
    add(p,
        TASK,
        ("--out", str, REQUIRED, "DIR", "output directory"),
        ("--env", str, None, "ENV_ID", "the real system (task's own)"),
        env_arg("a numeric argument of the real environment (repeatable), e.g. g=12"),
        *config_specs(LoopConfig),
        ("--resume", FLAG, False, None, "continue an interrupted loop in DIR"),
        ("--quiet", FLAG, False, None, "print only each round's summary"),
        LOG_DIR,
    )
    # fmt: on


def cmd_fit(args: argparse.Namespace) -> int:
    from .. import identify, tasks  # JAX: the library, when the command runs

    more = {"force": args.force, "progress": say(args), "env_id": args.env}
    task, config = tasks.resolve(args.task), config_of(FitConfig, args)
    done = identify.fit_dir(task, args.data, args.model, args.out, config, **more)
    print("\n".join(done.lines))
    return 0


def cmd_loop(args: argparse.Namespace) -> int:
    from .. import runs, tasks  # JAX: the library, when the command runs

    config = config_of(LoopConfig, args)
    more = {"env_kwargs": dict(args.env_arg), "resume": args.resume, "progress": say(args)}
    more |= {"log_dir": args.log_dir, "command": args.command_line}
    runs.loop(tasks.resolve(args.task), args.out, config, env_id=args.env, **more)
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    from .. import identify, tasks  # JAX: the library, when the command runs

    t0 = time.perf_counter()
    task = tasks.resolve(args.task) if args.task else None
    more = {"task": task, "force": args.force, "progress": say(args)}
    data, out = identify.record_data(args.env_id, config_of(RecordConfig, args), args.out, **more)
    print(f"wrote {out}: {identify.describe(data)} ({time.perf_counter() - t0:.1f} s)")
    return 0
