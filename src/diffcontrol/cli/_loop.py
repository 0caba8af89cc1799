"""``diffcontrol loop``: record -> fit -> train on a real system (``identify.loop``)."""

from __future__ import annotations

import argparse
from typing import Any

from ._args import names, param, positive_int
from ._fit import MODELS, TASK_HELP


def add_parser(sub: Any) -> None:
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
    p.add_argument("task", metavar="TASK", help=TASK_HELP)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--env", metavar="ENV_ID", default=None, help="the real system (task's own)")
    p.add_argument(
        "--env-arg",
        type=param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a numeric argument of the real environment (repeatable), e.g. g=12",
    )
    p.add_argument("--model", choices=MODELS, default="params", help="what to fit (params)")
    p.add_argument("--params", type=names, default=None, metavar="NAMES", help="to fit")
    p.add_argument("--rounds", type=positive_int, default=3, metavar="R", help="rounds (3)")
    p.add_argument("--episodes", type=positive_int, default=2, metavar="N", help="per round (2)")
    p.add_argument("--updates", type=positive_int, default=None, metavar="N", help="per round")
    p.add_argument("--seed", type=int, default=0, help="seed of training and recording (0)")
    p.add_argument("--eval-episodes", type=positive_int, default=20, metavar="N", help="(20)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted loop in DIR")
    p.add_argument("--quiet", action="store_true", help="print only each round's summary")


def cmd_loop(args: argparse.Namespace) -> int:
    from .. import identify, tasks

    identify.loop(
        tasks.resolve(args.task),
        args.out,
        env_id=args.env,
        env_kwargs=dict(args.env_arg),
        model=args.model,
        names=args.params,
        rounds=args.rounds,
        episodes=args.episodes,
        updates=args.updates,
        seed=args.seed,
        eval_episodes=args.eval_episodes,
        resume=args.resume,
        progress=None if args.quiet else print,
    )
    return 0
