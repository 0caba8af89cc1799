"""A user's own continuous-time task trained with the library's defaults, judged on held-out
starts by an independent integrator (issue 40, item 5).

The task is ``examples/damped_pendulum.py`` (a damped pendulum swing-up with |u| <= 3 from a
distribution of starts, its own ``ODETrainConfig(horizon_s=8, saves=81, starts=16,
updates=500)``). For each training seed, ``diffcontrol train damped_pendulum:DampedPendulum``
runs with nothing else set (``train_cli``: a fresh process, no compilation cache, core 0);
the NumPy policy that ``load`` gives then closes the loop from 20 starts of the task's reset
distribution that training never drew (``PRNGKey(1000 + i)``), integrated by SciPy's DOP853
(rtol = atol = 1e-10) over the task's 8 s. A start counts as upright when it ends within
0.1 rad of upright with |phi'| < 0.5 rad/s. Target: at least 18 of 20 for every seed.

The reference (``--planner``): ``diffcontrol plan damped_pendulum:DampedPendulum`` with its
defaults (box-iLQR at the task's 0.1 s control period, the trajectory loss as its cost), from
the same starts, each action held for 0.1 s, in the library's own float64 reference solve.
The grid optimum (``--optimum N``): ``diffcontrol evaluate RUN --task
gridded_pendulum:GriddedPendulum --optimum N`` (the same task with a state grid, in
``examples/``), the dynamic program's controller at the same period from the same starts.

    taskset -c 0 python benchmarks/user_continuous.py            # about 1 minute per seed
    taskset -c 0 python benchmarks/user_continuous.py --before --planner --optimum 401
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine, train_cli  # noqa: E402

EXAMPLES = HERE.parent / "examples"
SPEC = "damped_pendulum:DampedPendulum"
HELD_OUT = 1000  # first reset key of the held-out starts
# The settings ODETrainConfig defaulted to before truncated BPTT through the solve.
BEFORE = ["--window-s", "0", "--population", "1", "--hidden", "8", "--grad-clip", "0"]
BEFORE += ["--learning-rate", "0.05"]


def upright_from_held_out_starts(run: Path, starts: int = 20) -> list[dict]:
    """Where each held-out start ends after the task's horizon under ``load``'s policy."""
    import jax
    from scipy.integrate import solve_ivp

    import diffcontrol

    task = diffcontrol.tasks.resolve(SPEC)
    params = task.default_params()
    policy = diffcontrol.load(run)
    horizon = task.default_config().horizon_s
    ends = []
    for i in range(starts):
        y0 = np.asarray(task.reset(jax.random.PRNGKey(HELD_OUT + i), params), np.float64)

        def f(t, y):
            u = float(policy(y))  # a StatePolicy: the state in, the torque out
            return [y[1], params.g * np.sin(y[0]) - params.b * y[1] + u]

        sol = solve_ivp(f, (0.0, horizon), y0, method="DOP853", rtol=1e-10, atol=1e-10)
        phi = float((sol.y[0, -1] + np.pi) % (2 * np.pi) - np.pi)
        phidot = float(sol.y[1, -1])
        ends.append({"phi": phi, "phidot": phidot, "upright": abs(phi) < 0.1 and abs(phidot) < 0.5})
    return ends


def held_out_loss(run: Path, starts: int = 20):
    """``evaluate``'s closed loop of the run from the held-out starts: the library's float64
    reference solve (the action of a planner held for its control period)."""
    import diffcontrol
    from diffcontrol.evaluation import evaluate_run

    task = diffcontrol.tasks.resolve(SPEC)
    return evaluate_run(task, diffcontrol.open_run(run, task), episodes=starts, seed=HELD_OUT)


def planner_reference(work: Path, starts: int = 20) -> dict:
    """``diffcontrol plan`` with the task's defaults, judged from the held-out starts."""
    import subprocess

    out = work / "plan"
    shutil.rmtree(out, ignore_errors=True)  # this script's own run of an earlier time
    cmd = [sys.executable, "-m", "diffcontrol.cli", "plan", SPEC, "--out", str(out), "--quiet"]
    cmd = (["taskset", "-c", "0"] if shutil.which("taskset") else []) + cmd
    t0 = time.perf_counter()
    subprocess.run([*cmd, "--no-animation", "--final-eval", "1"], check=True)
    seconds = time.perf_counter() - t0
    result = held_out_loss(out, starts)
    phi = (result.final_states[:, 0] + np.pi) % (2 * np.pi) - np.pi
    upright = (np.abs(phi) < 0.1) & (np.abs(result.final_states[:, 1]) < 0.5)
    return {"way": "planner", "upright": int(upright.sum()), "starts": starts,
            "seconds": round(seconds, 1), "loss": float(np.mean(result.losses))}  # fmt: skip


def grid_optimum(run: Path, points: int, starts: int = 20) -> dict:
    """``diffcontrol evaluate RUN --optimum POINTS`` on the gridded task, from the held-out
    starts: the grid optimum's row (a cold process, core 0)."""
    import subprocess

    cmd = [sys.executable, "-m", "diffcontrol.cli", "evaluate", str(run), "--task"]
    cmd += ["gridded_pendulum:GriddedPendulum", "--episodes", str(starts), "--seed"]
    cmd += [str(HELD_OUT), "--optimum", str(points), "--json"]
    cmd = (["taskset", "-c", "0"] if shutil.which("taskset") else []) + cmd
    t0 = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    seconds = time.perf_counter() - t0
    opt = json.loads(out)["optimum"]
    ends = np.array([[e["phi"], e["phidot"]] for e in opt["final_states"]])
    phi = (ends[:, 0] + np.pi) % (2 * np.pi) - np.pi
    upright = (np.abs(phi) < 0.1) & (np.abs(ends[:, 1]) < 0.5)
    return {"way": "grid optimum", "points": points, "upright": int(upright.sum()),
            "starts": starts, "seconds": round(seconds, 1), "loss": opt["mean_loss"]}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="training seeds 0..N-1 (default 3)")
    ap.add_argument("--before", action="store_true", help="also train with the old defaults")
    ap.add_argument("--planner", action="store_true", help="also the planner's reference")
    ap.add_argument("--optimum", type=int, metavar="N", help="also the grid optimum, N x N")
    ap.add_argument("--work", type=Path, default=Path("runs/bench-user-continuous"))
    ap.add_argument("--out", type=Path, default=HERE / "results" / "user_continuous.json")
    args = ap.parse_args()
    work = args.work.resolve()
    out_json = args.out.resolve()
    os.chdir(EXAMPLES)  # where the user's module is found by name
    sys.path.insert(0, str(EXAMPLES))
    ways = {"defaults": []} | ({"before": BEFORE} if args.before else {})
    rows = []
    for way, extra in ways.items():
        for seed in range(args.seeds):
            run = work / f"{way}-seed{seed}"
            shutil.rmtree(run, ignore_errors=True)  # this script's own run of an earlier time
            metrics, seconds = train_cli(SPEC, seed, run, ["--no-animation", *extra])
            ends = upright_from_held_out_starts(run)
            loss = float(np.mean(held_out_loss(run).losses))
            rows.append(
                {
                    "way": way,
                    "flags": extra,
                    "seed": seed,
                    "upright": sum(e["upright"] for e in ends),
                    "starts": len(ends),
                    "seconds": round(seconds, 1),
                    "train_seconds": round(metrics["train_seconds"], 1),
                    "loss": loss,  # on the held-out starts
                    "ends": ends,
                }
            )
            r = rows[-1]
            print(
                f"{way:9s} seed {seed}: {r['upright']:2d}/{r['starts']} upright, loss {loss:.3f}, {seconds:.1f} s"
            )
    if args.planner:
        rows.append(planner_reference(work))
        r = rows[-1]
        print(f"planner: {r['upright']:2d}/{r['starts']} upright, loss {r['loss']:.3f}")
    if args.optimum:
        rows.append(grid_optimum(work / "defaults-seed0", args.optimum))
        r = rows[-1]
        print(f"grid optimum {args.optimum}: {r['upright']:2d}/{r['starts']} upright, loss "
              f"{r['loss']:.3f}, {r['seconds']:.1f} s")  # fmt: skip
    met = all(r["upright"] >= 18 for r in rows if r["way"] == "defaults")
    print(f"target (>= 18 of 20 for every seed with the defaults): {'met' if met else 'missed'}")
    doc = {"machine": machine(), "spec": SPEC, "held_out_keys": HELD_OUT, "rows": rows}
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out_json}")


if __name__ == "__main__":
    main()
