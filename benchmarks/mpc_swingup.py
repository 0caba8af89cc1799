"""Benchmark: the planner on the 10 s actuator-limited swing-up, judged on the true ODE.

The planner plans through ``mpc.discretise(cartpole-swingup-limited, dt)`` (the force held for
``dt``, RK4) with box-iLQR, the ``limited_hold`` planning cost and its energy-shaping end cost,
forces within +-Fmax, ``bound_starts=True``. Its first action is held for ``dt`` in the
continuous system itself (a float64 ``Dopri8`` solve at 1e-8, ``mpc.ode_episode``) for 10 s,
from the hanging start and from a batch of perturbed starts (cart position +-0.5 m, pole
angle pi +- 0.5 rad, pole rate +-0.5 rad/s, drawn uniformly with keys 0..N-1). The trained
``cartpole-swingup-limited`` controller (``--controller DIR``, or one trained here with the
task's defaults and ``--train-seed``) is solved from the same starts (float64 Dopri8 at 1e-9,
as its reference solve). Per start: |wrap theta| and |theta_dot| at 10 s, peak |F|, and the
bars of docs/benchmarks.md (|wrap theta| < 0.1 rad and |theta_dot| < 0.5 rad/s at 10 s). The
cost per planning step is the median (and 95th percentile) wall-clock of one jitted control
step in float32, over the states of the hanging start's episode.

    taskset -c 0 python benchmarks/mpc_swingup.py
    python benchmarks/mpc_swingup.py --starts 4 --controller runs/limited   # a quick look

Prints a table and writes benchmarks/results/mpc_swingup.json (machine, date, load, figures).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import mpc, policies  # noqa: E402
from diffcontrol.builtin.swingup.judge import swingup_result  # noqa: E402
from diffcontrol.evaluation import ContinuousRecording  # noqa: E402
from diffcontrol.rollout import force_fn, solve_closed_loop  # noqa: E402

HORIZON_S = 10.0
SETTINGS = [(0.05, 40, 6.0, 5), (0.05, 40, 5.0, 5), (0.05, 40, 4.5, 5), (0.05, 40, 4.0, 5)]
"""(dt s, horizon H, Fmax N, iLQR iterations) of the planners measured."""
ANGLE_BAR, RATE_BAR = 0.1, 0.5
"""|wrap theta| (rad) and |theta_dot| (rad/s) at 10 s, the bars of docs/benchmarks.md."""


def starts(task, params, n: int) -> np.ndarray:
    """The hanging start and ``n`` perturbed ones (keys 0..n-1), ``[n+1, 6]`` float64."""
    rows = [np.asarray(task.initial_state(params), np.float64)]
    for k in range(n):
        u = np.asarray(jax.random.uniform(jax.random.PRNGKey(k), (3,), minval=-1, maxval=1))
        rows.append(np.array([0.5 * u[0], 0.0, np.pi + 0.5 * u[1], 0.5 * u[2], 0.0, 0.0]))
    return np.stack(rows)


def end_figures(ys: np.ndarray, force: np.ndarray, dt: float) -> dict:
    """The end state, peak force, swings and upright time of a closed loop saved every ``dt``
    (``builtin.swingup.judge.swingup_result``: swings are the pole's reversals before it first comes
    within 0.1 rad of upright; ``upright_from_s`` the time from which it stays there)."""
    t = dt * np.arange(len(ys))
    res = swingup_result(ContinuousRecording("cartpole-swingup-limited", t, ys, force, np.nan))
    end = {
        "abs_theta_end": abs(res.final_theta),
        "abs_theta_dot_end": abs(res.final_theta_dot),
        "x_end": res.final_x,
        "peak_force": res.peak_force,
        "swings": res.swings,
        "upright_from_s": res.upright_time,
    }
    end["upright"] = end["abs_theta_end"] < ANGLE_BAR and end["abs_theta_dot_end"] < RATE_BAR
    return end


def planner_rows(task, params, y0s, dt, horizon, fmax, iterations) -> dict:
    disc = mpc.discretise(task, dt)
    planner = mpc.make_planner(
        disc,
        mpc.ILQR(iterations=iterations),
        horizon,
        bounds=((-fmax,), (fmax,)),
        terminal_cost=disc.terminal_cost("limited_hold", params),
        bound_starts=True,
    )
    steps = round(HORIZON_S / dt)
    with jax.enable_x64(True):
        run = eqx.filter_jit(jax.vmap(lambda y: mpc.ode_episode(planner, y, steps)))
        t0 = time.perf_counter()
        ys, us, infos = run(jnp.asarray(y0s))
        ys.block_until_ready()
        episodes_s = time.perf_counter() - t0
    ys, us = np.asarray(ys), np.asarray(us)
    per_start = [end_figures(ys[i], us[i, :, 0], dt) for i in range(len(y0s))]
    # The cost of one control step, float32, on the states the hanging start went through.
    control = eqx.filter_jit(planner.control)
    warm = planner.initial_plan()
    control(jnp.asarray(ys[0, 0], jnp.float32), warm)[0].block_until_ready()  # compile
    seconds = []
    for y in ys[0, :-1]:
        t0 = time.perf_counter()
        _, warm, _ = control(jnp.asarray(y, jnp.float32), warm)
        warm.block_until_ready()
        seconds.append(time.perf_counter() - t0)
    return {
        "dt_s": dt,
        "horizon": horizon,
        "horizon_s": horizon * dt,
        "fmax_n": fmax,
        "iterations": iterations,
        "episodes_seconds_incl_compile": episodes_s,
        "ms_per_step_median": 1000 * float(np.median(seconds)),
        "ms_per_step_p95": 1000 * float(np.percentile(seconds, 95)),
        "solves_finite": bool(np.all(np.asarray(infos.finite))),
        "per_start": per_start,
    }


def trained_rows(task, controller, params, y0s) -> list[dict]:
    ts = jnp.linspace(0.0, HORIZON_S, round(HORIZON_S * 100) + 1)
    with jax.enable_x64(True):
        ctrl = jax.tree.map(lambda a: jnp.asarray(np.asarray(a, np.float64)), controller)
        p64 = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), params)

        @jax.jit
        def one(y0):
            sol = solve_closed_loop(task.vector_field, y0, ts, (p64, force_fn(task, ctrl)),
                                    solver="dopri8", rtol=1e-9, atol=1e-9, max_steps=100_000)  # fmt: skip
            force = jax.vmap(lambda y: ctrl(task.observe(y[:4]))[0])(sol.ys)
            return sol.ys, force, sol.ok

        out = [one(jnp.asarray(y0)) for y0 in y0s]
    return [
        {**end_figures(np.asarray(ys), np.asarray(f), 0.01), "solve_ok": bool(ok)}
        for ys, f, ok in out
    ]


def summary(rows: list[dict]) -> str:
    up = sum(r["upright"] for r in rows)
    peaks = [r["peak_force"] for r in rows]
    return (f"{up}/{len(rows)} upright, peak |F| median {np.median(peaks):.2f} N "
            f"(max {max(peaks):.2f}), worst |θ| {max(r['abs_theta_end'] for r in rows):.3f}, "
            f"worst |θ̇| {max(r['abs_theta_dot_end'] for r in rows):.3f}, "
            f"swings {min(r['swings'] for r in rows)}-{max(r['swings'] for r in rows)}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=16, help="perturbed starts (keys 0..N-1)")
    parser.add_argument("--controller", type=Path, help="a trained run of the task to compare")
    parser.add_argument("--train-seed", type=int, default=0, help="seed of the one trained here")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "mpc_swingup.json")
    args = parser.parse_args()
    task = diffcontrol.make("cartpole-swingup-limited")
    params = task.default_params()
    y0s = starts(task, params, args.starts)
    doc = {"machine": machine(), "load_average_start": os.getloadavg(), "starts": len(y0s),
           "start_distribution": "hanging start, then x U(-0.5, 0.5) m, theta pi + U(-0.5, "
           "0.5) rad, theta_dot U(-0.5, 0.5) rad/s (keys 0..N-1)",
           "bars": {"abs_theta_rad": ANGLE_BAR, "abs_theta_dot_rad_s": RATE_BAR}}  # fmt: skip
    if args.controller:
        controller = policies.controller_from_dict(policies.read_model(args.controller))
        source = str(args.controller)
    else:
        print(f"training cartpole-swingup-limited with its defaults, seed {args.train_seed} ...")
        config = dataclasses.replace(task.default_config(), seed=args.train_seed)
        controller = diffcontrol.train(task, config).controller
        source = f"diffcontrol.train(cartpole-swingup-limited, seed={args.train_seed})"
    trained = trained_rows(task, controller, params, y0s)
    doc["trained"] = {"source": source, "summary": summary(trained), "per_start": trained}
    print(f"trained controller ({source}): {summary(trained)}")
    doc["planners"] = []
    print(f"{'dt':>5} {'H':>3} {'Fmax':>5} {'it':>3} {'ms/step':>8} {'p95':>6}  result")
    for dt, horizon, fmax, iterations in SETTINGS:
        row = planner_rows(task, params, y0s, dt, horizon, fmax, iterations)
        row["summary"] = summary(row["per_start"])
        doc["planners"].append(row)
        print(f"{dt:>5} {horizon:>3} {fmax:>5} {iterations:>3} {row['ms_per_step_median']:>8.2f}"
              f" {row['ms_per_step_p95']:>6.2f}  {row['summary']}")  # fmt: skip
    print("\nper start (start 0 hanging): |θ| / |θ̇| at 10 s, peak |F|")
    for i in range(len(y0s)):
        cells = [trained[i]] + [row["per_start"][i] for row in doc["planners"]]
        print(f"{i:>3} " + "  ".join(
            f"{c['abs_theta_end']:.3f}/{c['abs_theta_dot_end']:.3f}/{c['peak_force']:.1f}"
            + ("" if c["upright"] else "*") for c in cells))  # fmt: skip
    doc["load_average_end"] = os.getloadavg()
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
