"""``diffcontrol compare``: diffcontrol against RL baselines on one task (``run_comparison``)."""

from __future__ import annotations

import argparse
from typing import Any

from ..settings import CompareConfig
from ._args import FLAG, NO_COMPILE_CACHE, QUIET, REQUIRED, add, config_of, config_specs, say


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "compare",
        help="compare diffcontrol with RL baselines (Stable-Baselines3) on one task",
        description=(
            "Train diffcontrol's controller and the RL baselines (Stable-Baselines3 with "
            "rl-baselines3-zoo's settings; `pip install 'diffcontrol[rl]'`) on training seeds "
            "0..N-1, evaluate every method at regular points on the same reset seeds in the "
            "same environment (training seconds leave out these evaluations), and write "
            "DIR/comparison.{json,md,png} and DIR/runs/ (one file per finished run)."
        ),
    )
    # fmt: off
    add(p,
        ("task", str, REQUIRED, "TASK", "a task with RL baselines (the message names them)"),
        ("--out", str, None, "DIR", "output directory (default runs/compare-TASK)"),
        ("--resume", FLAG, False, None, "continue the comparison in DIR, keeping its runs"),
        ("--real", FLAG, False, None, "count the REAL system's steps: diffcontrol learns a "
         "model by acting on the real environment (explore, fit, train, act; grey box, hybrid, "
         "neural) beside the RL runs of --rl-results; writes DIR/loops/ as it goes"),
        *config_specs(CompareConfig),
        NO_COMPILE_CACHE,
        QUIET,
    )
    # fmt: on


def cmd_compare(args: argparse.Namespace) -> int:
    from ..compare import run_comparison  # JAX: the library, when the command runs

    more = {"real": args.real, "resume": args.resume, "progress": say(args)}
    more |= {"compile_cache": not args.no_compile_cache, "command": args.command_line}
    doc = run_comparison(args.task, args.out, config_of(CompareConfig, args), **more)
    print(doc["table"])
    if args.real:
        print(f"real steps to {doc['threshold']:g} per seed: {doc['real_steps_to_threshold']}")
    print(f"wrote {', '.join(doc['files'])}")
    return 0
