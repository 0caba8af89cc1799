"""How much of tracing a task's training programs is Python's garbage collector.

Each setting runs in a fresh process (pinned with ``taskset`` where available): the task's
start, evaluation program and training chunk are traced and lowered as ``diffcontrol train``
lowers them (the start is compiled too, to give the others their arguments: left out), with
the collector at Python's thresholds, at the console script's (``_jax_setup.GC_THRESHOLDS``)
and off. Reported per setting: the seconds of each lowering, the collections during them and
the seconds spent in them (``gc.callbacks``), full ones apart, and the process's peak
resident memory.

    python benchmarks/gc_tracing.py                      # cartpole-swingup, three rounds
    python benchmarks/gc_tracing.py --task cartpole --rounds 2

Prints a table and writes benchmarks/results/gc_tracing.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

SETTINGS = ("python", "console script", "off")

CHILD = r"""
import gc, json, os, resource, sys, time
os.environ.setdefault("EQX_ON_ERROR", "nan")
os.environ["DIFFCONTROL_NO_COMPILE_CACHE"] = "1"
import jax, numpy as np
import diffcontrol
from diffcontrol._jax_setup import GC_THRESHOLDS
from diffcontrol.training import _driver

setting, name = sys.argv[1], sys.argv[2]
if setting == "console script":
    gc.set_threshold(*GC_THRESHOLDS)
elif setting == "off":
    gc.disable()
events = []
gc.callbacks.append(lambda phase, info: events.append((phase, info["generation"], time.perf_counter())))
task = diffcontrol.make(name)
config = task.default_config()
params = _driver.task_params(task, config.params)
t0 = time.perf_counter()
kept = _driver._kept_trainer(task, config, None, None, params, lambda line: None)
_driver._START.lower(kept.trainer, np.int32(config.seed), params)
t1 = time.perf_counter()
ts, k_eval = _driver._first_state(kept, config.seed, params)
t2 = time.perf_counter()
jax.jit(kept.trainer.evaluate).lower(ts.controller, params, k_eval)
t3 = time.perf_counter()
end, stage = kept.stages[0]
jax.jit(stage.chunk).lower(ts, params, np.int32(config.updates))
t4 = time.perf_counter()
spent = full = 0.0
runs = fulls = 0
for (p1, g, s), (p2, _, e) in zip(events[::2], events[1::2]):
    if not (t0 <= s <= t1 or t2 <= s <= t4):  # the start's compilation left out
        continue
    spent += e - s
    runs += 1
    if g == 2:
        full += e - s
        fulls += 1
print(json.dumps({
    "start_lower_s": t1 - t0, "evaluate_lower_s": t3 - t2, "chunk_lower_s": t4 - t3,
    "traced_s": (t1 - t0) + (t4 - t2), "collections": runs, "collection_s": spent,
    "full_collections": fulls, "full_collection_s": full,
    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="cartpole-swingup")
    parser.add_argument("--rounds", type=int, default=3, help="each setting this many times")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "gc_tracing.json")
    args = parser.parse_args()
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    rows = []
    print(f"{'setting':16s} {'start':>6s} {'eval':>6s} {'chunk':>6s} {'traced':>7s} "
          f"{'gc runs':>7s} {'gc s':>6s} {'full':>4s} {'full s':>6s} {'rss MB':>7s}")  # fmt: skip
    for _ in range(args.rounds):  # the settings alternate: the machine's speed drifts
        for setting in SETTINGS:
            cmd = [*pin, sys.executable, "-c", CHILD, setting, args.task]
            done = subprocess.run(cmd, capture_output=True, text=True, check=True)
            row = {"setting": setting, **json.loads(done.stdout.strip().splitlines()[-1])}
            rows.append(row)
            print(
                f"{setting:16s} {row['start_lower_s']:6.2f} {row['evaluate_lower_s']:6.2f} "
                f"{row['chunk_lower_s']:6.2f} {row['traced_s']:7.2f} {row['collections']:7d} "
                f"{row['collection_s']:6.2f} {row['full_collections']:4d} "
                f"{row['full_collection_s']:6.2f} {row['peak_rss_mb']:7.0f}",
                flush=True,
            )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"machine": machine(), "task": args.task, "pinned": bool(pin), "runs": rows}
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
