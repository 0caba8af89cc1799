"""``diffcontrol fit`` for continuous-time tasks (the swing-ups): grey-box, hybrid or neural
models of the cart-pole from recorded state data (``diffcontrol.ode_fitting``).

Kept apart from ``_fit`` (the discrete-time fits); ``_fit.cmd_fit`` hands continuous-time
tasks to ``cmd_fit_ode``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any


def cmd_fit_ode(args: argparse.Namespace, task: Any) -> int:
    """Fit ``args.model`` to ``args.data`` for the continuous-time ``task``; write
    ``DIR/fitted.json`` (format ``diffcontrol-fitted-model``, version 1)."""
    from .. import ode_fitting as of
    from .._fit_plot import prediction_plot
    from ..data import read_trajectories
    from ._fit import (
        _check_out,
        _split,
        errors_doc,
        parameters_doc,
        report,
        result_doc,
        write_fitted,
    )

    data = read_trajectories(args.data)
    out = Path(args.out)
    _check_out(out, args.force)
    train, held_out = _split(data, args.holdout)
    say = (lambda line: None) if args.quiet else print
    nominal_params = task.default_params()
    say(
        f"fitting a {args.model} model of {task.name} to {train.num_episodes} episode(s) "
        f"({train.num_steps} transitions) of {args.data}, windows of {args.window} steps"
    )
    t0 = time.perf_counter()
    result = of.fit_swingup_model(
        train,
        args.model,
        nominal_params,
        window=args.window,
        steps=args.steps,
        learning_rate=args.learning_rate,
        lm_steps=args.lm_steps,
        hidden=args.hidden,
        seed=args.seed,
    )
    seconds = time.perf_counter() - t0
    errors = None
    if held_out is not None:
        errors = {
            "nominal": of.prediction_errors(of.nominal_model(nominal_params), held_out),
            "fitted": of.prediction_errors(result.model, held_out),
        }
    parameters = parameters_doc(
        result.values, result.standard_errors, dict.fromkeys(result.values, 0.0)
    )
    body = {
        "parameters": parameters,
        **{k: v for k, v in of.model_to_dict(result.model).items() if k != "kind"},
        "fit": result_doc(
            result,
            seconds,
            window_steps=result.window,
            windows=result.windows,
            dt_s=result.dt_s,
            rk4_substeps=result.substeps,
            adam_steps=args.steps,
            learning_rate=args.learning_rate,
            lm_steps=args.lm_steps if args.model == "params" else 0,
            num_parameters=result.num_parameters,
            hidden=list(args.hidden) if args.model != "params" else None,
            seed=args.seed,
        ),
        "data": {
            "file": str(args.data),
            "system": data.metadata.get("system"),
            "metadata": data.metadata,
            "fit_episodes": [e.id for e in train.episodes()],
            "held_out_episodes": [e.id for e in held_out.episodes()] if held_out else [],
            "fit_transitions": train.num_steps,
        },
        "prediction_error": errors_doc(
            "RMS error of the state (x m, x_dot m/s, theta rad, theta_dot rad/s) H steps "
            "ahead, open loop from every recorded state of the held-out episodes with the "
            "recorded forces",
            of.HORIZONS,
            errors,
        ),
    }
    write_fitted(out, task, args.model, body)
    shown = held_out if held_out is not None else train
    prediction_plot(
        {
            "fitted": _predictor(result.model, result.dt_s, result.substeps),
            "nominal": _predictor(of.nominal_model(nominal_params), result.dt_s, result.substeps),
        },
        shown,
        out / "prediction.png",
        title=f"{task.name} ({args.model}), {'held-out' if held_out is not None else 'fit'} "
        "episodes: open loop, restarted every 50 steps",
    )
    lines = []
    if errors is not None:
        for h in of.HORIZONS:
            nom, fit = errors["nominal"][h]["rmse"], errors["fitted"][h]["rmse"]
            lines.append(
                f"held-out RMS state error {h:>2} steps ahead: nominal {nom:.3g}, fitted {fit:.3g}"
            )
    report(parameters, result, out, seconds, lines)
    return 0


def _predictor(model: Any, dt: float, substeps: int):
    """A swing-up model as a ``_fit_plot.Predictor``: the states after each held force, open
    loop in float64 (``ode_fitting.predict``, as the prediction errors are measured)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .. import ode_fitting as of

    @eqx.filter_jit  # one program per segment length, not one per segment
    def open_loop(m, state, forces):
        return of.predict(m, state, forces, dt, substeps)

    def run(state0, actions):
        with jax.enable_x64(True):
            m = jax.tree.map(
                lambda a: jnp.asarray(a, jnp.float64) if eqx.is_inexact_array(a) else a, model
            )
            forces = jnp.asarray(actions[:, 0], jnp.float64)
            return np.asarray(open_loop(m, jnp.asarray(state0, jnp.float64), forces))

    return run
