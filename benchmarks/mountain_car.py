"""Benchmark of `mountain-car-continuous`: BPTT with the task's defaults on five training seeds.

Each run is the real command line, `diffcontrol train mountain-car-continuous --out DIR --seed
S`, in a fresh process pinned to one core (`taskset -c 0`) with the persistent compilation
cache off, so `train_seconds` includes compiling everything from scratch. Each trained
controller is then evaluated in Gymnasium's own `MountainCarContinuous-v0` on reset seeds
0-99 (the CLI's final evaluation, `diffcontrol.evaluate`).

The bar (the issue's): a mean return >= 93 for every training seed, each trained in under
60 s on one core. For scale: Gymnasium's `reward_threshold` is 90, rl-zoo's SAC scores 94.7.

    taskset -c 0 python benchmarks/mountain_car.py
    taskset -c 0 python benchmarks/mountain_car.py --seeds 10

Prints a table and writes benchmarks/results/mountain_car.json (machine, date, every figure).
Other processes may share the machine, which inflates the seconds, never the returns.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import gym_seeds_benchmark  # noqa: E402

if __name__ == "__main__":
    gym_seeds_benchmark(
        "mountain-car-continuous",
        __doc__,
        HERE / "results" / "mountain_car.json",
        target_return=93.0,
        target_seconds=60.0,
        reference="rl-zoo SAC: 94.7",
        note="",
    )
