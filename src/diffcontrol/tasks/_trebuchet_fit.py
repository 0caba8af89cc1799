"""Recorded throws (the trebuchet task's data): its unknown physics fitted to the distances.

A throw is one input ``(wind, release angle, counterweight)`` and one measured outcome, the
distance. The model is the differentiable trebuchet itself (``systems.trebuchet.shoot``) with
some of its parameters unknown (by default the drag coefficient ``C_d`` and ``wind_factor``,
how strongly the wind acts on the flight). They are fitted by least squares on the distance
residuals ``r_i = shoot(w_i, a_i, m_i; theta) - d_i`` (m), differentiating through the whole
simulated throw: no windows are needed, since a throw is one short open-loop run.

``record_throws`` plays the real trebuchet: it throws a ``TrebuchetParams`` (the "real" one,
e.g. ``C_d = 1.5`` and ``wind_factor = 1.5``) with random or given inputs and adds Gaussian
noise to the measured distances.

**The fit** runs in float64 on unconstrained coordinates ``z`` (``value = exp(z)`` for a
positive nominal value, ``value = z`` for a nominal 0): Adam (optax) for ``steps`` steps, then
up to ``lm_steps`` Levenberg-Marquardt steps, each kept only if it lowers the loss. One compiled
program computes the residuals and their Jacobian (forward mode: one pass per fitted parameter)
and serves all three stages, Adam (its gradient is ``2 J^T r / N``), Levenberg-Marquardt and the
standard errors. Why not ``identify.steps``' scan of Adam steps and optimistix: the trebuchet's
three phase scans take about 10-15 s to compile, and separate programs for the Adam scan, the
optimistix solve and the Jacobian of the standard errors would take three times that; a
throw batch costs milliseconds, so the host loop's per-step overhead does not matter.

**Uncertainty** from the curvature at the fit (Gauss-Newton, as in ``identify.steps``):
``cov = sigma^2 (J^T J)^-1``, ``sigma^2 = r^T r / (N - p)``; each throw is one independent
measurement, so no correction for overlapping windows is needed. ``inf`` where the data cannot
tell the parameters apart (for instance ``drag_coefficient`` with ``air_density``: only their
product enters).

**Divergence** is reported, not hidden: a non-finite loss stops the fit with ``diverged=True``
and the best parameters seen before it are kept; no NaN is returned.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..errors import ConfigError, InsufficientDataError
from ..io import now_iso
from ..systems import trebuchet as tb
from ._shooting import FitResult, set_params, standard_errors
from .data import ThrowData

MIN_THROWS_PER_PARAMETER = 5
"""The fewest recorded throws per fitted parameter."""
DEFAULT_NAMES = ("drag_coefficient", "wind_factor")
"""The parameters fitted by default: what the nominal trebuchet does not know."""
RANDOM_ANGLE_DEG = (20.0, 70.0)
"""``record_throws`` draws random release angles uniformly from here (degrees)."""
RANDOM_WEIGHT_LB = (50.0, 450.0)
"""``record_throws`` draws random counterweights uniformly from here (pounds)."""
RANDOM_WIND_STD_MPS = 5.0
"""``record_throws`` draws random winds ~ N(0, 5^2) m/s clipped to +-20, as the task does."""


def parameter_names() -> tuple[str, ...]:
    """The trebuchet's fittable parameters: the float fields of ``TrebuchetParams`` (the step
    budgets and ``swap_inertias`` are static and cannot be fitted)."""
    p = tb.TrebuchetParams()
    return tuple(
        f.name
        for f in dataclasses.fields(p)
        if not f.metadata.get("static", False) and isinstance(getattr(p, f.name), float)
    )


def trebuchet_params(env_args: list[tuple[str, float]]) -> tb.TrebuchetParams:
    """``TrebuchetParams`` with the ``--env-arg NAME=VALUE`` overrides (floats only).

    Raises:
        ConfigError: an unknown name (the message lists the trebuchet's parameters).
    """
    known = parameter_names()
    bad = [name for name, _ in env_args if name not in known]
    if bad:
        raise ConfigError(
            f"--env-arg {bad[0]}: the trebuchet has no parameter {bad[0]!r}; choose among "
            f"{', '.join(known)} (e.g. --env-arg drag_coefficient=1.5 --env-arg wind_factor=1.5)"
        )
    return tb.TrebuchetParams(**{name: float(value) for name, value in env_args})


def params_dict(params: tb.TrebuchetParams) -> dict[str, float]:
    """The fittable parameters of ``params`` as plain floats (for metadata and JSON)."""
    return {n: float(np.asarray(getattr(params, n))) for n in parameter_names()}


def _as64(params: tb.TrebuchetParams) -> tb.TrebuchetParams:
    return jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)


@jax.jit
def _shoot(wind, angle, weight, params):
    return tb.shoot(wind, angle, weight, params)


def predict_distances(params: tb.TrebuchetParams | None, data: ThrowData) -> np.ndarray:
    """The distances (m) the trebuchet ``params`` (default the nominal one) throws with the
    recorded inputs of ``data``, simulated in float64."""
    with jax.enable_x64(True):
        p = _as64(params or tb.TrebuchetParams())
        return np.asarray(_shoot(data.wind, data.release_angle, data.counterweight, p))


def distance_errors(params: tb.TrebuchetParams | None, data: ThrowData) -> dict[str, Any]:
    """How well ``params`` predicts the recorded distances: ``rmse_m`` (root mean square of
    predicted minus recorded, m), ``mean_abs_m``, ``max_abs_m`` and ``throws``."""
    err = predict_distances(params, data) - data.distance
    return {
        "rmse_m": float(np.sqrt(np.mean(err**2))),
        "mean_abs_m": float(np.mean(np.abs(err))),
        "max_abs_m": float(np.max(np.abs(err))),
        "throws": int(err.size),
    }


def record_throws(
    n: int,
    params: tb.TrebuchetParams | None = None,
    *,
    seed: int = 0,
    noise_m: float = 0.0,
    inputs: tuple[Any, Any, Any] | None = None,
    policy: Any = None,
    source: str | None = None,
) -> ThrowData:
    """Throw the trebuchet ``params`` (default nominal) ``n`` times and record the throws.

    The inputs are, in this order of precedence: ``inputs`` ``(wind_mps, angle_deg,
    weight_lb)`` (arrays of length ``n``, or scalars); or ``policy`` (a trained aiming
    controller, e.g. ``diffcontrol.load(run)``, whose ``action`` maps ``(target, wind)`` to
    ``(angle, weight)``) aiming at random targets ~ U(20, 100) m; or random inputs (angles
    ~ U(``RANDOM_ANGLE_DEG``), counterweights ~ U(``RANDOM_WEIGHT_LB``)). Random winds are
    N(0, 5^2) m/s clipped to +-20 m/s. Everything random comes from
    ``numpy.random.default_rng(seed)``; the recorded distance is the simulated one (float64)
    plus Gaussian noise of standard deviation ``noise_m`` (m).

    Returns:
        A ``ThrowData`` whose metadata records the system's parameters, the noise and seed.

    Raises:
        ConfigError: ``n < 1``, a negative or non-finite ``noise_m``, or inputs out of the
            simulator's checked ranges (the message names the bad value).
    """
    if not isinstance(n, int | np.integer) or n < 1:
        raise ConfigError(f"the number of throws must be a positive integer, got {n!r}")
    if not (math.isfinite(noise_m) and noise_m >= 0):
        raise ConfigError(f"noise_m must be a standard deviation >= 0 (m), got {noise_m!r}")
    p = params or tb.TrebuchetParams()
    rng = np.random.default_rng(seed)
    wind = np.clip(RANDOM_WIND_STD_MPS * rng.standard_normal(n), -20.0, 20.0)
    if inputs is not None:
        wind, angle, weight = (np.broadcast_to(np.asarray(x, np.float64), (n,)) for x in inputs)
        how = "given inputs"
    elif policy is not None:
        from ..tasks.trebuchet import TARGET_RANGE_M

        target = rng.uniform(*TARGET_RANGE_M, size=n)
        actions = np.asarray(policy.action(np.stack([target, wind], axis=-1)), np.float64)
        angle, weight = actions[:, 0], actions[:, 1]
        how = f"a controller (task {getattr(policy, 'task', '?')!r}) aiming at random targets"
    else:
        angle = rng.uniform(*RANDOM_ANGLE_DEG, size=n)
        weight = rng.uniform(*RANDOM_WEIGHT_LB, size=n)
        how = "random inputs"
    wind, angle, weight = tb.check_inputs(wind, angle, weight)
    distance = predict_distances(p, ThrowData(wind, angle, weight, np.zeros(n)))
    if not np.all(np.isfinite(distance)):
        i = int(np.flatnonzero(~np.isfinite(distance))[0])
        raise ConfigError(
            f"throw {i} (wind {wind[i]:g} m/s, {angle[i]:g} deg, {weight[i]:g} lb) diverged in "
            f"the simulator with these parameters; check them ({params_dict(p)})"
        )
    distance = distance + noise_m * rng.standard_normal(n)
    metadata = {
        "system": "trebuchet",
        "source": source or f"simulated trebuchet, {how}",
        "params": params_dict(p),
        "noise_m": float(noise_m),
        "seed": int(seed),
        "recorded": now_iso(),
    }
    return ThrowData(wind, angle, weight, distance, metadata)


def fit_throws(
    data: ThrowData,
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
    if not isinstance(steps, int) or steps < 0 or not isinstance(lm_steps, int) or lm_steps < 0:
        raise ConfigError(f"steps and lm_steps must be integers >= 0, got {steps!r}, {lm_steps!r}")
    if not (isinstance(learning_rate, int | float) and math.isfinite(learning_rate)):
        raise ConfigError(f"learning_rate must be a positive number, got {learning_rate!r}")
    if learning_rate <= 0:
        raise ConfigError(f"learning_rate must be a positive number, got {learning_rate!r}")
    need = MIN_THROWS_PER_PARAMETER * len(names)
    if data.num_throws < need:
        raise InsufficientDataError(
            f"{data.num_throws} recorded throw(s) are too few to fit {len(names)} parameter(s) "
            f"{list(names)}: at least {need} are needed ({MIN_THROWS_PER_PARAMETER} per "
            "parameter), with winds of both signs to tell wind_factor; record more throws "
            "(`diffcontrol record trebuchet --episodes N`)"
        )
    init = dict(init or {})
    unknown = [n for n in init if n not in names]
    if unknown:
        raise ConfigError(f"init names {unknown} are not among the fitted ones {list(names)}")
    with jax.enable_x64(True):
        return _fit(data, names, steps, learning_rate, lm_steps, init, _as64(base))


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
    inputs = tuple(jnp.asarray(getattr(data, f)) for f in ("wind", "release_angle"))
    inputs += (jnp.asarray(data.counterweight), jnp.asarray(data.distance))

    def to_values(z):
        return np.where(positive, np.exp(z), z)

    def to_z(values):
        return np.where(positive, np.log(np.where(positive, values, 1.0)), values)

    def evaluate(z):
        r, jac = _residuals_and_jacobian(
            jnp.asarray(z), jnp.asarray(positive), *inputs, base, names=names
        )
        r, jac = np.asarray(r), np.asarray(jac)
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
        windows=data.num_throws,
        transitions=data.num_throws,
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


def throws_plot(models: dict[str, Any], data: ThrowData, path: Any, title: str = "") -> Any:
    """Scatter the distances each model in ``models`` (label -> ``TrebuchetParams``) predicts
    for the throws of ``data`` against the recorded ones (left), and the residuals against
    the wind (right), where a wrong wind factor shows as a slope; write a PNG atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import write_figure

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
    fig.suptitle(title or f"{data.num_throws} recorded throws", fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=100)
