"""Benchmark: the reference optimum of Pendulum-v1 and the planning controller's gap to it.

1. The grid dynamic program (``diffcontrol.optimal``, 801 x 801 states, 41 torques, 200 steps):
   its greedy controller in Gymnasium's own ``Pendulum-v1`` on reset seeds 0-99 and 1000-1099.
2. The planner (``diffcontrol.mpc``: box-iLQR and Adam shooting, horizons H) in Gymnasium's
   ``Pendulum-v1`` on seeds 0-99, one solve per control step (``PlannerPolicy``), with its
   wall-clock cost per control step (median over all calls, this process on one core); and the
   planner with the grid value ``-V_0`` as its terminal cost (the place a learned value
   network will take).
3. The default trained controller (``diffcontrol train pendulum --seed 0``) on both seed sets.

    taskset -c 0 python benchmarks/mpc_pendulum.py                  # the full benchmark
    python benchmarks/mpc_pendulum.py --points 201 --episodes 10    # a quick look

Prints a table and writes benchmarks/results/mpc_pendulum.json (machine, date, load, figures).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import equinox as eqx
import numpy as np
import optax

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import grid_optima, machine, planner_episodes, train_cli  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import mpc  # noqa: E402
from diffcontrol.tasks import Pendulum  # noqa: E402

SOLVERS = {
    "ilqr": lambda: mpc.ILQR(iterations=10),
    "shooting": lambda: mpc.Shooting(optax.adam(0.3), iterations=30),
}


def run_planner(task, label, planner, seeds, optimum):
    policy = mpc.PlannerPolicy(planner)
    t0 = time.perf_counter()
    policy(np.array([1.0, 0.0, 0.0], np.float32))  # compile
    compile_s = time.perf_counter() - t0
    policy.reports.clear()
    returns, seconds = planner_episodes(policy, seeds)
    reports = policy.reports
    row = {
        "controller": label,
        "horizon": planner.horizon,
        "seeds": [seeds[0], seeds[-1]],
        "mean_return": float(returns.mean()),
        "min_return": float(returns.min()),
        "gap_to_optimum": optimum.gap(float(returns.mean())),
        "ms_per_step_median": 1e3 * float(np.median(seconds)),
        "ms_per_step_p90": 1e3 * float(np.percentile(seconds, 90)),
        "compile_seconds": compile_s,
        "solves": len(reports),
        "not_converged": sum(not r["converged"] for r in reports),
        "non_finite": sum(not r["finite"] for r in reports),
        "returns": returns.tolist(),
    }
    print_row(row)
    return row


def print_row(row):
    ms = f"{row['ms_per_step_median']:.2f}" if "ms_per_step_median" in row else "-"
    conv = f"{row['not_converged']}/{row['solves']}" if "solves" in row else "-"
    print(
        f"{row['controller']:<38} {row['seeds'][0]:>4}-{row['seeds'][1]:<4} "
        f"{row['mean_return']:>9.2f} {100 * row['gap_to_optimum']:>6.2f}% {ms:>8} {conv:>12}",
        flush=True,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=801)
    parser.add_argument("--levels", type=int, default=41)
    parser.add_argument("--horizons", type=int, nargs="+", default=[10, 20, 30])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--trained", type=Path, help="a trained run directory (else train one)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "mpc_pendulum.json")
    args = parser.parse_args()
    task = Pendulum()
    load_before = os.getloadavg()
    seed_sets = {
        "0-99": list(range(args.episodes)),
        "1000-1099": list(range(1000, 1000 + args.episodes)),
    }

    table, optima, solve_s = grid_optima(task, args.points, args.levels, seed_sets)
    header = (
        f"{'controller':<38} {'seeds':>9} {'return':>9} {'gap':>7} {'ms/step':>8} {'not conv.':>12}"
    )
    print(f"solved in {solve_s:.1f} s\n\n{header}\n{'-' * len(header)}")
    rows = []
    for opt in optima.values():
        row = {
            "controller": f"grid optimum {args.points}^2 x {args.levels}",
            "seeds": [opt.seeds[0], opt.seeds[-1]],
            "mean_return": opt.mean,
            "predicted_mean": opt.predicted_mean,
            "gap_to_optimum": 0.0,
            "returns": opt.returns.tolist(),
        }
        rows.append(row)
        print_row(row)

    seeds, optimum = seed_sets["0-99"], optima["0-99"]
    for name, make in SOLVERS.items():
        for horizon in args.horizons:
            planner = mpc.make_planner(task, make(), horizon=horizon, bound_starts=True)
            rows.append(run_planner(task, f"planner {name} H={horizon}", planner, seeds, optimum))
    # The grid value as the terminal cost: only V_0 is needed, so only it is kept (a constant
    # of the compiled solve, 2.5 MB at 801^2).
    first = eqx.tree_at(lambda t: t.values, table, table.values[:1])
    for name, make in SOLVERS.items():
        planner = mpc.make_planner(task, make(), horizon=10, bound_starts=True,
                                   terminal_cost=lambda x: -first.value(0, x))  # fmt: skip
        label = f"planner {name} H=10 + grid value"
        rows.append(run_planner(task, label, planner, seeds, optimum))

    with tempfile.TemporaryDirectory() as tmp:
        run_dir = args.trained
        train_seconds = None
        if run_dir is None:
            run_dir = Path(tmp) / "pendulum"
            metrics, train_seconds = train_cli(
                "pendulum", 0, run_dir, ["--no-animation", "--final-eval", "0"]
            )
        policy = diffcontrol.load(run_dir)
        for opt in optima.values():
            ev = diffcontrol.evaluate(policy, task, episodes=len(opt.seeds), seed=opt.seeds[0])
            row = {
                "controller": "trained MLP (train pendulum --seed 0)",
                "seeds": [opt.seeds[0], opt.seeds[-1]],
                "mean_return": ev.mean,
                "gap_to_optimum": opt.gap(ev.mean),
                "train_process_seconds": train_seconds,
                "returns": ev.returns.tolist(),
            }
            rows.append(row)
            print_row(row)

    doc = {
        "machine": {**machine(), "loadavg_before": load_before, "loadavg_after": os.getloadavg()},
        "grid": {"points": args.points, "levels": args.levels, "solve_seconds": solve_s},
        "optimum": {k: v.to_json() for k, v in optima.items()},
        "rows": rows,
        "command": "taskset -c 0 python benchmarks/mpc_pendulum.py " + " ".join(sys.argv[1:]),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"\nload average before {load_before}, after {os.getloadavg()}\nwrote {args.out}")


if __name__ == "__main__":
    main()
