"""``diffcontrol loop``: record -> fit -> train, a few rounds, for a system known only by acting.

Each round is made of the other commands, run in this process on files in DIR, so every
round's outputs are the ones those commands document and an interrupted loop continues
where it stopped (``--resume``): a round's data, fitted model and controller are each kept
once written.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from ..errors import DiffcontrolError, RunDirectoryError
from ._args import names, param, positive_int
from ._fit import MODELS

LOOP_FILE = "loop.json"


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "loop",
        help="alternate record -> fit -> train on a real system for a few rounds",
        description=(
            "Learn a controller for a system you can only run: record N episodes of the real "
            "environment ENV_ID (random actions at first), fit a model of TASK's system to all "
            "data so far (`diffcontrol fit`), train a controller through the fitted model "
            "(`diffcontrol train --model`), evaluate it on the real environment, record N more "
            "episodes with it, and repeat for R rounds. Writes DIR/data.csv (all recorded "
            "episodes), DIR/round_K/{fit,run}/ (each round's fitted model and controller), "
            "DIR/loop.json (per round: data, fit, return on the real system) and DIR/loop.png. "
            "The last round's controller is DIR/round_R/run/model.json."
        ),
    )
    p.add_argument(
        "task",
        metavar="TASK",
        help="a task name (`diffcontrol list`), or your own task as module:Class (from the current directory) or an entry point of the diffcontrol.tasks group",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--env",
        metavar="ENV_ID",
        default=None,
        help="the real system: a Gymnasium id (default: the task's own, e.g. Pendulum-v1)",
    )
    p.add_argument(
        "--env-arg",
        type=param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a numeric argument of the real environment (repeatable), e.g. g=12",
    )
    p.add_argument("--model", choices=MODELS, default="params", help="what to fit (params)")
    p.add_argument(
        "--params",
        type=names,
        default=None,
        metavar="NAMES",
        help="--model params: the parameters to fit (default: fit's default, g,friction)",
    )
    p.add_argument("--rounds", type=positive_int, default=3, metavar="R", help="rounds (3)")
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=2,
        metavar="N",
        help="episodes recorded per round: random actions before round 1, then the round's "
        "controller (2)",
    )
    p.add_argument(
        "--updates",
        type=positive_int,
        default=None,
        metavar="N",
        help="training updates per round (default: the task's)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of training and recording (0)")
    p.add_argument(
        "--eval-episodes",
        type=positive_int,
        default=20,
        metavar="N",
        help="episodes on the real system after each round (20)",
    )
    p.add_argument("--resume", action="store_true", help="continue an interrupted loop in DIR")
    p.add_argument("--quiet", action="store_true", help="print only each round's summary")


def cmd_loop(args: argparse.Namespace) -> int:
    from .. import tasks
    from ..data import concat, read_trajectories, write_trajectories
    from ..io import NumpyPolicy, now_iso, read_json, read_model, write_json
    from ..recording import record
    from . import main

    task = tasks.resolve(args.task)
    if task.kind != "control" or not task.gym_id:
        raise DiffcontrolError(
            f"loop needs a discrete-time control task with a Gymnasium environment, not "
            f"{task.name!r}; e.g. pendulum"
        )
    env_id = args.env or task.gym_id
    env_kwargs = dict(args.env_arg)
    out = Path(args.out)
    settings = {
        "task": task.name,
        "env_id": env_id,
        "env_kwargs": env_kwargs,
        "model": args.model,
        "params": args.params,
        "episodes_per_round": args.episodes,
        "updates": args.updates,
        "seed": args.seed,
    }
    state = _start(out, settings, args.resume, read_json)
    say = (lambda line: None) if args.quiet else print
    quiet = ["--quiet"] if args.quiet else []

    def record_round(k: int, policy: Any) -> None:
        """Record the episodes of round k (random for k = 0) and append them to data.csv."""
        part = out / f"round_{k}" / "recorded.csv"
        if not part.exists():
            data = record(
                env_id,
                args.episodes,
                policy=policy,
                seed=args.seed + 1000 * k,
                env_kwargs=env_kwargs,
                source="random actions" if policy is None else f"round {k} controller",
            )
            part.parent.mkdir(parents=True, exist_ok=True)
            write_trajectories(part, data)
        parts = [read_trajectories(out / f"round_{j}" / "recorded.csv") for j in range(k + 1)]
        write_trajectories(out / "data.csv", concat(parts))

    record_round(0, None)
    for k in range(1, args.rounds + 1):
        t0 = time.perf_counter()
        here = out / f"round_{k}"
        data = read_trajectories(out / "data.csv")
        say(f"round {k}/{args.rounds}: fitting {args.model} to {data.num_episodes} episodes")
        if not (here / "fit" / "fitted.json").exists():
            fit = ["fit", task.name, "--data", str(out / "data.csv"), "--model", args.model]
            fit += ["--out", str(here / "fit"), "--holdout", "0", *quiet]
            if args.params:
                fit += ["--params", ",".join(args.params)]
            code = main(fit)
            if code:
                return code
        if not (here / "run" / "model.json").exists():
            train = ["train", task.name, "--model", str(here / "fit"), "--out", str(here / "run")]
            train += ["--seed", str(args.seed), "--final-eval", str(args.eval_episodes)]
            train += ["--no-animation", *quiet]
            if args.updates:
                train += ["--updates", str(args.updates)]
            if (here / "run" / "checkpoint.npz").exists():
                train.append("--resume")
            code = main(train)
            if code:
                return code
        metrics = read_json(here / "run" / "metrics.json", "metrics")
        fitted = read_json(here / "fit" / "fitted.json", "fitted model")
        row = {
            "round": k,
            "episodes": data.num_episodes,
            "transitions": data.num_steps,
            "fit_loss": fitted["fit"]["loss"],
            "fitted_parameters": {
                n: p["value"] for n, p in (fitted.get("parameters") or {}).items()
            },
            "real_return": metrics.get("gym_eval", {}).get("mean_return"),
            "real_return_std": metrics.get("gym_eval", {}).get("std_return"),
            "seconds": time.perf_counter() - t0,
        }
        state["rounds"] = [r for r in state["rounds"] if r["round"] != k] + [row]
        write_json(out / LOOP_FILE, {**state, "updated": now_iso()})
        ret = row["real_return"]
        fitted_txt = ", ".join(f"{n} = {v:.4g}" for n, v in row["fitted_parameters"].items())
        print(
            f"round {k}: {row['episodes']} episodes ({row['transitions']} transitions)"
            + (f", {fitted_txt}" if fitted_txt else f", fit loss {row['fit_loss']:.3g}")
            + (f"; return on the real system {ret:.1f}" if ret is not None else "")
        )
        if k < args.rounds:
            record_round(k, NumpyPolicy(read_model(here / "run")))
    _plot(state, out / "loop.png")
    print(
        f"wrote {out / LOOP_FILE}, {out / 'loop.png'} and {out / 'data.csv'}; the controller: "
        f"{out / f'round_{args.rounds}' / 'run' / 'model.json'}"
    )
    return 0


def _start(out: Path, settings: dict, resume: bool, read_json: Any) -> dict:
    """The loop's state: new (refusing a DIR with another loop in it) or resumed."""
    path = out / LOOP_FILE
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out} is a file; give a directory")
    if path.exists():
        old = read_json(path, "loop file")
        if not resume:
            raise RunDirectoryError(
                f"{out} already holds a loop; pass --resume to continue it, or choose another --out"
            )
        if old.get("settings") != json.loads(json.dumps(settings)):
            raise RunDirectoryError(
                f"{out} holds a loop with other settings ({old.get('settings')}); resume it with "
                "those, or choose another --out"
            )
        return old
    if out.exists() and any(out.iterdir()) and not resume:
        raise RunDirectoryError(f"--out {out} is not empty; choose a new or empty directory")
    out.mkdir(parents=True, exist_ok=True)
    return {"format": "diffcontrol-loop", "version": 1, "settings": settings, "rounds": []}


def _plot(state: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import write_figure

    rows = sorted(state["rounds"], key=lambda r: r["round"])
    rows = [r for r in rows if r["real_return"] is not None]
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    if rows:
        ax.errorbar(
            [r["round"] for r in rows],
            [r["real_return"] for r in rows],
            yerr=[r["real_return_std"] or 0 for r in rows],
            marker="o",
            capsize=3,
        )
    s = state["settings"]
    ax.set_xlabel("round (record -> fit -> train)")
    ax.set_ylabel("return on the real system")
    ax.set_title(f"{s['task']}: {s['model']} model, real system {s['env_id']}", fontsize=9)
    ax.grid(alpha=0.3)
    write_figure(fig, path)
