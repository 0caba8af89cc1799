"""Benchmark of grey-box parameter recovery: Pendulum's g and joint friction from recorded data.

The "real" pendulum is Gymnasium's own ``Pendulum-v1`` with g = 12 m/s^2 (the nominal model
has 10) wrapped with joint friction 0.1 N m s/rad (``diffcontrol/PendulumFriction-v0``; the
nominal has none). For each data seed S: 10 episodes of 200 steps with random torques in
[-2, 2] N m (reset seeds 100 S .. 100 S + 9), the first 8 fitted with
``diffcontrol.identify.fit_parameters`` (window 10, 300 Adam steps, 20 Levenberg-Marquardt
steps), the last 2 held out; once noise-free and once with Gaussian sensor noise of standard
deviation 0.01 on cos(theta) and sin(theta) and 0.05 rad/s on theta_dot.

    python benchmarks/fit_pendulum.py [--seeds 5]

Prints a table and writes benchmarks/results/fit_pendulum.json (machine, date, every figure).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import identify as fitting  # noqa: E402

TRUTH = {"g": 12.0, "friction": 0.1}
NOISE = np.array([0.01, 0.01, 0.05])


def run(seed: int, noisy: bool) -> dict:
    data = diffcontrol.record(
        "diffcontrol/PendulumFriction-v0", 10, seed=100 * seed, env_kwargs=TRUTH
    )
    if noisy:
        rng = np.random.default_rng(seed)
        obs = data.observations + rng.normal(size=data.observations.shape) * NOISE
        data = dataclasses.replace(data, observations=obs)
    train, held_out = data.split(8)
    task = diffcontrol.make("pendulum")
    t0 = time.perf_counter()
    result = fitting.fit_parameters(task, train, tuple(TRUTH))
    seconds = time.perf_counter() - t0
    nominal = fitting.prediction_errors(task, task.default_params(), held_out)
    fitted = fitting.prediction_errors(task, result.params, held_out)
    return {
        "seed": seed,
        "noisy": noisy,
        "seconds": seconds,
        "values": result.values,
        "standard_errors": result.standard_errors,
        "relative_error": {n: (result.values[n] - t) / t for n, t in TRUTH.items()},
        "z": {n: (result.values[n] - t) / result.standard_errors[n] for n, t in TRUTH.items()},
        "held_out_rmse": {
            "nominal": {h: e["rmse"] for h, e in nominal.items()},
            "fitted": {h: e["rmse"] for h, e in fitted.items()},
        },
        "diverged": result.diverged,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    rows = [run(s, noisy) for noisy in (False, True) for s in range(args.seeds)]
    print("noise  seed  g (rel err, z)            friction (rel err, z)     10-step RMSE nom/fit")
    for r in rows:
        g, f = r["relative_error"]["g"], r["relative_error"]["friction"]
        zg, zf = r["z"]["g"], r["z"]["friction"]
        nom, fit = r["held_out_rmse"]["nominal"][10], r["held_out_rmse"]["fitted"][10]
        print(
            f"{'yes' if r['noisy'] else 'no':5}  {r['seed']:4}  {g:+.2e} ({zg:+5.2f})  "
            f"{f:+.2e} ({zf:+5.2f})  {nom:.3g} / {fit:.3g}  ({r['seconds']:.1f} s)"
        )
    out = HERE / "results" / "fit_pendulum.json"
    doc = {"machine": machine(), "truth": TRUTH, "noise_std": NOISE.tolist(), "runs": rows}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
