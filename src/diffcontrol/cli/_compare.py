"""``diffcontrol compare``: diffcontrol against RL baselines on one task (``run_comparison``)."""

from __future__ import annotations

import argparse
from typing import Any

from ..settings import CompareConfig
from . import _args as a
from ._args import FLAG, REQUIRED, add


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "compare",
        help="compare diffcontrol with RL baselines (Stable-Baselines3) on one task",
        description=(
            "Train diffcontrol's controller (the task's defaults) and the RL baselines "
            "(Stable-Baselines3 with rl-baselines3-zoo's published settings: PPO and DQN for "
            "cartpole, SAC and TD3 for pendulum and trebuchet; `pip install "
            "'diffcontrol[rl]'`) with the same training seeds 0..N-1. Every method is "
            "evaluated at regular points during training on the same reset seeds in the same "
            "environment (Gymnasium's own Pendulum-v1 / CartPole-v1; diffcontrol/Trebuchet-v0). "
            "Training seconds leave out these evaluations. Writes to DIR: compare.json "
            "(settings), runs/METHOD-seedS.json (each finished run, as it finishes; --resume "
            "skips them), comparison.json, comparison.md (the table) and comparison.png."
        ),
    )
    # fmt: off
    add(p,
        ("task", str, REQUIRED, "TASK", "cartpole, pendulum or trebuchet"),
        ("--out", str, None, "DIR", "output directory (default runs/compare-TASK)"),
        ("--resume", FLAG, False, None, "continue the comparison in DIR, keeping its runs"),
        ("--real", FLAG, False, None,
         "count the REAL system's steps: diffcontrol learns a model by acting on the real "
         "environment (the loop: explore, fit, train, act) instead of using the task's "
         "simulator; rows diffcontrol (grey box), (hybrid), (neural) beside the RL runs of "
         "--rl-results; writes DIR/loops/ and DIR/runs/ as it goes (--resume)"),
        *a.config_specs(CompareConfig),
        a.NO_COMPILE_CACHE,
        a.QUIET,
    )
    # fmt: on


def cmd_compare(args: argparse.Namespace) -> int:
    from ..compare import run_comparison

    doc = run_comparison(
        args.task,
        args.out,
        a.config_of(CompareConfig, args),
        real=args.real,
        resume=args.resume,
        progress=a.say(args),
        compile_cache=not args.no_compile_cache,
        command=args.command_line,
    )
    print(doc["table"])
    if args.real:
        print(f"real steps to {doc['threshold']:g} per seed: {doc['real_steps_to_threshold']}")
    print(f"wrote {', '.join(doc['files'])}")
    return 0
