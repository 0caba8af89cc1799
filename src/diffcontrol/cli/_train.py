"""``diffcontrol train``: train a controller and write the run's files."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Any

from ..config import ODETrainConfig, TrainConfig, help_of
from ..errors import DiffcontrolError
from ._args import (
    add_common,
    finite_float,
    nonneg_int,
    param,
    positive_float,
    positive_int,
    widths,
    yes_no,
)
from ._runs import example_throw

_CONFIG_OPTIONS: dict[str, tuple[Any, str]] = {
    "seed": (int, "N"),
    "updates": (positive_int, "N"),
    "batch": (positive_int, "N"),
    "window": (positive_int, "STEPS"),
    "horizon": (nonneg_int, "STEPS"),
    "learning_rate": (finite_float, "LR"),
    "lr_schedule": (str, "NAME"),
    "lr_final_fraction": (finite_float, "F"),
    "grad_clip": (finite_float, "NORM"),
    "hidden": (widths, "W,W"),
    "activation": (str, "NAME"),
    "head": (str, "NAME"),
    "loss": (str, "NAME"),
    "eval_every": (positive_int, "N"),
    "eval_episodes": (positive_int, "N"),
    "target_return": (float, "R"),
    "keep_best": (yes_no, "yes|no"),
}

_ODE_OPTIONS: dict[str, tuple[Any, str]] = {
    "horizon_s": (positive_float, "S"),
    "saves": (positive_int, "N"),
    "solver": (str, "NAME"),
    "rtol": (positive_float, "TOL"),
    "atol": (positive_float, "TOL"),
    "max_steps": (positive_int, "N"),
    "gradient": (str, "METHOD"),
    "population": (positive_int, "N"),
    "curriculum_start": (finite_float, "F"),
    "curriculum_fraction": (finite_float, "F"),
}


def _add_options(group: Any, options: dict[str, tuple[Any, str]], config_cls: type) -> None:
    """One ``--name`` option per config field, its help the field's documentation."""
    for name, (typ, metavar) in options.items():
        group.add_argument(
            "--" + name.replace("_", "-"),
            dest=name,
            type=typ,
            metavar=metavar,
            default=None,
            help=help_of(name, config_cls).replace("%", "%%"),
        )


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "train",
        help="train a controller and write model, metrics, plots and an animation",
        description=(
            "Train a controller for TASK by differentiating through its simulator, with the "
            "task's tuned defaults unless options change them: backpropagation through time "
            "for discrete-time tasks, through an adaptive ODE solve for continuous-time ones "
            "(cartpole-swingup*). Writes to DIR: model.json (the controller, runnable with "
            "NumPy alone), metrics.json (timings, simulated steps and episodes, learning "
            "curve, evaluation), learning_curve.png, rollout.png and rollout.gif (swing-ups: "
            "data.json with the time series, swingup.png with angle, position and force), "
            "and checkpoint.npz (for --resume)."
        ),
    )
    p.add_argument("task", metavar="TASK", help="task name (see `diffcontrol list`)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (new or empty)")
    p.add_argument(
        "--recipe",
        metavar="NAME",
        help="start from a named set of settings, e.g. 'original' for the 2019 Flux recipe",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in DIR from its last checkpoint",
    )
    p.add_argument(
        "--final-eval",
        type=nonneg_int,
        default=None,
        metavar="N",
        help="evaluate after training: Gymnasium episodes on seeds 0..N-1 (default 100), or "
        "random targets for aiming tasks (default 1000); 0 skips",
    )
    p.add_argument("--no-animation", action="store_true", help="skip the GIF (saves a few seconds)")
    p.add_argument(
        "--model",
        metavar="FIT_DIR",
        help="train through the model fitted by `diffcontrol fit` in FIT_DIR instead of the "
        "nominal simulator (fitted parameters, or the hybrid/neural model), and evaluate on "
        "the system its data was recorded from (e.g. diffcontrol/PendulumFriction-v0 with "
        "its arguments)",
    )
    add_common(p)
    group = p.add_argument_group(
        "training settings (defaults depend on the task; see `diffcontrol list`)"
    )
    _add_options(group, _CONFIG_OPTIONS, TrainConfig)
    ode = p.add_argument_group(
        "continuous-time tasks only (cartpole-swingup*): the ODE solve and its gradient"
    )
    _add_options(ode, _ODE_OPTIONS, ODETrainConfig)
    group.add_argument(
        "--param",
        dest="params",
        type=param,
        action="append",
        metavar="NAME=VALUE",
        help="override a physical parameter of the simulator (repeatable), e.g. --param g=9.81",
    )


def cmd_train(args: argparse.Namespace) -> int:
    from .. import _jax_setup, io, tasks
    from ..evaluation import evaluate, record_episode
    from ..models import as_env
    from ..training import resolve_config, train

    task = tasks.make(args.task)
    config_cls = type(task.default_config())
    fields = {f.name for f in dataclasses.fields(config_cls)}
    overrides = {name: getattr(args, name) for name in {**_CONFIG_OPTIONS, **_ODE_OPTIONS}}
    foreign = sorted(n for n, v in overrides.items() if v is not None and n not in fields)
    if foreign:
        kind = "a continuous-time" if task.kind == "ode" else "a discrete-time"
        flags = ", ".join("--" + n.replace("_", "-") for n in foreign)
        raise DiffcontrolError(
            f"{flags} do{'es' if len(foreign) == 1 else ''} not apply to {task.name!r} ({kind} "
            "task); see `diffcontrol train --help` for the settings of each kind"
        )
    overrides = {n: v for n, v in overrides.items() if n in fields}
    task, fitted_params, real = _fitted(args, task)
    if fitted_params or args.params:
        overrides["params"] = (*fitted_params, *(args.params or ()))  # --param wins
    out = Path(args.out)
    explicit = args.recipe is not None or any(v is not None for v in overrides.values())
    if args.resume and not explicit and (out / io.RUN_FILE).exists():
        config = config_cls.from_json(io.read_json(out / io.RUN_FILE, "run file")["config"])
    else:
        config = resolve_config(task, args.recipe, **overrides)

    cache_dir = None
    if not (args.no_compile_cache or os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE")):
        cache_dir = _jax_setup.enable_compile_cache()
    say = (lambda line: None) if args.quiet else (lambda line: print(line, flush=True))
    if task.kind == "ode":
        say(
            f"training {task.name}: {config.updates} updates of {config.population} closed-loop "
            f"solve(s) over {config.horizon_s:g} s ({config.solver}, rtol {config.rtol:g}, atol "
            f"{config.atol:g}, gradient {config.gradient}; seed {config.seed}) -> {out}"
        )
        if config.gradient == "backsolve":
            print(
                "note: --gradient backsolve is the continuous adjoint: its gradient is "
                "approximate (the backward solve re-creates the state with the solver's error); "
                "checkpoint is exact for the computed solve",
                file=sys.stderr,
            )
    else:
        say(
            f"training {task.name}: {config.updates} updates x window {config.window} x batch "
            f"{config.batch} (seed {config.seed}) -> {out}"
        )
    try:
        result = train(task, config, out_dir=out, resume=args.resume, progress=say)
    except KeyboardInterrupt:
        print(
            f"\ninterrupted; the last checkpoint is in {out}. Continue with: "
            f"diffcontrol train {task.name} --out {out} --resume",
            file=sys.stderr,
        )
        return 130
    metrics = result.metrics
    metrics["compile_cache"] = {
        "dir": str(cache_dir) if cache_dir else None,
        **_jax_setup.cache_events(),
    }
    metrics["command"] = " ".join(["diffcontrol", *sys.argv[1:]])
    metrics["created"] = io.now_iso()

    from .. import __version__

    doc = io.controller_to_dict(
        result.controller,
        task,
        {
            "diffcontrol_version": __version__,
            "created": metrics["created"],
            "seed": config.seed,
            "train_seconds": metrics["train_seconds"],
            "config": config.to_json(),
        },
    )
    io.write_json(out / "model.json", doc)
    if args.model:
        metrics["model"] = {"dir": str(args.model), "kind": _kind_of(task), "real_system": real}
    if task.kind == "aiming":
        return _finish_aiming(args, task, out, doc, metrics, say, real)
    if task.kind == "ode":
        return _finish_ode(args, task, out, result, metrics, say)
    policy = io.NumpyPolicy(doc)
    final_eval = 100 if args.final_eval is None else args.final_eval
    if final_eval and task.gym_id:
        t0 = time.perf_counter()
        ev = evaluate(policy, task, episodes=final_eval, seed=0, real=as_env(real))
        metrics["gym_eval"] = {**ev.to_json(), "seconds": time.perf_counter() - t0}
        where = "the real system" if as_env(real) else "Gymnasium"
        say(f"{where} {ev.env_id}, seeds 0-{final_eval - 1}: return {ev.mean:.1f} ± {ev.std:.1f}")
    io.write_json(out / "metrics.json", metrics)

    from .. import plots

    plots.learning_curve(metrics, out / "learning_curve.png", task.reward_threshold)
    files = ["model.json", "metrics.json", "learning_curve.png"]
    if task.gym_id:
        rec = record_episode(policy, task, seed=0, real=as_env(real))
        plots.rollout(rec, task, out / "rollout.png")
        files.append("rollout.png")
        if not args.no_animation:
            from ..animation import animate

            animate(rec, task, out / "rollout.gif")
            files.append("rollout.gif")
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']:.4g} simulated episodes ({metrics['simulated_steps']} steps)"
        + (
            f"; Gymnasium return {metrics['gym_eval']['mean_return']:.1f} ± "
            f"{metrics['gym_eval']['std_return']:.1f}"
            if "gym_eval" in metrics
            else ""
        )
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0


def _fitted(args: argparse.Namespace, task: Any) -> tuple[Any, tuple, tuple | None]:
    """``--model FIT_DIR``: the task to train (a hybrid or neural model's own), the fitted
    physical parameters as ``--param`` overrides, and the real system its data came from
    (``models.real_system``; ``None`` without --model or where the data does not say)."""
    if not args.model:
        return task, (), None
    import numpy as np

    from ..models import fitted_model, fitted_physics, model_task, read_fitted, real_system

    doc = read_fitted(args.model)
    fitted_physics(task, doc)  # refuses a model of another task
    real = real_system(doc)
    if doc["model"] == "params":
        return task, tuple(sorted(doc["all_parameters"].items())), real
    if args.params:
        raise DiffcontrolError(
            f"--param cannot change the physics of the {doc['model']} model in {args.model}; "
            "refit it, or train with a grey-box (--model params) fit"
        )
    if task.kind == "ode":
        from ..tasks.fitted_swingup import FittedSwingUp, model_from_dict

        fitted = FittedSwingUp(task, model_from_dict(doc, doc["_path"]))
        fitted.name = task.name  # model.json names the task the controller runs on
    else:
        fitted = model_task(task, fitted_model(task, doc))
    weights = sum(
        np.asarray(l["weight"]).size + len(l["bias"]) for l in doc["network"].get("layers", [])
    )
    print(f"training through the {doc['model']} model in {args.model} ({weights} network weights)")
    return fitted, (), real


def _kind_of(task: Any) -> str:
    """``params``, ``hybrid`` or ``neural``: what a --model run trains through."""
    from ..models import HybridModel, NeuralModel

    fitted = getattr(task, "model", None)  # a swing-up's FittedSwingUp
    if fitted is not None and getattr(fitted, "kind", None) in ("hybrid", "neural"):
        return fitted.kind
    model = task.default_params()
    if isinstance(model, HybridModel):
        return "hybrid"
    return "neural" if isinstance(model, NeuralModel) else "params"


def _finish_aiming(args, task, out: Path, doc: dict, metrics: dict, say, real=None) -> int:
    """The end of `train` for aiming tasks: miss statistics (on the real trebuchet of a
    --model run), the throw plot and animation."""
    from .. import io, plots
    from ..evaluation import evaluate_aiming
    from ..models import real_params

    policy = io.AimingPolicy(doc)
    n = 1000 if args.final_eval is None else args.final_eval
    if n:
        t0 = time.perf_counter()
        params = real_params(task, real)
        ev = evaluate_aiming(policy, task, targets=n, seed=0, params=params)
        metrics["aim_eval"] = {**ev.to_json(), "seconds": time.perf_counter() - t0}
        where = " on the real trebuchet" if params is not None else ""
        say(f"{n} random targets (seed 0){where}: {ev.summary()}")
    io.write_json(out / "metrics.json", metrics)
    plots.learning_curve(metrics, out / "learning_curve.png", None)
    files = ["model.json", "metrics.json", "learning_curve.png", "rollout.png"]
    target, wind = 80.0, -3.0
    throw = example_throw(policy, target, wind)
    plots.throw(throw, target, wind, out / "rollout.png")
    if not args.no_animation:
        from ..animation import animate_throw

        animate_throw(throw, target, wind, out / "rollout.gif")
        files.append("rollout.gif")
    summary = f"; mean |miss| {metrics['aim_eval']['mean_miss_m']:.3f} m" if n else ""
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']:.4g} simulated throws{summary}"
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0


def _finish_ode(args, task, out: Path, result, metrics: dict, say) -> int:
    """The end of `train` for continuous-time tasks: a reference solve, data.json, plots, GIF."""
    from .. import io, plots
    from ..evaluation import simulate_continuous, swingup_result
    from ..models import real_params

    base = getattr(task, "base", task)  # a fitted model's task: the system it models
    real = real_params(base, (metrics.get("model") or {}).get("real_system"))
    if real is not None:  # a --model run: on the real system its data came from
        rec = simulate_continuous(base, result.controller, real, config=result.config)
    else:
        rec = simulate_continuous(task, result.controller, result.params, config=result.config)
    report = swingup_result(rec)
    metrics["swingup"] = report.to_json()
    say(f"reference solve{' on the real system' if real is not None else ''}: {report.summary()}")
    io.write_json(out / "metrics.json", metrics)
    io.write_json(out / "data.json", rec.to_json())
    plots.learning_curve(metrics, out / "learning_curve.png", None)
    plots.swingup(rec, out / "swingup.png")
    files = ["model.json", "data.json", "metrics.json", "learning_curve.png", "swingup.png"]
    if not args.no_animation:
        from ..animation import animate_swingup

        animate_swingup(rec, out / "rollout.gif")
        files.append("rollout.gif")
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']} closed-loop solves ({metrics['simulated_steps']} solver "
        f"steps); final |θ| {abs(report.final_theta):.3f} rad, ẋ {report.final_x_dot:+.3f} m/s, "
        f"peak |F| {report.peak_force:.1f} N; loss {report.loss:.4g}"
        + (" on the real system" if real is not None else "")
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0
