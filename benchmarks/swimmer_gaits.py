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

3. The stroke search (``--search``): the best clipped sinusoid per joint, by an evolution
   strategy on the C engine; ``diffcontrol.builtin.mujoco.Swimmer.stroke`` is its result, the
   open-loop stroke that Swimmer's training starts from.

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


def search_stroke(env: gym.Env, generations: int) -> dict:
    """The best clipped sinusoid per joint, ``clip(a_i sin(w t) + b_i cos(w t), -1, 1)`` with
    the period ``20 + 80 sigmoid(p)`` steps: a (4, 16) evolution strategy (log-rank weights,
    step size 0.5 shrunk 3 % a generation) from the bang-bang optimum's neighbourhood, each
    candidate one 600-step episode on reset seed ``generation % 5``. Returns the stroke as
    ``Stroke``'s period, amplitudes and phases, and its return over reset seeds 1000-1009."""
    plain = env.unwrapped

    def drive(theta: np.ndarray, t: np.ndarray) -> np.ndarray:
        w = 2 * np.pi * t / (20 + 80 / (1 + np.exp(-theta[0])))
        c = theta[1:].reshape(2, 2)
        return np.clip(np.outer(c[:, 0], np.sin(w)) + np.outer(c[:, 1], np.cos(w)), -1, 1)

    def ret(theta: np.ndarray, seed: int, steps: int = 1000) -> float:
        plain.reset(seed=seed)
        return float(sum(plain.step(u)[1] for u in drive(theta, np.arange(steps)).T))

    rng = np.random.default_rng(0)
    mean = np.array([np.log(1 / 3), 3.0, 0.0, 2.1, -2.1])  # 40 steps, phase lag pi/4
    sigma, lam, mu = 0.5, 16, 4
    w = np.log(mu + 0.5) - np.log(np.arange(1, mu + 1))
    w /= w.sum()
    for g in range(generations):
        x = mean + sigma * rng.standard_normal((lam, mean.size))
        f = np.array([ret(xi, seed=g % 5, steps=600) for xi in x])
        mean = w @ x[np.argsort(-f)[:mu]]
        sigma *= 0.97
    c = mean[1:].reshape(2, 2)
    return {
        "period": float(20 + 80 / (1 + np.exp(-mean[0]))),
        "amplitude": np.hypot(c[:, 0], c[:, 1]).tolist(),
        "phase": np.arctan2(c[:, 1], c[:, 0]).tolist(),
        "generations": generations,
        "return_seeds_1000_1009": [ret(mean, seed) for seed in range(1000, 1010)],
    }


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
    parser.add_argument(
        "--search",
        type=int,
        default=60,
        metavar="GENERATIONS",
        help="generations of the stroke search (0: none)",
    )
    parser.add_argument("--out", type=Path, default=HERE / "results" / "swimmer_gaits.json")
    args = parser.parse_args()
    for run in args.runs:
        if not (run / "model.json").is_file():
            parser.error(f"{run} has no model.json: name a finished run's folder")
    try:
        periods = [int(p) for p in args.periods.split(",")]
    except ValueError:
        parser.error(f"--periods {args.periods!r}: give whole steps, for example 32,40,50")
    if min(periods) < 2 or args.phases < 1 or args.search < 0:
        parser.error(
            "--periods needs periods of 2 steps or more, --phases at least 1 and --search 0 or more"
        )
    env = gym.make("Swimmer-v5")
    loops = open_loop(env, periods, args.phases)
    print(f"{'open loop':<10} {'period':>6} {'phase':>6} {'return':>8}")
    for r in loops:
        print(f"{r['shape']:<10} {r['period']:>6} {r['phase']:>6.2f} {r['return']:>8.1f}")
    stroke = search_stroke(env, args.search) if args.search > 0 else None
    if stroke:
        rets = stroke["return_seeds_1000_1009"]
        print(
            f"\nstroke: period {stroke['period']:.2f} steps, amplitude "
            f"{np.round(stroke['amplitude'], 3).tolist()}, phase "
            f"{np.round(stroke['phase'], 3).tolist()}: return {np.mean(rets):.1f} "
            f"+- {np.std(rets):.1f} (reset seeds 1000-1009, open loop)"
        )
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
        stroke=stroke,
        gaits=gaits,
    )
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
