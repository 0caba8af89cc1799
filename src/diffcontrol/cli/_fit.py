"""``diffcontrol fit``: fit a task's model to recorded trajectories (grey box, hybrid or black box)."""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

from ..errors import ConfigError, RunDirectoryError
from ._args import finite_float, names, nonneg_int, positive_float, positive_int

DEFAULTS = {"params": (300, 0.02), "hybrid": (2000, 3e-3), "neural": (2000, 3e-3)}
"""Adam steps and learning rate by model kind."""
DEFAULTS_ODE = {"params": (300, 0.02), "hybrid": (500, 1e-2), "neural": (500, 1e-2)}
"""The same for continuous-time tasks (the swing-ups; ``benchmarks/fit_swingup.py``)."""

MODELS = ("params", "hybrid", "neural")


def widths(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(w) for w in text.split(","))
    except ValueError:
        values = ()
    if not values or any(w < 1 for w in values):
        raise argparse.ArgumentTypeError(f"must be positive widths like 32,32, got {text!r}")
    return values


def holdout_fraction(text: str) -> float:
    value = finite_float(text)
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be a fraction in [0, 1), got {text!r}")
    return value


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "fit",
        help="fit a model of the task's system to recorded trajectories (or throws)",
        description=(
            "Fit a model of TASK's system to the trajectories in FILE (a "
            "diffcontrol-trajectories CSV or NPZ, e.g. from `diffcontrol record`) by "
            "differentiating it through short windows: from every recorded state, predict "
            "WINDOW steps with the recorded actions and minimise the squared error of the "
            "predicted observations. --model params fits physical parameters of TASK's own "
            "simulator (grey box: Adam, then Levenberg-Marquardt, with standard errors); "
            "hybrid adds a small network to the nominal physics for what it leaves out; neural "
            "learns the dynamics from the data alone (black box). The last episodes (a "
            "fraction F) are held out to measure the prediction error 1, 10 and 50 steps "
            "ahead for the nominal and the fitted model. Writes DIR/fitted.json (the model, "
            "weights as JSON lists) and DIR/prediction.png; `diffcontrol train TASK --model "
            "DIR` then trains a controller through it. For the trebuchet (TASK trebuchet), "
            "FILE holds recorded throws instead (a diffcontrol-throws CSV or NPZ, e.g. from "
            "`diffcontrol record trebuchet`): its parameters are fitted to the measured "
            "distances, the last throws are held out, and prediction.png plots predicted "
            "against recorded distances."
        ),
    )
    p.add_argument(
        "task",
        metavar="TASK",
        help="a task name (`diffcontrol list`), or your own task as module:Class (from the current directory) or an entry point of the diffcontrol.tasks group",
    )
    p.add_argument(
        "--data", required=True, metavar="FILE", help="recorded trajectories (or throws)"
    )
    p.add_argument(
        "--model",
        required=True,
        choices=MODELS,
        help="params: the task's physics with fitted parameters (grey box); hybrid: the "
        "nominal physics plus a network correction; neural: a network alone (black box)",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--params",
        type=names,
        default=None,
        metavar="NAMES",
        help="--model params: comma-separated parameters to fit (default g,friction; for "
        "the trebuchet drag_coefficient,wind_factor; the swing-ups always fit their four "
        "friction coefficients); the others keep their nominal values",
    )
    p.add_argument(
        "--hidden",
        type=widths,
        default=(32, 32),
        metavar="W,W",
        help="--model hybrid/neural: the network's hidden layer widths (32,32)",
    )
    p.add_argument("--seed", type=nonneg_int, default=0, help="the network's initial weights (0)")
    p.add_argument(
        "--window",
        type=positive_int,
        default=10,
        metavar="N",
        help="steps per window (10; not for the trebuchet's throws)",
    )
    p.add_argument(
        "--steps",
        type=nonneg_int,
        default=None,
        metavar="N",
        help="Adam steps (300 for params; 2000 for hybrid and neural, 500 for the swing-ups')",
    )
    p.add_argument(
        "--lm-steps",
        type=nonneg_int,
        default=20,
        metavar="N",
        help="--model params: Levenberg-Marquardt steps after Adam (20; 0 for none)",
    )
    p.add_argument(
        "--learning-rate",
        type=positive_float,
        default=None,
        metavar="LR",
        help="Adam's step size: for params in log-parameter units (0.02: about 2 %% a "
        "step); for networks 0.003 (swing-ups 0.01), cosine-decayed",
    )
    p.add_argument(
        "--holdout",
        type=holdout_fraction,
        default=0.2,
        metavar="F",
        help="fraction of the episodes (the last ones; for the trebuchet the last throws) held "
        "out for the prediction errors (0.2; at least one when F > 0; 0 for none)",
    )
    p.add_argument("--force", action="store_true", help="replace DIR/fitted.json if it exists")
    p.add_argument("--quiet", action="store_true", help="print only the final summary")


def _check_out(out: Path, force: bool) -> None:
    """Refuse, before fitting, an --out that could not take fitted.json (nothing is created)."""
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out} is a file; give a directory")
    if (out / "fitted.json").exists() and not force:
        raise RunDirectoryError(
            f"{out / 'fitted.json'} already exists; pass --force to replace it or choose "
            "another --out"
        )
    parent = next((p for p in (out, *out.parents) if p.exists()), Path("."))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise RunDirectoryError(f"cannot write --out {out}: {parent} is not writable")


def _make_out(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RunDirectoryError(f"cannot create --out {out} ({e.strerror})") from None


def _split(data: Any, fraction: float, unit: str = "episode") -> tuple[Any, Any]:
    """``(fitted, held_out)``: the last ``fraction`` of the episodes (or throws: ``unit``)
    held out, at least one when ``fraction > 0``; ``held_out`` is None for 0."""
    n = data.num_throws if unit == "throw" else data.num_episodes
    if fraction == 0:
        return data, None
    held = max(1, round(fraction * n))
    if n - held < 1:
        raise ConfigError(
            f"--holdout {fraction} of {n} {unit}(s) leaves none to fit; record at least 2 "
            f"{unit}s, or pass --holdout 0"
        )
    return data.split(n - held)


def _params_dict(params: Any) -> dict[str, float]:
    import dataclasses

    import numpy as np

    return {f.name: float(np.asarray(getattr(params, f.name))) for f in dataclasses.fields(params)}


def parameters_doc(values: dict, standard_errors: dict, nominal: dict) -> dict:
    """fitted.json's ``parameters``: per fitted name, its value, standard error and nominal."""
    return {
        n: {"value": v, "standard_error": standard_errors[n], "nominal": nominal[n]}
        for n, v in values.items()
    }


def result_doc(fit: Any, seconds: float, **settings: Any) -> dict:
    """fitted.json's ``fit``: the fit's ``settings``, then how it ended (any fit result)."""
    return {
        **settings,
        "loss": fit.loss,
        "nominal_loss": fit.nominal_loss,
        "diverged": fit.diverged,
        "message": fit.message,
        "loss_history": [float(v) for v in fit.loss_history],
        "seconds": seconds,
    }


def errors_doc(what: str, horizons: Any, errors: dict | None) -> dict | None:
    """fitted.json's ``prediction_error`` for per-horizon errors by model label."""
    if errors is None:
        return None
    by_label = {label: {str(h): e for h, e in by_h.items()} for label, by_h in errors.items()}
    return {"what": what, "horizons_steps": list(horizons), **by_label}


def write_fitted(out: Path, task: Any, model: str, body: dict) -> None:
    """Write ``out/fitted.json``: the format's head, ``body``, and when and by what."""
    from .. import __version__
    from ..io import now_iso, write_json
    from ..models import FITTED_FILE, FITTED_FORMAT

    head = {"format": FITTED_FORMAT, "version": 1, "task": task.name, "model": model}
    tail = {"created": now_iso(), "diffcontrol_version": __version__}
    _make_out(out)
    write_json(out / FITTED_FILE, {**head, **body, **tail})


def report(parameters: dict, fit: Any, out: Path, seconds: float, held_out_lines: list) -> None:
    """Print the fitted parameters with their standard errors, the held-out errors, a
    divergence and the files written."""
    for n, p in parameters.items():
        se = p["standard_error"]
        pm = f" ± {se:.3g}" if math.isfinite(se) else " (not identifiable from this data)"
        print(f"{n} = {p['value']:.6g}{pm} (nominal {p['nominal']:.6g})")
    for line in held_out_lines:
        print(line)
    if fit.diverged:
        print(f"warning: {fit.message}")
    print(f"wrote {out / 'fitted.json'} and {out / 'prediction.png'} ({seconds:.1f} s fit)")


def cmd_fit(args: argparse.Namespace) -> int:
    from .. import tasks
    from ..data import read_trajectories

    task = tasks.resolve(args.task)
    steps, lr = (DEFAULTS_ODE if task.kind == "ode" else DEFAULTS)[args.model]
    args.steps = steps if args.steps is None else args.steps
    args.learning_rate = lr if args.learning_rate is None else args.learning_rate
    if task.kind == "aiming":  # the trebuchet: fitted to recorded throws
        from ._throws import cmd_fit_throws

        return cmd_fit_throws(args, task)
    if task.kind == "ode":  # the swing-ups: fitted to recorded states
        from ._fit_ode import cmd_fit_ode

        return cmd_fit_ode(args, task)
    if task.kind != "control":
        raise ConfigError(
            f"task {task.name!r} is a {task.kind!r} task; fitting needs a discrete-time "
            "control task such as pendulum"
        )
    data = read_trajectories(args.data)
    out = Path(args.out)
    _check_out(out, args.force)
    train, held_out = _split(data, args.holdout)
    args.params = args.params or ["g", "friction"]
    say = (lambda line: None) if args.quiet else print
    what = ", ".join(args.params) if args.model == "params" else f"a {args.model} model"
    say(
        f"fitting {what} of {task.name} to {train.num_episodes} episode(s) "
        f"({train.num_steps} transitions) of {args.data}, windows of {args.window} steps"
    )
    t0 = time.perf_counter()
    fit, predictor, model_doc = _fit(args, task, train)
    seconds = time.perf_counter() - t0
    _write(args, task, data, train, held_out, fit, predictor, model_doc, seconds, out)
    return 0


def _fit(args: argparse.Namespace, task: Any, train: Any) -> tuple[Any, Any, dict]:
    """Fit the model asked for; returns the fit result, ``(task, params)`` to predict with, and
    the model's part of fitted.json."""
    if args.model == "params":
        from ..fitting import fit_parameters

        result = fit_parameters(
            task,
            train,
            args.params,
            window=args.window,
            steps=args.steps,
            learning_rate=args.learning_rate,
            lm_steps=args.lm_steps,
        )
        doc = {
            "parameters": parameters_doc(result.values, result.standard_errors, result.nominal),
            "all_parameters": _params_dict(result.params),
        }
        return result, (task, result.params), doc
    from ..models import correction_to_dict, fit_model, model_task

    result = fit_model(
        task,
        train,
        args.model,
        window=args.window,
        steps=args.steps,
        learning_rate=args.learning_rate,
        hidden=args.hidden,
        seed=args.seed,
    )
    doc = {
        "all_parameters": _params_dict(result.model.params),
        "network": {
            "what": "hybrid: next state = the task's step with all_parameters + network("
            "observation, action); neural: next state = state + network(observation, action)",
            "inputs": "observation then action",
            "parameters": result.num_parameters,
            **correction_to_dict(result.model.correction),
        },
    }
    return result, (model_task(task, result.model), result.model), doc


def _write(args, task, data, train, held_out, fit, predictor, model_doc, seconds, out) -> None:
    from .._fit_plot import prediction_plot, task_predictor
    from ..fitting import HORIZONS, prediction_errors

    errors = None
    if held_out is not None:
        errors = {
            "nominal": prediction_errors(task, task.default_params(), held_out),
            "fitted": prediction_errors(*predictor, held_out),
        }
    settings = dict(
        window_steps=fit.window,
        windows=fit.windows,
        adam_steps=args.steps,
        learning_rate=args.learning_rate,
    )
    if args.model == "params":
        settings["lm_steps"] = args.lm_steps
    else:
        settings.update(hidden=list(args.hidden), seed=args.seed)
    body = {
        **model_doc,
        "fit": result_doc(fit, seconds, **settings),
        "data": {
            "file": str(args.data),
            "env_id": data.env_id,
            "env_kwargs": data.metadata.get("env_kwargs"),
            "fit_episodes": [e.id for e in train.episodes()],
            "held_out_episodes": [e.id for e in held_out.episodes()] if held_out else [],
            "fit_transitions": train.num_steps,
        },
        "prediction_error": errors_doc(
            "RMS error of the observations H steps ahead, open loop from every recorded state "
            "of the held-out episodes with the recorded actions",
            HORIZONS,
            errors,
        ),
    }
    write_fitted(out, task, args.model, body)
    shown = held_out if held_out is not None else train
    prediction_plot(
        {
            "fitted": task_predictor(*predictor),
            "nominal": task_predictor(task, task.default_params()),
        },
        shown,
        out / "prediction.png",
        title=f"{task.name} ({args.model}), {'held-out' if held_out is not None else 'fit'} "
        "episodes: open loop, restarted every 50 steps",
    )
    lines = []
    if "network" in model_doc:
        lines.append(
            f"{args.model} model: {model_doc['network']['parameters']} weights, {fit.message}"
        )
    if errors is not None:
        for h in HORIZONS:
            nom, fitted = errors["nominal"][h]["rmse"], errors["fitted"][h]["rmse"]
            lines.append(
                f"held-out RMS error {h:>2} steps ahead: nominal {nom:.3g}, fitted {fitted:.3g}"
            )
    report(model_doc.get("parameters", {}), fit, out, seconds, lines)
