"""Benchmark: real Pendulum-v1 steps to -150 for diffcontrol's loop, against SAC's 11,000.

The real command line, in this process:

    diffcontrol compare pendulum --real --seeds 5 --rl-results benchmarks/results/compare.json \
        --out runs/benchmark-real-pendulum [--resume]

For every seed S and model (grey box starting from g = 8, friction 0.1 where Pendulum-v1 has
g = 10 and none; hybrid with the same wrong physics plus a network; neural: a network alone),
``runs.loop`` records real episodes (random torques first, then the current controller
with action noise 0.1 of the half range), fits the model to all of them, trains a controller
through it and evaluates it on Pendulum-v1 over 100 episodes with reset seeds 1000-1099 (as
``benchmarks/compare.py`` evaluates SAC), until a controller reaches -150 over the 100 episodes or after --max-rounds rounds (3). The
curve points, as ``compare``'s RL evaluation points, are the mean over the first 20 of them
(seeds 1000-1019): "steps to -150" is reported for both (SAC's 11,000 is on 20 episodes; over
100 episodes its returned controllers get -152.5 to -159.1, none -150).
Episodes per round: 1 (grey box, hybrid), 5 (neural: a network needs 1,000 transitions). Real
steps count every recorded transition; the evaluation episodes are not counted, as for RL.

    python benchmarks/real_pendulum.py [--seeds 5] [--models params,hybrid,neural] [--resume]
    python benchmarks/real_pendulum.py --controllers plan --name _plan   # planners act

With ``--controllers plan`` a planner through each round's fitted model acts instead of the
trained MLP (``loop_planner``: box-iLQR, H = 10, terminal cost ``-V_0`` of a 201-point
grid optimum solved through the fitted model; rows ``diffcontrol (grey box, planner)`` etc.).

Prints the table and the real steps to -150 per seed, and writes
benchmarks/results/real_pendulum.json and benchmarks/results/real_pendulum.png.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import real_benchmark  # noqa: E402

TARGETS = {
    f"diffcontrol ({label}{acting})": steps
    for label, steps in (("grey box", 400), ("hybrid", 600), ("neural", 1000))
    for acting in ("", ", planner")
}
"""Issue 14's targets: real steps to -150 on every seed (an MLP or a planner acting)."""

if __name__ == "__main__":
    real_benchmark("pendulum", "sac", TARGETS, __doc__)
