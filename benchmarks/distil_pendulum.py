"""Benchmark: the planner distilled into the plain MLP (``diffcontrol.mpc.distil``, DAgger) on
Pendulum-v1, against the planner itself and the reference optimum.

1. The grid dynamic program (``diffcontrol.optimal``, ``--points``^2 states, 41 torques): its
   greedy controller in Gymnasium's ``Pendulum-v1`` on reset seeds 0-99 and 1000-1099 (the
   optimum every gap is measured from), and its value ``V_0`` as the planner's terminal cost.
2. The teacher: box-iLQR, H = 10, best of three starts per step, terminal cost ``-V_0``
   (``benchmarks/mpc_pendulum.py``'s best planner), in Gymnasium on both seed sets
   (``PlannerPolicy``).
3. ``mpc.distil`` with its defaults for each ``--seeds`` (wall clock, compilation, planner
   calls), the result saved as a run directory, loaded back with ``diffcontrol.load`` (the
   NumPy policy of ``model.json``) and evaluated in Gymnasium on both seed sets.

    taskset -c 0 python benchmarks/distil_pendulum.py                     # the full benchmark
    python benchmarks/distil_pendulum.py --points 401 --rounds 4          # a quicker look
    taskset -c 0 python benchmarks/distil_pendulum.py --points 201 --rounds 8 --fit-steps 3000 \
        --seeds 0 1 2 3 4 --out benchmarks/results/distil_pendulum-201.json  # under a minute each

Prints a table and writes benchmarks/results/distil_pendulum.json (machine, date, load, figures).
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

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import grid_optima, machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import mpc  # noqa: E402
from diffcontrol.tasks import Pendulum  # noqa: E402

SEED_SETS = {"0-99": 0, "1000-1099": 1000}


def print_row(row):
    print(
        f"{row['controller']:<44} {row['seeds']:>9} {row['mean_return']:>9.2f} "
        f"{100 * row['gap_to_optimum']:>6.2f}% {row.get('seconds', float('nan')):>8.1f} "
        f"{row.get('planner_calls', 0):>9}",
        flush=True,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=801, help="grid points per state axis")
    parser.add_argument("--levels", type=int, default=41)
    parser.add_argument("--episodes", type=int, default=100, help="Gymnasium seeds per set")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="distillation seeds")
    parser.add_argument("--rounds", type=int, default=None, help="default: distil's")
    parser.add_argument("--fit-steps", type=int, default=None, help="default: distil's")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "distil_pendulum.json")
    args = parser.parse_args()
    task = Pendulum()
    load_before = os.getloadavg()
    seed_sets = {k: list(range(s, s + args.episodes)) for k, s in SEED_SETS.items()}

    table, optima, grid_s = grid_optima(task, args.points, args.levels, seed_sets)
    header = (
        f"{'controller':<44} {'seeds':>9} {'return':>9} {'gap':>7} {'seconds':>8} {'planner':>9}"
    )
    print(f"solved in {grid_s:.1f} s\n\n{header}\n{'-' * len(header)}")
    rows = []
    for key, opt in optima.items():
        row = {"controller": f"grid optimum {args.points}^2 x {args.levels}", "seeds": key,
               "mean_return": opt.mean, "gap_to_optimum": 0.0, "returns": opt.returns.tolist()}  # fmt: skip
        rows.append(row)
        print_row(row)

    # The teacher. Only V_0 is kept (a constant of the compiled solve).
    first = eqx.tree_at(lambda t: t.values, table, table.values[:1])
    planner = mpc.make_planner(task, mpc.ILQR(iterations=10), horizon=10, bound_starts=True,
                               terminal_cost=lambda x: -first.value(0, x))  # fmt: skip
    policy = mpc.PlannerPolicy(planner)
    for key, opt in optima.items():
        t0 = time.perf_counter()
        ev = diffcontrol.evaluate(policy, task, episodes=args.episodes, seed=opt.seeds[0])
        row = {"controller": "planner iLQR H=10 + grid value (teacher)", "seeds": key,
               "mean_return": ev.mean, "gap_to_optimum": opt.gap(ev.mean),
               "seconds": time.perf_counter() - t0, "planner_calls": len(policy.reports),
               "returns": ev.returns.tolist()}  # fmt: skip
        policy.reports.clear()
        rows.append(row)
        print_row(row)

    runs = []
    options = {} if args.rounds is None else {"rounds": args.rounds}
    if args.fit_steps is not None:
        options["fit_steps"] = args.fit_steps
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            print(f"\ndistilling (seed {seed})...", flush=True)
            result = mpc.distil(task, planner, seed=seed, progress=print, **options)
            m = result.metrics
            run_dir = Path(tmp) / f"distilled-{seed}"
            result.save(run_dir, final_eval=0, animation=False)
            mlp = diffcontrol.load(run_dir)  # the NumPy policy of model.json
            runs.append({"seed": seed, "train_seconds": m["train_seconds"],
                         "compile_seconds": m["compile_seconds"], **m["distillation"],
                         "curve": m["curve"]})  # fmt: skip
            for key, opt in optima.items():
                ev = diffcontrol.evaluate(mlp, task, episodes=args.episodes, seed=opt.seeds[0])
                row = {"controller": f"distilled MLP (DAgger, seed {seed})", "seeds": key,
                       "mean_return": ev.mean, "gap_to_optimum": opt.gap(ev.mean),
                       "seconds": m["train_seconds"],
                       "planner_calls": m["distillation"]["planner_calls"],
                       "returns": ev.returns.tolist()}  # fmt: skip
                rows.append(row)
                print_row(row)

    print(
        "\nseconds: the teacher's row is its Gymnasium evaluation, a distilled row the whole "
        "distillation (compilation included); planner: planner calls (control steps solved)."
    )
    doc = {
        "machine": {**machine(), "loadavg_before": load_before, "loadavg_after": os.getloadavg()},
        "grid": {"points": args.points, "levels": args.levels, "solve_seconds": grid_s},
        "optimum": {k: v.to_json() for k, v in optima.items()},
        "rows": rows,
        "distillations": runs,
        "command": "taskset -c 0 python benchmarks/distil_pendulum.py " + " ".join(sys.argv[1:]),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"\nload average before {load_before}, after {os.getloadavg()}\nwrote {args.out}")


if __name__ == "__main__":
    main()
