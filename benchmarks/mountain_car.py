"""Benchmark of `mountain-car-continuous`: BPTT with the task's defaults on five training seeds.

Each run is the real command line, `diffcontrol train mountain-car-continuous --out DIR --seed
S`, in a fresh process pinned to one core (`taskset -c 0`) with the persistent compilation
cache off, so `train_seconds` includes compiling everything from scratch. Each trained
controller is then evaluated in Gymnasium's own `MountainCarContinuous-v0` on reset seeds
0-99 (the CLI's final evaluation, `diffcontrol.evaluate`).

The bar (the issue's): a mean return >= 93 for every training seed, each trained in under
60 s on one core. For scale: Gymnasium's `reward_threshold` is 90, rl-zoo's SAC scores 94.7.

    taskset -c 0 python benchmarks/mountain_car.py
    taskset -c 0 python benchmarks/mountain_car.py --seeds 10

Prints a table and writes benchmarks/results/mountain_car.json (machine, date, every figure).
Other processes may share the machine, which inflates the seconds, never the returns.
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
from _common import machine, train_cli  # noqa: E402

TASK = "mountain-car-continuous"
TARGET_RETURN = 93.0
TARGET_SECONDS = 60.0


def run(seed: int, workdir: Path) -> dict:
    """Train one seed with the defaults and evaluate it on Gymnasium's seeds 0-99."""
    out = workdir / f"{TASK}-{seed}"
    metrics, process_seconds = train_cli(TASK, seed, out, ["--no-animation", "--final-eval", "100"])
    ev = metrics["gym_eval"]
    return {
        "seed": seed,
        "train_seconds": metrics["train_seconds"],
        "compile_seconds": metrics["compile_seconds"],
        "process_seconds": process_seconds,
        "simulated_episodes": metrics["simulated_episodes"],
        "simulated_steps": metrics["simulated_steps"],
        "returned_update": metrics["returned_update"],
        "gym_env": ev["env_id"],
        "eval_episodes": ev["episodes"],
        "eval_mean": ev["mean_return"],
        "eval_std": ev["std_return"],
        "eval_min": ev["min_return"],
        "eval_mean_length": ev["mean_length"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=5, help="training seeds 0..N-1 (default 5)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "mountain_car.json")
    args = parser.parse_args()

    header = (
        f"{'seed':>4} {'train s':>8} {'compile s':>9} {'process s':>9} {'update':>6} "
        f"{'Gymnasium return (seeds 0-99)':>30} {'min':>6} {'steps':>6}"
    )
    print(header)
    print("-" * len(header))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            r = run(seed, Path(tmp))
            rows.append(r)
            print(
                f"{seed:>4} {r['train_seconds']:>8.1f} {r['compile_seconds']:>9.1f} "
                f"{r['process_seconds']:>9.1f} {r['returned_update']:>6} "
                f"{r['eval_mean']:>21.2f} ± {r['eval_std']:<6.2f} {r['eval_min']:>6.1f} "
                f"{r['eval_mean_length']:>6.0f}",
                flush=True,
            )
    means = [r["eval_mean"] for r in rows]
    seconds = [r["train_seconds"] for r in rows]
    summary = {
        "task": TASK,
        "seeds": len(rows),
        "median_eval_mean": statistics.median(means),
        "worst_eval_mean": min(means),
        "best_eval_mean": max(means),
        "median_train_seconds": statistics.median(seconds),
        "max_train_seconds": max(seconds),
        "target_return": TARGET_RETURN,
        "target_seconds": TARGET_SECONDS,
        "seeds_meeting_target": sum(
            m >= TARGET_RETURN and s < TARGET_SECONDS for m, s in zip(means, seconds)
        ),
    }
    print(
        f"\nworst {summary['worst_eval_mean']:.2f}, median {summary['median_eval_mean']:.2f}; "
        f"train s median {summary['median_train_seconds']:.1f}, max "
        f"{summary['max_train_seconds']:.1f}; {summary['seeds_meeting_target']}/{len(rows)} "
        f"seeds meet >= {TARGET_RETURN:g} in < {TARGET_SECONDS:g} s"
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps({"machine": machine(), "runs": rows, "summary": summary}, indent=1) + "\n"
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
