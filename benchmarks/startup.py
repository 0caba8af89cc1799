"""Time to the first controller: where the time of `diffcontrol train TASK` goes.

Each run is the real command line, `diffcontrol train TASK --out DIR --seed 0` with the task's
defaults (final evaluation and GIF included), in a fresh process pinned to one core
(`taskset -c 0`): first with a cold persistent compilation cache (a fresh, empty directory),
then again with the cache that run filled (warm). The breakdown comes from the run's
`metrics.json` (`timings`: import, compile with the number of programs, train, evaluate,
write, and the process's age when its files were written); `process s` is the whole command,
measured from outside (interpreter start-up and exit included). Also timed: `diffcontrol
--help` and `diffcontrol list`, which import no JAX.

    python benchmarks/startup.py                         # the four tasks, cold and warm
    python benchmarks/startup.py --tasks cartpole --repeat 3
    git worktree add /tmp/before HEAD~1
    python benchmarks/startup.py --tasks cartpole --repeat 2 --baseline /tmp/before/src

With `--baseline`, the package in that directory (the commit before a change, say) runs too,
alternating with this one, so that both meet the same machine: its speed can move by a
quarter within an hour, and only paired runs compare.

Prints a table and writes benchmarks/results/startup.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

TASKS = ("cartpole", "pendulum", "trebuchet", "cartpole-swingup")
TARGETS_COLD = {"cartpole": 5.0, "pendulum": 12.0, "trebuchet": 25.0, "cartpole-swingup": 10.0}
"""The issue's targets for the whole command with a cold cache (s, one core)."""
TARGETS_WARM = {"cartpole": 3.0}
PARTS = ("import", "compile", "train", "evaluate", "write")


def _pinned(cmd: list[str]) -> list[str]:
    return ["taskset", "-c", "0", *cmd] if shutil.which("taskset") else cmd


def run_command(args: list[str], cache: Path, src: str | None = None) -> float:
    """Run `diffcontrol ARGS` in a fresh process on core 0 (with the package found first in
    ``src``, where given); returns its wall-clock seconds."""
    cmd = _pinned([sys.executable, "-m", "diffcontrol.cli", *args])
    env = {k: v for k, v in os.environ.items() if k != "DIFFCONTROL_NO_COMPILE_CACHE"}
    env["DIFFCONTROL_CACHE_DIR"] = str(cache)
    if src:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def train_once(task: str, out: Path, cache: Path, extra: list[str], src: str | None) -> dict:
    """`diffcontrol train TASK --out OUT --seed 0`: the timings of its metrics.json, the whole
    process's seconds and the headline figure."""
    seconds = run_command(
        ["train", task, "--out", str(out), "--seed", "0", "--quiet", *extra], cache, src
    )
    metrics = json.loads((out / "metrics.json").read_text())
    ev = metrics.get(metrics.get("final_evaluation") or "", {})
    return {
        **{k: metrics["timings"].get(k) for k in (*PARTS, "compile_programs", "total")},
        "process": seconds,
        "train_seconds": metrics["train_seconds"],
        "compile_cache": {k: metrics["compile_cache"].get(k) for k in ("hits", "misses")},
        "result": ev.get("mean_return", ev.get("mean_miss_m", ev.get("loss"))),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--tasks", default=",".join(TASKS), help="comma-separated task names")
    parser.add_argument("--repeat", type=int, default=1, help="cold/warm pairs per task")
    parser.add_argument("--extra", default="", help="more options for every train command")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "startup.json")
    parser.add_argument(
        "--baseline",
        metavar="SRC",
        help="also time the package in SRC (e.g. a worktree's src of the commit before a "
        "change), alternating with this one run by run, so that both meet the same machine",
    )
    args = parser.parse_args()
    extra = args.extra.split()
    codes = [("baseline", args.baseline), ("current", None)] if args.baseline else [("", None)]

    rows = []
    header = (
        f"{'code':<8} "
        * bool(args.baseline)
        + f"{'task':<17} {'cache':<5} {'import':>6} {'compile':>7} {'progs':>5} {'train':>6} "
        f"{'evaluate':>8} {'write':>6} {'total':>6} {'process':>7} {'target':>6}  result"
    )
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        commands = {}
        for name, cmd in (("--help", ["--help"]), ("list", ["list"])):
            commands[name] = min(run_command(cmd, work / "cache-cli") for _ in range(3))
        print("  ".join(f"diffcontrol {k}: {v:.2f} s" for k, v in commands.items()))
        print(header)
        print("-" * len(header))
        for task, rep, (code, src) in itertools.product(
            args.tasks.split(","), range(args.repeat), codes
        ):
            cache = work / f"cache-{task}-{code}-{rep}"  # fresh: the cold run compiles everything
            for state in ("cold", "warm"):
                out = work / f"{task}-{code}-{rep}-{state}"
                r = {"task": task, "cache": state, **train_once(task, out, cache, extra, src)}
                if code:
                    r["code"] = code
                target = (TARGETS_COLD if state == "cold" else TARGETS_WARM).get(task)
                r["target"] = target
                rows.append(r)
                print(
                    f"{code:<8} " * bool(code) + f"{task:<17} {state:<5} {r['import']:>6.2f} "
                    f"{r['compile']:>7.2f} "
                    f"{r['compile_programs']:>5} {r['train']:>6.2f} {r['evaluate']:>8.2f} "
                    f"{r['write']:>6.2f} {r['total'] or 0:>6.2f} {r['process']:>7.2f} "
                    f"{target or '':>6}  {r['result']}",
                    flush=True,
                )
    summary = {}
    for task, state, (code, _) in itertools.product(args.tasks.split(","), ("cold", "warm"), codes):
        seconds = [
            r["process"]
            for r in rows
            if r["task"] == task and r["cache"] == state and r.get("code", "") == code
        ]
        summary[f"{code} {task} {state}".strip()] = statistics.median(seconds)
    doc = {
        "machine": machine(),
        "note": "process = the whole `diffcontrol train TASK --out DIR --seed 0` pinned to "
        "core 0; cold = an empty persistent compilation cache, warm = the one the cold run filled",
        "baseline": args.baseline,
        "commands": commands,
        "runs": rows,
        "median_process_seconds": summary,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
