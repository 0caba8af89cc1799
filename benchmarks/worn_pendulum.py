"""Benchmark: does `diffcontrol loop` close the gap on worn pendulums (issue 40, item 2)?

Each real system is ``diffcontrol/WornPendulum-v0`` (``diffcontrol.wrappers.WornPendulum``):
Gymnasium's Pendulum with an actuator that delivers ``gain`` of the command past a dead band of
``deadband`` N m, Coulomb joint friction ``coulomb`` N m and gravity ``g``; the model is the
nominal Pendulum (gain 1, no dead band, no friction, g = 10). For each system and seed S:

    diffcontrol loop pendulum --env diffcontrol/WornPendulum-v0 --env-arg gain=G \
        --env-arg deadband=D --env-arg coulomb=C --env-arg g=GRAV \
        --model hybrid --rounds 2 --episodes 5 --seed S

(10 real episodes; the loop's own defaults otherwise: its controller, the planner for the
Pendulum, and its 20 evaluation episodes, reset seeds 0-19). The controller the loop hands back
and the nominal one (its round 0) are then judged on the real system on reset seeds 1000-1099,
which the loop never saw, next to that system's optimum: the greedy controller of the grid
dynamic program (``optimal.solve``, 801^2 states, 41 torques) solved on the system's true
physics (``WornTask``, checked here against the wrapper step by step) and run in the real
system on the same seeds. The gap closed is ``(R_loop - R_nominal) / (R_opt - R_nominal)``.

    taskset -c 0 python benchmarks/worn_pendulum.py [--seeds 0 1 2] [--systems a,b,c]

Prints a table and writes benchmarks/results/worn_pendulum.json (machine, date, every return).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import grid_optima, machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol.cli import main as cli  # noqa: E402
from diffcontrol.evaluation import evaluate  # noqa: E402
from diffcontrol.systems import pendulum as pend  # noqa: E402
from diffcontrol.tasks.pendulum import Pendulum  # noqa: E402
from diffcontrol.wrappers import WORN_PENDULUM_ID  # noqa: E402

SYSTEMS = {  # name: the WornPendulum-v0 arguments (g included)
    "a": {"gain": 0.8, "deadband": 0.3, "coulomb": 0.2, "g": 11.0},
    "b": {"gain": 0.65, "deadband": 0.2, "coulomb": 0.1, "g": 9.5},
    "c": {"gain": 0.9, "deadband": 0.5, "coulomb": 0.3, "g": 10.5},
}
JUDGED = list(range(1000, 1100))


class WornTask(Pendulum):
    """The Pendulum whose step is ``WornPendulum``'s (the true physics of a worn system), for
    the grid dynamic program: the delivered torque ``gain (u - clip(u, -deadband, deadband))
    - coulomb sign(theta_dot)`` with ``u`` the clipped command, Gymnasium's cost of ``u``."""

    name = "worn-pendulum"

    def __init__(self, gain: float, deadband: float, coulomb: float):
        self.gain, self.deadband, self.coulomb = gain, deadband, coulomb

    def step(self, params, state, action):
        u = pend.clip_torque(params, action[0])
        torque = self.gain * (u - jnp.clip(u, -self.deadband, self.deadband))
        torque = torque - self.coulomb * jnp.sign(state[1])
        past_clip = eqx.tree_at(lambda p: p.max_torque, params, jnp.inf)  # worn after the clip
        new = pend.step(past_clip, state, torque)
        return new, -pend.cost(params, state, action[0]), jnp.asarray(False)


def check_parity(task: WornTask, params, kwargs: dict) -> float:
    """The largest difference between ``task``'s step (float64) and the wrapper's, over 300
    random states and commands (past the clips): the optimum is only that of the real system
    if they agree."""
    import gymnasium

    rng = np.random.default_rng(0)
    env = gymnasium.make(WORN_PENDULUM_ID, **kwargs)
    env.reset(seed=0)
    worst = 0.0
    with jax.enable_x64(True):
        step = jax.jit(task.step)
        for _ in range(300):
            state = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-9, 9)])
            u = rng.uniform(-3, 3)
            env.unwrapped.state = state.copy()
            _, reward, *_ = env.step(np.array([u]))
            want, want_r, _ = step(params, jnp.asarray(state), jnp.asarray([u]))
            worst = max(
                worst, *np.abs(env.unwrapped.state - np.asarray(want)), abs(reward - want_r)
            )
    env.close()
    return float(worst)


def run_loop(kwargs: dict, seed: int, extra: list[str]) -> dict:
    """The loop's command on one system; its nominal and handed-back controllers judged on
    ``JUDGED`` in the real system."""
    task = diffcontrol.tasks.resolve("pendulum")
    args = [a for k, v in kwargs.items() for a in ("--env-arg", f"{k}={v}")]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "loop"
        argv = ["loop", "pendulum", "--env", WORN_PENDULUM_ID, *args, "--model", "hybrid"]
        argv += ["--rounds", "2", "--episodes", "5", "--seed", str(seed), *extra]
        t0 = time.perf_counter()
        if cli([*argv, "--out", str(out), "--quiet"]):
            raise SystemExit("diffcontrol loop failed")
        seconds = time.perf_counter() - t0
        doc = json.loads((out / "loop.json").read_text())
        judged = {}
        for label, k in (("nominal", 0), ("loop", doc["best_round"])):
            policy = diffcontrol.load(out / f"round_{k}" / "run")
            ev = evaluate(policy, task, len(JUDGED), JUDGED[0], real=(WORN_PENDULUM_ID, kwargs))
            judged[label] = ev.returns.tolist()
    return {
        "seed": seed,
        "command": "diffcontrol " + " ".join(argv),
        "loop_seconds": seconds,
        "best_round": doc["best_round"],
        "loop_rows": {
            "nominal": doc["nominal"]["real_return"],
            **{f"round_{r['round']}": r["real_return"] for r in doc["rounds"]},
        },
        "kept_rounds": [r["kept_round"] for r in doc["rounds"]],
        "judged_returns": judged,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--systems", default=",".join(SYSTEMS))
    parser.add_argument("--points", type=int, default=801, help="grid points per state axis")
    parser.add_argument("--loop-args", default="", help="more options of diffcontrol loop")
    parser.add_argument("--out", default=str(HERE / "results" / "worn_pendulum.json"))
    args = parser.parse_args()
    base = diffcontrol.tasks.resolve("pendulum").default_params()
    results = {"machine": machine(), "judged_seeds": "1000-1099", "systems": {}}
    for name in args.systems.split(","):
        kwargs = SYSTEMS[name]
        task = WornTask(kwargs["gain"], kwargs["deadband"], kwargs["coulomb"])
        params = eqx.tree_at(lambda p: p.g, base, kwargs["g"])
        parity = check_parity(task, params, {**kwargs})
        assert parity < 1e-9, f"the worn step differs from the wrapper's by {parity}"
        _, optima, solve_s = grid_optima(
            task, args.points, 41, {"judged": JUDGED}, params=params,
            real=(WORN_PENDULUM_ID, kwargs),
        )  # fmt: skip
        optimum = float(optima["judged"].returns.mean())
        rows = []
        for seed in args.seeds:
            row = run_loop(kwargs, seed, args.loop_args.split())
            nominal = float(np.mean(row["judged_returns"]["nominal"]))
            got = float(np.mean(row["judged_returns"]["loop"]))
            row["gap_closed"] = (got - nominal) / (optimum - nominal)
            rows.append(row)
            print(
                f"system {name} seed {seed}: nominal {nominal:.1f}, loop {got:.1f} (round "
                f"{row['best_round']}), optimum {optimum:.1f}: {100 * row['gap_closed']:.0f} % of "
                f"the gap closed ({row['loop_seconds']:.0f} s)",
                flush=True,
            )
        results["systems"][name] = {
            "env_kwargs": kwargs,
            "parity_max_abs": parity,
            "optimum": {"mean_return": optimum, "returns": optima["judged"].returns.tolist(),
                        "solve_seconds": solve_s, "points": args.points, "levels": 41},
            "runs": rows,
        }  # fmt: skip
    print("\nsystem  seed   nominal      loop   optimum   gap closed")
    for name, s in results["systems"].items():
        for r in s["runs"]:
            nominal = np.mean(r["judged_returns"]["nominal"])
            got = np.mean(r["judged_returns"]["loop"])
            opt = s["optimum"]["mean_return"]
            print(f"{name:6s} {r['seed']:5d} {nominal:9.1f} {got:9.1f} {opt:9.1f} "
                  f"{100 * r['gap_closed']:10.0f} %")  # fmt: skip
    Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
