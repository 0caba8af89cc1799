"""Benchmark of sweeps and populations (issue 16): one vmapped program against separate runs.

Three measurements, each printed as a table and written to benchmarks/results/sweep.json:

1. **Sweep against separate runs.** `diffcontrol sweep cartpole --seeds 0-15 --set
   learning_rate=...` (64 members: 16 seeds x 4 learning rates, the task's defaults otherwise)
   as one process, against `diffcontrol train cartpole --seed S --learning-rate LR` for the
   same members one after the other (each a fresh process, the persistent compilation cache
   warm, as a user's second run would be; their final Gymnasium evaluation and GIF skipped,
   `--final-eval 0 --no-animation`, so that they write what a sweep member writes). Running
   all 64 separately takes long, so `--separate K` of them (default 8, spread over the grid)
   are run and their mean time is multiplied by 64; the per-member results of those K are
   compared with the sweep's (same returned update and in-simulator return, to noise).
2. **Population scaling on one device**: simulated steps per second (forward and backward,
   compilation and evaluation excluded) of the Pendulum trainer's chunk vmapped over 1, 8, 64
   and 512 members (batch 64, window 20 each).
3. **Devices**: the same throughput for 64 members on 1 device pinned to one core, on 1
   device with both cores (XLA's intra-op threads), and split over 2 devices
   (`--xla_force_host_platform_device_count=2`) with one thread each, one per core: each in
   its own process under `taskset` (meaningful on an otherwise idle 2-core machine).

    taskset -c 0 python benchmarks/sweep.py            # 1 and 2 on one pinned core
    python benchmarks/sweep.py --only devices         # pins its own processes
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

LRS = (3e-3, 1e-2, 3e-2, 1e-1)
SEEDS = 16


def _cli(*args: str, env: dict | None = None) -> float:
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "diffcontrol.cli", *args, "--quiet"],
        check=True,
        stdout=subprocess.DEVNULL,
        env={**os.environ, **(env or {})},
    )
    return time.perf_counter() - t0


def sweep_vs_separate(separate: int) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    cache = {"DIFFCONTROL_CACHE_DIR": str(tmp / "cache")}
    lrs = ",".join(f"{x:g}" for x in LRS)
    out = tmp / "sweep"
    cold = _cli("sweep", "cartpole", "--out", str(out), "--seeds", f"0-{SEEDS - 1}",
                "--set", f"learning_rate={lrs}", "--final-eval", "0", env=cache)  # fmt: skip
    warm = _cli("sweep", "cartpole", "--out", str(tmp / "sweep2"), "--seeds", f"0-{SEEDS - 1}",
                "--set", f"learning_rate={lrs}", "--final-eval", "0", env=cache)  # fmt: skip
    doc = json.loads((out / "sweep.json").read_text())
    members = doc["members"]
    picks = [round(i * (len(members) - 1) / max(separate - 1, 1)) for i in range(separate)]
    rows = []
    times = []
    for i in picks:
        seed, lr = i % SEEDS, LRS[i // SEEDS]
        run = tmp / f"run{i}"
        seconds = _cli("train", "cartpole", "--out", str(run), "--seed", str(seed),
                       "--learning-rate", f"{lr:g}", "--final-eval", "0", "--no-animation",
                       env=cache)  # fmt: skip
        times.append(seconds)
        alone = json.loads((run / "metrics.json").read_text())
        member = json.loads((out / members[i] / "metrics.json").read_text())
        rows.append(
            {
                "member": members[i],
                "seconds_separate": seconds,
                "returned_update": [alone["returned_update"], member["returned_update"]],
                "eval_return": [alone["final_eval_return"], member["final_eval_return"]],
            }
        )
    per_run = sum(times[1:]) / max(len(times) - 1, 1)  # the first one warms the cache
    separate_total = per_run * len(members)
    return {
        "members": len(members),
        "sweep_seconds_cold_cache": cold,
        "sweep_seconds_warm_cache": warm,
        "separate_seconds_per_run_warm_cache": per_run,
        "separate_seconds_64_estimated": separate_total,
        "speedup_warm": separate_total / warm,
        "speedup_cold": separate_total / cold,
        "compared": rows,
    }


def population_scaling(sizes=(1, 8, 64, 512), devices: int = 1) -> list[dict]:
    import jax
    import jax.numpy as jnp

    import diffcontrol as dc
    from diffcontrol.training import resolve_config
    from diffcontrol.training._bptt import Trainer, make_optimizer
    from diffcontrol.training._sweep import _placement

    task = dc.make("pendulum")
    # the windows recipe (no terminal value: the trainer is built by hand); a short chunk,
    # since 512 members are slow
    cfg = resolve_config(task, "windows", eval_every=5)
    params = jax.tree.map(jnp.asarray, task.default_params())
    trainer = Trainer(task=task, config=cfg, step_loss=task.step_loss(task.losses[0]),
                      optimizer=make_optimizer(cfg), horizon=cfg.horizon)  # fmt: skip
    rows = []
    for n in sizes:
        shard, replicate = _placement(devices)
        keys = shard(jax.random.split(jax.random.PRNGKey(0), n))
        ts = shard(jax.jit(jax.vmap(trainer.init, in_axes=(0, None)))(keys, params))
        chunk = jax.jit(jax.vmap(trainer.chunk, in_axes=(0, None, None)))
        total = jnp.asarray(10**9, jnp.int32)
        ts, _ = chunk(ts, replicate(params), total)  # compile and warm up
        jax.block_until_ready(ts)
        reps, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < 3.0:
            ts, _ = chunk(ts, replicate(params), total)
            jax.block_until_ready(ts)
            reps += 1
        seconds = (time.perf_counter() - t0) / reps
        steps = n * cfg.eval_every * cfg.window * cfg.batch
        rows.append({"members": n, "devices": devices, "steps_per_second": steps / seconds})
        del ts
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--separate", type=int, default=8)
    parser.add_argument("--only", choices=("sweep", "population", "devices"))
    parser.add_argument("--out", default=str(HERE / "results" / "sweep.json"))
    args = parser.parse_args()
    result = {"machine": machine(), "affinity": sorted(os.sched_getaffinity(0))}
    path = Path(args.out)
    if path.exists():
        result = {**json.loads(path.read_text()), **result}
    if args.only in (None, "sweep"):
        s = sweep_vs_separate(args.separate)
        result["sweep"] = s
        print(f"64-member cartpole sweep: {s['sweep_seconds_warm_cache']:.1f} s warm cache "
              f"({s['sweep_seconds_cold_cache']:.1f} s cold); separate runs "
              f"{s['separate_seconds_per_run_warm_cache']:.1f} s each, x64 = "
              f"{s['separate_seconds_64_estimated']:.0f} s -> {s['speedup_warm']:.1f}x "
              f"({s['speedup_cold']:.1f}x against the cold sweep); target >= 20x")  # fmt: skip
        print(
            "member                         returned update (alone, sweep)  return (alone, sweep)"
        )
        for r in s["compared"]:
            print(f"{r['member']:<30} {str(r['returned_update']):<32} {r['eval_return']}")
        _write(path, result)
    if args.only in (None, "population"):
        rows = population_scaling()
        result["population"] = rows
        print("members  steps/s (pendulum trainer, one device)  vs population 1")
        for r in rows:
            per = r["steps_per_second"] / rows[0]["steps_per_second"]
            print(f"{r['members']:>7}  {r['steps_per_second']:>14,.0f}  {per:8.2f}x")
    if args.only == "devices":
        rows = device_rows()
        result["devices"] = rows
        base = rows[0]["steps_per_second"]
        print("64 members, pendulum trainer       cores  steps/s       vs 1 device on 1 core")
        for r in rows:
            print(f"{r['setting']:<34} {r['cores']:>5}  {r['steps_per_second']:>12,.0f}  "
                  f"{r['steps_per_second'] / base:6.2f}x")  # fmt: skip
        print(f"target: 2 devices (one per core) >= 1.8x one device; "
              f"{rows[-1]['steps_per_second'] / base:.2f}x")  # fmt: skip
    _write(path, result)
    print(f"wrote {path}")


DEVICE_SETTINGS = (
    # (label, cores for taskset, devices, XLA flags)
    ("1 device, 1 core", "0", 1, "--xla_cpu_multi_thread_eigen=false"),
    ("1 device, 2 cores (intra-op threads)", "0,1", 1, ""),
    ("2 devices, one thread each", "0,1", 2, "--xla_cpu_multi_thread_eigen=false"),
)


def device_rows() -> list[dict]:
    """The 64-member throughput of each ``DEVICE_SETTINGS`` row, each in a fresh process
    pinned with ``taskset`` (the device count and XLA's threading are fixed at start-up)."""
    rows = []
    for label, cores, devices, flags in DEVICE_SETTINGS:
        code = (
            f"import json, sys; sys.path.insert(0, {str(HERE)!r}); "
            "from sweep import population_scaling; "
            f"print(json.dumps(population_scaling((64,), {devices})[0]))"
        )
        xla = f"--xla_force_host_platform_device_count={devices} {flags}".strip()
        env = {**os.environ, "XLA_FLAGS": xla}
        out = subprocess.run(["taskset", "-c", cores, sys.executable, "-c", code], env=env,
                             check=True, capture_output=True, text=True).stdout  # fmt: skip
        row = json.loads(out.strip().splitlines()[-1])
        rows.append({"setting": label, "cores": len(cores.split(",")), "xla_flags": xla, **row})
    return rows


def _write(path: Path, result: dict) -> None:
    """Write what is measured so far (a long run keeps its parts)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
