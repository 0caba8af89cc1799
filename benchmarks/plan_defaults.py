"""Benchmark: `diffcontrol plan TASK` with the task's own settings, in its Gymnasium environment.

For each task, one fresh process on core 0 (the persistent compilation cache off):

    diffcontrol plan TASK --out DIR --no-animation

whose final evaluation is the planner in Gymnasium's environment on reset seeds 0-99, then

    diffcontrol evaluate DIR --seed 1000 --episodes 100 --json

on seeds it was never tuned on. ``--src PATH`` runs another source tree (a commit before, for
a paired time).

    python benchmarks/plan_defaults.py [--tasks pendulum,acrobot] [--src /tmp/before/src]

Prints a table and writes benchmarks/results/plan_defaults.json (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402


def cli(args: list[str], src: str | None) -> tuple[str, float]:
    """Run ``diffcontrol ARGS`` in a fresh process (on core 0 where ``taskset`` exists): its
    standard output and wall seconds."""
    cmd = [sys.executable, "-m", "diffcontrol.cli", *args]
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", "0", *cmd]
    env = dict(os.environ, DIFFCONTROL_NO_COMPILE_CACHE="1")
    if src:
        env["PYTHONPATH"] = src
    t0 = time.perf_counter()
    done = subprocess.run(cmd, check=True, env=env, capture_output=True, text=True)
    return done.stdout, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", default="pendulum,acrobot")
    parser.add_argument("--src", default=None, help="a source tree to run instead")
    parser.add_argument("--out", default=str(HERE / "results" / "plan_defaults.json"))
    args = parser.parse_args()
    rows = []
    for task in args.tasks.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            run = Path(tmp) / "plan"
            _, seconds = cli(["plan", task, "--out", str(run), "--no-animation"], args.src)
            metrics = json.loads((run / "metrics.json").read_text())
            model = json.loads((run / "model.json").read_text())
            unseen, eval_seconds = cli(
                ["evaluate", str(run), "--seed", "1000", "--episodes", "100", "--json"], args.src
            )
        unseen = json.loads(unseen)
        rows.append(
            {
                "task": task,
                "command": f"taskset -c 0 diffcontrol plan {task} --out DIR --no-animation",
                "settings": model["controller"]["settings"],
                "seconds_wall": seconds,
                "seeds_0_99": metrics["gym_eval"],
                "seeds_1000_1099": {
                    k: unseen[k] for k in ("mean_return", "std_return", "returns") if k in unseen
                },
                "evaluate_seconds_wall": eval_seconds,
            }
        )
        print(
            f"{task}: {rows[-1]['seeds_0_99']['mean_return']:.2f} on seeds 0-99, "
            f"{rows[-1]['seeds_1000_1099']['mean_return']:.2f} on 1000-1099; plan {seconds:.1f} s",
            flush=True,
        )
    print("\ntask          seconds   seeds 0-99   seeds 1000-1099")
    for r in rows:
        print(
            f"{r['task']:12s} {r['seconds_wall']:8.1f} {r['seeds_0_99']['mean_return']:12.2f} "
            f"{r['seeds_1000_1099']['mean_return']:17.2f}"
        )
    doc = {"machine": machine(), "src": args.src or "this checkout", "rows": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
