"""``diffcontrol compare``: diffcontrol against RL baselines on one task."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from ._args import add_common, names, nonneg_int, positive_int


def add_parser(sub: Any) -> None:
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
    p.add_argument("task", metavar="TASK", help="cartpole, pendulum or trebuchet")
    p.add_argument(
        "--out", metavar="DIR", default=None, help="output directory (default runs/compare-TASK)"
    )
    p.add_argument(
        "--seeds", type=positive_int, default=3, metavar="N", help="training seeds (default 3)"
    )
    p.add_argument(
        "--methods",
        type=names,
        default=None,
        metavar="M,M",
        help="a subset of the methods, e.g. diffcontrol,ppo (default: all for the task)",
    )
    p.add_argument(
        "--rl-steps",
        type=positive_int,
        default=None,
        metavar="N",
        help="RL budget in environment steps (default: each baseline's zoo budget)",
    )
    p.add_argument(
        "--updates",
        type=positive_int,
        default=None,
        metavar="N",
        help="diffcontrol's gradient updates (default: the task's default config)",
    )
    p.add_argument(
        "--eval-every",
        type=positive_int,
        default=None,
        metavar="STEPS",
        help="RL evaluation interval in environment steps (default: cartpole 2000, "
        "pendulum 1000, trebuchet 1000); diffcontrol is evaluated at its own evaluation points",
    )
    p.add_argument(
        "--eval-episodes",
        type=positive_int,
        default=20,
        metavar="N",
        help="episodes per evaluation point (default 20)",
    )
    p.add_argument(
        "--final-episodes",
        type=positive_int,
        default=100,
        metavar="N",
        help="episodes for each method's returned controller (default 100)",
    )
    p.add_argument(
        "--eval-seed",
        type=nonneg_int,
        default=1000,
        metavar="S",
        help="first reset seed of the evaluation episodes (default 1000)",
    )
    p.add_argument(
        "--torch-threads",
        type=positive_int,
        default=1,
        metavar="N",
        help="PyTorch threads for the RL baselines (default 1)",
    )
    p.add_argument(
        "--resume", action="store_true", help="continue the comparison in DIR, keeping its runs"
    )
    add_common(p)


def cmd_compare(args: argparse.Namespace) -> int:
    from .. import _jax_setup, tasks
    from ..compare import run_comparison

    task = tasks.resolve(args.task)
    out = Path(args.out or f"runs/compare-{task.name}")
    if not (args.no_compile_cache or os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE")):
        _jax_setup.enable_compile_cache()
    say = (lambda line: None) if args.quiet else (lambda line: print(line, flush=True))
    try:
        doc = run_comparison(
            task,
            out,
            seeds=args.seeds,
            methods=args.methods,
            rl_steps=args.rl_steps,
            updates=args.updates,
            eval_every=args.eval_every,
            eval_episodes=args.eval_episodes,
            final_episodes=args.final_episodes,
            eval_seed=args.eval_seed,
            torch_threads=args.torch_threads,
            resume=args.resume,
            progress=say,
        )
    except KeyboardInterrupt:
        print(
            f"\ninterrupted; the finished runs are in {out / 'runs'}. Continue with the same "
            f"options and --resume: diffcontrol {' '.join(sys.argv[1:] or ['compare', task.name])}"
            + ("" if args.resume else " --resume"),
            file=sys.stderr,
        )
        return 130
    print(doc["table"])
    print(f"wrote {out / 'comparison.json'}, {out / 'comparison.md'}, {out / 'comparison.png'}")
    return 0
