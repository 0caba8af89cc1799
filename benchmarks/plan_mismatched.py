"""Benchmark: the planner through a model fitted from 10 real episodes, on a mismatched real
pendulum, against the policy trained through the same model and the real optimum.

The real system is the gap benchmark's (``fit_gap_pendulum.py``): Gymnasium's ``Pendulum-v1``
with g = 12 m/s^2 and joint friction 0.1 N m s/rad (``diffcontrol/PendulumFriction-v0``; the
nominal model has g = 10 and no friction). For each seed S:

1. 10 episodes of 200 steps with random torques in [-2, 2] N m are recorded from the real
   system (reset seeds 2000 + 100 S .., none of them an evaluation start; ``--data-seeds
   legacy``: 100 S .., as the first measurement, whose seed 0 started from evaluation seeds
   0-9), with that benchmark's sensor noise (``record_real``): the only real episodes used,
   all 10 fitted (none held out);
2. each model of ``--models`` is fitted to them (``identify.fit_model``, seed S): ``hybrid``,
   the nominal physics plus a 32-32 correction (what ``diffcontrol fit pendulum --model
   hybrid`` fits); ``neural``, a 32-32 network alone, no physics (``--members K``: an
   ensemble of K, their mean the model);
3. the planner through that model, docs/planning.md's best Pendulum planner: box-iLQR (10
   iterations), H = 10, three starts per step, terminal cost ``-V_0`` of the grid optimum
   solved *through the fitted model* (``mpc.planner_from_config`` with ``PlanConfig(horizon=10,
   value_grid=G)``, as ``diffcontrol plan pendulum --model FIT_DIR --horizon 10
   --value-grid G`` builds it);
4. the MLP trained with the task's default settings (seed S) through the same model (as
   ``diffcontrol train pendulum --model FIT_DIR``);

both judged in the real system on reset seeds 0-99 and 1000-1099, next to the real system's
grid optimum (``optimal.solve`` with g = 12, friction 0.1, its greedy controller run in
``PendulumFriction-v0``) and, once, the same planner through the true physics (its terminal
value solved on them too: what the model costs) and through the nominal physics (g = 10, no
friction: what a model fitted to data gains; the gap a fitted model closes is
``(R_fitted - R_nominal) / (R_true - R_nominal)`` of the planners' returns).

    taskset -c 0 python benchmarks/plan_mismatched.py [--seeds 0 1 2 3 4] [--value-grid 201]
    taskset -c 0 python benchmarks/plan_mismatched.py --models neural --members 5 \
        --out benchmarks/results/plan_mismatched_neural.json
    python benchmarks/plan_mismatched.py --merge a.json b.json   # runs split over processes

Prints a table and writes benchmarks/results/plan_mismatched.json (machine, date, every return).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import grid_optima, machine, planner_episodes  # noqa: E402
from fit_gap_pendulum import EPISODES, NOISE, REAL, record_real  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import _gym, identify, mpc, policies  # noqa: E402
from diffcontrol.evaluation import evaluate  # noqa: E402
from diffcontrol.settings import PlanConfig  # noqa: E402
from diffcontrol.training import resolve_config  # noqa: E402

SEED_SETS = {"0-99": list(range(100)), "1000-1099": list(range(1000, 1100))}


def planner_rows(label: str, planner, optima: dict, build_seconds: float) -> dict:
    """The planner in the real system on every seed set: returns, gap, ms per step, solves."""
    policy = mpc.PlannerPolicy(planner)
    policy(np.array([1.0, 0.0, 0.0], np.float32))  # compile before timing
    policy.reports.clear()
    out = {"controller": label, "build_seconds": build_seconds, "seed_sets": {}}
    times = []
    for key, seeds in SEED_SETS.items():
        returns, seconds = planner_episodes(policy, seeds, real=REAL)
        times.append(seconds)
        out["seed_sets"][key] = {
            "mean_return": float(returns.mean()),
            "gap_to_optimum": optima[key].gap(float(returns.mean())),
            "returns": returns.tolist(),
        }
    seconds = np.concatenate(times)
    reports = policy.reports
    out["ms_per_step_median"] = 1e3 * float(np.median(seconds))
    out["ms_per_step_p90"] = 1e3 * float(np.percentile(seconds, 90))
    out["solves"] = len(reports)
    out["not_converged"] = sum(not r["converged"] for r in reports)
    out["non_finite"] = sum(not r["finite"] for r in reports)
    return out


def policy_rows(label: str, policy, task, optima: dict) -> dict:
    out = {"controller": label, "seed_sets": {}}
    for key, seeds in SEED_SETS.items():
        ev = evaluate(policy, task, episodes=len(seeds), seed=seeds[0], real=REAL)
        out["seed_sets"][key] = {
            "mean_return": ev.mean,
            "gap_to_optimum": optima[key].gap(ev.mean),
            "returns": ev.returns.tolist(),
        }
    return out


def data_start(seed: int, legacy: bool) -> int:
    """The first reset seed of seed S's real episodes: 2000 + 100 S (past both evaluation
    sets), or the first measurement's 100 S (``legacy``)."""
    return 100 * seed if legacy else 2000 + 100 * seed


def labels(kind: str, members: int) -> tuple[str, str]:
    model = f"{kind} model" + (f" (ensemble of {members})" if members > 1 else "")
    return f"planner, {model}", f"MLP trained through the {model}"


def run_seed(task, seed: int, args, optima: dict, updates: int | None) -> dict:
    data = record_real(seed, first=data_start(seed, args.data_seeds == "legacy"))
    rows, fits = [], {}
    for kind in args.models:
        members = args.members if kind == "neural" else 1
        planner_label, mlp_label = labels(kind, members)
        t0 = time.perf_counter()
        fit = identify.fit_model(task, data, kind, seed=seed, members=members)
        fit_seconds = time.perf_counter() - t0
        print(f"seed {seed}: {kind} fitted in {fit_seconds:.0f} s ({fit.message})", flush=True)
        fits[kind] = {"seconds": fit_seconds, "loss": fit.loss, "nominal_loss": fit.nominal_loss}
        model_task = identify.model_task(task, fit.model)
        t0 = time.perf_counter()
        planner = mpc.planner_from_config(
            model_task, PlanConfig(horizon=10, value_grid=args.value_grid), params=fit.model
        )
        planner_row = planner_rows(planner_label, planner, optima, time.perf_counter() - t0)
        show(seed, planner_row)
        rows.append(planner_row)
        if args.no_mlp:
            continue
        t0 = time.perf_counter()
        # the windows recipe (the defaults until 2026-11-28): the figures of docs/planning.md
        config = resolve_config(task, "windows", seed=seed)
        config = config if updates is None else config.replace(updates=updates)
        trained = diffcontrol.train(model_task, config)
        policy = policies.NumpyPolicy(policies.controller_to_dict(trained.controller, task))
        mlp_row = policy_rows(mlp_label, policy, task, optima)
        mlp_row["train_seconds"] = time.perf_counter() - t0
        mlp_row["return_on_model"] = trained.metrics["final_eval_return"]
        show(seed, mlp_row)
        rows.append(mlp_row)
    return {
        "seed": seed,
        "real_episodes": data.num_episodes,
        "real_transitions": data.num_steps,
        "data_reset_seeds_from": data_start(seed, args.data_seeds == "legacy"),
        "fit": fits,
        "rows": rows,
    }


def show(seed, row) -> None:
    ms = f"{row['ms_per_step_median']:.2f}" if "ms_per_step_median" in row else "-"
    cells = "".join(
        f"{r['mean_return']:>10.2f} {100 * r['gap_to_optimum']:>6.2f}%"
        for r in row["seed_sets"].values()
    )
    print(f"{seed!s:>4} {row['controller']:<38}{cells} {ms:>8}", flush=True)


def report(doc: dict) -> None:
    head = f"{'seed':>4} {'controller':<38}" + "".join(f"{k:>10} {'gap':>7}" for k in SEED_SETS)
    print(f"\nmean return on the real system, reset seeds {' and '.join(SEED_SETS)}")
    print(f"{head} {'ms/step':>8}\n{'-' * (len(head) + 9)}")
    for key, opt in doc["optimum"].items():
        print(f"real-system grid optimum (greedy), seeds {key}: {opt['mean_return']:.2f}")
    for row in doc["reference"]:
        show("-", row)
    for run in doc["runs"]:
        for row in run["rows"]:
            show(run["seed"], row)
    names = sorted({r["controller"] for run in doc["runs"] for r in run["rows"]})
    nominal = {r["controller"]: r for r in doc["reference"]}.get("planner, nominal physics")
    true = doc["reference"][0]
    for label in names:
        for key in SEED_SETS:
            means = [
                r["seed_sets"][key]["mean_return"]
                for run in doc["runs"]
                for r in run["rows"]
                if r["controller"] == label
            ]
            if means:
                gaps = [doc["optimum"][key]["mean_return"] - m for m in means]
                worst = max(gaps) / abs(doc["optimum"][key]["mean_return"])
                closed = ""
                if nominal and label.startswith("planner"):
                    r_nom = nominal["seed_sets"][key]["mean_return"]
                    r_true = true["seed_sets"][key]["mean_return"]
                    share = [(m - r_nom) / (r_true - r_nom) for m in means]
                    closed = f"; gap to the nominal planner closed {_pcts(share)}"
                print(
                    f"{label}, seeds {key}: mean {np.mean(means):.2f}, worst gap to the optimum "
                    f"{100 * worst:.2f} %{closed}"
                )


def _pcts(shares: list[float]) -> str:
    return " / ".join(f"{100 * x:.0f} %" for x in shares) + f" (mean {100 * np.mean(shares):.0f} %)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--value-grid", type=int, default=201, help="the planner's (201)")
    parser.add_argument("--points", type=int, default=801, help="the real optimum's grid")
    parser.add_argument(
        "--quick", action="store_true", help="a smoke test: 3 episodes per seed set, 20 updates"
    )
    parser.add_argument("--models", default="hybrid", help="hybrid, neural or hybrid,neural")
    parser.add_argument("--members", type=int, default=1, help="the neural model's ensemble")
    parser.add_argument(
        "--data-seeds", choices=["clean", "legacy"], default="clean",
        help="clean: reset seeds 2000 + 100 S ..; legacy: 100 S .. (seed 0 overlapped 0-99)",
    )  # fmt: skip
    parser.add_argument("--no-mlp", action="store_true", help="the planners only")
    parser.add_argument("--merge", type=Path, nargs="+", help="join these results and report")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "plan_mismatched.json")
    args = parser.parse_args()
    args.models = args.models.split(",")
    if args.merge:
        docs = [json.loads(p.read_text()) for p in args.merge]
        doc = {
            **docs[0],
            "runs": sorted((r for d in docs for r in d["runs"]), key=lambda r: r["seed"]),
        }
        doc["command"] = [d["command"] for d in docs]
        doc["machine"] = [d["machine"] for d in docs]
    else:
        doc = measure(args)
    report(doc)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


def measure(args) -> dict:
    if args.quick:
        for key, seeds in SEED_SETS.items():
            SEED_SETS[key] = seeds[:3]
    task = diffcontrol.make("pendulum")
    load_before = os.getloadavg()
    real_params = _gym.params_of_env(task, *REAL)
    _, optima, solve_s = grid_optima(task, args.points, 41, SEED_SETS, real_params, REAL)
    for key, opt in optima.items():
        print(f"real-system optimum, seeds {key}: {opt.mean:.2f} (solved in {solve_s:.0f} s)")
    t0 = time.perf_counter()
    config = PlanConfig(horizon=10, value_grid=args.value_grid)
    true_planner = mpc.planner_from_config(task, config, params=real_params)
    reference = planner_rows(
        "planner, true physics", true_planner, optima, time.perf_counter() - t0
    )
    show("-", reference)
    t0 = time.perf_counter()
    nominal_planner = mpc.planner_from_config(task, config, params=task.default_params())
    nominal = planner_rows(
        "planner, nominal physics", nominal_planner, optima, time.perf_counter() - t0
    )
    show("-", nominal)
    updates = 20 if args.quick else None
    runs = [run_seed(task, seed, args, optima, updates) for seed in args.seeds]
    return {
        "machine": {**machine(), "loadavg_before": load_before, "loadavg_after": os.getloadavg()},
        "real_system": {"env_id": REAL[0], "env_kwargs": REAL[1]},
        "data": f"{EPISODES} episodes of random torques per seed (reset seeds "
        f"{'100 S' if args.data_seeds == 'legacy' else '2000 + 100 S'} ..), all fitted; sensor "
        f"noise std {NOISE.tolist()}",
        "models": args.models,
        "members": args.members,
        "planner": {**config.to_json(), "terminal_value": "grid optimum through the model"},
        "optimum": {k: {**v.to_json(), "solve_seconds": solve_s} for k, v in optima.items()},
        "reference": [reference, nominal],
        "runs": runs,
        "command": "python benchmarks/plan_mismatched.py " + " ".join(sys.argv[1:]),
    }


if __name__ == "__main__":
    main()
