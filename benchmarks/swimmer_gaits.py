"""Swimmer-v5's gaits in Gymnasium's own environment: the strokes an open-loop clock makes,
and the gaits trained controllers settle in.

1. Open loop: both joints driven by a clock, ``u_i = shape(2 pi t / period - i * phase)`` with
   ``shape`` a square wave (bang-bang, ``sign sin``) or ``sin``, for every period and phase of
   the grid; one episode each (reset seed 0, 1000 steps), the best phase per period.
2. ``--runs DIR ...``: each trained run's controller (its ``model.json``) on Gymnasium's reset
   seed 1000, described over the episode's second half: the return, each joint's mean and
   spread, the period of its largest Fourier component (none for a joint held still), the
   mean |action|, the share of actions within 2 % of a bound and the share of steps within
   0.01 rad of a joint limit.

A controller that holds a pose shows a spread near 0 (often at a joint limit); one that
strokes shows its period beside the open-loop optimum's.

    python benchmarks/swimmer_gaits.py --runs runs/swimmer-seed0 runs/swimmer-seed1

Prints the tables and writes benchmarks/results/swimmer_gaits.json (machine, date, command,
every figure). NumPy and MuJoCo's C engine only: nothing is compiled.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

SHAPES = {"bang-bang": lambda w: np.sign(np.sin(w)), "sine": np.sin}


def episode(env: gym.Env, act, seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    """One whole episode: its return, the joint angles and the actions of every step."""
    obs, _ = env.reset(seed=seed)
    total, joints, actions = 0.0, [], []
    for t in range(1000):
        u = np.asarray(act(t, obs), np.float64)
        obs, reward, terminated, truncated, _ = env.step(u)
        total += float(reward)
        joints.append(obs[1:3].copy())
        actions.append(u)
        if terminated or truncated:
            break
    return total, np.array(joints), np.array(actions)


def open_loop(env: gym.Env, periods: list[int], phases: int) -> list[dict]:
    """The best phase of each shape and period (one episode on reset seed 0)."""
    rows = []
    for shape, wave in SHAPES.items():
        for period in periods:
            best = None
            for phase in np.arange(phases) * 2 * np.pi / phases:

                def act(t, _obs, period=period, phase=phase, wave=wave):
                    w = 2 * np.pi * t / period
                    return wave(np.array([w, w - phase]))

                ret = episode(env, act, seed=0)[0]
                if best is None or ret > best["return"]:
                    best = dict(shape=shape, period=period, phase=float(phase), **{"return": ret})
            rows.append(best)
    return rows


def gait(env: gym.Env, run: Path) -> dict:
    """The trained controller's gait over the second half of one episode (reset seed 1000)."""
    from diffcontrol.policies import NumpyPolicy, read_model

    policy = NumpyPolicy(read_model(run / "model.json"))
    ret, joints, actions = episode(env, lambda _t, obs: policy(obs), seed=1000)
    half = joints[len(joints) // 2 :]
    spectrum = np.abs(np.fft.rfft(half - half.mean(0), axis=0))
    peak = spectrum[1:].argmax(0) + 1  # the strongest nonzero frequency
    still = half.std(0) < 1e-3  # a held joint has no period
    limit = env.unwrapped.model.jnt_range[-2:, 1]  # the two hinges' upper limits (symmetric)
    config = json.loads((run / "run.json").read_text()).get("config", {})
    return {
        "run": str(run),
        "config": config,
        "return": ret,
        "joint_mean": half.mean(0).tolist(),
        "joint_std": half.std(0).tolist(),
        "period_steps": [None if s else len(half) / k for s, k in zip(still, peak)],
        "mean_abs_action": np.abs(actions[len(actions) // 2 :]).mean(0).tolist(),
        "saturated_share": float(np.mean(np.abs(actions[len(actions) // 2 :]) > 0.98)),
        "at_limit_share": float(np.mean(np.abs(half) > limit - 0.01)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", type=Path, nargs="*", default=[], help="trained run folders")
    parser.add_argument("--periods", default="16,24,32,40,50,64,80,100,125")
    parser.add_argument("--phases", type=int, default=8, help="phases tried per period")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "swimmer_gaits.json")
    args = parser.parse_args()
    for run in args.runs:
        if not (run / "model.json").is_file():
            parser.error(f"{run} has no model.json: name a finished run's folder")
    try:
        periods = [int(p) for p in args.periods.split(",")]
    except ValueError:
        parser.error(f"--periods {args.periods!r}: give whole steps, for example 32,40,50")
    if min(periods) < 2 or args.phases < 1:
        parser.error("--periods needs periods of 2 steps or more and --phases at least 1")
    env = gym.make("Swimmer-v5")
    loops = open_loop(env, periods, args.phases)
    print(f"{'open loop':<10} {'period':>6} {'phase':>6} {'return':>8}")
    for r in loops:
        print(f"{r['shape']:<10} {r['period']:>6} {r['phase']:>6.2f} {r['return']:>8.1f}")
    gaits = [gait(env, run) for run in args.runs]
    if gaits:
        print(
            f"\n{'run':<28} {'return':>7} {'joint std':>12} {'period':>12} {'sat':>5} {'limit':>5}"
        )
    for g in gaits:
        std = "/".join(f"{s:.2f}" for s in g["joint_std"])
        period = "/".join("-" if p is None else f"{p:.0f}" for p in g["period_steps"])
        print(
            f"{Path(g['run']).name:<28} {g['return']:>7.1f} {std:>12} {period:>12} "
            f"{g['saturated_share']:>5.2f} {g['at_limit_share']:>5.2f}"
        )
    doc = dict(
        machine=machine(),
        command=" ".join(["python", "benchmarks/swimmer_gaits.py", *sys.argv[1:]]),
        open_loop=loops,
        gaits=gaits,
    )
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
