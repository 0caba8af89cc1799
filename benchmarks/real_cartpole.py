"""Benchmark: real CartPole-v1 steps to 500 for diffcontrol's loop, against PPO's and DQN's.

The real command line, in this process:

    diffcontrol compare cartpole --real --seeds 5 --rl-results benchmarks/results/compare.json \
        --out runs/benchmark-real-cartpole [--resume]

For every seed S and model (grey box starting from gravity 12, pole half-length 0.8 m and a
7 N push where CartPole-v1 has 9.8, 0.5 m and 10 N; hybrid with the same wrong physics plus a
network; neural: a network alone), ``runs.loop`` records real steps (random pushes
first, then the current controller with a random push on 10 % of the steps), fits the model
to all of them, trains a controller through it and evaluates it on CartPole-v1 over 100
episodes with reset seeds 1000-1099 (as ``benchmarks/compare.py`` evaluates PPO and DQN),
until a controller reaches 500 over the 100 episodes or after --max-rounds rounds (3). The
curve points, as ``compare``'s RL evaluation points, are the mean over the first 20 of them
(seeds 1000-1019): "steps to 500" is reported for both.
Real steps per round (``CartPole.real_steps_per_round``): 250 for the grey box and the hybrid
(~12 random episodes; a controller's episode is cut at the budget), 1,000 for the neural model
(the least a network is fitted to). Real steps count every recorded transition; the
evaluation episodes are not counted, as for RL.

    python benchmarks/real_cartpole.py [--seeds 5] [--models params,hybrid,neural] [--resume]
        [--controllers train,plan] [--fit-steps N] [--compile-cache DIR] [--name _SUFFIX]

``--compile-cache DIR`` turns on JAX's persistent compilation cache in DIR, as
``diffcontrol compare --real`` has it (off by default: every program is compiled, as in the
figures measured before it); a new DIR is cold for seed 0 and warm for the later seeds.

Prints the table and the real steps to 500 per seed, and writes
benchmarks/results/real_cartpole.json and benchmarks/results/real_cartpole.png.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import real_benchmark  # noqa: E402

TARGETS = {
    "diffcontrol (grey box)": None,
    "diffcontrol (hybrid)": 500,
    "diffcontrol (neural)": 2000,
    "diffcontrol (grey box, planner)": None,
    "diffcontrol (hybrid, planner)": 500,
    "diffcontrol (neural, planner)": 2000,
}
"""Issue 14's targets: real steps to 500 on every seed (none stated for the grey box)."""

if __name__ == "__main__":
    real_benchmark("cartpole", "ppo", TARGETS, __doc__)
