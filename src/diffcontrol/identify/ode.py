"""Continuous-time models fitted to recorded state trajectories (``ContinuousTask``).

The data: episodes of the full state sampled every ``dt_s`` seconds, and the action held
constant over each interval (a zero-order hold), in the ``diffcontrol-trajectories`` format
with the task's ``data_columns()``. What is particular to a system comes from the hooks here
(``tasks._hooks``): ``nominal_model`` (the known physics), ``initial_model`` (the model before
fitting: which parameters a grey box fits, how a hybrid's network enters the vector field),
``fit_parameter_names`` and ``state_error`` (e.g. an angle difference wrapped to one turn).
A model has ``derivative(state, action) -> d state / dt`` and ``params``; a network model has
``correction`` (a ``Correction``).

The models are fitted by **multiple shooting**: from every recorded state of every episode, the
model's ODE is solved ``window`` intervals ahead with the recorded actions (``substeps`` fixed
RK4 steps per interval, so the solve is the same differentiable program for every window),
and the loss is the mean squared difference between the predicted and the recorded states,
each state column divided by its standard deviation in the data (so metres and radians per
second weigh alike), plus ``weight_decay`` times the mean squared network weight. Adam (optax)
on all windows at once, in float64; the grey box is refined by Levenberg-Marquardt and gets
standard errors from the curvature (``identify.steps``' method).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .._jax_setup import float64
from .._shell import command
from ..errors import ConfigError, DataFileError, InsufficientDataError
from ..tasks._hooks import task_hook
from ._shooting import (
    HORIZONS,
    MIN_TRANSITIONS_PER_PARAMETER,
    FitResult,
    adam_fit,
    check_settings,
    lm_refine,
    standard_errors,
)
from ._task import data_columns, fit_parameter_names
from .data import TrajectoryData, parse_column
from .kinds import kind

MIN_TRANSITIONS_NETWORK = 250
"""The fewest recorded transitions a hybrid or neural fit accepts (5 s of data at 50 Hz)."""


# --- what a continuous-time task's model is: the layer's defaults, a task's own overrides ------


@task_hook
def nominal_model(task: Any, params: Any) -> Any:
    """The known physics of ``task`` as a model (``derivative(state, action)``, ``params``)."""
    raise ConfigError(f"task {task.name!r} defines no model to fit (nominal_model)")


@task_hook
def initial_model(task: Any, model_type: str, nominal: Any, data: Any, dt_s: float,
                  hidden: tuple[int, ...], key: Any) -> Any:  # fmt: skip
    """The model of ``model_type`` before fitting, with the ``nominal`` parameters; a network
    model holds its network as ``correction``."""
    raise ConfigError(f"task {task.name!r} defines no model to fit (initial_model)")


@task_hook
def state_error(task: Any, pred: Any, target: Any) -> Any:
    """Predicted minus recorded state (a task wraps its angles here)."""
    return pred - target


@task_hook
def model_document(task: Any, model: Any) -> dict:
    """The fitted model as fitted.json's ``all_parameters`` and ``network``."""
    raise ConfigError(f"task {task.name!r} cannot store a fitted model (model_document)")


def _hold_solve(model: Any, state, force, dt, substeps: int):
    """The model's state ``dt`` seconds after ``state`` under the constant action ``force`` [m]:
    ``substeps`` classical Runge-Kutta (RK4) steps.

    Plain JAX rather than ``diffrax.diffeqsolve``: with a fixed step there is nothing to adapt,
    and Diffrax's step loop (checkpointed ``while_loop``s, also over the stages of one step)
    is much slower under ``vmap`` over thousands of windows and cannot be differentiated in
    forward mode, which the Levenberg-Marquardt refinement and the standard errors use. The
    recorded "real" data is solved adaptively by Diffrax.
    """
    h = dt / substeps

    def f(y):
        return model.derivative(y, force)

    y = state
    for _ in range(substeps):
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def predict(model: Any, state, actions, dt, substeps: int = 2):
    """Open loop: the states [len(actions), n] after each held action of ``actions`` [T, m]
    from ``state`` [n], every ``dt`` seconds."""

    def body(s, a):
        s = _hold_solve(model, s, a, dt, substeps)
        return s, s

    return jax.lax.scan(body, state, actions)[1]


def check_data(task: Any, data: TrajectoryData) -> float:
    """Refuse data that is not the task's state at a fixed time step; returns ``dt_s``.

    Raises:
        DataFileError: other columns (names or units), time not in seconds, no fixed step.
    """
    where = data.metadata.get("system") or data.metadata.get("env_id") or "the data"
    expected = data_columns(task)
    got = [parse_column(c) for c in (*data.observation_columns, *data.action_columns)]
    want = [parse_column(c) for c in (*expected[0], *expected[1])]
    if got != want:
        raise DataFileError(
            f"{where} has the columns {list(data.columns[2:])}, but the models of {task.name} "
            f"are fitted to its full state {[*expected[0], *expected[1]]}; record the state "
            f"(`{command('record', task.name)}`)"
        )
    if parse_column(data.columns[0])[2] != "s":
        raise DataFileError(f"{where}: time is in steps; the ODE models need time in seconds")
    steps = np.diff(data.time)[data.episode[1:] == data.episode[:-1]]
    dt = float(np.median(steps))
    if not np.allclose(steps, dt, rtol=1e-6, atol=0.0):
        raise DataFileError(
            f"{where}: the time steps vary from {steps.min()!r} to {steps.max()!r} s; record "
            "at a fixed time step (the action is held over each step)"
        )
    return dt


def _windows(data: TrajectoryData, window: int):
    """Every start with ``window`` recorded intervals after it: start states [N, n], actions
    [N, window, m] and recorded states [N, window, n], as float64 arrays (``None`` if none)."""
    starts, actions, targets = [], [], []
    for ep in data.episodes():
        n = len(ep.actions)
        for t in range(n - window + 1):
            starts.append(ep.observations[t])
            actions.append(ep.actions[t : t + window])
            targets.append(ep.observations[t + 1 : t + window + 1])
    if not starts:
        return None
    return tuple(jnp.asarray(np.stack(a), jnp.float64) for a in (starts, actions, targets))


def _f64(tree: Any) -> Any:
    return jax.tree.map(
        lambda a: jnp.asarray(a, jnp.float64) if eqx.is_inexact_array(a) else a, tree
    )


def fit_vector_field(
    task: Any,
    data: TrajectoryData,
    model_type: str = "hybrid",
    params: Any = None,
    *,
    window: int = 10,
    steps: int = 1000,
    learning_rate: float = 3e-3,
    hidden: Sequence[int] = (32, 32),
    weight_decay: float = 1e-5,
    substeps: int = 2,
    lm_steps: int = 20,
    seed: int = 0,
) -> FitResult:
    """Fit a model of ``model_type`` of a continuous-time ``task`` to recorded states (module
    docstring).

    Args:
        task: a ``ContinuousTask`` with the model-learning hooks.
        data: episodes with the task's ``data_columns()`` at a fixed step.
        model_type: ``params`` (the task's ``fit_parameter_names``), ``hybrid`` or ``neural``.
        params: the known physics (default the task's ``default_params()``), made nominal by
            ``nominal_model(task, ...)``.
        window: intervals predicted from every recorded state (>= 1).
        steps: Adam steps (>= 0) at ``learning_rate`` (cosine-decayed to 5 % for networks;
            for ``params`` in the parameters' units per step).
        hidden: the network's hidden widths.
        weight_decay: weight of the mean squared network weight in the loss.
        substeps: fixed RK4 steps per recorded interval.
        lm_steps: Levenberg-Marquardt steps after Adam (``params`` only).
        seed: the network's initial weights.

    Raises:
        ConfigError: an unknown ``model_type`` or a bad setting (named).
        DataFileError: data that is not the task's state (``check_data``).
        InsufficientDataError: too few transitions (says how many are needed) or no
            episode longer than ``window``.
    """
    network = kind(model_type).network
    if not isinstance(substeps, int) or isinstance(substeps, bool) or substeps < 1:
        raise ConfigError(f"substeps must be a positive integer, got {substeps!r}")
    if not isinstance(window, int) or isinstance(window, bool) or window < 1:
        raise ConfigError(f"window must be a positive integer, got {window!r}")
    check_settings(window, steps, learning_rate, lm_steps)
    if not (math.isfinite(weight_decay) and weight_decay >= 0):
        raise ConfigError(f"weight_decay must be >= 0, got {weight_decay!r}")
    dt = check_data(task, data)
    names = fit_parameter_names(task)
    need = MIN_TRANSITIONS_NETWORK if network else MIN_TRANSITIONS_PER_PARAMETER * len(names)
    if data.num_steps < need:
        raise InsufficientDataError(
            f"{data.num_steps} recorded transitions are too few for a {model_type} model: at "
            f"least {need} are needed ({need * dt:g} s at this data's {dt:g} s step); record "
            "more episodes"
        )
    params = task.default_params() if params is None else params
    with float64():
        return _fit(
            task, data, model_type, network, params, names, window, steps, learning_rate, tuple(hidden),
            weight_decay, substeps, lm_steps, seed, dt,
        )  # fmt: skip


def _fit(
    task, data, model_type, network, params, names, window, steps, lr, hidden, weight_decay, substeps, lm_steps,
    seed, dt,
) -> FitResult:  # fmt: skip
    physics = _f64(nominal_model(task, jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)))
    nominal = physics.params
    batch = _windows(data, window)
    if batch is None:
        longest = max(len(e.actions) for e in data.episodes())
        raise InsufficientDataError(
            f"no episode has {window} steps to predict (the longest has {longest}); choose a "
            f"window of at most {longest} steps or record longer episodes"
        )
    model0 = _f64(
        initial_model(task, model_type, nominal, data, dt, hidden, jax.random.PRNGKey(seed))
    )
    if not network:
        where = lambda m: tuple(getattr(m.params, n) for n in names)  # noqa: E731
        theta0 = jnp.stack([jnp.asarray(v, jnp.float64) for v in where(model0)])
    else:
        where = lambda m: m.correction.net.layers  # noqa: E731
        theta0 = where(model0)
    inv_std = jnp.asarray(1 / np.maximum(np.std(data.observations, axis=0), 1e-6))

    def build(theta):
        if not network:
            return eqx.tree_at(where, model0, tuple(theta[i] for i in range(len(names))))
        return eqx.tree_at(where, model0, theta)

    def residuals(theta, batch):
        starts, forces, targets = batch
        m = build(theta)
        pred = jax.vmap(lambda s, f: predict(m, s, f, dt, substeps))(starts, forces)
        return (state_error(task, pred, targets) * inv_std).reshape(-1)

    def penalty(theta):
        if not network or weight_decay == 0:
            return 0.0
        leaves = [l.weight for l in theta]
        return weight_decay * sum(jnp.sum(w**2) for w in leaves) / sum(w.size for w in leaves)

    def loss(theta, batch):
        return jnp.mean(residuals(theta, batch) ** 2) + penalty(theta)

    if not network:
        optimiser = optax.adam(lr)
    else:
        optimiser = optax.adam(optax.cosine_decay_schedule(lr, max(steps, 1), alpha=0.05))
    nominal_loss = float(_nominal_loss(task, physics, batch, dt, substeps, inv_std))

    best, best_loss, history, diverged, message = adam_fit(
        loss, theta0, optimiser, steps, batch, "model"
    )
    if not network and lm_steps and not diverged:
        best, best_loss, _ = lm_refine(residuals, loss, best, best_loss, batch, lm_steps)
    model = build(best)
    values, errors = {}, {}
    if not network:
        se = standard_errors(lambda v: residuals(v, batch), best) * math.sqrt(window)
        values = dict(zip(names, np.asarray(best).tolist()))
        errors = dict(zip(names, np.asarray(se).tolist()))
    if not message:
        message = f"loss {best_loss:.3g} (frictionless physics: {nominal_loss:.3g})"
    return FitResult(
        model=model,
        model_type=model_type,
        params=model.params,
        names=() if network else names,
        values=values,
        nominal=dict.fromkeys(values, 0.0),
        standard_errors=errors,
        loss=best_loss,
        nominal_loss=nominal_loss,
        loss_history=np.asarray(history, np.float64),
        diverged=diverged,
        message=message,
        window=window,
        windows=int(batch[0].shape[0]),
        transitions=data.num_steps,
        dt_s=dt,
        substeps=substeps,
        num_parameters=model.correction.num_parameters if network else len(names),
    )


def _nominal_loss(task, nominal_model, batch, dt, substeps, inv_std):
    starts, actions, targets = batch
    pred = jax.vmap(lambda s, a: predict(nominal_model, s, a, dt, substeps))(starts, actions)
    return jnp.mean((state_error(task, pred, targets) * inv_std) ** 2)


def prediction_errors(
    task: Any,
    model: Any,
    data: TrajectoryData,
    horizons: Sequence[int] = HORIZONS,
    substeps: int = 2,
) -> dict[int, dict[str, Any]]:
    """Open-loop prediction error ``horizon`` intervals ahead, from every recorded state of
    every episode with the recorded actions, against the recorded state.

    Returns:
        Per horizon: ``rmse`` (root mean square over starts and the state columns, in their
        units), ``rmse_by_column`` and ``starts`` (0 and NaN where no episode is long enough).
    """
    dt = check_data(task, data)
    names = [parse_column(c)[1] for c in data_columns(task)[0]]
    out = {}
    with float64():
        m = _f64(model)
        run = jax.jit(jax.vmap(lambda s, a: predict(m, s, a, dt, substeps)[-1]))
        for h in horizons:
            batch = _windows(data, h)
            if batch is None:
                out[h] = {
                    "rmse": math.nan,
                    "rmse_by_column": dict.fromkeys(names, math.nan),
                    "starts": 0,
                }
                continue
            err = np.asarray(state_error(task, run(batch[0], batch[1]), batch[2][:, -1]))
            out[h] = {
                "rmse": float(np.sqrt(np.mean(err**2))),
                "rmse_by_column": dict(zip(names, np.sqrt(np.mean(err**2, axis=0)).tolist())),
                "starts": int(err.shape[0]),
            }
    return out
