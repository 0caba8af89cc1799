"""Discrete-time grey box: a task's physical parameters from recorded trajectories.

The model is the task's own simulator (``task.step``) with some of its parameters unknown.
They are fitted by differentiating the simulator through **short windows** (multiple
shooting): from every recorded observation ``y_t`` of an episode (turned into a state by
``state_from_observation``; for the Pendulum ``theta = atan2(sin, cos)``), the model is
stepped ``window`` times with the recorded actions ``u_t .. u_{t+window-1}``, and the loss is
the mean squared difference between the predicted and the recorded observations
``y_{t+1} .. y_{t+window}``, over every start of every episode. Short windows keep the
gradient informative where a long open-loop rollout of a chaotic system would not.

The optimiser is Adam (optax) on unconstrained coordinates ``z`` (``value = exp(z)`` for a
parameter whose nominal value is positive, so it stays positive; ``value = z`` for one whose
nominal value is 0, such as the Pendulum's ``friction``), then ``lm_steps`` Levenberg-Marquardt
steps (optimistix) on the residuals. Everything runs in float64.

**Uncertainty** from the curvature at the fit (Gauss-Newton): with ``r`` the ``R`` residuals and
``J = dr/dθ`` their Jacobian with respect to the ``p`` physical parameters,
``cov = sigma^2 (J^T J)^-1`` with ``sigma^2 = r^T r / (R - p)``, and the standard errors are
``sqrt(diag(cov))``. The overlapping windows reuse every recorded point up to ``window`` times
and carry the noise of their start state through the whole window, so the residuals are not
independent and this textbook formula is too narrow; the covariance is therefore multiplied by
``window`` (each recorded point counted once). The standard errors do not include the small
bias that sensor noise in the start states causes (errors in variables). Parameters that
the data cannot tell apart give a singular ``J^T J`` and the standard error ``inf`` (for the
Pendulum, g, m and l enter only as ``g / l`` and ``1 / (m l^2)``: fit at most two of them).

**Divergence** is reported, not hidden: the best parameters seen so far are kept, a
non-finite loss stops the fit with ``diverged=True`` and a message, and no NaN is returned.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .. import _gym
from .._jax_setup import float64
from .._shell import command
from ..errors import ConfigError, DataFileError, InsufficientDataError
from ._shooting import (
    HORIZONS,
    MIN_TRANSITIONS_PER_PARAMETER,
    FitResult,
    adam_fit,
    check_settings,
    lm_refine,
    set_params,
    standard_errors,
)
from ._task import data_columns, fit_parameter_names
from .data import TrajectoryData, parse_column


def parameter_names(task: Any) -> tuple[str, ...]:
    """The names of the task's physical parameters (the fields of ``task.default_params()``)."""
    return tuple(f.name for f in dataclasses.fields(task.default_params()))


def check_data(task: Any, data: TrajectoryData) -> None:
    """Refuse data that is not from the task's system: other columns (names or units), another
    time step, or a task that cannot reconstruct states from observations.

    Raises:
        DataFileError: the data's columns or time step do not fit the task (naming both).
        ConfigError: the task cannot be fitted to recorded observations.
    """
    where = data.metadata.get("env_id") or "the data"
    if not _gym.knows_state(task):
        raise ConfigError(
            f"task {task.name!r} cannot be fitted to recorded data yet (it does not reconstruct "
            "its state from observations: define its state_from_observation); fit the pendulum"
        )
    expected = data_columns(task)
    want = [parse_column(c) for c in (*expected[0], *expected[1])]
    got = [parse_column(c) for c in (*data.observation_columns, *data.action_columns)]
    if got != want:
        system = task.gym_id or task.name
        raise DataFileError(
            f"{where} has the columns {list(data.columns[2:])}, but task {task.name!r} "
            f"({system}) needs {[*expected[0], *expected[1]]}; record the task's system "
            f"(`{command('record', system)}`) or fit the task the data is from"
        )
    dt = data.metadata.get("dt_s")
    model_dt = getattr(task.default_params(), "dt", None)
    if isinstance(dt, int | float) and model_dt is not None and not math.isclose(dt, model_dt):
        raise DataFileError(
            f"{where} was recorded every {dt} s but task {task.name!r} steps {model_dt} s; "
            "record at the task's time step"
        )
    check_within_spaces(task, data, where)


OBSERVATION_SLACK = 0.1
"""How far outside its space a recorded observation may lie, as a share of the space's span
on that axis: measured data carries sensor noise (0.01 on a pendulum's cos and sin is 0.5 % of
their span)."""


def check_within_spaces(task: Any, data: TrajectoryData, where: str) -> None:
    """Refuse observations outside the task's observation space (its Gymnasium twin's, where
    it has one) by more than sensor noise could explain (``OBSERVATION_SLACK`` of the space's
    span), and actions outside its action space (an index a ``Discrete`` space does not have):
    values the system cannot produce, which would fit a model to something else. Names the
    first such row.

    Raises:
        DataFileError: the first value out of its space, with its row, column and bounds.
    """
    from gymnasium import spaces

    observation_space = _gym.observation_space(task)
    if task.gym_id and ":" not in task.gym_id:  # a Gymnasium twin: its bounds are the system's
        twin = _gym.make_gym_env(task)
        observation_space = twin.observation_space
        twin.close()
    tables = (
        (data.observations, observation_space, data.observation_columns, "observation"),
        (data.actions, _gym.action_space(task), data.action_columns, "action"),
    )
    for (values, space, columns, what), share in zip(tables, (OBSERVATION_SLACK, 0.0), strict=True):
        if isinstance(space, spaces.Discrete):
            low, high = (
                np.full(values.shape[1], space.start),
                np.full(values.shape[1], space.start + space.n - 1),
            )
            whole = np.isnan(values) | (values == np.round(values))
        elif isinstance(space, spaces.Box):
            low, high = (np.broadcast_to(np.asarray(b, np.float64).reshape(-1), values.shape[1:])
                         for b in (space.low, space.high))  # fmt: skip
            whole = np.ones(values.shape, bool)
        else:
            continue
        span = np.where(np.isfinite(high - low), high - low, 0.0)
        slack = share * span + 1e-6 * (1.0 + np.abs(np.where(np.isfinite(high), high, 0.0)))
        bad = ~whole | (values < low - slack) | (values > high + slack)
        bad &= ~np.isnan(values)  # an episode's last row has no action
        if bad.any():
            row, col = (int(i) for i in np.argwhere(bad)[0])
            raise DataFileError(
                f"{where}: data row {row + 1} has {columns[col]} = {values[row, col]:.6g}, which "
                f"task {task.name!r}'s {what}s never take (its {what} space: {space}); the data "
                "is not from this system (or damaged): check the file, or record it again"
            )


def task_actions(task: Any, actions: np.ndarray) -> np.ndarray:
    """Recorded actions [T, m] as the task's own action vectors: a Gymnasium ``Discrete``
    index becomes what the task's step takes (``action_from_gym``: the push ``±1`` of a
    sign head, the one-hot choice of an argmax head); other actions are kept as recorded."""
    from gymnasium import spaces

    if not isinstance(_gym.action_space(task), spaces.Discrete):
        return actions
    vectors = [_gym.action_from_gym(task, int(a[0])) for a in np.asarray(actions)]
    return np.stack(vectors) if vectors else np.zeros((0, task.action_size))


class Windows(NamedTuple):
    """Every start of every episode with ``window`` recorded steps after it, padded to
    ``padded_size`` rows so that data sets of about the same size share one compiled program:
    the start states [N, n], actions [N, window, m] (the task's own action vectors), recorded
    observations [N, window, k], and ``mask`` [N] (1 for a recorded window, 0 for a padding row,
    which repeats the first window)."""

    states: jax.Array
    actions: jax.Array
    targets: jax.Array
    mask: jax.Array

    @property
    def count(self) -> int:
        """The number of recorded (not padding) windows."""
        return int(np.sum(np.asarray(self.mask)))


PAD_ROWS = 256
"""The windows of a fit are padded to a multiple of this many rows (or of a quarter of the
octave their number lies in, where that is larger)."""


def padded_size(n: int) -> int:
    """``n`` rounded up to a multiple of ``PAD_ROWS`` (256), or above 2,048 of a quarter of its
    octave (2,560, 3,072, ..., 5,120, 6,144, ...): at most 255 rows or a quarter more of work,
    and one compiled fit for the data sets of a round's step budget (a CartPole round of 250
    real steps gives 115 to 169 windows of 10 steps, all padded to 256)."""
    step = max(PAD_ROWS, 2 ** ((max(n, 1) - 1).bit_length() - 3))
    return -(-n // step) * step


def _windows(task, data: TrajectoryData, window: int) -> Windows | None:
    """The data's ``Windows`` of ``window`` steps (None if no episode is that long)."""
    starts, actions, targets = [], [], []
    for ep in data.episodes():
        n = len(ep.actions)
        acts = task_actions(task, ep.actions)
        for t in range(n - window + 1):
            starts.append(ep.observations[t])
            actions.append(acts[t : t + window])
            targets.append(ep.observations[t + 1 : t + window + 1])
    if not starts:
        return None
    count = len(starts)
    extra = padded_size(count) - count  # padding rows: copies of the first window
    obs0, acts, outs = (np.stack([*x, *[x[0]] * extra]) for x in (starts, actions, targets))
    mask = np.concatenate([np.ones(count), np.zeros(extra)])
    states = jax.vmap(_gym.state_from_observation.bound(task))(jnp.asarray(obs0))
    return Windows(states, jnp.asarray(acts), jnp.asarray(outs), jnp.asarray(mask))


def masked_mean(values: jax.Array, mask: jax.Array) -> jax.Array:
    """The mean of ``values`` [N, ...] over the rows where ``mask`` [N] is 1 (a window's
    padding rows count for nothing)."""
    keep = mask.reshape(mask.shape + (1,) * (values.ndim - 1)) > 0
    size = jnp.sum(mask) * (values.size // values.shape[0])
    return jnp.sum(jnp.where(keep, values, 0.0)) / size


def predict(task: Any, params: Any, state: jax.Array, actions: jax.Array) -> jax.Array:
    """Open-loop prediction: the observations [len(actions), k] after each of ``actions``
    [T, m], stepping the task's simulator with ``params`` from ``state``."""

    def body(s, a):
        s_next = task.step(params, s, a)[0]
        return s_next, task.observe(s_next)

    return jax.lax.scan(body, state, actions)[1]


def fit_parameters(
    task: Any,
    data: TrajectoryData,
    names: Sequence[str] | None = None,
    *,
    window: int = 10,
    steps: int = 300,
    learning_rate: float = 0.02,
    lm_steps: int = 20,
    init: dict[str, float] | None = None,
) -> FitResult:
    """Fit the parameters ``names`` of ``task`` to the recorded ``data`` (module docstring).

    Args:
        task: a discrete-time task whose ``state_from_observation`` is implemented.
        data: recorded episodes of the task's system (its observation and action columns).
        names: the parameters to fit, fields of ``task.default_params()`` (default: the
            task's ``fit_parameter_names``); the others keep their nominal values.
        window: steps predicted from every recorded state (>= 1).
        steps: Adam steps (>= 0) at ``learning_rate`` (in the unconstrained coordinates:
            0.02 is about 2 % of a positive parameter's value per step).
        lm_steps: Levenberg-Marquardt steps after Adam (0: none); kept only if they lower the
            loss.
        init: starting values by name (default: the nominal ones).

    Returns:
        A ``FitResult``: fitted parameters with standard errors, the loss history, whether the
        fit diverged.

    Raises:
        ConfigError: an unknown or repeated name (the message lists the task's parameters), a
            bad ``window``/``steps``/``learning_rate``, or a task that cannot be fitted.
        DataFileError: data from another system (columns or time step).
        InsufficientDataError: fewer than ``MIN_TRANSITIONS_PER_PARAMETER`` transitions per
            fitted parameter, or no episode longer than ``window``.
    """
    names = tuple(names or fit_parameter_names(task))
    known = parameter_names(task)
    bad = [n for n in names if n not in known]
    if bad or not names or len(set(names)) != len(names):
        what = f"unknown parameter(s) {bad}" if bad else f"parameter names {list(names)}"
        raise ConfigError(
            f"{what} for task {task.name!r}; choose distinct names among {list(known)}"
        )
    check_settings(window, steps, learning_rate, lm_steps)
    check_data(task, data)
    need = MIN_TRANSITIONS_PER_PARAMETER * len(names)
    if data.num_steps < need:
        raise InsufficientDataError(
            f"{data.num_steps} recorded transitions are too few to fit {len(names)} "
            f"parameter(s) {list(names)}: at least {need} are needed "
            f"({MIN_TRANSITIONS_PER_PARAMETER} per parameter); record more episodes"
        )
    with float64():
        return _fit(task, data, names, window, steps, learning_rate, lm_steps, init or {})


def _fit(task, data, names, window, steps, learning_rate, lm_steps, init) -> FitResult:
    nominal_params = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), task.default_params())
    nominal = {n: float(getattr(nominal_params, n)) for n in names}
    batch = _windows(task, data, window)
    if batch is None:
        longest = max(len(e.actions) for e in data.episodes())
        raise InsufficientDataError(
            f"no episode has {window} steps to predict (the longest has {longest}); "
            f"choose a window of at most {longest} steps or record longer episodes"
        )
    positive = jnp.array([nominal[n] > 0 for n in names])
    start = jnp.array([float(init.get(n, nominal[n])) for n in names])
    if bool(jnp.any(positive & (start <= 0))):
        raise ConfigError(f"initial values {dict(zip(names, start.tolist()))} must be positive")

    def to_values(z):
        return jnp.where(positive, jnp.exp(z), z)

    def to_z(values):
        return jnp.where(positive, jnp.log(jnp.where(positive, values, 1.0)), values)

    def residuals(values, batch):  # [N, window, k]; zero on the padding rows
        params = set_params(nominal_params, names, values)
        pred = jax.vmap(predict, in_axes=(None, None, 0, 0))(
            task, params, batch.states, batch.actions
        )
        keep = batch.mask[:, None, None] > 0
        return jnp.where(keep, pred - batch.targets, 0.0)

    def loss(z, batch):
        return masked_mean(residuals(to_values(z), batch) ** 2, batch.mask)

    def flat_residuals(z, batch):
        return residuals(to_values(z), batch).reshape(-1)

    optimiser = optax.adam(learning_rate)
    z = to_z(start)
    nominal_loss = float(jax.jit(loss)(to_z(jnp.array([nominal[n] for n in names])), batch))
    best_z, best_loss, history, diverged, message = adam_fit(
        loss, z, optimiser, steps, batch, "parameters"
    )
    if lm_steps and not diverged:
        best_z, best_loss, lm_loss = lm_refine(
            flat_residuals, loss, best_z, best_loss, batch, lm_steps
        )
        if not math.isfinite(lm_loss):
            message = "the Levenberg-Marquardt refinement diverged; kept the Adam fit"
        history.append(lm_loss if math.isfinite(lm_loss) else math.nan)
    values = to_values(best_z)
    # * sqrt(window): the overlapping windows count each recorded point `window` times
    size = batch.count * window * batch.targets.shape[-1]  # the recorded residuals
    errors = standard_errors(
        lambda v, b: residuals(v, b).reshape(-1), values, batch, size=size
    ) * math.sqrt(window)
    fitted = set_params(nominal_params, names, values)
    if not message:
        message = (
            f"mean squared window error {best_loss:.3g} (nominal parameters: {nominal_loss:.3g})"
        )
    return FitResult(
        model=fitted,
        model_type="params",
        params=fitted,
        num_parameters=len(names),
        names=names,
        values=dict(zip(names, np.asarray(values).tolist())),
        nominal=nominal,
        standard_errors=dict(zip(names, np.asarray(errors).tolist())),
        loss=best_loss,
        nominal_loss=nominal_loss,
        loss_history=np.asarray(history, np.float64),
        diverged=diverged,
        message=message,
        window=window,
        windows=batch.count,
        transitions=data.num_steps,
    )


def prediction_errors(
    task: Any, params: Any, data: TrajectoryData, horizons: Sequence[int] = HORIZONS
) -> dict[int, dict[str, Any]]:
    """Open-loop prediction error ``horizon`` steps ahead, from every recorded state of every
    episode with the recorded actions, against the recorded observation.

    Returns:
        Per horizon: ``rmse`` (root mean square over starts and observation columns, in the
        observations' units), ``rmse_by_column`` (per observation column) and ``starts`` (how
        many predictions; 0 and ``rmse`` NaN where no episode is that long).
    """
    out = {}
    with float64():
        params = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)
        # the parameters are an argument: one program for every model of the same shape
        run = jax.jit(jax.vmap(lambda p, s, a: predict(task, p, s, a)[-1], (None, 0, 0)))
        columns = [parse_column(c)[1] for c in data.observation_columns]
        for h in horizons:
            batch = _windows(task, data, h)
            if batch is None:
                nan = {c: math.nan for c in columns}
                out[h] = {"rmse": math.nan, "rmse_by_column": nan, "starts": 0}
                continue
            n = batch.count
            err = np.asarray(run(params, batch.states, batch.actions))[:n]
            err = err - np.asarray(batch.targets)[:n, -1]
            out[h] = {
                "rmse": float(np.sqrt(np.mean(err**2))),
                "rmse_by_column": dict(zip(columns, np.sqrt(np.mean(err**2, axis=0)).tolist())),
                "starts": int(err.shape[0]),
            }
    return out
