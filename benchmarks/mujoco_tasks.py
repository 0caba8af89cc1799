"""Benchmark of the MuJoCo tasks: BPTT through MJX, judged in Gymnasium's own environments.

Each run is the real command line, `diffcontrol train NAME --out DIR --seed S [FLAGS]` (NAME:
the task's registered name), in a fresh process pinned to one core (`taskset -c 0`) with the
persistent compilation cache off, so `train_seconds` includes compiling from scratch. Each
controller is then judged as issue 41 asks: `diffcontrol evaluate DIR --episodes 50 --seed
1000`, the mean return of 50 episodes of Gymnasium's own environment on reset seeds the
training never saw (training draws its starts from JAX keys, not Gymnasium seeds).

    taskset -c 0 python benchmarks/mujoco_tasks.py InvertedDoublePendulum
    taskset -c 0 python benchmarks/mujoco_tasks.py Reacher --seeds 3 -- --updates 2000

Targets (issue 41): InvertedDoublePendulum-v5 >= 9,300, Reacher-v5 >= -3.75, Swimmer-v5 >= 282
(stretch 366), each within 30 minutes of one core. Prints a table and writes
benchmarks/results/mujoco_<CLASS>.json (machine, date, command, every figure).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, train_cli  # noqa: E402

TARGETS = {"InvertedDoublePendulum": 9300.0, "Reacher": -3.75, "Swimmer": 282.0}
NAMES = {
    "InvertedDoublePendulum": "inverted-double-pendulum",
    "Reacher": "reacher",
    "Swimmer": "swimmer",
}
MINUTES = 30.0


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("task", choices=sorted(TARGETS), help="a class of builtin.mujoco.tasks")
    parser.add_argument("--seeds", type=int, default=1, help="training seeds 0..N-1 (default 1)")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--eval-seed", type=int, default=1000)
    parser.add_argument("--out", type=Path)
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    args = parser.parse_args(argv[:cut])
    args.flags = argv[cut + 1 :]  # after --: flags of `diffcontrol train`
    path = NAMES[args.task]
    out = args.out or HERE / "results" / f"mujoco_{args.task}.json"
    print(f"{'seed':>4} {'train s':>8} {'compile s':>9} {'process s':>9} {'return':>10} {'std':>8}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            run = Path(tmp) / f"seed{seed}"
            extra = ["--no-animation", "--final-eval", "1", *args.flags]
            metrics, seconds = train_cli(path, seed, run, extra)
            cmd = [sys.executable, "-m", "diffcontrol.cli", "evaluate", str(run), "--task", path]
            cmd += ["--episodes", str(args.episodes), "--seed", str(args.eval_seed), "--json"]
            ev = json.loads(subprocess.run(cmd, check=True, capture_output=True).stdout)
            row = dict(
                seed=seed,
                train_seconds=metrics["train_seconds"],
                compile_seconds=metrics["compile_seconds"],
                process_seconds=seconds,
                simulated_steps=metrics["simulated_steps"],
                returned_update=metrics["returned_update"],
                eval=ev,
            )
            rows.append(row)
            print(
                f"{seed:>4} {row['train_seconds']:>8.1f} {row['compile_seconds']:>9.1f} "
                f"{seconds:>9.1f} {ev['mean_return']:>10.2f} {ev['std_return']:>8.2f}"
            )
    target = TARGETS[args.task]
    met = [
        r["eval"]["mean_return"] >= target and r["process_seconds"] <= 60 * MINUTES for r in rows
    ]
    print(
        f"target: >= {target:g} within {MINUTES:g} min of one core: met by {sum(met)} of {len(rows)}"
    )
    doc = dict(
        machine=machine(),
        command=" ".join(["python", "benchmarks/mujoco_tasks.py", *sys.argv[1:]]),
        task=path,
        flags=args.flags,
        eval_episodes=args.episodes,
        eval_seeds=[args.eval_seed, args.eval_seed + args.episodes - 1],
        target=target,
        rows=rows,
    )
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
