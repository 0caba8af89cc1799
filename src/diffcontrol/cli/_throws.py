"""The trebuchet's side of ``diffcontrol record`` and ``diffcontrol fit``: recorded throws.

``diffcontrol record trebuchet --episodes N`` throws a (real) trebuchet N times (an episode
of the trebuchet task is one throw) and writes a diffcontrol-throws file; ``diffcontrol fit
trebuchet --data THROWS --model params`` fits its physical parameters to the distances.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from ..errors import ConfigError, InsufficientDataError


def trebuchet_params(env_args: list[tuple[str, float]]) -> Any:
    """``TrebuchetParams`` with the ``--env-arg NAME=VALUE`` overrides (floats only).

    Raises:
        ConfigError: an unknown name (the message lists the trebuchet's parameters).
    """
    from ..fit_throws import parameter_names
    from ..systems.trebuchet import TrebuchetParams

    known = parameter_names()
    bad = [name for name, _ in env_args if name not in known]
    if bad:
        raise ConfigError(
            f"--env-arg {bad[0]}: the trebuchet has no parameter {bad[0]!r}; choose among "
            f"{', '.join(known)} (e.g. --env-arg drag_coefficient=1.5 --env-arg wind_factor=1.5)"
        )
    return TrebuchetParams(**{name: float(value) for name, value in env_args})


def cmd_record_throws(args: argparse.Namespace, check_out) -> int:
    """``diffcontrol record trebuchet``: ``--episodes`` throws with random inputs (or a
    ``--controller`` aiming at random targets) of the trebuchet ``--env-arg``s describe."""
    from ..data import write_throws
    from ..fit_throws import record_throws
    from ..io import AimingPolicy, read_model
    from ._data import write_out

    if args.max_steps is not None:
        raise ConfigError(
            "--max-steps does not apply to the trebuchet (one episode is one throw); drop it"
        )
    params = trebuchet_params(args.env_arg)
    out = Path(args.out or "trebuchet-throws.csv")
    check_out(out, args.force)
    policy = None
    if args.controller:
        policy = AimingPolicy(read_model(args.controller))
        if policy.task != "trebuchet":
            raise ConfigError(
                f"--controller {args.controller} was trained for task {policy.task!r}, not "
                "trebuchet; give a trebuchet run, or omit --controller for random throws"
            )
    noise = args.noise_m or 0.0
    say = (lambda line: None) if args.quiet else print
    changed = ", ".join(f"{n}={v:g}" for n, v in args.env_arg) or "the nominal parameters"
    what = f"controller {args.controller}" if policy else "random inputs"
    say(f"recording {args.episodes} throw(s) of the trebuchet ({changed}) with {what}")
    t0 = time.perf_counter()
    data = record_throws(
        args.episodes,
        params,
        seed=args.seed,
        noise_m=noise,
        policy=policy,
        source=f"controller {args.controller}" if policy else None,
    )
    write_out(write_throws, out, data)
    print(
        f"wrote {out}: {data.num_throws} throw(s), distance noise {noise:g} m "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    return 0


def cmd_fit_throws(args: argparse.Namespace, task: Any) -> int:
    """``diffcontrol fit trebuchet``: the grey box from recorded throws (``fit_throws``)."""
    from .._throws_plot import throws_plot
    from ..data import read_throws
    from ..fit_throws import (
        DEFAULT_NAMES,
        MIN_THROWS_PER_PARAMETER,
        distance_errors,
        fit_throws,
        params_dict,
    )
    from ._fit import _check_out, _split, parameters_doc, report, result_doc, write_fitted

    if args.model != "params":
        raise ConfigError(
            f"--model {args.model} is not supported for aiming tasks such as {task.name!r} "
            "(a throw has no trajectory to learn a correction from); use --model params to "
            "fit its physical parameters"
        )
    names = tuple(args.params or DEFAULT_NAMES)
    data = read_throws(args.data)
    out = Path(args.out)
    _check_out(out, args.force)
    train, held_out = _split(data, args.holdout, "throw")
    say = (lambda line: None) if args.quiet else print
    say(
        f"fitting {', '.join(names)} of the trebuchet to {train.num_throws} throw(s) of "
        f"{args.data}" + (f" ({held_out.num_throws} held out)" if held_out else "")
    )
    need = MIN_THROWS_PER_PARAMETER * len(names)
    if held_out is not None and train.num_throws < need <= data.num_throws:
        raise InsufficientDataError(
            f"holding out {held_out.num_throws} of the {data.num_throws} throws (--holdout "
            f"{args.holdout}) leaves {train.num_throws} to fit {len(names)} parameter(s), but "
            f"at least {need} are needed; record more throws or pass --holdout 0"
        )
    t0 = time.perf_counter()
    result = fit_throws(
        train, names, steps=args.steps, learning_rate=args.learning_rate, lm_steps=args.lm_steps
    )
    seconds = time.perf_counter() - t0
    nominal_params = task.default_params()
    errors = None
    if held_out is not None:
        errors = {
            "nominal": distance_errors(nominal_params, held_out),
            "fitted": distance_errors(result.params, held_out),
        }
    parameters = parameters_doc(result.values, result.standard_errors, result.nominal)
    body = {
        "parameters": parameters,
        # the float fields of TrebuchetParams only (its step budgets are static, not fitted)
        "all_parameters": params_dict(result.params),
        "fit": result_doc(
            result,
            seconds,
            residual="predicted minus recorded distance (m), one per throw",
            adam_steps=args.steps,
            learning_rate=args.learning_rate,
            lm_steps=args.lm_steps,
        ),
        "data": {
            "file": str(args.data),
            "kind": "throws",
            "metadata": data.metadata,
            "fit_throws": train.num_throws,
            "held_out_throws": held_out.num_throws if held_out else 0,
        },
        "prediction_error": None
        if errors is None
        else {
            "what": "error of the predicted distance (m) of the held-out throws (the last "
            "ones of the file), with their recorded inputs",
            **errors,
        },
    }
    write_fitted(out, task, "params", body)
    shown = held_out if held_out is not None else train
    throws_plot(
        {"fitted": result.params, "nominal": nominal_params},
        shown,
        out / "prediction.png",
        title=f"trebuchet, {shown.num_throws} {'held-out' if held_out else 'fitted'} throws "
        f"of {Path(args.data).name}",
    )
    lines = []
    if errors is not None:
        nom, fit = errors["nominal"]["rmse_m"], errors["fitted"]["rmse_m"]
        lines.append(
            f"held-out RMS distance error over {held_out.num_throws} throw(s): nominal "
            f"{nom:.3g} m, fitted {fit:.3g} m"
        )
    report(parameters, result, out, seconds, lines)
    return 0
