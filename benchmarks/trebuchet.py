"""Benchmark of the trebuchet demo: aiming accuracy, training time, network vs direct aiming.

The controller is the network's aim refined at act time by two Gauss-Newton steps through the
simulator (``task.REFINEMENT``); its misses are also reported for the network alone (the
NumPy-only form), and its throws simulated again in float64.

Each training run is the real command line, `diffcontrol train trebuchet --out DIR --seed S`,
in a fresh process pinned to one core (`taskset -c 0`) with the persistent compilation cache
off, so `train_seconds` includes compiling everything. Each trained network then aims at the
same 1,000 random targets (20-100 m, wind ~ N(0, 5^2) m/s, seed 0); misses are counted over
the reachable targets and the unreachable ones are reported. Then, in this process (pin it
too: `taskset -c 0 python benchmarks/trebuchet.py`), the time per target of the network
(NumPy, one call per target, and one batched call) and of direct aiming by Gauss-Newton
steps on the simulator alone (jitted, one target per call).

    taskset -c 0 python benchmarks/trebuchet.py             # 3 training seeds
    taskset -c 0 python benchmarks/trebuchet.py --seeds 1

Prints a table and writes benchmarks/results/trebuchet.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, train_cli  # noqa: E402


def run_train(seed: int, workdir: Path, extra: list[str]) -> dict:
    """One training run by the command line; its final evaluation (the controller: the
    network's aim refined through the simulator), and the same 1,000 targets aimed by the
    network alone and judged again in float64."""
    out = workdir / f"trebuchet-{seed}"
    m, process = train_cli(
        "trebuchet", seed, out, ["--no-animation", "--final-eval", "1000", *extra]
    )
    row = {
        "seed": seed,
        "run_dir": str(out),
        "simulated_throws": m["simulated_episodes"],
        "updates": m["updates"],
        "process_seconds": process,
        "train_seconds": m["train_seconds"],
        "compile_seconds": m["compile_seconds"],
        **{k: m["aim_eval"][k] for k in m["aim_eval"] if k not in ("task", "seed")},
    }
    row["network_alone"], row["float64_judge"] = judged_again(out)
    return row


class _NetworkAlone:
    """A refined policy's network without the refinement (what NumPy readers run)."""

    def __init__(self, policy):
        self.action = policy.network_action


def judged_again(run_dir: Path) -> tuple[dict, dict]:
    """The run's network alone on the evaluation's targets, and the controller's throws
    simulated again in float64 (the trebuchet trains and aims in float32)."""
    import jax

    import diffcontrol
    from diffcontrol.builtin.trebuchet import system as tb
    from diffcontrol.builtin.trebuchet import task as aim
    from diffcontrol.builtin.trebuchet.judge import evaluate_aiming

    task, policy = diffcontrol.make("trebuchet"), diffcontrol.load(run_dir)
    alone = evaluate_aiming(_NetworkAlone(policy), task, targets=1000).stats
    ev = evaluate_aiming(policy, task, targets=1000)
    with jax.enable_x64(True):
        distances = np.asarray(
            jax.jit(jax.vmap(tb.shoot, (0, 0, 0, None)))(ev.winds, ev.angles, ev.weights, None)
        )
    wide = aim.miss_statistics(distances - ev.targets, ev.reachable)
    return alone, wide


def time_per_call(fn, args_list, repeat: int = 1) -> float:
    """Mean seconds per call of ``fn`` over ``args_list`` (after one warm-up call)."""
    fn(*args_list[0])
    t0 = time.perf_counter()
    for _ in range(repeat):
        for args in args_list:
            fn(*args)
    return (time.perf_counter() - t0) / (repeat * len(args_list))


def aiming_speed(run_dir: str, n_direct: int) -> dict:
    import jax

    import diffcontrol
    from diffcontrol.builtin.trebuchet import task as aim

    policy = diffcontrol.load(run_dir)
    rng = np.random.default_rng(1)
    targets = rng.uniform(30, 90, size=1000)
    winds = rng.normal(0, 3, size=1000)
    pairs = list(zip(targets.tolist(), winds.tolist()))
    obs = [np.array(p) for p in pairs]

    net_single = time_per_call(lambda o: policy.network_action(o), [(o,) for o in obs])
    t0 = time.perf_counter()
    for _ in range(20):
        policy.network_action(np.stack([targets, winds], -1))
    net_batched = (time.perf_counter() - t0) / (20 * len(targets))
    refined_single = time_per_call(policy, pairs[:20])
    t0 = time.perf_counter()
    for _ in range(5):
        policy(targets, winds)
    refined_batched = (time.perf_counter() - t0) / (5 * len(targets))

    direct = jax.jit(aim.aim_directly)
    results = []

    def one(target, wind):
        results.append(jax.block_until_ready(direct(target, wind)))

    direct_single = time_per_call(one, pairs[:n_direct])
    misses = np.array([float(r[2]) for r in results[1 : n_direct + 1]])
    shortest, longest = (np.asarray(x) for x in aim.reachable_range(winds[:n_direct]))
    reach = (targets[:n_direct] >= shortest) & (targets[:n_direct] <= longest)
    hit = np.abs(misses[reach]) < 0.01
    return {
        "network_seconds_per_target_single_call": net_single,
        "network_seconds_per_target_batched_1000": net_batched,
        "refined_seconds_per_target_single_call": refined_single,
        "refined_seconds_per_target_batched_1000": refined_batched,
        "direct_seconds_per_target": direct_single,
        "direct_targets": n_direct,
        "direct_reachable_targets": int(reach.sum()),
        "direct_hits_within_1cm": int(hit.sum()),
        "direct_median_abs_miss_m": float(np.median(np.abs(misses[reach]))),
        "speedup_single": direct_single / net_single,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=3, help="training seeds (default 3)")
    parser.add_argument("--direct-targets", type=int, default=200, help="targets aimed directly")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "trebuchet.json")
    parser.add_argument("extra", nargs="*", help="extra `diffcontrol train` options (after --)")
    args = parser.parse_args()

    header = (
        f"{'seed':>4} {'throws':>8} {'process s':>9} {'train s':>7} {'reachable':>9} "
        f"{'mean m':>8} {'median m':>8} {'p95 m':>7} {'worst m':>8} {'f64 mean':>8} "
        f"{'net mean':>8}"
    )
    print(header)
    print("-" * len(header))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            r = run_train(seed, Path(tmp), args.extra)
            rows.append(r)
            print(
                f"{seed:>4} {r['simulated_throws']:>8.0f} {r['process_seconds']:>9.1f} "
                f"{r['train_seconds']:>7.1f} {r['reachable']:>5}/{r['targets']:<4}"
                f"{r['mean_miss_m']:>8.5f} {r['median_miss_m']:>8.5f} {r['p95_miss_m']:>7.4f} "
                f"{r['worst_miss_m']:>8.3f} {r['float64_judge']['mean_miss_m']:>8.5f} "
                f"{r['network_alone']['mean_miss_m']:>8.3f}",
                flush=True,
            )
        speed = aiming_speed(rows[0]["run_dir"], args.direct_targets)
    print()
    print(
        f"network, one NumPy call per target: {speed['network_seconds_per_target_single_call'] * 1e6:.1f} us"
        f"; batched (1000 per call): {speed['network_seconds_per_target_batched_1000'] * 1e6:.2f} us"
    )
    print(
        f"controller (network + refinement, JAX): "
        f"{speed['refined_seconds_per_target_single_call'] * 1e3:.1f} ms per single call; "
        f"batched (1000 per call): {speed['refined_seconds_per_target_batched_1000'] * 1e6:.1f} us"
    )
    print(
        f"direct Gauss-Newton aiming (jitted, 1 target per call): "
        f"{speed['direct_seconds_per_target'] * 1e3:.1f} ms per target; within 1 cm on "
        f"{speed['direct_hits_within_1cm']} of {speed['direct_reachable_targets']} reachable targets"
    )
    speed["speedup_batched"] = (
        speed["direct_seconds_per_target"] / speed["network_seconds_per_target_batched_1000"]
    )
    print(
        f"network is {speed['speedup_single']:.0f}x faster per target in single calls, "
        f"{speed['speedup_batched']:.0f}x batched"
    )
    summary = {
        "seeds": len(rows),
        "median_mean_miss_m": statistics.median(r["mean_miss_m"] for r in rows),
        "worst_mean_miss_m": max(r["mean_miss_m"] for r in rows),
        "median_network_alone_mean_miss_m": statistics.median(
            r["network_alone"]["mean_miss_m"] for r in rows
        ),
        "worst_float64_mean_miss_m": max(r["float64_judge"]["mean_miss_m"] for r in rows),
        "median_process_seconds": statistics.median(r["process_seconds"] for r in rows),
        "max_process_seconds": max(r["process_seconds"] for r in rows),
        "median_train_seconds": statistics.median(r["train_seconds"] for r in rows),
        "max_train_seconds": max(r["train_seconds"] for r in rows),
    }
    print(
        f"\nmean |miss| over seeds: median {summary['median_mean_miss_m']:.5f} m, worst "
        f"{summary['worst_mean_miss_m']:.5f} m (float64 judge: worst "
        f"{summary['worst_float64_mean_miss_m']:.5f} m; the network alone: median "
        f"{summary['median_network_alone_mean_miss_m']:.3f} m); the command "
        f"{summary['median_process_seconds']:.1f} s (max {summary['max_process_seconds']:.1f} s), "
        f"training {summary['median_train_seconds']:.1f} s (max {summary['max_train_seconds']:.1f} s)"
    )
    for r in rows:
        r.pop("run_dir")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {"machine": machine(), "runs": rows, "aiming_speed": speed, "summary": summary},
            indent=1,
        )
        + "\n"
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
