"""Benchmark: diffcontrol against RL baselines on CartPole and Pendulum, 5 seeds each (or on
other tasks with baselines, such as the MuJoCo ones at a fixed budget; examples below).

Each task is the real command line, `diffcontrol compare TASK --seeds 5`, in a fresh
process pinned to one core (`taskset -c CORE`, default core 1) with the persistent
compilation cache off (diffcontrol's training time includes compiling from scratch) and one
PyTorch/OpenMP thread. The RL baselines are Stable-Baselines3's PPO and DQN (CartPole-v1)
and SAC and TD3 (Pendulum-v1) with rl-baselines3-zoo's published settings and budgets.

    python benchmarks/compare.py                      # both tasks, 5 seeds (about an hour)
    python benchmarks/compare.py --tasks cartpole --seeds 2
    python benchmarks/compare.py --resume             # continue an interrupted benchmark
    python benchmarks/compare.py --tasks swimmer --seeds 1 --compare-args "--rl-steps 200000" \
        --out benchmarks/results/compare_swimmer.json

Prints the tables and a check of the claim "at least 10x fewer simulated episodes and 10x
less wall-clock than the best RL baseline", and writes benchmarks/results/compare.json
(machine, date, every run) and benchmarks/results/compare-TASK.png. The run directories are
kept in runs/benchmark-compare/TASK (for --resume).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def claim_check(summary: list[dict]) -> list[dict]:
    """Per threshold: diffcontrol's median episodes and seconds to reach it against the best
    (lowest median) RL baseline's, and whether both ratios are at least 10."""
    dc = next((r for r in summary if r["method"] == "diffcontrol"), None)
    rl = [r for r in summary if r["method"] != "diffcontrol"]
    out = []
    if dc is None:  # --compare-args "--methods ..." without diffcontrol: nothing to check
        return out
    for i, t in enumerate(dc["thresholds"]):
        row = {"threshold": t["threshold"], "diffcontrol_reached": f"{t['reached']}/{t['of']}"}
        for key in ("episodes", "train_seconds"):
            ours = t[key]["median"]
            best = None
            for r in rl:
                theirs = r["thresholds"][i][key]["median"]
                if theirs is not None and (best is None or theirs < best[1]):
                    best = (r["method"], theirs)
            row[key] = {
                "diffcontrol": ours,
                "best_rl": best[1] if best else None,
                "best_rl_method": best[0] if best else None,
                "ratio": (best[1] / ours) if (best and ours) else None,
            }
        ratios = [row[k]["ratio"] for k in ("episodes", "train_seconds")]
        row["claim_holds"] = all(r is not None and r >= 10 for r in ratios)
        out.append(row)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--tasks", nargs="*", default=["cartpole", "pendulum"])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--core", type=int, default=1, help="CPU core to pin to (default 1)")
    parser.add_argument("--resume", action="store_true", help="keep finished runs")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "compare.json")
    parser.add_argument(
        "--compare-args", default="", help="extra options for `diffcontrol compare` (quick checks)"
    )
    args = parser.parse_args()

    env = dict(
        os.environ,
        DIFFCONTROL_NO_COMPILE_CACHE="1",
        OMP_NUM_THREADS="1",
        MKL_NUM_THREADS="1",
        PYTHONUNBUFFERED="1",
    )
    pin = ["taskset", "-c", str(args.core)] if shutil.which("taskset") else []
    report = {
        "command": " ".join(["python", "benchmarks/compare.py", *sys.argv[1:]]),
        "date": dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat(),
        "pinned_core": args.core if pin else None,
        "tasks": {},
    }
    for task in args.tasks:
        run_dir = ROOT / "runs" / "benchmark-compare" / task
        if run_dir.exists() and not args.resume:
            shutil.rmtree(run_dir)
        cmd = [*pin, sys.executable, "-m", "diffcontrol.cli", "compare", task]
        cmd += ["--out", str(run_dir), "--seeds", str(args.seeds), "--torch-threads", "1"]
        cmd += ["--resume"] if args.resume and run_dir.exists() else []
        cmd += args.compare_args.split()
        print("$ " + " ".join(cmd), flush=True)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env)
        doc = json.loads((run_dir / "comparison.json").read_text())
        doc["benchmark_wall_seconds"] = time.perf_counter() - t0
        doc["claim"] = claim_check(doc["summary"])
        doc["table"] = (run_dir / "comparison.md").read_text().strip()
        report["machine"] = doc["machine"]
        report["tasks"][task] = doc
        shutil.copyfile(run_dir / "comparison.png", HERE / "results" / f"compare-{task}.png")
    print()
    for doc in report["tasks"].values():
        print(doc["table"])
        print()
        for row in doc["claim"]:
            e, s = row["episodes"], row["train_seconds"]
            print(
                f"  threshold {row['threshold']:g}: episodes diffcontrol {e['diffcontrol']} vs "
                f"best RL {e['best_rl']} ({e['best_rl_method']}), ratio {e['ratio']}; seconds "
                f"{s['diffcontrol']} vs {s['best_rl']} ({s['best_rl_method']}), ratio "
                f"{s['ratio']}; >=10x on both: {row['claim_holds']}"
            )
        print()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(report, indent=1) + "\n")
    os.replace(tmp, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
