"""Benchmark of the trebuchet's grey box: drag and wind fitted from throws, then aiming.

The "real" trebuchet (``REAL``) has drag coefficient 1.5 (the nominal model has 1.0) and a
wind that acts 1.5 times as strongly as the nominal model assumes (``wind_factor``). At 45
degrees and 200 lb in calm air it throws 63 m where the nominal model says 83 m.

1. Parameter recovery: for data seeds S = 0 .. 4, ``N_THROWS`` throws of the real trebuchet
   with random inputs (winds N(0, 5^2) m/s, angles U(20, 70) deg, counterweights U(50, 450) lb;
   the task's ``record_data(seed=S)``, one-step episodes), once noise-free and once with
   Gaussian noise of ``NOISE_M`` m on the measured distance; ``diffcontrol.identify.fit`` fits
   drag_coefficient and wind_factor (300 Adam steps, 20 Levenberg-Marquardt steps). Held-out: 200 more throws
   (seed 1000 + S, same noise) predicted by the nominal and the fitted model.
2. Gap closure: for training seeds S = 0 .. SEEDS-1, three controllers trained with the same
   budget (the task's default config unless --updates is given) on (a) the nominal model, (b)
   the model fitted from the noisy throws of data seed S, (c) the true model; each aims at the
   same 1,000 targets on the real trebuchet (``evaluate_aiming(params=REAL)``, targets
   U(20, 100) m, winds N(0, 5^2) m/s, seed 0; the real trebuchet's unreachable targets are
   left out). Gap closed = (miss_a - miss_b) / (miss_a - miss_c).

    taskset -c 1 python benchmarks/fit_trebuchet.py [--seeds 3] [--updates 2000]

Prints tables and writes benchmarks/results/fit_trebuchet.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import identify, io, policies  # noqa: E402
from diffcontrol.builtin.trebuchet import system as tb  # noqa: E402
from diffcontrol.builtin.trebuchet.fit import distance_errors  # noqa: E402
from diffcontrol.builtin.trebuchet.judge import evaluate_aiming  # noqa: E402

TRUTH = {"drag_coefficient": 1.5, "wind_factor": 1.5}
REAL = tb.TrebuchetParams(**TRUTH)
N_THROWS = 10
"""Throws recorded for each fit: 10, as the issue's "at most 10 episodes" (a trebuchet
episode is one throw)."""
NOISE_M = 0.5
"""Standard deviation (m) of the Gaussian noise on the measured distances: a tape or
laser measurement of where a projectile landed, including its bounce mark."""
HELD_OUT = 200


def recovery(seed: int, noise_m: float) -> tuple[dict, object]:
    task = diffcontrol.make("trebuchet")
    data = task.record_data(N_THROWS, env_kwargs=TRUTH, seed=seed, noise_m=noise_m)
    held_out = task.record_data(HELD_OUT, env_kwargs=TRUTH, seed=1000 + seed, noise_m=noise_m)
    t0 = time.perf_counter()
    result = identify.fit(task, data, "params", names=tuple(TRUTH))
    seconds = time.perf_counter() - t0
    row = {
        "seed": seed,
        "noise_m": noise_m,
        "throws": data.num_episodes,
        "seconds": seconds,
        "values": result.values,
        "standard_errors": result.standard_errors,
        "relative_error": {n: (result.values[n] - t) / t for n, t in TRUTH.items()},
        "z": {
            n: (result.values[n] - t) / result.standard_errors[n] if noise_m else None
            for n, t in TRUTH.items()
        },
        "held_out": {
            "nominal": distance_errors(None, held_out),
            "fitted": distance_errors(result.params, held_out),
        },
        "diverged": result.diverged,
        "message": result.message,
    }
    return row, result


def train_and_aim(task, config, params: dict, seed: int) -> dict:
    cfg = config.replace(params=tuple(params.items()), seed=seed)
    t0 = time.perf_counter()
    result = diffcontrol.train(task, cfg)
    seconds = time.perf_counter() - t0
    policy = policies.AimingPolicy(policies.controller_to_dict(result.controller, task))
    ev = evaluate_aiming(policy, task, targets=1000, seed=0, params=REAL)
    return {"train_seconds": seconds, **ev.stats}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=3, help="training seeds (default 3)")
    parser.add_argument("--recovery-seeds", type=int, default=5, help="data seeds (default 5)")
    parser.add_argument("--updates", type=int, default=None, help="training updates")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "fit_trebuchet.json")
    args = parser.parse_args()

    print(f"real trebuchet: {TRUTH}; {N_THROWS} throws per fit; noise {NOISE_M} m or none")
    print(
        "noise m  seed  drag_coefficient (rel err, z)  wind_factor (rel err, z)   held-out RMS "
        "nominal / fitted (m)"
    )
    rows, fits = [], {}
    for noise in (0.0, NOISE_M):
        for s in range(args.recovery_seeds):
            row, result = recovery(s, noise)
            rows.append(row)
            if noise:
                fits[s] = result
            e, z = row["relative_error"], row["z"]
            zs = [f"{z[n]:+5.2f}" if z[n] is not None else "  -  " for n in TRUTH]
            ho = row["held_out"]
            print(
                f"{noise:7.1f}  {s:4}  {e['drag_coefficient']:+.2e} ({zs[0]})          "
                f"{e['wind_factor']:+.2e} ({zs[1]})      {ho['nominal']['rmse_m']:.3g} / "
                f"{ho['fitted']['rmse_m']:.3g}  ({row['seconds']:.1f} s)",
                flush=True,
            )

    task = diffcontrol.make("trebuchet")
    config = task.default_config()
    if args.updates:
        config = config.replace(updates=args.updates)
    print(
        f"\ntraining: {config.updates} updates of batch {config.batch} (loss {config.loss}) per "
        "controller; mean |miss| on the REAL trebuchet over its reachable targets of 1,000"
    )
    print("seed  (a) nominal m  (b) fitted m  (c) true m  gap closed  reachable")
    gap_rows = []
    for s in range(args.seeds):
        fit = fits.get(s) or recovery(s, NOISE_M)[1]
        models = {"nominal": {}, "fitted": fit.values, "true": TRUTH}
        out = {name: train_and_aim(task, config, p, s) for name, p in models.items()}
        a, b, c = (out[k]["mean_miss_m"] for k in ("nominal", "fitted", "true"))
        gap = (a - b) / (a - c)
        gap_rows.append({"seed": s, "fitted_values": fit.values, **out, "gap_closed": gap})
        print(
            f"{s:4}  {a:13.3f}  {b:12.3f}  {c:10.3f}  {100 * gap:9.1f} %  "
            f"{out['true']['reachable']}/{out['true']['targets']}",
            flush=True,
        )

    def rel(noise):
        return max(
            abs(r["relative_error"][n]) for r in rows if r["noise_m"] == noise for n in TRUTH
        )

    summary = {
        "worst_relative_error_noise_free": rel(0.0),
        "worst_relative_error_noisy": rel(NOISE_M),
        "median_gap_closed": statistics.median(r["gap_closed"] for r in gap_rows),
        "worst_gap_closed": min(r["gap_closed"] for r in gap_rows),
        "median_miss_m": {
            k: statistics.median(r[k]["mean_miss_m"] for r in gap_rows)
            for k in ("nominal", "fitted", "true")
        },
    }
    print(
        f"\nworst relative parameter error: {summary['worst_relative_error_noise_free']:.1e} "
        f"noise-free, {summary['worst_relative_error_noisy']:.1e} with {NOISE_M} m noise; gap "
        f"closed: median {100 * summary['median_gap_closed']:.1f} %, worst "
        f"{100 * summary['worst_gap_closed']:.1f} %"
    )
    doc = {
        "machine": machine(),
        "truth": TRUTH,
        "throws_per_fit": N_THROWS,
        "noise_m": NOISE_M,
        "held_out_throws": HELD_OUT,
        "train_config": {
            "updates": config.updates,
            "batch": config.batch,
            "loss": config.loss,
            "learning_rate": config.learning_rate,
            "hidden": list(config.hidden),
        },
        "recovery": rows,
        "gap": gap_rows,
        "summary": summary,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(io._finite(doc), indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
