"""Benchmark of grey-box parameter recovery for the swing-up: its friction from recorded states.

The "real" cart-pole is ``cartpole-swingup-friction``'s (cart: viscous 1 N s/m, Coulomb
0.5 N; joint: viscous 0.1 N m s/rad, Coulomb 0); the nominal model has no friction. Per data
seed S: 10 episodes of 5 s at 50 Hz recorded with ``ode_fitting.record_swingup`` (seed S),
8 fitted with ``ode_fitting.fit_swingup_model(kind="params")`` (the four friction
coefficients; 200 Adam and 20 Levenberg-Marquardt steps, windows of 10 intervals), once
noise-free and once with Gaussian sensor noise of standard deviation 0.005 m on x, 0.05 m/s
on x_dot, 0.005 rad on theta and 0.05 rad/s on theta_dot.

    taskset -c 0 python benchmarks/fit_swingup_recovery.py [--seeds 3]

Prints a table and writes benchmarks/results/fit_swingup_recovery.json.
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
from diffcontrol.builtin.swingup import fitted as of  # noqa: E402
from diffcontrol.builtin.swingup.fitted import FRICTION_NAMES  # noqa: E402

NOISE = np.array([0.005, 0.05, 0.005, 0.05])


def run(seed: int, noisy: bool) -> dict:
    real = diffcontrol.make("cartpole-swingup-friction").default_params()
    truth = {n: float(getattr(real, n)) for n in FRICTION_NAMES}
    data = of.record_swingup(real, 10, seed=seed)
    if noisy:
        rng = np.random.default_rng(1000 + seed)
        obs = data.observations + rng.normal(size=data.observations.shape) * NOISE
        data = dataclasses.replace(data, observations=obs)
    train, _ = data.split(8)
    t0 = time.perf_counter()
    fit = of.fit_swingup_model(train, "params", real, steps=200, learning_rate=0.02)
    seconds = time.perf_counter() - t0
    return {
        "seed": seed,
        "noisy": noisy,
        "seconds": seconds,
        "truth": truth,
        "values": fit.values,
        "standard_errors": fit.standard_errors,
        "error": {n: fit.values[n] - truth[n] for n in truth},
        "relative_error": {n: (fit.values[n] - t) / t for n, t in truth.items() if t},
        "diverged": fit.diverged,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    rows = [run(s, noisy) for noisy in (False, True) for s in range(args.seeds)]
    print(
        "noise  seed  cart_viscous  cart_coulomb  pole_viscous  (relative error)  pole_coulomb (abs, N m)"
    )
    for r in rows:
        rel = r["relative_error"]
        print(
            f"{'yes' if r['noisy'] else 'no':5}  {r['seed']:4}  {rel['cart_viscous']:+.2e}     "
            f"{rel['cart_coulomb']:+.2e}     {rel['pole_viscous']:+.2e}                    "
            f"{r['error']['pole_coulomb']:+.2e}   ({r['seconds']:.0f} s)"
        )
    out = HERE / "results" / "fit_swingup_recovery.json"
    doc = {"machine": machine(), "noise_std": NOISE.tolist(), "runs": rows}
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
