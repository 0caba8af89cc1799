"""Fitting continuous-time models (the swing-up cart-pole) to recorded state trajectories.

The data: episodes of the full mechanical state ``(x, x_dot, theta, theta_dot)`` sampled every
``dt_s`` seconds, and the force held constant over each interval (a zero-order hold), in the
``diffcontrol-trajectories`` format with the columns ``STATE_COLUMNS`` and
``ACTION_COLUMNS``. ``record_swingup`` makes such data from a simulated "real" system.

The models (``diffcontrol.tasks.fitted_swingup.SwingUpModel``): ``params`` (grey box, the
four friction coefficients of the known physics), ``hybrid`` (the frictionless physics plus a
network giving the missing generalised forces from the velocities) and ``neural`` (a network
giving the accelerations, no physics). They are fitted by **multiple shooting**: from every
recorded state of every episode, the model's ODE is solved ``window`` intervals ahead with the
recorded forces (``substeps`` fixed RK4 steps per interval, so the solve is the same
differentiable program for every window), and the loss is the mean squared difference
between the predicted and the recorded states, each state column divided by its standard
deviation in the data (so metres and radians per second weigh alike), plus
``weight_decay`` times the mean squared network weight. Adam (optax) on all windows at once,
in float64; the grey box is refined by Levenberg-Marquardt and gets standard errors from the
curvature (``diffcontrol.fitting``'s method).

Divergence is handled as in ``diffcontrol.fitting``: the best weights seen are kept, a
non-finite loss stops the fit with ``diverged=True`` and a message, and no NaN is returned.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from .data import TrajectoryData, parse_column
from .errors import ConfigError, DataFileError, InsufficientDataError
from .fitting import HORIZONS, MIN_TRANSITIONS_PER_PARAMETER, _standard_errors, adam_fit
from .models import Correction
from .systems import cartpole_swingup as cp
from .tasks.fitted_swingup import (  # noqa: F401  (model_to_dict/from_dict: re-exported)
    FRICTION_NAMES,
    SwingUpModel,
    frictionless,
    model_from_dict,
    model_to_dict,
)

STATE_COLUMNS = ("state.x [m]", "state.x_dot [m/s]", "state.theta [rad]", "state.theta_dot [rad/s]")
"""The recorded state of the swing-up cart-pole (theta = 0 upright, not wrapped)."""
ACTION_COLUMNS = ("action.force [N]",)
"""The recorded force on the cart, held over each interval."""
MIN_TRANSITIONS_NETWORK = 250
"""The fewest recorded transitions a hybrid or neural fit accepts (5 s of data at 50 Hz)."""
FIT_KINDS = ("params", "hybrid", "neural")


# --- data ------------------------------------------------------------------------------------


def _hold_solve(model: SwingUpModel, state, force, dt, substeps: int):
    """The model's state ``dt`` seconds after ``state`` under the constant ``force``:
    ``substeps`` classical Runge-Kutta (RK4) steps.

    Plain JAX rather than ``diffrax.diffeqsolve``: with a fixed step there is nothing to adapt,
    and Diffrax's step loop (checkpointed ``while_loop``s, also over the stages of one step)
    made the fit about 10x slower under ``vmap`` over thousands of windows and cannot be
    differentiated in forward mode, which the Levenberg-Marquardt refinement and the standard
    errors use. The recorded "real" data is solved adaptively by Diffrax.
    """
    h = dt / substeps

    def f(y):
        x_acc, theta_acc, _ = model.accelerations(y, force)
        return jnp.stack([y[1], x_acc, y[3], theta_acc])

    y = state
    for _ in range(substeps):
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def predict(model: SwingUpModel, state, forces, dt, substeps: int = 2):
    """Open loop: the states [len(forces), 4] after each held force of ``forces`` [T] from
    ``state`` [4], every ``dt`` seconds."""

    def body(s, f):
        s = _hold_solve(model, s, f, dt, substeps)
        return s, s

    return jax.lax.scan(body, state, forces)[1]


def record_swingup(
    params: cp.SwingUpParams,
    episodes: int,
    *,
    seed: int = 0,
    dt_s: float = 0.02,
    duration_s: float = 5.0,
    force_max: float = 40.0,
    hold_s: float = 0.2,
) -> TrajectoryData:
    """Record ``episodes`` episodes of the swing-up cart-pole with ``params`` (the "real"
    system) under exploratory forces.

    Each episode starts at rest at ``x = 0`` with the pole at a uniformly random angle. The
    force is a random level in ``[-force_max, force_max]`` (N), redrawn every ``hold_s``
    seconds, minus a weak centring feedback ``5 x + 2 x_dot`` that keeps the cart from running
    away, clipped to ``+-force_max`` and held over each ``dt_s`` interval. This swings the
    pole through whole turns at the speeds of a swing-up (|x_dot| up to about 5 m/s,
    |theta_dot| up to about 10 rad/s), so friction is excited where the controller will meet
    it. Solved with Tsit5 at rtol 1e-9 / atol 1e-9 in float64.

    Returns:
        ``TrajectoryData`` with ``STATE_COLUMNS`` and ``ACTION_COLUMNS``, time in seconds,
        metadata ``system``, ``params``, ``dt_s``, ``seed`` and ``source``.
    """
    if not isinstance(episodes, int) or episodes < 1:
        raise ConfigError(f"episodes must be a positive integer, got {episodes!r}")
    for name, value in (
        ("dt_s", dt_s),
        ("duration_s", duration_s),
        ("force_max", force_max),
        ("hold_s", hold_s),
    ):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"{name} must be a positive number, got {value!r}")
    steps = int(round(duration_s / dt_s))
    hold = max(1, int(round(hold_s / dt_s)))
    with jax.enable_x64(True):
        p = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)
        model = SwingUpModel("params", p)

        def advance(y, f):
            term = diffrax.ODETerm(lambda t, y, f: model.vector_field(t, y, lambda t, s: f)[:4])
            sol = diffrax.diffeqsolve(
                term,
                diffrax.Tsit5(),
                0.0,
                dt_s,
                None,
                y,
                args=f,
                stepsize_controller=diffrax.PIDController(rtol=1e-9, atol=1e-9),
                max_steps=10_000,
            )
            return sol.ys[-1]

        @jax.jit
        def episode(key):
            k0, k1 = jax.random.split(key)
            theta0 = jax.random.uniform(k0, (), minval=-jnp.pi, maxval=jnp.pi)
            levels = jax.random.uniform(k1, (steps // hold + 1,), minval=-1.0, maxval=1.0)
            drive = force_max * jnp.repeat(levels, hold)[:steps]

            def body(y, d):
                f = jnp.clip(d - 5.0 * y[0] - 2.0 * y[1], -force_max, force_max)
                return advance(y, f), (y, f)

            y0 = jnp.array([0.0, 0.0, theta0, 0.0])
            last, (ys, fs) = jax.lax.scan(body, y0, drive)
            return jnp.concatenate([ys, last[None]]), fs

        keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
        runs = [episode(k) for k in keys]
    names = [f.name for f in dataclasses.fields(params)]
    return TrajectoryData.from_episodes(
        [np.asarray(ys) for ys, _ in runs],
        [np.asarray(fs)[:, None] for _, fs in runs],
        STATE_COLUMNS,
        ACTION_COLUMNS,
        dt_s=dt_s,
        metadata={
            "system": "cartpole-swingup",
            "params": {n: float(np.asarray(getattr(params, n))) for n in names},
            "seed": seed,
            "source": f"random force levels in +-{force_max} N held {hold_s} s, minus "
            "5 x + 2 x_dot",
        },
    )


def check_data(data: TrajectoryData) -> float:
    """Refuse data that is not swing-up state data at a fixed time step; returns ``dt_s``.

    Raises:
        DataFileError: other columns (names or units), time not in seconds, no fixed step.
    """
    where = data.metadata.get("system") or data.metadata.get("env_id") or "the data"
    got = [parse_column(c) for c in (*data.observation_columns, *data.action_columns)]
    want = [parse_column(c) for c in (*STATE_COLUMNS, *ACTION_COLUMNS)]
    if got != want:
        raise DataFileError(
            f"{where} has the columns {list(data.columns[2:])}, but the swing-up models are "
            f"fitted to the full state {[*STATE_COLUMNS, *ACTION_COLUMNS]}; record the state "
            "(diffcontrol.ode_fitting.record_swingup, or `diffcontrol record-swingup`)"
        )
    if parse_column(data.columns[0])[2] != "s":
        raise DataFileError(f"{where}: time is in steps; the ODE models need time in seconds")
    steps = np.diff(data.time)[data.episode[1:] == data.episode[:-1]]
    dt = float(np.median(steps))
    if not np.allclose(steps, dt, rtol=1e-6, atol=0.0):
        raise DataFileError(
            f"{where}: the time steps vary from {steps.min()!r} to {steps.max()!r} s; record "
            "at a fixed time step (the force is held over each step)"
        )
    return dt


def _windows(data: TrajectoryData, window: int):
    """Every start with ``window`` recorded intervals after it: start states [N, 4], forces
    [N, window] and recorded states [N, window, 4], as float64 arrays (``None`` if none)."""
    starts, forces, targets = [], [], []
    for ep in data.episodes():
        n = len(ep.actions)
        for t in range(n - window + 1):
            starts.append(ep.observations[t])
            forces.append(ep.actions[t : t + window, 0])
            targets.append(ep.observations[t + 1 : t + window + 1])
    if not starts:
        return None
    return tuple(jnp.asarray(np.stack(a), jnp.float64) for a in (starts, forces, targets))


def _state_error(pred, target):
    """Predicted minus recorded state, the angle difference wrapped to ``[-pi, pi)``."""
    err = pred - target
    return err.at[..., 2].set(cp.wrap_angle(err[..., 2]))


# --- fitting ---------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class ODEFitResult:
    """The outcome of ``fit_swingup_model``.

    Attributes:
        model: the fitted ``SwingUpModel`` (float64).
        kind: ``params``, ``hybrid`` or ``neural``.
        values, standard_errors: the grey box's friction coefficients (empty otherwise).
        loss: the fit's loss at the returned model (normalised squared error plus the weight
            penalty); ``nominal_loss``: the frictionless physics' on the same windows.
        loss_history: the loss before each Adam step taken.
        diverged, message: as ``diffcontrol.fitting.FitResult``.
        window, windows, transitions, dt_s, substeps: what the fit used.
        num_parameters: fitted numbers (network weights, or 4).
    """

    model: SwingUpModel
    kind: str
    values: dict[str, float]
    standard_errors: dict[str, float]
    loss: float
    nominal_loss: float
    loss_history: np.ndarray
    diverged: bool
    message: str
    window: int
    windows: int
    transitions: int
    dt_s: float
    substeps: int
    num_parameters: int


def nominal_model(params: cp.SwingUpParams) -> SwingUpModel:
    """The frictionless physics with ``params``' masses, length and gravity."""
    return SwingUpModel("nominal", frictionless(params))


def _initial_model(kind, nominal, data, dt, hidden, key) -> SwingUpModel:
    """The model before fitting: zero friction, or a network with a zero last layer whose
    input and output scalings come from the data (inputs of order 1; an output of 1 is a
    force that changes a speed by one standard deviation per second, or for ``neural`` one
    standard deviation of the recorded accelerations)."""
    if kind == "params":
        return SwingUpModel("params", nominal)
    y = data.observations
    std = np.maximum(np.std(y, axis=0), 1e-6)
    p = nominal
    if kind == "hybrid":
        out = [float(p.cart_mass + p.pole_mass) * std[1], float(p.pole_mass * p.length**2) * std[3]]
        net = Correction(key, 2, 2, hidden, in_scale=1 / std[[1, 3]], out_scale=out)
    else:
        acc = []
        for ep in data.episodes():
            acc.append(np.diff(ep.observations[:, [1, 3]], axis=0) / dt)
        acc_std = np.maximum(np.std(np.concatenate(acc), axis=0), 1e-6)
        f_std = max(float(np.std(data.actions[np.isfinite(data.actions)])), 1e-6)
        in_scale = [1 / std[1], 1.0, 1.0, 1 / std[3], 1 / f_std]
        net = Correction(key, 5, 2, hidden, in_scale=in_scale, out_scale=acc_std, zero_output=False)
    net = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64) if eqx.is_inexact_array(a) else a, net)
    return SwingUpModel(kind, nominal, net)


def _trainable(model: SwingUpModel):
    """What the fit changes: the friction coefficients, or the network's layers."""
    if model.kind == "params":
        return lambda m: tuple(getattr(m.params, n) for n in FRICTION_NAMES)
    return lambda m: m.correction.net.layers


def fit_swingup_model(
    data: TrajectoryData,
    kind: str = "hybrid",
    params: cp.SwingUpParams | None = None,
    *,
    window: int = 10,
    steps: int = 1000,
    learning_rate: float = 3e-3,
    hidden: Sequence[int] = (32, 32),
    weight_decay: float = 1e-5,
    substeps: int = 2,
    lm_steps: int = 20,
    seed: int = 0,
) -> ODEFitResult:
    """Fit a swing-up model of ``kind`` to recorded state trajectories (module docstring).

    Args:
        data: episodes with ``STATE_COLUMNS`` and ``ACTION_COLUMNS`` at a fixed step.
        kind: ``params`` (the friction coefficients), ``hybrid`` or ``neural``.
        params: the known physics (default ``SwingUpParams()``); its friction is ignored
            (the nominal model is frictionless).
        window: intervals predicted from every recorded state (>= 1).
        steps: Adam steps (>= 0) at ``learning_rate`` (cosine-decayed to 5 % for networks;
            for ``params`` in N s/m, N, N m s/rad and N m per step).
        hidden: the network's hidden widths.
        weight_decay: weight of the mean squared network weight in the loss.
        substeps: fixed RK4 steps per recorded interval.
        lm_steps: Levenberg-Marquardt steps after Adam (``params`` only).
        seed: the network's initial weights.

    Raises:
        ConfigError: an unknown ``kind`` or a bad setting (named).
        DataFileError: data that is not the swing-up's state (``check_data``).
        InsufficientDataError: too few transitions (says how many are needed) or no
            episode longer than ``window``.
    """
    if kind not in FIT_KINDS:
        raise ConfigError(f"unknown model kind {kind!r}; choose one of {', '.join(FIT_KINDS)}")
    for name, value in (("window", window), ("substeps", substeps)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ConfigError(f"{name} must be a positive integer, got {value!r}")
    if not isinstance(steps, int) or steps < 0 or not isinstance(lm_steps, int) or lm_steps < 0:
        raise ConfigError(f"steps and lm_steps must be integers >= 0, got {steps!r}, {lm_steps!r}")
    if not (math.isfinite(learning_rate) and learning_rate > 0):
        raise ConfigError(f"learning_rate must be a positive number, got {learning_rate!r}")
    if not (math.isfinite(weight_decay) and weight_decay >= 0):
        raise ConfigError(f"weight_decay must be >= 0, got {weight_decay!r}")
    dt = check_data(data)
    need = (
        MIN_TRANSITIONS_PER_PARAMETER * len(FRICTION_NAMES)
        if kind == "params"
        else MIN_TRANSITIONS_NETWORK
    )
    if data.num_steps < need:
        raise InsufficientDataError(
            f"{data.num_steps} recorded transitions are too few for a {kind} model: at least "
            f"{need} are needed ({need * dt:g} s at this data's {dt:g} s step); record more "
            "episodes"
        )
    with jax.enable_x64(True):
        return _fit(
            data,
            kind,
            params or cp.SwingUpParams(),
            window,
            steps,
            learning_rate,
            tuple(hidden),
            weight_decay,
            substeps,
            lm_steps,
            seed,
            dt,
        )


def _fit(
    data, kind, params, window, steps, lr, hidden, weight_decay, substeps, lm_steps, seed, dt
) -> ODEFitResult:
    nominal = frictionless(jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params))
    batch = _windows(data, window)
    if batch is None:
        longest = max(len(e.actions) for e in data.episodes())
        raise InsufficientDataError(
            f"no episode has {window} steps to predict (the longest has {longest}); choose a "
            f"window of at most {longest} steps or record longer episodes"
        )
    model0 = _initial_model(kind, nominal, data, dt, hidden, jax.random.PRNGKey(seed))
    where = _trainable(model0)
    inv_std = jnp.asarray(1 / np.maximum(np.std(data.observations, axis=0), 1e-6))
    # the grey box starts frictionless; a network at its initial weights
    theta0 = jnp.zeros(len(FRICTION_NAMES)) if kind == "params" else where(model0)

    def build(theta):
        if kind == "params":
            return eqx.tree_at(where, model0, tuple(theta[i] for i in range(len(FRICTION_NAMES))))
        return eqx.tree_at(where, model0, theta)

    def residuals(theta, batch):
        starts, forces, targets = batch
        m = build(theta)
        pred = jax.vmap(lambda s, f: predict(m, s, f, dt, substeps))(starts, forces)
        return (_state_error(pred, targets) * inv_std).reshape(-1)

    def penalty(theta):
        if kind == "params" or weight_decay == 0:
            return 0.0
        leaves = [l.weight for l in theta]
        return weight_decay * sum(jnp.sum(w**2) for w in leaves) / sum(w.size for w in leaves)

    def loss(theta, batch):
        return jnp.mean(residuals(theta, batch) ** 2) + penalty(theta)

    if kind == "params":
        optimiser = optax.adam(lr)
    else:
        optimiser = optax.adam(optax.cosine_decay_schedule(lr, max(steps, 1), alpha=0.05))
    nominal_loss = float(_nominal_loss(nominal, batch, dt, substeps, inv_std))

    best, best_loss, history, diverged, message = adam_fit(
        loss, theta0, optimiser, steps, batch, "model"
    )
    if kind == "params" and lm_steps and not diverged:
        sol = optx.least_squares(
            residuals,
            optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12),
            best,
            args=batch,
            max_steps=lm_steps,
            throw=False,
        )
        lm_loss = float(loss(sol.value, batch))
        if math.isfinite(lm_loss) and lm_loss < best_loss:
            best, best_loss = sol.value, lm_loss
    model = build(best)
    values, errors = {}, {}
    if kind == "params":
        se = _standard_errors(lambda v: residuals(v, batch), best) * math.sqrt(window)
        values = dict(zip(FRICTION_NAMES, np.asarray(best).tolist()))
        errors = dict(zip(FRICTION_NAMES, np.asarray(se).tolist()))
    if not message:
        message = f"loss {best_loss:.3g} (frictionless physics: {nominal_loss:.3g})"
    return ODEFitResult(
        model=model,
        kind=kind,
        values=values,
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
        num_parameters=4 if kind == "params" else model.correction.num_parameters,
    )


def _nominal_loss(nominal, batch, dt, substeps, inv_std):
    starts, forces, targets = batch
    m = SwingUpModel("nominal", nominal)
    pred = jax.vmap(lambda s, f: predict(m, s, f, dt, substeps))(starts, forces)
    return jnp.mean((_state_error(pred, targets) * inv_std) ** 2)


# --- evaluation ------------------------------------------------------------------------------


def prediction_errors(
    model: SwingUpModel,
    data: TrajectoryData,
    horizons: Sequence[int] = HORIZONS,
    substeps: int = 2,
) -> dict[int, dict[str, Any]]:
    """Open-loop prediction error ``horizon`` intervals ahead, from every recorded state of
    every episode with the recorded forces, against the recorded state.

    Returns:
        Per horizon: ``rmse`` (root mean square over starts and the four state columns, in
        their units), ``rmse_by_column`` and ``starts`` (0 and NaN where no episode is long
        enough).
    """
    dt = check_data(data)
    names = [parse_column(c)[1] for c in STATE_COLUMNS]
    out = {}
    with jax.enable_x64(True):
        m = jax.tree.map(
            lambda a: jnp.asarray(a, jnp.float64) if eqx.is_inexact_array(a) else a, model
        )
        run = jax.jit(jax.vmap(lambda s, f: predict(m, s, f, dt, substeps)[-1]))
        for h in horizons:
            batch = _windows(data, h)
            if batch is None:
                out[h] = {
                    "rmse": math.nan,
                    "rmse_by_column": dict.fromkeys(names, math.nan),
                    "starts": 0,
                }
                continue
            err = np.asarray(_state_error(run(batch[0], batch[1]), batch[2][:, -1]))
            out[h] = {
                "rmse": float(np.sqrt(np.mean(err**2))),
                "rmse_by_column": dict(zip(names, np.sqrt(np.mean(err**2, axis=0)).tolist())),
                "starts": int(err.shape[0]),
            }
    return out
