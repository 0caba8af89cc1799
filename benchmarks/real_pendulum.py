"""Benchmark: real Pendulum-v1 steps to -150 for diffcontrol's loop, against SAC's 11,000.

The real command line, in this process:

    diffcontrol compare pendulum --real --seeds 5 --rl-results benchmarks/results/compare.json \
        --out runs/benchmark-real-pendulum [--resume]

For every seed S and model (grey box starting from g = 8, friction 0.1 where Pendulum-v1 has
g = 10 and none; hybrid with the same wrong physics plus a network; neural: a network alone),
``identify.loop`` records real episodes (random torques first, then the current controller
with action noise 0.1 of the half range), fits the model to all of them, trains a controller
through it and evaluates it on Pendulum-v1 over 100 episodes with reset seeds 1000-1099 (as
``benchmarks/compare.py`` evaluates SAC), until a controller reaches -150 over the 100 episodes or after --max-rounds rounds (3). The
curve points, as ``compare``'s RL evaluation points, are the mean over the first 20 of them
(seeds 1000-1019): "steps to -150" is reported for both (SAC's 11,000 is on 20 episodes; over
100 episodes its returned controllers get -152.5 to -159.1, none -150).
Episodes per round: 1 (grey box, hybrid), 5 (neural: a network needs 1,000 transitions). Real
steps count every recorded transition; the evaluation episodes are not counted, as for RL.

    python benchmarks/real_pendulum.py [--seeds 5] [--models params,hybrid,neural] [--resume]

Prints the table and the real steps to -150 per seed, and writes
benchmarks/results/real_pendulum.json and benchmarks/results/real_pendulum.png.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

from diffcontrol.compare import run_real_comparison  # noqa: E402

TARGETS = {"diffcontrol (grey box)": 400, "diffcontrol (hybrid)": 600, "diffcontrol (neural)": 1000}
"""Issue 14's targets: real steps to -150 on every seed."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--models", default="params,hybrid,neural")
    parser.add_argument("--max-rounds", type=int, default=3)
    parser.add_argument("--out", default="runs/benchmark-real-pendulum")
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args()
    rl_file = HERE / "results" / "compare.json"
    t0 = time.perf_counter()
    doc = run_real_comparison(
        "pendulum",
        args.out,
        seeds=args.seeds,
        max_rounds=args.max_rounds,
        models=args.models.split(","),
        rl_results=rl_file,
        resume=args.resume,
        progress=lambda line: print(line, flush=True),
    )
    wall = time.perf_counter() - t0
    rl = json.loads(rl_file.read_text())["tasks"]["pendulum"]
    sac = next(r for r in rl["summary"] if r["method"] == "sac")
    sac_150 = next(t for t in sac["thresholds"] if t["threshold"] == -150.0)
    print(doc["table"])
    print(
        f"\nreal steps to -150 (target; SAC: median {sac_150['env_steps']['median']:,.0f} "
        f"steps, {sac_150['train_seconds']['median']:.0f} s, {sac_150['reached']}/5 seeds)"
    )
    rows = []
    for method, target in TARGETS.items():
        runs = [r for r in doc["runs"] if r["method"] == method]
        if not runs:
            continue
        steps = {int(s): v for s, v in doc["real_steps_to_threshold"].get(method, {}).items()}
        all100 = doc["real_steps_to_threshold_over_all_episodes"].get(method, {})
        steps100 = {int(s): v for s, v in all100.items()}
        finals = {r["seed"]: r["final"]["mean_return"] for r in runs}
        points = {r["seed"]: [round(p["mean_return"], 1) for p in r["curve"]] for r in runs}
        secs = {}
        for r in runs:
            hit = next((p for p in r["curve"] if p["mean_return"] >= -150.0), None)
            secs[r["seed"]] = hit["train_seconds"] if hit else None
        reached = [v for v in steps.values() if v is not None]
        row = {
            "method": method,
            "target_steps": target,
            "steps_to_-150_on_20_episodes": steps,
            "steps_to_-150_on_100_episodes": steps100,
            "seconds_to_-150_on_20_episodes": secs,
            "returns_20_episodes_by_round": points,
            "last_return_100_episodes": finals,
            "met_target_on_every_seed_20": len(reached) == len(runs)
            and all(v <= target for v in reached),
            "median_steps_20": statistics.median(reached) if reached else None,
        }
        rows.append(row)
        for name, table in (("20 ep", steps), ("100 ep", steps100)):
            cells = ", ".join(
                f"seed {s}: {table[s] if table[s] is not None else 'missed'}" for s in sorted(table)
            )
            print(f"{method:24} ({name}) target <= {target:5}: {cells}")
        print(f"{'':24} returns by round (20 ep): {points}; last (100 ep): {finals}")
    out = HERE / "results" / "real_pendulum.json"
    (HERE / "results").mkdir(exist_ok=True)
    shutil.copyfile(Path(args.out) / "comparison.png", HERE / "results" / "real_pendulum.png")
    result = {
        "command": "python benchmarks/real_pendulum.py " + " ".join(sys.argv[1:]),
        "machine": machine(),
        "benchmark_wall_seconds": wall,
        "sac_to_-150": sac_150,
        "rows": rows,
        "comparison": {k: v for k, v in doc.items() if k not in ("files",)},
    }
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out} and {HERE / 'results' / 'real_pendulum.png'}")


if __name__ == "__main__":
    main()
