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
    python benchmarks/gc_tracing.py --memory 12          # 12 trainings in one process

With ``--memory N``, each setting (and the thresholds ``10000, 50, 50``, tried first) instead
runs N CartPole trainings of 30 updates in one process through ``cli.main``, the network one
width larger each time (new programs every run, as a long loop or sweep makes them), and
reports the resident memory after the last, the full collections and the unreachable objects
one more full collection then finds.

Prints a table and writes benchmarks/results/gc_tracing.json (``--memory``: gc_memory.json;
machine, date, every figure).
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
from diffcontrol.training import _driver, _programs

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
kept = _programs._kept_trainer(task, config, None, params, lambda line: None)
t0 = time.perf_counter()
_programs._START.lower(kept.trainer, np.int32(config.seed), params)
t1 = time.perf_counter()
ts, k_eval = _programs._first_state(kept, config.seed, params)
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


MEMORY_CHILD = r"""
import contextlib, gc, io, json, os, sys, tempfile, time
os.environ["DIFFCONTROL_NO_COMPILE_CACHE"] = "1"
from diffcontrol._jax_setup import GC_THRESHOLDS
from diffcontrol.cli import main
setting, n = sys.argv[1], int(sys.argv[2])
if setting == "console script":
    gc.set_threshold(*GC_THRESHOLDS)
elif setting == "10000, 50, 50":
    gc.set_threshold(10_000, 50, 50)
full = []
gc.callbacks.append(lambda p, i: full.append(1) if p == "start" and i["generation"] == 2 else None)
out, t0 = tempfile.mkdtemp(), time.perf_counter()
for i in range(n):
    h = 8 + 4 * i
    args = ["train", "cartpole", "--updates", "30", "--hidden", f"{h},{h}", "--quiet",
            "--eval-episodes", "10", "--final-eval", "0", "--no-animation", "--out", f"{out}/{i}"]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(args) == 0
seconds = time.perf_counter() - t0
with open("/proc/self/statm") as f:
    rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
print(json.dumps({"rss_mb": rss, "full_collections": len(full), "seconds": seconds,
                  "unreachable_at_end": gc.collect()}))
"""


def memory(runs: int, pin: list[str]) -> list[dict]:
    rows = []
    print(f"{'setting':16s} {'rss MB':>7s} {'full':>5s} {'unreachable':>11s} {'seconds':>8s}")
    for setting in (*SETTINGS[:2], "10000, 50, 50"):
        cmd = [*pin, sys.executable, "-c", MEMORY_CHILD, setting, str(runs)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        row = {"setting": setting, "runs": runs, **json.loads(done.stdout.strip().splitlines()[-1])}
        rows.append(row)
        print(
            f"{setting:16s} {row['rss_mb']:7.0f} {row['full_collections']:5d} "
            f"{row['unreachable_at_end']:11d} {row['seconds']:8.1f}",
            flush=True,
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="cartpole-swingup")
    parser.add_argument("--rounds", type=int, default=3, help="each setting this many times")
    parser.add_argument("--memory", type=int, default=0, help="N trainings in one process")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    if args.memory:
        rows = memory(args.memory, pin)
        out = args.out or HERE / "results" / "gc_memory.json"
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"machine": machine(), "runs": rows}, indent=1) + "\n")
        print(f"wrote {out}")
        return
    args.out = args.out or HERE / "results" / "gc_tracing.json"
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
