"""Benchmark: does a controller trained through a model fitted from data close the gap?

The "real" pendulum is Gymnasium's own ``Pendulum-v1`` with g = 12 m/s^2 (our nominal model
has 10) and joint friction 0.1 N m s/rad (``diffcontrol/PendulumFriction-v0``; the nominal
has none). For each seed S: 10 episodes of 200 steps with random torques in [-2, 2] N m are
recorded from the real system (reset seeds 2000 + 100 S .., none of them a start the
controllers are judged on; ``--data-seeds legacy``: 100 S .., the first measurements', whose
seed 0 started from evaluation seeds 0-9) with Gaussian sensor noise (standard
deviation 0.01 on cos(theta) and sin(theta), 0.05 rad/s on theta_dot, as in
``fit_pendulum.py``); 8 are fitted and 2 held out. From them
three models are fitted: grey box (g and friction, ``identify.fit_parameters``), hybrid (the
nominal physics plus a 32-32 network) and black box (a 32-32 network alone;
``identify.fit_model``). A controller is then trained with the task's default settings
(seed S; with ``--restarts K``, seeds S + 1000 j for j < K and the controller with the best
return on that model's own simulator kept, never chosen on the real system) through each
of: the nominal model, the three fitted models, and the true model; every controller is
evaluated on the real system (100 episodes, reset seeds 0-99).

The gap closed is ``(R_fitted - R_nominal) / (R_true - R_nominal)`` with ``R`` the mean return
on the real system. The held-out prediction errors (RMS over the 3 observations, 1, 10 and
50 steps ahead, open loop with the recorded torques) are reported for every model.

    taskset -c 0 python benchmarks/fit_gap_pendulum.py [--seeds 3] [--restarts 3]

Prints two tables and writes benchmarks/results/fit_gap_pendulum.json (machine, date, every
figure).

With ``--members K`` an ensemble of K black boxes (``fit_model(..., members=K)``, fitted once)
is added, trained through with each weight of ``--penalties`` (the members' spread in the
training loss; a column ``ensemble-wW`` each); ``--kinds`` runs a subset of the columns
(nominal and true are always run: the gap needs them). The file is then
``fit_gap_pendulum-ensembleK.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import machine  # noqa: E402

import diffcontrol  # noqa: E402
from diffcontrol import identify, policies  # noqa: E402
from diffcontrol.evaluation import evaluate  # noqa: E402
from diffcontrol.training import resolve_config  # noqa: E402

REAL = ("diffcontrol/PendulumFriction-v0", {"g": 12.0, "friction": 0.1})
NOISE = np.array([0.01, 0.01, 0.05])
EPISODES, FIT_EPISODES, EVAL_EPISODES = 10, 8, 100
KINDS = ("nominal", "params", "hybrid", "neural", "true")


DATA_SEEDS = {"clean": 2000, "legacy": 0}
"""The first reset seed of seed 0's real episodes (seed S: that + 100 S)."""


def record_real(seed: int, episodes: int = EPISODES, first: int | None = None):
    """``episodes`` episodes of random torques on the real system (reset seeds ``first`` ..,
    default 2000 + 100 S ..), with the sensor noise ``NOISE`` (seeded by S) added to the
    observations."""
    first = DATA_SEEDS["clean"] + 100 * seed if first is None else first
    data = diffcontrol.record(REAL[0], episodes, seed=first, env_kwargs=REAL[1])
    rng = np.random.default_rng(seed)
    noisy = data.observations + rng.normal(size=data.observations.shape) * NOISE
    return dataclasses.replace(data, observations=noisy)


def fit_all(
    task, seed: int, kinds: tuple, members: int, penalties: tuple, bootstrap: bool, first: int
):
    """The fitted models (label -> (task to train/predict with, its params)), their
    held-out prediction errors, the fit seconds and (for an ensemble) its mean spread."""
    train, held_out = record_real(seed, first=first).split(FIT_EPISODES)
    nominal = task.default_params()
    fitted, seconds, extra = {"nominal": (task, nominal)}, {}, {}
    if "params" in kinds:
        t0 = time.perf_counter()
        grey = identify.fit_parameters(task, train, ("g", "friction"))
        seconds["params"] = time.perf_counter() - t0
        fitted["params"] = (task, grey.params)
        extra = {"params_values": grey.values, "params_standard_errors": grey.standard_errors}
    for kind in ("hybrid", "neural"):
        if kind in kinds:
            t0 = time.perf_counter()
            result = identify.fit_model(task, train, kind, seed=seed)
            seconds[kind] = time.perf_counter() - t0
            fitted[kind] = (identify.model_task(task, result.model), result.model)
    if members > 1:
        t0 = time.perf_counter()
        result = identify.fit_model(
            task, train, "neural", seed=seed, members=members, bootstrap=bootstrap
        )
        seconds["ensemble"] = time.perf_counter() - t0
        for w in penalties:
            model = dataclasses.replace(
                result.model, correction=dataclasses.replace(result.model.correction, penalty=w)
            )
            fitted[f"ensemble-w{w:g}"] = (identify.model_task(task, model), model)
        extra["ensemble_spread"] = {
            name: identify.ensemble.mean_spread(task, result.model, d)
            for name, d in (("fit", train), ("held_out", held_out))
        }
    errors = {
        label: {h: e["rmse"] for h, e in identify.prediction_errors(t, p, held_out).items()}
        for label, (t, p) in fitted.items()
    }
    return fitted, errors, {"fit_seconds": seconds, **extra}


def real_return(task, controller) -> dict:
    policy = policies.NumpyPolicy(policies.controller_to_dict(controller, task))
    ev = evaluate(policy, task, episodes=EVAL_EPISODES, seed=0, real=REAL)
    return {"mean": ev.mean, "std": ev.std}


def run(seed: int, restarts: int, kinds: tuple, ensemble: tuple, data_seeds: str) -> dict:
    task = diffcontrol.make("pendulum")
    first = DATA_SEEDS[data_seeds] + 100 * seed
    fitted, errors, extra = fit_all(task, seed, kinds, *ensemble, first)
    # the windows recipe (the defaults until 2026-11-28): the figures of docs/benchmarks.md
    config = resolve_config(task, "windows", seed=seed)
    plans = {label: (t, config) for label, (t, _) in fitted.items()}
    plans["true"] = (task, config.replace(params=tuple(REAL[1].items())))
    if "params" in fitted:
        grey = fitted["params"][1]
        grey_values = (("g", float(grey.g)), ("friction", float(grey.friction)))
        plans["params"] = (task, config.replace(params=grey_values))
    labels = [k for k in KINDS if k in plans][:-1] + sorted(set(plans) - set(KINDS)) + ["true"]
    returns, train_seconds, tries = {}, {}, {}
    for label in labels:
        t, cfg = plans[label]
        t0 = time.perf_counter()
        runs = []
        for j in range(restarts):  # the best on the model itself, never on the real system
            result = diffcontrol.train(t, cfg.replace(seed=seed + 1000 * j))
            runs.append((result.metrics["final_eval_return"], j, result.controller))
        model_return, best_j, controller = max(runs, key=lambda r: r[0])
        train_seconds[label] = time.perf_counter() - t0
        returns[label] = {**real_return(task, controller), "on_model": model_return}
        tries[label] = {"model_returns": [r[0] for r in runs], "chosen": best_j}
        print(
            f"  seed {seed} {label:8} real-system return {returns[label]['mean']:8.1f} "
            f"({train_seconds[label]:.0f} s)",
            flush=True,
        )
    r = {k: v["mean"] for k, v in returns.items()}
    gap = r["true"] - r["nominal"]
    closed = {k: (r[k] - r["nominal"]) / gap for k in labels if k not in ("nominal", "true")}
    return {
        "seed": seed,
        "real_return": returns,
        "gap_closed": closed,
        "nominal_worse_by": (r["nominal"] - r["true"]) / abs(r["true"]),
        "held_out_rmse": errors,
        "restarts": tries,
        "train_seconds": train_seconds,
        **extra,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument(
        "--restarts",
        type=int,
        default=1,
        help="train K controller seeds through each model and keep the one with the best "
        "return on that model (as a user without the real system would); default 1",
    )
    parser.add_argument("--kinds", default=",".join(KINDS[1:-1]), help="of params,hybrid,neural")
    parser.add_argument("--members", type=int, default=1, help="K > 1 adds a K-member ensemble")
    parser.add_argument("--penalties", default="1", help="the ensemble's penalty weights, W,W")
    parser.add_argument("--bootstrap", action="store_true", help="members fit resamples")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument(
        "--data-seeds", choices=list(DATA_SEEDS), default="clean",
        help="clean: real episodes from reset seeds 2000 + 100 S ..; legacy: 100 S .. (the "
        "first measurements': seed 0's overlapped the evaluation's 0-99)",
    )  # fmt: skip
    args = parser.parse_args()
    kinds = tuple(k for k in args.kinds.split(",") if k)
    penalties = tuple(float(w) for w in args.penalties.split(","))
    ensemble = (args.members, penalties, args.bootstrap)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows = [run(s, args.restarts, kinds, ensemble, args.data_seeds) for s in seeds]
    cols = list(rows[0]["real_return"])
    gaps = [k for k in cols if k not in ("nominal", "true")]
    print("\nreturn on the real system (100 episodes), controller trained through each model")
    print("seed  " + "".join(f"{k:>14}" for k in cols) + "   gap closed: " + " / ".join(gaps))
    for r in rows:
        rets = "".join(f"{r['real_return'][k]['mean']:14.1f}" for k in cols)
        gc = " / ".join(f"{100 * r['gap_closed'][k]:5.1f} %" for k in gaps)
        print(f"{r['seed']:4}  {rets}   {gc}")
    print("\nheld-out RMS prediction error (1 / 10 / 50 steps ahead)")
    for r in rows:
        for label, e in r["held_out_rmse"].items():
            print(f"seed {r['seed']} {label:8} {e[1]:.2e} / {e[10]:.2e} / {e[50]:.2e}")
    name = "fit_gap_pendulum" + (f"-best{args.restarts}" if args.restarts > 1 else "")
    name += f"-ensemble{args.members}" if args.members > 1 else ""
    name += "-bootstrap" if args.bootstrap else ""
    name += f"-seeds{args.first_seed}-{seeds[-1]}" if args.first_seed else ""
    name += "-legacy-data" if args.data_seeds == "legacy" else ""
    out = HERE / "results" / f"{name}.json"
    doc = {
        "machine": machine(),
        "real_system": {"env_id": REAL[0], "env_kwargs": REAL[1]},
        "data": f"{EPISODES} episodes of random torques per seed, {FIT_EPISODES} fitted, "
        f"{EPISODES - FIT_EPISODES} held out, reset seeds {DATA_SEEDS[args.data_seeds]} + 100 S ..",
        "noise_std": NOISE.tolist(),
        "evaluation": f"{EVAL_EPISODES} episodes on the real system, reset seeds 0-{EVAL_EPISODES - 1}",
        "restarts": f"{args.restarts} training seed(s) (S + 1000 j) per model, the best on the "
        "model's own simulator kept",
        "columns": cols,
        "ensemble": {
            "members": args.members,
            "penalties": list(penalties),
            "bootstrap": args.bootstrap,
        }
        if args.members > 1
        else None,  # fmt: skip
        "runs": rows,
    }
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
