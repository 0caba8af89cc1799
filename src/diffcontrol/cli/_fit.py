"""``diffcontrol fit``: fit a task's model to recorded trajectories (the grey box for now)."""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

from ..errors import ConfigError, RunDirectoryError
from ._args import finite_float, names, nonneg_int, positive_float, positive_int

MODELS = ("params", "hybrid", "neural")


def holdout_fraction(text: str) -> float:
    value = finite_float(text)
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be a fraction in [0, 1), got {text!r}")
    return value


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "fit",
        help="fit the task's model to recorded trajectories (grey box: its physical parameters)",
        description=(
            "Fit the physical parameters of TASK's simulator to the trajectories in FILE (a "
            "diffcontrol-trajectories CSV or NPZ, e.g. from `diffcontrol record`) by "
            "differentiating the simulator through short windows: from every recorded state, "
            "predict WINDOW steps with the recorded actions and minimise the squared error of "
            "the predicted observations (Adam, then Levenberg-Marquardt). The last episodes "
            "(a fraction F) are held out to measure the prediction error 1, 10 and 50 steps "
            "ahead for the nominal and the fitted model. Writes DIR/fitted.json and "
            "DIR/prediction.png."
        ),
    )
    p.add_argument("task", metavar="TASK", help="a registered task (`diffcontrol list`)")
    p.add_argument("--data", required=True, metavar="FILE", help="recorded trajectories")
    p.add_argument(
        "--model",
        required=True,
        choices=MODELS,
        help="params: the task's physics with fitted parameters (grey box); hybrid and "
        "neural are not implemented yet",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--params",
        type=names,
        default=["g", "friction"],
        metavar="NAMES",
        help="comma-separated parameters to fit (default g,friction); the others keep their "
        "nominal values",
    )
    p.add_argument(
        "--window", type=positive_int, default=10, metavar="N", help="steps per window (10)"
    )
    p.add_argument("--steps", type=nonneg_int, default=300, metavar="N", help="Adam steps (300)")
    p.add_argument(
        "--lm-steps",
        type=nonneg_int,
        default=20,
        metavar="N",
        help="Levenberg-Marquardt steps after Adam (20; 0 for none)",
    )
    p.add_argument(
        "--learning-rate",
        type=positive_float,
        default=0.02,
        metavar="LR",
        help="Adam's step size in log-parameter units (0.02: about 2 %% a step)",
    )
    p.add_argument(
        "--holdout",
        type=holdout_fraction,
        default=0.2,
        metavar="F",
        help="fraction of the episodes (the last ones) held out for the prediction errors "
        "(0.2; at least one episode when F > 0; 0 for none)",
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


def _split(data: Any, fraction: float) -> tuple[Any, Any]:
    n = data.num_episodes
    if fraction == 0:
        return data, None
    held = max(1, round(fraction * n))
    if n - held < 1:
        raise ConfigError(
            f"--holdout {fraction} of {n} episode(s) leaves none to fit; record at least 2 "
            "episodes, or pass --holdout 0"
        )
    return data.split(n - held)


def _params_dict(params: Any) -> dict[str, float]:
    import dataclasses

    import numpy as np

    return {f.name: float(np.asarray(getattr(params, f.name))) for f in dataclasses.fields(params)}


def cmd_fit(args: argparse.Namespace) -> int:
    from .. import __version__, tasks
    from .._fit_plot import prediction_plot
    from ..data import read_trajectories
    from ..fitting import HORIZONS, fit_parameters, prediction_errors
    from ..io import now_iso, write_json

    if tasks.make(args.task).kind == "ode":  # the swing-ups: their own branch, _fit_ode
        from ._fit_ode import cmd_fit_ode

        return cmd_fit_ode(args, tasks.make(args.task))
    if args.model != "params":
        raise ConfigError(
            f"--model {args.model} is not implemented yet; use --model params (the task's "
            "physics with fitted parameters)"
        )
    task = tasks.make(args.task)
    if task.kind != "control":
        raise ConfigError(
            f"task {task.name!r} is a {task.kind!r} task; fitting needs a discrete-time "
            "control task such as pendulum"
        )
    data = read_trajectories(args.data)
    out = Path(args.out)
    _check_out(out, args.force)
    train, held_out = _split(data, args.holdout)
    say = (lambda line: None) if args.quiet else print
    say(
        f"fitting {', '.join(args.params)} of {task.name} to {train.num_episodes} episode(s) "
        f"({train.num_steps} transitions) of {args.data}, windows of {args.window} steps"
    )
    t0 = time.perf_counter()
    result = fit_parameters(
        task,
        train,
        args.params,
        window=args.window,
        steps=args.steps,
        learning_rate=args.learning_rate,
        lm_steps=args.lm_steps,
    )
    seconds = time.perf_counter() - t0
    errors = None
    if held_out is not None:
        errors = {
            "nominal": prediction_errors(task, task.default_params(), held_out),
            "fitted": prediction_errors(task, result.params, held_out),
        }
    doc = {
        "format": "diffcontrol-fitted-model",
        "version": 1,
        "task": task.name,
        "model": "params",
        "parameters": {
            n: {
                "value": result.values[n],
                "standard_error": result.standard_errors[n],
                "nominal": result.nominal[n],
            }
            for n in result.names
        },
        "all_parameters": _params_dict(result.params),
        "fit": {
            "window_steps": result.window,
            "windows": result.windows,
            "adam_steps": args.steps,
            "learning_rate": args.learning_rate,
            "lm_steps": args.lm_steps,
            "loss": result.loss,
            "nominal_loss": result.nominal_loss,
            "diverged": result.diverged,
            "message": result.message,
            "loss_history": result.loss_history.tolist(),
            "seconds": seconds,
        },
        "data": {
            "file": str(args.data),
            "env_id": data.env_id,
            "env_kwargs": data.metadata.get("env_kwargs"),
            "fit_episodes": [e.id for e in train.episodes()],
            "held_out_episodes": [e.id for e in held_out.episodes()] if held_out else [],
            "fit_transitions": train.num_steps,
        },
        "prediction_error": None
        if errors is None
        else {
            "what": "RMS error of the observations H steps ahead, open loop from every "
            "recorded state of the held-out episodes with the recorded actions",
            "horizons_steps": list(HORIZONS),
            **{label: {str(h): e for h, e in by_h.items()} for label, by_h in errors.items()},
        },
        "created": now_iso(),
        "diffcontrol_version": __version__,
    }
    _make_out(out)
    write_json(out / "fitted.json", doc)
    shown = held_out if held_out is not None else train
    prediction_plot(
        task,
        {"fitted": result.params, "nominal": task.default_params()},
        shown,
        out / "prediction.png",
        title=f"{task.name}, {'held-out' if held_out is not None else 'fit'} episodes: open "
        "loop from the recorded state every 50 steps",
    )
    for n in result.names:
        se = result.standard_errors[n]
        pm = f" ± {se:.3g}" if math.isfinite(se) else " (not identifiable from this data)"
        print(f"{n} = {result.values[n]:.6g}{pm} (nominal {result.nominal[n]:.6g})")
    if errors is not None:
        for h in HORIZONS:
            nom, fit = errors["nominal"][h]["rmse"], errors["fitted"][h]["rmse"]
            print(f"held-out RMS error {h:>2} steps ahead: nominal {nom:.3g}, fitted {fit:.3g}")
    if result.diverged:
        print(f"warning: {result.message}")
    print(f"wrote {out / 'fitted.json'} and {out / 'prediction.png'} ({seconds:.1f} s fit)")
    return 0
