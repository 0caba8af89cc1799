"""``diffcontrol record``, ``fit`` and ``loop``: trajectories recorded to CSV or NPZ
(``identify.record_data``), a model of a task's system learnt from them (``identify.fit_dir``),
and record -> fit -> train on a real system (``identify.loop``)."""

from __future__ import annotations

import argparse
import time
from typing import Any

from ..settings import MODELS, FitConfig, LoopConfig, RecordConfig
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
        *a.config_specs(RecordConfig),
        ("--out", str, None, "FILE", "a .csv or .npz file"),
        ("--force", FLAG, False, None, "overwrite FILE if it exists"),
        a.QUIET,
    )
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
    add(p,
        a.TASK,
        ("--data", str, REQUIRED, "FILE", "recorded trajectories/throws"),
        ("--model", MODELS, REQUIRED, None, "grey box, hybrid or neural"),
        ("--out", str, REQUIRED, "DIR", "output directory"),
        *a.config_specs(FitConfig),
        ("--force", FLAG, False, None, "replace DIR/fitted.json if it exists"),
        a.QUIET,
    )
    p = sub.add_parser(
        "loop",
        help="alternate record -> fit -> train on a real system for a few rounds",
        description=(
            "Learn a controller for a system you can only run: record N episodes of the real "
            "environment ENV_ID (random actions at first), fit a model of TASK's system to all "
            "data so far, train a controller through it, evaluate it on the real environment, "
            "record N more episodes with it, and repeat for R rounds. Writes DIR/data.csv, "
            "DIR/round_K/{fit,run}/, DIR/loop.json and DIR/loop.png; the last round's "
            "controller is DIR/round_R/run/model.json."
        ),
    )
    add(p,
        a.TASK,
        ("--out", str, REQUIRED, "DIR", "output directory"),
        ("--env", str, None, "ENV_ID", "the real system (task's own)"),
        a.env_arg("a numeric argument of the real environment (repeatable), e.g. g=12"),
        *a.config_specs(LoopConfig),
        ("--resume", FLAG, False, None, "continue an interrupted loop in DIR"),
        ("--quiet", FLAG, False, None, "print only each round's summary"),
    )
    # fmt: on


def cmd_fit(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    done = identify.fit_dir(
        tasks.resolve(args.task),
        args.data,
        args.model,
        args.out,
        a.config_of(FitConfig, args),
        force=args.force,
        progress=a.say(args),
    )
    print("\n".join(done.lines))
    return 0


def cmd_loop(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    identify.loop(
        tasks.resolve(args.task),
        args.out,
        a.config_of(LoopConfig, args),
        env_id=args.env,
        env_kwargs=dict(args.env_arg),
        resume=args.resume,
        progress=a.say(args),
    )
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    t0 = time.perf_counter()
    data, out = identify.record_data(
        args.env_id,
        a.config_of(RecordConfig, args),
        args.out,
        task=tasks.resolve(args.task) if args.task else None,
        force=args.force,
        progress=a.say(args),
    )
    print(f"wrote {out}: {identify.describe(data)} ({time.perf_counter() - t0:.1f} s)")
    return 0
