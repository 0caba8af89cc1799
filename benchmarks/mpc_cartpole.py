"""Benchmark: the planning controller on CartPole-v1, its return and its cost per control step.

The CartPole's action is a push of fixed size left or right (``Discrete(2)``); the planner
plans the relaxed push ``u`` in [-1, 1] (``make_planner(..., bounds=((-1,), (1,)))``: the force
``u * force_mag`` in the task's simulator) with the task's ``quadratic`` loss (cart position
and pole angle over their limits, squared) and Gymnasium gets the sign of the first action
(``gym_action``). Box-iLQR at horizons H, one solve per control step
(``PlannerPolicy``), in Gymnasium's own ``CartPole-v1`` on reset seeds 0-99; the wall-clock
cost per control step is the median (and 95th percentile) over all calls of this process.

    taskset -c 0 python benchmarks/mpc_cartpole.py
    python benchmarks/mpc_cartpole.py --episodes 10     # a quick look

Prints a table and writes benchmarks/results/mpc_cartpole.json (machine, date, load, figures).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, planner_episodes  # noqa: E402

from diffcontrol import make, mpc  # noqa: E402

SETTINGS = [(10, 3), (20, 3), (30, 5)]
"""(horizon, iLQR iterations) of the planners measured."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100, help="reset seeds 0..N-1")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "mpc_cartpole.json")
    args = parser.parse_args()
    task = make("cartpole")
    rows = []
    print(f"{'H':>3} {'iter':>4} {'mean return':>11} {'min':>5} {'ms/step':>8} {'p95 ms':>7}"
          f" {'compile s':>9}  solves")  # fmt: skip
    for horizon, iterations in SETTINGS:
        planner = mpc.make_planner(
            task, mpc.ILQR(iterations=iterations), horizon, loss="quadratic", bounds=((-1,), (1,))
        )
        policy = mpc.PlannerPolicy(planner)
        t0 = time.perf_counter()
        policy.action(np.zeros(4, np.float32))  # compile once, outside the timings
        compile_s = time.perf_counter() - t0
        policy.reports.clear()
        returns, seconds = planner_episodes(policy, range(args.episodes), task=task)
        row = {
            "horizon": horizon,
            "iterations": iterations,
            "mean_return": float(returns.mean()),
            "min_return": float(returns.min()),
            "returns": returns.tolist(),
            "ms_per_step_median": 1000 * float(np.median(seconds)),
            "ms_per_step_p95": 1000 * float(np.percentile(seconds, 95)),
            "compile_seconds": compile_s,
            "steps": int(seconds.size),
            "solves": policy.summary(),
        }
        rows.append(row)
        print(f"{horizon:>3} {iterations:>4} {row['mean_return']:>11.1f} {row['min_return']:>5.0f}"
              f" {row['ms_per_step_median']:>8.3f} {row['ms_per_step_p95']:>7.3f}"
              f" {compile_s:>9.1f}  {row['solves']}")  # fmt: skip
    doc = {
        "machine": machine(),
        "load_average": os.getloadavg(),
        "episodes": args.episodes,
        "loss": "quadratic",
        "rows": rows,
    }
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
