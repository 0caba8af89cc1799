"""``diffcontrol train``: train a controller and write the run's files."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
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

# How the command line reads a config field, by its type; the exceptions by name. The fields
# themselves (and their help) come from the config dataclasses, so a new field is a new flag.
_BY_TYPE: dict[str, tuple[Any, str]] = {
    "int": (positive_int, "N"),
    "float": (finite_float, "X"),
    "str": (str, "NAME"),
    "bool": (yes_no, "yes|no"),
    "tuple[int, ...]": (widths, "W,W"),
}
_BY_NAME: dict[str, tuple[Any, str]] = {
    "seed": (int, "N"),
    "horizon": (nonneg_int, "STEPS"),
    "window": (positive_int, "STEPS"),
    "learning_rate": (finite_float, "LR"),
    "grad_clip": (finite_float, "NORM"),
    "target_return": (float, "R"),
    "horizon_s": (positive_float, "S"),
    "rtol": (positive_float, "TOL"),
    "atol": (positive_float, "TOL"),
    "gradient": (str, "METHOD"),
}


def _fields(config_cls: type) -> list[Any]:
    """The fields of a config that are command-line flags (``params`` is ``--param``)."""
    return [f for f in dataclasses.fields(config_cls) if f.name != "params"]


def _add_options(group: Any, config_cls: type, skip: set[str] = frozenset()) -> None:
    """One ``--name`` option per config field, its help the field's documentation."""
    for f in _fields(config_cls):
        if f.name in skip:
            continue
        typ, metavar = _BY_NAME.get(f.name) or _BY_TYPE[str(f.type)]
        group.add_argument(
            "--" + f.name.replace("_", "-"),
            dest=f.name,
            type=typ,
            metavar=metavar,
            default=None,
            help=help_of(f.name, config_cls).replace("%", "%%"),
        )


_SETTINGS = [f.name for f in _fields(TrainConfig)] + [
    f.name for f in _fields(ODETrainConfig) if f.name not in {g.name for g in _fields(TrainConfig)}
]


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
    p.add_argument(
        "task",
        metavar="TASK",
        nargs="?",
        default=None,
        help="(optional with --resume: the run's own) a task name (`diffcontrol list`), or your own task as module:Class (from the current directory) or an entry point of the diffcontrol.tasks group",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (new or empty)")
    p.add_argument(
        "--recipe",
        metavar="NAME",
        help="start from a named set of settings, e.g. 'original' for the 2019 Flux recipe",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in DIR from its last checkpoint, with the settings "
        "of its run.json (a finished run is left as it is)",
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
    _add_options(group, TrainConfig)
    ode = p.add_argument_group(
        "continuous-time tasks only (cartpole-swingup*): the ODE solve and its gradient"
    )
    _add_options(ode, ODETrainConfig, skip={f.name for f in _fields(TrainConfig)})
    group.add_argument(
        "--param",
        dest="params",
        type=param,
        action="append",
        metavar="NAME=VALUE",
        help="override a physical parameter of the simulator (repeatable), e.g. --param g=9.81",
    )


def _resume_settings(args: argparse.Namespace) -> bool:
    """With --resume, take what the command line leaves out from the run's own run.json (the
    task, the fitted model, the final evaluation, the animation). Returns False when the run
    is finished (nothing to do)."""
    from .. import tasks
    from ..runs import read_run_file

    stored = read_run_file(args.out) if args.resume else None
    if stored is None:
        if args.task is None:
            raise DiffcontrolError("name the TASK to train (or --resume the run in --out)")
        return True
    if stored.get("complete"):
        return False
    invocation = stored.get("invocation") or {}
    if args.task is None:
        spec = invocation.get("task") or stored.get("task")
        if spec not in tasks.names():  # never import a module because a file names it
            raise DiffcontrolError(
                f"{args.out} was trained on the task {spec!r}, which is not registered; name "
                f"it: diffcontrol train {spec} --out {args.out} --resume"
            )
        args.task = spec
    args.model = args.model or invocation.get("model")
    if args.final_eval is None:
        args.final_eval = invocation.get("final_eval")
    args.no_animation = args.no_animation or invocation.get("animation") is False
    return True


def cmd_train(args: argparse.Namespace) -> int:
    from .. import _jax_setup, io
    from ..runs import describe, fitted_training, mark_complete, release_claim, save_run
    from ..tasks import resolve
    from ..training import resolve_config, train

    if not _resume_settings(args):
        print(f"{args.out} holds a finished run; nothing to resume (its files are unchanged)")
        return 0
    task = resolve(args.task)
    config_cls = type(task.default_config())
    fields = {f.name for f in dataclasses.fields(config_cls)}
    overrides = {name: getattr(args, name) for name in _SETTINGS}
    foreign = sorted(n for n, v in overrides.items() if v is not None and n not in fields)
    if foreign:
        flags = ", ".join("--" + n.replace("_", "-") for n in foreign)
        raise DiffcontrolError(
            f"{flags} do{'es' if len(foreign) == 1 else ''} not apply to {task.name!r} (trained "
            f"with a {config_cls.__name__}); see `diffcontrol train --help` for the settings of "
            "each kind of task"
        )
    overrides = {n: v for n, v in overrides.items() if n in fields}
    fitted_params, real, model_info = (), None, None
    if args.model:
        task, fitted_params, real, model_info = fitted_training(task, args.model, args.params)
        print(model_info.pop("note"))
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
    if not args.quiet:  # training warnings come as progress lines; not twice
        import warnings

        from ..errors import TrainingWarning

        warnings.simplefilter("ignore", TrainingWarning)
    say(describe(task, config, out))
    if getattr(config, "gradient", None) == "backsolve":
        print(
            "note: --gradient backsolve is the continuous adjoint: its gradient is "
            "approximate (the backward solve re-creates the state with the solver's error); "
            "checkpoint is exact for the computed solve",
            file=sys.stderr,
        )
    invocation = {
        "task": args.task,
        "model": args.model,
        "final_eval": args.final_eval,
        "animation": not args.no_animation,
    }
    named = "" if args.task in _builtin_names() else f" {args.task}"
    try:
        result = train(
            task, config, out_dir=out, resume=args.resume, progress=say, invocation=invocation
        )
    except BaseException as e:
        kept = args.resume or not release_claim(out)  # nothing to resume: give the dir back
        if not isinstance(e, KeyboardInterrupt):
            raise
        if kept:
            print(
                f"\ninterrupted; the last checkpoint is in {out}. Continue with: "
                f"diffcontrol train{named} --out {out} --resume",
                file=sys.stderr,
            )
        else:
            print("\ninterrupted before the first checkpoint; nothing was kept", file=sys.stderr)
        return 130
    metrics = result.metrics
    metrics["compile_cache"] = {
        "dir": str(cache_dir) if cache_dir else None,
        **_jax_setup.cache_events(),
    }
    metrics["command"] = " ".join(["diffcontrol", *sys.argv[1:]])
    metrics["created"] = io.now_iso()
    if model_info:
        metrics["model"] = model_info
    try:
        run, files = save_run(
            result,
            out,
            final_eval=args.final_eval,
            animation=not args.no_animation,
            real=real,
            progress=say,
        )
    except KeyboardInterrupt:
        print(
            f"\ninterrupted while writing the run's files; finish them with: "
            f"diffcontrol train{named} --out {out} --resume",
            file=sys.stderr,
        )
        return 130
    mark_complete(out)
    headline = run.metrics.get("headline")
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']:.4g} simulated episodes ({metrics['simulated_steps']} "
        f"steps)" + (f"; {headline}" if headline else "") + (" on the real system" if real else "")
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0


def _builtin_names() -> set[str]:
    from .. import tasks

    return {n for n in tasks.names() if not getattr(tasks.make(n), "source", None)}
