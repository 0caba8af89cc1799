"""Benchmark of the core demos: Pendulum and CartPole trained with `diffcontrol train` defaults.

Each run is the real command line, `diffcontrol train TASK --out DIR --seed S`, in a fresh
process pinned to one core (`taskset -c 0`) with the persistent compilation cache turned off,
so `train_seconds` includes compiling everything from scratch. Each trained controller is
then evaluated in Gymnasium's own environment on reset seeds 0-99.

    python benchmarks/core.py                 # defaults, 5 training seeds per task
    python benchmarks/core.py --original      # also the 2019 recipes, swept over 1-20 episodes
    python benchmarks/core.py --seeds 1 --tasks cartpole
    python benchmarks/core.py --tasks pendulum --recipe grid-value --no-defaults \
        --more-seeds 1000 --out benchmarks/results/core-grid-value.json  # a recipe instead,
                                                         # also on Gymnasium seeds 1000-1099
    python benchmarks/core.py --tasks mountain-car-continuous --recipe grid-value \
        --optimum 201 --out benchmarks/results/core-mountain-car-grid-value.json
                                     # the defaults and a recipe, each with its gap to the optimum

Prints a table and writes benchmarks/results/core.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, train_cli  # noqa: E402, F401 (machine: also imported from here)

# The quality bars, for "first reached" columns (in-simulator evaluation curve).
THRESHOLDS = {"pendulum": -150.0, "cartpole": 475.0}
# Updates per training episode of the original recipes (window 4, batch 1).
ORIGINAL_UPDATES_PER_EPISODE = {"pendulum": 200 // 4, "pendulum-unclipped": 1000 // 4}


def first_reached(curve: list[dict], threshold: float | None) -> dict:
    """Simulated episodes and seconds at the first evaluation point at or above threshold."""
    for point in curve if threshold is not None else []:
        if point["eval_return"] >= threshold:
            return {"episodes": point["simulated_episodes"], "seconds": point["seconds"]}
    return {"episodes": None, "seconds": None}


def run_train(
    task: str, seed: int, label: str, extra: list[str], workdir: Path, more_seeds: int | None
) -> dict:
    out = workdir / f"{task}-{seed}-{abs(hash(tuple(extra))) % 10**6}"
    metrics, wall = train_cli(task, seed, out, ["--no-animation", "--final-eval", "100", *extra])
    reached = first_reached(metrics["curve"], THRESHOLDS.get(task))
    more = {}
    if more_seeds is not None:  # the saved model.json's NumPy policy, in this process
        import diffcontrol

        ev = diffcontrol.evaluate(
            diffcontrol.load(out), diffcontrol.make(task), episodes=100, seed=more_seeds
        )
        more = {"more_seeds_first": more_seeds, "more_seeds_eval_mean": ev.mean}
    return {
        "task": task,
        "recipe": label,
        "args": extra,
        "seed": seed,
        "simulated_episodes": metrics["simulated_episodes"],
        "simulated_steps": metrics["simulated_steps"],
        "train_seconds": metrics["train_seconds"],
        "compile_seconds": metrics["compile_seconds"],
        "gym_env": metrics["gym_eval"]["env_id"],
        "eval_mean": metrics["gym_eval"]["mean_return"],
        "eval_std": metrics["gym_eval"]["std_return"],
        "eval_episodes": metrics["gym_eval"]["episodes"],
        "returned_update": metrics["returned_update"],
        "threshold": THRESHOLDS.get(task),
        "threshold_first_episodes": reached["episodes"],
        "threshold_first_seconds": reached["seconds"],
        "wall_seconds": wall,
        **more,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=5, help="training seeds per task (default 5)")
    parser.add_argument(
        "--tasks", nargs="*", default=["pendulum", "cartpole"], help="tasks run with defaults"
    )
    parser.add_argument("--original", action="store_true", help="also run the 2019 recipes")
    parser.add_argument(
        "--original-episodes",
        default="1,2,5,10,20",
        help="training-episode counts for the original Pendulum recipes (default 1,2,5,10,20)",
    )
    parser.add_argument(
        "--recipe", action="append", default=[], metavar="NAME",
        help="also run each task of --tasks with `--recipe NAME` (repeatable)",
    )  # fmt: skip
    parser.add_argument("--no-defaults", action="store_true", help="skip the defaults' runs")
    parser.add_argument(
        "--more-seeds", type=int, default=None, metavar="FIRST",
        help="also evaluate each controller on Gymnasium's reset seeds FIRST..FIRST+99",
    )  # fmt: skip
    parser.add_argument(
        "--optimum", type=int, default=None, metavar="POINTS",
        help="also solve each task's grid optimum (POINTS per state axis, 41 actions; tasks "
        "with a state grid) on Gymnasium's seeds 0-99 and report every controller's gap to it",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=HERE / "results" / "core.json")
    args = parser.parse_args()
    optima = {}
    if args.optimum is not None:
        import diffcontrol
        from diffcontrol import optimal

        for task in args.tasks:
            the_task = diffcontrol.make(task)
            if not the_task.state_grid(the_task.default_params()):
                print(f"{task}: no state grid, so no optimum", flush=True)
                continue
            optima[task] = optimal.optimal_return(the_task, range(100), args.optimum)
            print(optima[task].summary(), flush=True)

    configs = [] if args.no_defaults else [(task, "defaults", []) for task in args.tasks]
    configs += [(task, name, ["--recipe", name]) for name in args.recipe for task in args.tasks]
    if args.original:
        for task, per_episode in ORIGINAL_UPDATES_PER_EPISODE.items():
            for n in (int(x) for x in args.original_episodes.split(",")):
                extra = ["--recipe", "original", "--updates", str(n * per_episode)]
                configs.append((task, f"original, {n} ep", extra))
        configs.append(("cartpole", "original", ["--recipe", "original"]))
    rows = []
    header = (
        f"{'task':<19} {'recipe':<16} {'seed':>4} {'episodes':>9} {'steps':>9} {'wall s':>7} "
        f"{'compile s':>9}  {'Gymnasium return (100 seeds)':<28}"
    )
    print(header)
    print("-" * len(header))
    with tempfile.TemporaryDirectory() as tmp:
        for task, label, extra in configs:
            for seed in range(args.seeds):
                r = run_train(task, seed, label, extra, Path(tmp), args.more_seeds)
                if task in optima:
                    r["gap_to_optimum"] = optima[task].gap(r["eval_mean"])
                rows.append(r)
                more = f"  {r['more_seeds_eval_mean']:.1f}" if "more_seeds_first" in r else ""
                print(
                    f"{r['task']:<19} {label:<16} {seed:>4} {r['simulated_episodes']:>9.4g} "
                    f"{r['simulated_steps']:>9} {r['train_seconds']:>7.1f} "
                    f"{r['compile_seconds']:>9.1f}  {r['eval_mean']:>9.1f} ± {r['eval_std']:<6.1f} "
                    f"({r['gym_env']}){more}",
                    flush=True,
                )
    summary = []
    for task, label, _ in configs:
        group = [r for r in rows if r["task"] == task and r["recipe"] == label]
        means = [r["eval_mean"] for r in group]
        firsts = [r["threshold_first_episodes"] for r in group]
        summary.append(
            {
                "task": task,
                "recipe": label,
                "seeds": len(group),
                "median_eval_mean": statistics.median(means),
                "worst_eval_mean": min(means),
                "best_eval_mean": max(means),
                "median_train_seconds": statistics.median(r["train_seconds"] for r in group),
                "max_train_seconds": max(r["train_seconds"] for r in group),
                "simulated_episodes": group[0]["simulated_episodes"],
                "simulated_steps": group[0]["simulated_steps"],
                "threshold": group[0]["threshold"],
                "seeds_reaching_threshold_in_gymnasium": sum(
                    group[0]["threshold"] is not None and m >= group[0]["threshold"] for m in means
                ),
                "threshold_first_episodes_in_training": firsts,
            }
        )
    print()
    print(
        f"{'task':<19} {'recipe':<16} {'seeds':>5} {'episodes':>9} {'median return':>13} "
        f"{'worst':>8} {'best':>8} {'median s':>8} {'max s':>6}"
    )
    for s in summary:
        print(
            f"{s['task']:<19} {s['recipe']:<16} {s['seeds']:>5} {s['simulated_episodes']:>9.4g} "
            f"{s['median_eval_mean']:>13.1f} {s['worst_eval_mean']:>8.1f} {s['best_eval_mean']:>8.1f} "
            f"{s['median_train_seconds']:>8.1f} {s['max_train_seconds']:>6.1f}"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "machine": machine(),
                "runs": rows,
                "summary": summary,
                "optima": {k: v.to_json() for k, v in optima.items()},
                "command": "python benchmarks/core.py " + " ".join(sys.argv[1:]),
            },
            indent=1,
        )
        + "\n"
    )
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
