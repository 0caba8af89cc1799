"""The swing-up with unknown friction, with a planner acting through the fitted model.

Issue 14 asks the controller of the hybrid loop to come within 5 % of the true-model
controller's real loss from at most 5 real episodes. Trained through the fitted model, the MLP
misses on some seeds by chance (docs/benchmarks.md, "The swing-up with unknown friction"): the
basin a training ends in moves its loss by 5-25 %. Here no controller is trained: the task's
planner (``CartPoleSwingUpFriction.default_plan_config``: box-iLQR with 10 iterations, the
force held for 0.05 s, 2 s planned, within 40 N, the ``energy`` planning loss) plans through
each model, and is judged on the real system by the task's own evaluation (the float64
reference solve with the planner in the loop, the task's ``energy`` loss).

Per data seed S: 10 episodes of exploratory forces are recorded from the real system
(``builtin.swingup.fitted.record_swingup(real, 10, seed=S)``, as ``benchmarks/fit_swingup.py`` does
for S = 0; 5 s each) and the first N are fitted (a grey box and a hybrid, the fit's defaults:
200 and 500 Adam steps). Rows: the planner through the nominal model (no friction), the grey
box, the hybrid and the true model. The target compares the hybrid's planner with the true
model's planner (like for like) and with the trained true-model controllers of
``benchmarks/results/fit_swingup.json`` (the task's default training, seeds 0-2), the issue's
words.

    taskset -c 0 python benchmarks/plan_swingup_friction.py                 # seeds 0-2, 5 and 3
    taskset -c 0 python benchmarks/plan_swingup_friction.py --seeds 0 --episodes 5

Prints a table and writes benchmarks/results/plan_swingup_friction.json (``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import numpy as np  # noqa: E402
from _common import machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import mpc  # noqa: E402
from diffcontrol.builtin.swingup import fitted as of  # noqa: E402
from diffcontrol.builtin.swingup.fitted import FittedSwingUp  # noqa: E402
from diffcontrol.evaluation import simulate_continuous  # noqa: E402
from diffcontrol.mpc._config import default_plan_config  # noqa: E402

TASK = "cartpole-swingup-friction"
RECORDED = 10
FITS = {"params": (200, 0.02), "hybrid": (500, 1e-2)}
"""Adam steps and learning rate of each fit (the vector-field route's defaults)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2", help="data seeds (comma-separated)")
    parser.add_argument("--episodes", default="5,3", help="episodes fitted (comma-separated)")
    parser.add_argument("--out", default=str(HERE / "results" / "plan_swingup_friction.json"))
    args = parser.parse_args()
    task = diffcontrol.make(TASK)
    real = task.default_params()
    config = default_plan_config(task)
    trained = json.loads((HERE / "results" / "fit_swingup.json").read_text())
    trained_true = {r["seed"]: r["true"]["real_loss"] for r in trained["runs"]}

    def judge(model_task) -> tuple[float, dict, float]:
        t0 = time.perf_counter()
        planner = mpc.planner_from_config(model_task, config)
        rec = simulate_continuous(task, mpc.SampledPlannerPolicy(planner), real)
        end_theta = (rec.y[-1, 2] + np.pi) % (2 * np.pi) - np.pi
        summary = {
            "end_abs_theta": float(abs(end_theta)),
            "peak_force": float(np.abs(rec.force).max()),
            "dissipated_j": float(rec.y[-1, 5]),
        }
        return float(rec.loss), summary, time.perf_counter() - t0

    true_loss, true_summary, true_s = judge(task)
    nominal_loss, nominal_summary, nominal_s = judge(FittedSwingUp(task, of.nominal_model(real)))
    print(f"planner through the true model: real loss {true_loss:.4f} ({true_s:.1f} s)")
    print(f"planner through the nominal model: real loss {nominal_loss:.4f}", flush=True)
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        recorded = of.record_swingup(real, RECORDED, seed=seed)
        for n in (int(e) for e in args.episodes.split(",")):
            data, _ = recorded.split(n)
            for kind, (steps, lr) in FITS.items():
                t0 = time.perf_counter()
                fit = of.fit_swingup_model(data, kind, real, steps=steps, learning_rate=lr)
                fit_s = time.perf_counter() - t0
                loss, summary, plan_s = judge(FittedSwingUp(task, fit.model))
                row = {
                    "data_seed": seed,
                    "episodes": n,
                    "model": kind,
                    "real_loss": loss,
                    **summary,
                    "vs_true_planner": (loss - true_loss) / true_loss,
                    "vs_trained_true": {
                        str(s): (loss - v) / v for s, v in sorted(trained_true.items())
                    },
                    "fit_seconds": fit_s,
                    "plan_and_judge_seconds": plan_s,
                    "fit_loss": fit.loss,
                }
                rows.append(row)
                print(
                    f"data seed {seed}, {n} episodes, {kind}: real loss {loss:.4f} "
                    f"({row['vs_true_planner']:+.2%} against the true-model planner); fit "
                    f"{fit_s:.0f} s, plan and judge {plan_s:.0f} s",
                    flush=True,
                )
    best_trained = min(trained_true.values())
    print(
        f"\nthe energy loss on the real system (true-model planner {true_loss:.4f}, nominal-model "
        f"planner {nominal_loss:.4f}; trained true-model controllers "
        + ", ".join(f"{v:.2f}" for v in trained_true.values())
        + ")\n"
    )
    print("| data seed | episodes | model | real loss | vs true-model planner | within 5 %? |")
    print("|---|---|---|---|---|---|")

    def within(r) -> bool:
        """Within 5 % of the true model's planner and of every trained true-model controller."""
        return r["vs_true_planner"] <= 0.05 and r["real_loss"] <= 1.05 * best_trained

    for r in rows:
        print(
            f"| {r['data_seed']} | {r['episodes']} | {r['model']} | {r['real_loss']:.4f} | "
            f"{r['vs_true_planner']:+.2%} | {'yes' if within(r) else 'NO'} |"
        )
    met = {
        n: all(within(r) for r in rows if r["model"] == "hybrid" and r["episodes"] == n)
        for n in sorted({r["episodes"] for r in rows})
    }
    print(
        "\nissue 14 (the hybrid within 5 % of the true-model controller from at most 5 real "
        "episodes, on every data seed; against the true model's planner and the best trained "
        f"true-model controller, {best_trained:.3f}): "
        + "; ".join(f"{n} episodes {'met' if ok else 'MISSED'}" for n, ok in met.items())
    )
    doc = {
        "machine": machine(),
        "task": TASK,
        "real_params": {
            n: float(getattr(real, n)) for n in ("cart_viscous", "cart_coulomb", "pole_viscous")
        },
        "plan_config": config.to_json(),
        "recorded_episodes": RECORDED,
        "fits": {k: {"adam_steps": s, "learning_rate": lr} for k, (s, lr) in FITS.items()},
        "true_planner": {"real_loss": true_loss, **true_summary, "seconds": true_s},
        "nominal_planner": {"real_loss": nominal_loss, **nominal_summary, "seconds": nominal_s},
        "trained_true_controllers": trained_true,
        "rows": rows,
        "target_met_by_episodes": met,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
