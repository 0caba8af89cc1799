"""Training through one fitted swing-up model after another, in one process: what a refit costs.

A loop round, the next seed of `benchmarks/fit_swingup.py` or `fit_swingup_basins.py`, fits a
new model and trains a controller through it (`FittedSwingUp`). This script records 3 random
episodes of the friction cart-pole, fits `--fits` hybrid models to them (each from its own
network seed), and trains a controller through each in turn with the task's configuration
(`--updates` changed), timing every training with its compilation (`metrics["timings"]`).
The first training compiles; what the later ones pay is the point. The persistent
compilation cache is off (the trainings share programs only within the process).

    taskset -c 0 python benchmarks/refit_swingup.py
    git worktree add /tmp/before HEAD~1
    PYTHONPATH=/tmp/before/src taskset -c 0 python benchmarks/refit_swingup.py --name _before

Prints a table and writes benchmarks/results/refit_swingup{NAME}.json (machine, date, figures).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ["DIFFCONTROL_NO_COMPILE_CACHE"] = "1"

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--fits", type=int, default=3, help="models fitted and trained through")
    parser.add_argument("--updates", type=int, default=100, help="updates of each training")
    parser.add_argument("--fit-steps", type=int, default=300, help="Adam steps of each fit")
    parser.add_argument("--name", default="", help="suffix of the results file")
    args = parser.parse_args()

    import jax
    import numpy as np

    import diffcontrol
    from diffcontrol.builtin.swingup import fitted as fs

    task = diffcontrol.make("cartpole-swingup-friction")
    data = fs.record_swingup(task.default_params(), 3, seed=0)
    config = task.default_config().replace(updates=args.updates, eval_every=args.updates // 2)
    rows = []
    for i in range(args.fits):
        t0 = time.perf_counter()
        fit = fs.fit_swingup_model(data, "hybrid", steps=args.fit_steps, seed=i)
        fit_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        result = diffcontrol.train(fs.FittedSwingUp(task, fit.model), config)
        train_s = time.perf_counter() - t0
        timings = result.metrics["timings"]
        leaves = jax.tree.leaves(result.controller)
        rows.append(
            {
                "fit": i,
                "fit_seconds": round(fit_s, 2),
                "train_seconds": round(train_s, 2),
                "compile_seconds": round(timings["compile"], 2),
                "compile_programs": timings["compile_programs"],
                "final_eval_return": result.metrics["final_eval_return"],
                "weights_sum": float(sum(np.sum(np.asarray(x, np.float64)) for x in leaves)),
            }
        )
        r = rows[-1]
        print(
            f"fit {i}: fit {r['fit_seconds']:6.2f} s  train {r['train_seconds']:6.2f} s "
            f"(compile {r['compile_seconds']:5.2f} s, {r['compile_programs']} programs)  "
            f"final return {r['final_eval_return']:.6g}",
            flush=True,
        )
    doc = {
        "machine": machine(),
        "command": " ".join(sys.argv),
        "package": diffcontrol.__file__,
        "settings": vars(args),
        "rows": rows,
    }
    out = HERE / "results" / f"refit_swingup{args.name}.json"
    out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
