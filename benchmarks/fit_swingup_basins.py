"""Diagnosis: is the friction swing-up's hybrid miss the model, or the controller's training?

Issue 14 asks the controller trained through a hybrid model fitted from at most 5 real episodes
to come within 5 % of the true-model controller's real loss (``benchmarks/fit_swingup.py``
measures it). This script separates the two possible causes. Per training seed it trains a
controller through the true model and one through the hybrid model (the same configuration
and seed), and evaluates **both controllers on both**: the real system (float64 reference
solve, the task's loss) and the hybrid model. If the hybrid model ranks the two as the real
system does and scores the true-model controller lower than its own, the model is right and
the training through it stopped in a worse basin; if the model scores them equal where the
real system does not, the model is what misses.

``--rounds R`` runs the loop R more times: the real system is run once with the latest
hybrid controller (3 s from the hanging start, the controller's force held over each 0.02 s,
as a digital controller would run it; no exploration noise), that episode is added to the data,
the hybrid model is fitted again from the start and the controller trained again. So
``--episodes 4 --rounds 1`` uses 5 real episodes in all.

    taskset -c 1 python benchmarks/fit_swingup_basins.py --episodes 5 --seeds 0,1,2 \
        --config '{"updates": 3000, "lr_schedule": "cosine", "population": 16}'
    taskset -c 1 python benchmarks/fit_swingup_basins.py --episodes 4 --rounds 1 --seeds 0,2 \
        --config '{"updates": 3000, "lr_schedule": "cosine", "population": 16}' --name loop

Data and fit as in ``benchmarks/fit_swingup.py`` (10 episodes of random forces recorded with
seed 0, the first N fitted; the hybrid by multiple shooting, 500 Adam steps at 1e-2).
Prints a line per run and writes benchmarks/results/fit_swingup_basins[-NAME].json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol.builtin.swingup import fitted as of  # noqa: E402
from diffcontrol.builtin.swingup.fitted import (  # noqa: E402
    ACTION_COLUMNS,
    STATE_COLUMNS,
    FittedSwingUp,
)
from diffcontrol.evaluation import simulate_continuous  # noqa: E402
from diffcontrol.identify.data import TrajectoryData, concat  # noqa: E402

TASK = "cartpole-swingup-friction"
DT_S = 0.02


def record_controller(task, params, controller, duration_s: float) -> TrajectoryData:
    """One episode of the real system from the hanging start with ``controller``'s force held
    over each ``DT_S`` (float64 Tsit5 at 1e-9, as ``record_swingup`` solves)."""
    with jax.enable_x64(True):
        advance = jax.jit(of.held_force_step(params, DT_S))

        y = jnp.asarray(task.initial_state(params), jnp.float64)[:4]
        ys, fs = [], []
        for _ in range(int(round(duration_s / DT_S))):
            f = float(controller(task.observe(jnp.asarray(y, jnp.float32)))[0])
            ys.append(np.asarray(y))
            fs.append(f)
            y = advance(y, jnp.float64(f))
        ys.append(np.asarray(y))
    return TrajectoryData.from_episodes(
        [np.stack(ys)],
        [np.asarray(fs)[:, None]],
        STATE_COLUMNS,
        ACTION_COLUMNS,
        dt_s=DT_S,
        metadata={"system": "cartpole-swingup", "source": "the hybrid controller"},
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=5, help="random episodes fitted first")
    parser.add_argument("--rounds", type=int, default=0, help="controller episodes added")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--config", default="{}", help="ODETrainConfig overrides, JSON")
    parser.add_argument("--name", default="", help="suffix of the JSON file")
    args = parser.parse_args()
    task = diffcontrol.make(TASK)
    real = task.default_params()
    config = task.default_config().replace(**json.loads(args.config))
    data, _ = of.record_swingup(real, 10, seed=0).split(args.episodes)

    def loss(t, params, controller) -> float:
        return float(simulate_continuous(t, controller, params, config=config).loss)

    runs = []
    for seed in (int(s) for s in args.seeds.split(",")):
        t0 = time.perf_counter()
        true_ctrl = diffcontrol.train(task, config.replace(seed=seed)).controller
        true_real = loss(task, real, true_ctrl)
        d = data
        for rnd in range(args.rounds + 1):
            fit = of.fit_swingup_model(d, "hybrid", real, steps=500, learning_rate=1e-2)
            hybrid = FittedSwingUp(task, fit.model)
            ctrl = diffcontrol.train(hybrid, config.replace(seed=seed)).controller
            row = {
                "seed": seed,
                "round": rnd,
                "real_episodes": d.num_episodes,
                "hybrid_controller": {
                    "real": loss(task, real, ctrl),
                    "on_hybrid": loss(hybrid, hybrid.default_params(), ctrl),
                },
                "true_controller": {
                    "real": true_real,
                    "on_hybrid": loss(hybrid, hybrid.default_params(), true_ctrl),
                },
                "seconds": time.perf_counter() - t0,
            }
            h, tc = row["hybrid_controller"], row["true_controller"]
            row["gap"] = (h["real"] - tc["real"]) / tc["real"]
            runs.append(row)
            print(
                f"seed {seed} round {rnd} ({d.num_episodes} real episodes): hybrid controller "
                f"real {h['real']:.3f}, on the model {h['on_hybrid']:.3f}; true-model "
                f"controller real {tc['real']:.3f}, on the model {tc['on_hybrid']:.3f}; "
                f"gap {row['gap']:+.1%}  [{row['seconds']:.0f} s]",
                flush=True,
            )
            if rnd < args.rounds:
                d = concat([d, record_controller(task, real, ctrl, config.horizon_s)])
    name = "fit_swingup_basins" + (f"-{args.name}" if args.name else "")
    out = HERE / "results" / f"{name}.json"
    doc = {
        "machine": machine(),
        "task": TASK,
        "random_episodes": args.episodes,
        "rounds": args.rounds,
        "config": json.loads(args.config),
        "runs": runs,
    }
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
