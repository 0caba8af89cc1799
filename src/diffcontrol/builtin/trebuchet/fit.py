"""The trebuchet's physics fitted to recorded throws, and its route of model learning.

A throw is one input ``(wind, release angle, counterweight)`` and one measured outcome, the
distance (a one-step episode: ``throws``). The model is the differentiable trebuchet
itself (``system.shoot``) with some of its parameters unknown (by default the drag
coefficient ``C_d`` and ``wind_factor``, how strongly the wind acts on the flight). They are
fitted by least squares on the distance residuals ``r_i = shoot(w_i, a_i, m_i; theta) - d_i``
(m), differentiating through the whole simulated throw: no windows are needed, since a throw is
one short open-loop run.

**The fit** runs in float64 on unconstrained coordinates ``z`` (``value = exp(z)`` for a
positive nominal value, ``value = z`` for a nominal 0): Adam (optax) for ``steps`` steps, then
up to ``lm_steps`` Levenberg-Marquardt steps, each kept only if it lowers the loss. One compiled
program computes the residuals and their Jacobian (forward mode: one pass per fitted parameter)
and serves all three stages, Adam (its gradient is ``2 J^T r / N``), Levenberg-Marquardt and the
standard errors. Why not ``identify.steps``' scan of Adam steps and optimistix: compiling the
trebuchet's three phase scans is most of a fit's cost, and separate programs for the Adam
scan, the optimistix solve and the Jacobian of the standard errors would compile them three
times; a throw batch is quick to run, so the host loop's per-step overhead does not matter.

**Uncertainty** from the curvature at the fit (Gauss-Newton, as in ``identify.steps``):
``cov = sigma^2 (J^T J)^-1``, ``sigma^2 = r^T r / (N - p)``; each throw is one independent
measurement, so no correction for overlapping windows is needed. ``inf`` where the data cannot
tell the parameters apart (for instance ``drag_coefficient`` with ``air_density``: only their
product enters).

**Divergence** is reported, not hidden: a non-finite loss stops the fit with ``diverged=True``
and the best parameters seen before it are kept; no NaN is returned.

``THROWS`` is the task's ``model_route``: ``identify.fit`` and ``identify.fit_dir`` reach the
fit, the held-out distance errors and the plot through it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..._jax_setup import float64
from ...errors import ConfigError, InsufficientDataError
from ...identify._routes import TrajectoryRoute
from ...identify._shooting import FitResult, check_settings, set_params, standard_errors
from ...identify.data import TrajectoryData
from ...identify.kinds import kind, parameters_doc
from ...io import write_figure
from . import system as tb
from .record import as64, padded_rows, parameter_names, params_dict, predict_distances
from .throws import Throws, read_throws, throws_of

MIN_THROWS_PER_PARAMETER = 5
"""The fewest recorded throws per fitted parameter."""
DEFAULT_NAMES = ("drag_coefficient", "wind_factor")
"""The parameters fitted by default: what the nominal trebuchet does not know."""


def _throws(data: TrajectoryData | Throws) -> Throws:
    return data if isinstance(data, Throws) else throws_of(data)


def distance_errors(params: tb.TrebuchetParams | None, data: TrajectoryData | Throws) -> dict:
    """How well ``params`` predicts the recorded distances: ``rmse_m`` (root mean square of
    predicted minus recorded, m), ``mean_abs_m``, ``max_abs_m`` and ``throws``."""
    throws = _throws(data)
    err = predict_distances(params, throws) - throws.distance
    return {
        "rmse_m": float(np.sqrt(np.mean(err**2))),
        "mean_abs_m": float(np.mean(np.abs(err))),
        "max_abs_m": float(np.max(np.abs(err))),
        "throws": int(err.size),
    }


def fit_throws(
    data: TrajectoryData | Throws,
    names: Sequence[str] = DEFAULT_NAMES,
    *,
    steps: int = 300,
    learning_rate: float = 0.02,
    lm_steps: int = 20,
    init: dict[str, float] | None = None,
    params: tb.TrebuchetParams | None = None,
) -> FitResult:
    """Fit the trebuchet parameters ``names`` to recorded throws (module docstring).

    Args:
        data: recorded throws (``read_throws``, ``record_throws``).
        names: fields of ``TrebuchetParams`` to fit; the others keep the values of ``params``.
        steps: Adam steps (>= 0) at ``learning_rate`` in the unconstrained coordinates (0.02 is
            about 2 % of a positive parameter a step).
        lm_steps: Levenberg-Marquardt steps after Adam (>= 0; 0 for none).
        init: starting values by name (default those of ``params``).
        params: the nominal trebuchet (default ``TrebuchetParams()``).

    Returns:
        A ``FitResult``: ``loss`` is the mean squared distance residual (m^2), ``window`` 1,
        ``windows`` and ``transitions`` the number of throws.

    Raises:
        ConfigError: an unknown or repeated name (the message lists the fittable ones), or a
            bad ``steps``/``lm_steps``/``learning_rate``/``init``.
        InsufficientDataError: fewer than ``MIN_THROWS_PER_PARAMETER`` throws per parameter.
    """
    names = tuple(names)
    base = params or tb.TrebuchetParams()
    known = parameter_names()
    bad = [n for n in names if n not in known]
    if bad or not names or len(set(names)) != len(names):
        what = f"unknown parameter(s) {bad}" if bad else f"parameter names {list(names)}"
        raise ConfigError(f"{what} for the trebuchet; choose distinct names among {list(known)}")
    check_settings(steps=steps, learning_rate=learning_rate, lm_steps=lm_steps)
    need = MIN_THROWS_PER_PARAMETER * len(names)
    throws = _throws(data)
    if throws.wind.size < need:
        raise InsufficientDataError(
            f"{throws.wind.size} recorded throw(s) are too few to fit {len(names)} parameter(s) "
            f"{list(names)}: at least {need} are needed ({MIN_THROWS_PER_PARAMETER} per "
            "parameter), with winds of both signs to tell wind_factor; record more throws "
            "(`diffcontrol record trebuchet --episodes N`)"
        )
    init = dict(init or {})
    unknown = [n for n in init if n not in names]
    if unknown:
        raise ConfigError(f"init names {unknown} are not among the fitted ones {list(names)}")
    with float64():
        return _fit(throws, names, steps, learning_rate, lm_steps, init, as64(base))


@functools.partial(jax.jit, static_argnames="names")
def _residuals_and_jacobian(z, positive, wind, angle, weight, distance, base, names):
    """Residuals [N] (m) at ``z`` and their Jacobian [N, p] with respect to ``z``."""

    def residuals(z):
        values = jnp.where(positive, jnp.exp(z), z)
        p = set_params(base, names, values)
        return tb.shoot(wind, angle, weight, p) - distance

    return residuals(z), jax.jacfwd(residuals)(z)


def _fit(data, names, steps, learning_rate, lm_steps, init, base) -> FitResult:
    nominal = {n: float(getattr(base, n)) for n in names}
    positive = np.array([nominal[n] > 0 for n in names])
    start = np.array([float(init.get(n, nominal[n])) for n in names])
    if not np.all(np.isfinite(start)) or np.any(positive & (start <= 0)):
        raise ConfigError(
            f"initial values {dict(zip(names, start.tolist()))} must be finite, and positive "
            "where the nominal value is"
        )
    columns = (data.wind, data.release_angle, data.counterweight, data.distance)
    n, padded = padded_rows(*columns)
    inputs = tuple(jnp.asarray(c) for c in padded)  # one program per 64 rows

    def to_values(z):
        return np.where(positive, np.exp(z), z)

    def to_z(values):
        return np.where(positive, np.log(np.where(positive, values, 1.0)), values)

    def evaluate(z):
        r, jac = _residuals_and_jacobian(
            jnp.asarray(z), jnp.asarray(positive), *inputs, base, names=names
        )
        r, jac = np.asarray(r)[:n], np.asarray(jac)[:n]
        loss = float(np.mean(r**2))
        ok = math.isfinite(loss) and bool(np.all(np.isfinite(jac)))
        return (loss if ok else math.inf), r, jac, ok

    nominal_loss = evaluate(to_z(np.array(list(nominal.values()))))[0]
    optimiser = optax.adam(learning_rate)
    z = to_z(start)
    opt_state = optimiser.init(jnp.asarray(z))
    best_z, best_loss, history, diverged, message = z, math.inf, [], False, ""
    for i in range(steps + 1):
        loss, r, jac, ok = evaluate(z)
        if not ok:
            diverged = True
            message = (
                f"Adam step {i} gave a non-finite loss; kept the best parameters so far"
                if i
                else "the loss is not finite at the starting values; try other init values"
            )
            break
        if loss < best_loss:
            best_z, best_loss, best_r, best_jac = z, loss, r, jac
        if i == steps:
            break
        history.append(loss)
        grad = 2.0 * jac.T @ r / r.size
        updates, opt_state = optimiser.update(jnp.asarray(grad), opt_state)
        z = np.asarray(optax.apply_updates(jnp.asarray(z), updates))
    if lm_steps and math.isfinite(best_loss) and not diverged:
        best_z, best_loss, best_r, best_jac, lm_ok = _levenberg_marquardt(
            evaluate, best_z, best_loss, best_r, best_jac, lm_steps
        )
        history.append(best_loss)
        if not lm_ok:
            message = "a Levenberg-Marquardt step diverged; kept the best fit so far"
    values = to_values(best_z)
    if math.isfinite(best_loss):
        # The Gauss-Newton formula needs only r and dr/dvalue at the fit: pass the
        # linearisation, so that no second program of the throw is compiled.
        dvalue_dz = np.where(positive, values, 1.0)
        jac_v = jnp.asarray(best_jac / dvalue_dz)
        r0, v0 = jnp.asarray(best_r), jnp.asarray(values)
        errors = np.asarray(standard_errors(lambda v: r0 + jac_v @ (v - v0), v0))
    else:  # diverged at the very start: the nominal values, unknown uncertainty
        values, errors = start, np.full(len(names), math.inf)
    if not message:
        message = (
            f"mean squared distance error {best_loss:.3g} m^2 (nominal parameters: "
            f"{nominal_loss:.3g} m^2)"
        )
    fitted = set_params(base, names, jnp.asarray(values))
    return FitResult(
        model=fitted,
        model_type="params",
        params=fitted,
        num_parameters=len(names),
        names=names,
        values=dict(zip(names, values.tolist())),
        nominal=nominal,
        standard_errors=dict(zip(names, errors.tolist())),
        loss=best_loss,
        nominal_loss=nominal_loss,
        loss_history=np.asarray(history, np.float64),
        diverged=diverged,
        message=message,
        window=1,
        windows=data.wind.size,
        transitions=data.wind.size,
    )


def _levenberg_marquardt(evaluate, z, loss, r, jac, max_steps):
    """Levenberg-Marquardt with Marquardt's scaling ``diag(J^T J)``: a step is taken only if
    it lowers the loss; otherwise the damping grows tenfold. Stops at ``max_steps`` tries or
    when a step changes ``z`` by less than 1e-10. Returns the best ``(z, loss, r, jac)`` and
    whether every evaluated step was finite."""
    damping, all_finite = 1e-3, True
    for _ in range(max_steps):
        jtj, g = jac.T @ jac, jac.T @ r
        a = jtj + damping * np.diag(np.maximum(np.diag(jtj), 1e-12))
        try:
            step = -np.linalg.solve(a, g)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(step)):
            break
        new_loss, new_r, new_jac, ok = evaluate(z + step)
        all_finite &= ok
        if ok and new_loss < loss:
            z, loss, r, jac = z + step, new_loss, new_r, new_jac
            damping = max(damping / 10, 1e-12)
            if np.max(np.abs(step)) < 1e-10:
                break
        else:
            damping *= 10
    return z, loss, r, jac, all_finite


def throws_plot(
    models: dict[str, Any], data: TrajectoryData | Throws, path: Any, title: str = ""
) -> Any:
    """Scatter the distances each model in ``models`` (label -> ``TrebuchetParams``) predicts
    for the throws of ``data`` against the recorded ones (left), and the residuals against
    the wind (right), where a wrong wind factor shows as a slope; write a PNG atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = _throws(data)
    fig, (ax, ax_wind) = plt.subplots(1, 2, figsize=(10.0, 4.2))
    lo = min(0.0, float(np.min(data.distance)))
    hi = float(np.max(data.distance))
    for c, (label, params) in enumerate(models.items()):
        pred = predict_distances(params, data)
        rms = float(np.sqrt(np.mean((pred - data.distance) ** 2)))
        style = dict(color=f"C{c}", marker="os^"[c % 3], s=18, alpha=0.8)
        ax.scatter(data.distance, pred, label=f"{label} (RMS {rms:.2f} m)", **style)
        ax_wind.scatter(data.wind, pred - data.distance, label=label, **style)
        lo, hi = min(lo, float(np.min(pred))), max(hi, float(np.max(pred)))
    ax.plot([lo, hi], [lo, hi], color="0.5", lw=1.0, ls="--", label="predicted = recorded")
    ax.set_xlabel("recorded distance (m)")
    ax.set_ylabel("predicted distance (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax_wind.axhline(0.0, color="0.5", lw=1.0, ls="--")
    ax_wind.set_xlabel("wind (m/s, + toward the target)")
    ax_wind.set_ylabel("predicted - recorded (m)")
    ax_wind.legend(loc="best", fontsize=8)
    fig.suptitle(title or f"{data.wind.size} recorded throws", fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=100)


class ThrowRoute(TrajectoryRoute):
    """The trebuchet's route of model learning (its ``model_route``): its grey box fitted to
    recorded throws (one-step episodes), judged by the held-out distance errors."""

    unit = "throw"

    def read(self, path: Any) -> TrajectoryData:
        return read_throws(path)

    def announce(self, task, model_type, train, held_out, data_file, settings) -> str:
        names = settings.get("names") or task.fit_parameter_names
        held = f" ({held_out.num_episodes} held out)" if held_out else ""
        return (
            f"fitting {', '.join(names)} of the trebuchet to {train.num_episodes} throw(s) of "
            f"{data_file}{held}"
        )

    def check_split(self, task, data, train, held_out, settings) -> None:
        """Refuse a hold-out that leaves too few throws for the fit."""
        names = settings.get("names") or task.fit_parameter_names
        need = MIN_THROWS_PER_PARAMETER * len(names)
        if held_out is not None and train.num_episodes < need <= data.num_episodes:
            raise InsufficientDataError(
                f"holding out {held_out.num_episodes} of the {data.num_episodes} throws "
                f"(--holdout {settings.get('holdout')}) leaves {train.num_episodes} to fit "
                f"{len(names)} parameter(s), but at least {need} are needed; record more "
                "throws or pass --holdout 0"
            )

    def check_model(self, task: Any, model_type: str) -> None:
        """Refuse a network model: a throw has no trajectory to learn a correction from."""
        if kind(model_type).network:
            raise ConfigError(
                f"--model {model_type} is not supported for aiming tasks such as {task.name!r} "
                "(a throw has no trajectory to learn a correction from); use --model params to "
                "fit its physical parameters"
            )

    def fit(self, task: Any, data: Any, model_type: str, **s: Any) -> FitResult:
        self.check_model(task, model_type)
        keys = ("steps", "learning_rate", "lm_steps", "init", "params")
        kw = {k: s[k] for k in keys if s.get(k) is not None}
        return fit_throws(data, tuple(s.get("names") or task.fit_parameter_names), **kw)

    def outputs(self, task, result, data, train, held_out, data_file, settings, out):
        nominal = task.default_params()
        errors = None
        if held_out is not None:
            errors = {
                "nominal": distance_errors(nominal, held_out),
                "fitted": distance_errors(result.params, held_out),
            }
        body = {
            "parameters": parameters_doc(result),
            # the float fields of TrebuchetParams only (its step budgets are static, not fitted)
            "all_parameters": params_dict(result.params),
            "fit": dict(
                residual="predicted minus recorded distance (m), one per throw",
                adam_steps=settings["steps"],
                learning_rate=settings["learning_rate"],
                lm_steps=settings.get("lm_steps", 20),
            ),
            "data": {
                "file": str(data_file),
                "kind": "throws",
                "metadata": data.metadata,
                "fit_throws": train.num_episodes,
                "held_out_throws": held_out.num_episodes if held_out else 0,
            },
            "prediction_error": None
            if errors is None
            else {
                "what": "error of the predicted distance (m) of the held-out throws (the last "
                "ones of the file), with their recorded inputs",
                **errors,
            },
        }
        shown = held_out if held_out is not None else train
        throws_plot(
            {"fitted": result.params, "nominal": nominal},
            shown,
            out / "prediction.png",
            title=f"trebuchet, {shown.num_episodes} {'held-out' if held_out else 'fitted'} "
            f"throws of {Path(data_file).name}",
        )
        lines = []
        if errors is not None:
            nom, fit = errors["nominal"]["rmse_m"], errors["fitted"]["rmse_m"]
            lines.append(
                f"held-out RMS distance error over {held_out.num_episodes} throw(s): nominal "
                f"{nom:.3g} m, fitted {fit:.3g} m"
            )
        return body, lines


THROWS = ThrowRoute()
"""The trebuchet's ``model_route``."""
