"""Swing-up models learned from data, and the task that trains a controller through one.

A ``SwingUpModel`` is the cart-pole's vector field as the fitted model sees it, one of:

- ``nominal`` / ``params``: the known physics (``builtin.swingup.system``) with
  its parameters (``params``: friction coefficients fitted from data, a grey box);
- ``hybrid``: the known **frictionless** physics plus a small network (``models.Correction``)
  that gives the generalised forces the physics leaves out, a cart force ``Q_x`` (N) and a
  joint torque ``Q_theta`` (N m), as functions of the velocities ``(x_dot, theta_dot)``
  (a universal differential equation). They enter the equations of motion exactly as the
  friction of ``system`` does, through the known mass matrix ``M(theta)``:
  ``(x_acc, theta_acc) += M(theta)^-1 (Q_x, Q_theta)``. Why this shape rather than a free
  correction of the accelerations: friction and drag *are* generalised forces of the
  velocities, so a 2-input network covers from a few recorded episodes the region a swing-up
  visits (a 5-input correction of ``(x_dot, theta, theta_dot, F)`` would have to extrapolate),
  and the power they take out of the mechanical energy is then exact,
  ``-(Q_x x_dot + Q_theta theta_dot)``, so the friction task's energy loss stays meaningful;
- ``neural``: a black box, the network gives ``(x_acc, theta_acc)`` from
  ``(x_dot, cos theta, sin theta, theta_dot, F)`` and nothing of the physics is used. It has no
  notion of energy: its dissipated power is 0.

``FittedSwingUp(task, model)`` is ``task`` (a swing-up) with its vector field replaced by the
model's, so ``diffcontrol.train(FittedSwingUp(task, model))`` trains a controller through the
fitted model; evaluate it on the real system with
``diffcontrol.evaluation.simulate_continuous(task, controller, real_params)``.

``model_to_dict`` / ``model_from_dict`` store a model as plain JSON (the physical parameters,
and the network as lists under ``"network"``), as ``diffcontrol fit`` writes it in
``fitted.json``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._jax_setup import float64
from ...errors import ConfigError, ModelFileError
from ...identify.data import TrajectoryData
from ...identify.network import Correction, correction_from_dict, correction_to_dict
from ...identify.ode import fit_vector_field
from ...identify.ode import prediction_errors as ode_prediction_errors
from ...tasks import check_params
from . import system as cp
from .task import ACTION_COLUMNS, STATE_COLUMNS, CartPoleSwingUp

MODEL_TYPES = ("nominal", "params", "hybrid", "neural")
"""What a ``SwingUpModel`` can be (module docstring)."""

FRICTION_NAMES = CartPoleSwingUp.fit_parameter_names
"""The swing-up's friction coefficients: zero in the nominal (frictionless) model."""


def frictionless(params: cp.SwingUpParams) -> cp.SwingUpParams:
    """``params`` with every friction coefficient 0: the physics the hybrid model knows."""
    return eqx.tree_at(
        lambda p: tuple(getattr(p, n) for n in FRICTION_NAMES),
        params,
        tuple(0.0 * jnp.asarray(getattr(params, n), float) for n in FRICTION_NAMES),
    )


def generalized_force_accelerations(
    params: cp.SwingUpParams, theta: Array, cart_force: Array, joint_torque: Array
) -> tuple[Array, Array]:
    """``M(theta)^-1 (Q_x, Q_theta)``: the accelerations an extra cart force (N) and joint
    torque (N m) add, the same terms as the friction of ``system.accelerations``."""
    p = params
    sin, cos = jnp.sin(theta), jnp.cos(theta)
    denom = p.cart_mass + p.pole_mass * sin**2
    x_acc = (cart_force - joint_torque * cos / p.length) / denom
    theta_acc = -x_acc * cos / p.length + joint_torque / (p.pole_mass * p.length**2)
    return x_acc, theta_acc


class SwingUpModel(eqx.Module):
    """A fitted model of the swing-up cart-pole (module docstring).

    Attributes:
        model_type: one of ``MODEL_TYPES``.
        params: the physical parameters (for ``hybrid``, the frictionless nominal ones; unused
            by ``neural``).
        correction: the network of ``hybrid`` (2 inputs ``(x_dot, theta_dot)``, 2 outputs
            ``(Q_x [N], Q_theta [N m])``) or ``neural`` (5 inputs
            ``(x_dot, cos theta, sin theta, theta_dot, F)``, 2 outputs ``(x_acc, theta_acc)``);
            ``None`` for ``nominal`` and ``params``.
    """

    model_type: str = eqx.field(static=True)
    params: cp.SwingUpParams
    correction: Any = None

    def __check_init__(self):
        if self.model_type not in MODEL_TYPES:
            raise ConfigError(
                f"unknown model kind {self.model_type!r}; choose one of {MODEL_TYPES}"
            )
        if (self.correction is None) != (self.model_type in ("nominal", "params")):
            raise ConfigError(
                f"a {self.model_type!r} model got correction={type(self.correction).__name__}: hybrid "
                "and neural models need a correction network, nominal and params models none"
            )

    @property
    def kind(self) -> str:
        """Deprecated: ``model_type``."""
        return self.model_type

    def derivative(self, state: Float[Array, " 4"], action: Float[Array, " 1"]) -> Array:
        """``d state / dt`` under the held ``action`` (the force, N): what ``identify.ode``
        integrates."""
        x_acc, theta_acc, _ = self.accelerations(state, action[0])
        return jnp.stack([state[1], x_acc, state[3], theta_acc])

    def accelerations(
        self, state: Float[Array, " 4"], force: Float[Array, ""]
    ) -> tuple[Array, Array, Array]:
        """``(x_acc, theta_acc, friction_power)`` as ``system.accelerations``."""
        x_dot, theta, theta_dot = state[1], state[2], state[3]
        if self.model_type == "neural":
            features = jnp.stack([x_dot, jnp.cos(theta), jnp.sin(theta), theta_dot, force])
            acc = self.correction(features)
            return acc[0], acc[1], jnp.zeros_like(acc[0])
        x_acc, theta_acc, power = cp.accelerations(self.params, state, force)
        if self.model_type == "hybrid":
            q = self.correction(jnp.stack([x_dot, theta_dot]))
            dx, dth = generalized_force_accelerations(self.params, theta, q[0], q[1])
            x_acc, theta_acc = x_acc + dx, theta_acc + dth
            power = power - (q[0] * x_dot + q[1] * theta_dot)
        return x_acc, theta_acc, power

    def vector_field(self, t: Array, y: Float[Array, " 6"], force_fn: Any) -> Array:
        """``dy/dt`` of the closed loop, as ``system.vector_field``."""
        state = y[:4]
        force = jnp.reshape(force_fn(t, state), ())
        x_acc, theta_acc, power = self.accelerations(state, force)
        return jnp.stack([y[1], x_acc, y[3], theta_acc, force, power])


class FittedSwingUpParams(cp.SwingUpParams):
    """The parameters a ``FittedSwingUp`` with a network passes to its compiled programs: the
    model's physical parameters, as ``SwingUpParams``, and its network (``correction``).

    The network travels as an argument, not as constants baked into the programs, so a refit
    (the next round's or seed's) runs the programs already compiled for a model of the same
    shape instead of compiling its own.
    """

    correction: Any = None
    """The model's network (``SwingUpModel.correction``)."""


_PHYSICAL = tuple(f.name for f in dataclasses.fields(cp.SwingUpParams))


class FittedSwingUp(CartPoleSwingUp):
    """A swing-up task whose simulator is a fitted ``SwingUpModel`` (module docstring).

    Everything but the vector field is the wrapped task's: losses, horizon, training
    configuration, controller, planning losses and planner settings. The parameters that
    ``train`` passes (and ``config.params`` overrides) are the model's: its physical ones and,
    for a model with a network, the network (``FittedSwingUpParams``), an argument of the
    compiled programs that only the controller's training does not change. Like the physical
    parameters, the network in a run's parameters is in the run's precision (float32 unless
    x64 is on), also where a float64 reference solve uses them.
    """

    def __init__(self, task: CartPoleSwingUp, model: SwingUpModel):
        if not isinstance(task, CartPoleSwingUp):
            raise TypeError(f"FittedSwingUp wraps a swing-up task, got {task!r}")
        self.base = task
        self.model = model
        self.name = f"{task.name}[{model.model_type}]"
        self.env_name = task.env_name
        self.summary = f"{task.summary} (through a fitted {model.model_type} model)"
        self.losses = task.losses
        self.planning_losses = task.planning_losses

    def default_plan_config(self):
        return self.base.default_plan_config()

    def running_cost(self, name: str):
        return self.base.running_cost(name)

    def terminal_cost(self, name: str):
        return self.base.terminal_cost(name)

    def default_params(self) -> cp.SwingUpParams:
        # plain floats, as every task's: the trainer makes them arrays of its own precision
        physical = jax.tree.map(float, self.model.params)
        if self.model.correction is None:
            return physical
        values = {n: getattr(physical, n) for n in _PHYSICAL}
        return FittedSwingUpParams(**values, correction=self.model.correction)

    def default_config(self):
        return self.base.default_config()

    def recipes(self):
        return self.base.recipes()

    def vector_field(self, t, y, args):
        params, force_fn = args
        # the network passed in ``params`` (default_params), or this model's own where the
        # caller passed physical parameters only
        correction = getattr(params, "correction", None)
        if correction is None:
            correction = self.model.correction
        if correction is not None:  # in the solve's precision (fitted in float64)
            correction = jax.tree.map(lambda a: jnp.asarray(a, y.dtype), correction)
        physical = cp.SwingUpParams(**{n: getattr(params, n) for n in _PHYSICAL})
        model = SwingUpModel(self.model.model_type, physical, correction)
        return model.vector_field(t, y, force_fn)

    def _programs_key(self) -> tuple[CartPoleSwingUp, tuple, tuple[str, ...]]:
        """What this task's compiled programs depend on besides its plain attributes, for
        ``training._programs`` to reuse the trainer of an equal key: the wrapped task, and the
        kind of model and the shapes of its network, not its weights or physical parameters,
        which are arguments (``default_params``); and the names of the attributes those
        stand for."""
        leaves = jax.tree.leaves(self.model.correction)
        shapes = tuple((np.shape(x), np.asarray(x).dtype.str) for x in leaves)
        structure = jax.tree.structure(self.model.correction)
        return self.base, (self.model.model_type, structure, shapes), ("base", "model")

    def check_params(self, params) -> None:
        """The wrapped task's checks, and a network of the model's structure (``correction``
        is the fitted network, not a parameter to set)."""
        correction = getattr(params, "correction", None)
        if jax.tree.structure(correction) != jax.tree.structure(self.model.correction):
            raise ConfigError(
                f"the parameters of task {self.name!r} carry a correction that is not the "
                "fitted model's network; set physical parameters only (correction is the "
                "network the fit wrote)"
            )
        check_params.dispatch(object)(self, params)  # every task's checks (the default)

    def __repr__(self) -> str:
        return f"<task {self.name}>"


# --- storing a fitted model ------------------------------------------------------------------

NETWORK_SIGNATURES = {
    "hybrid": (["x_dot [m/s]", "theta_dot [rad/s]"], ["cart_force [N]", "joint_torque [N m]"]),
    "neural": (
        ["x_dot [m/s]", "cos(theta) [1]", "sin(theta) [1]", "theta_dot [rad/s]", "force [N]"],
        ["x_acc [m/s^2]", "theta_acc [rad/s^2]"],
    ),
}
"""What a stored network takes and gives, per model kind (written next to it for readers)."""


def model_to_dict(model: SwingUpModel) -> dict[str, Any]:
    """The model as plain JSON: its kind, every physical parameter and, for ``hybrid`` and
    ``neural``, the network (``models.correction_to_dict``) with its inputs and outputs."""
    doc: dict[str, Any] = {
        "kind": model.model_type,
        "all_parameters": {
            f.name: float(np.asarray(getattr(model.params, f.name)))
            for f in dataclasses.fields(model.params)
        },
    }
    if model.correction is not None:
        inputs, outputs = NETWORK_SIGNATURES[model.model_type]
        doc["network"] = {
            "inputs": inputs,
            "outputs": outputs,
            **correction_to_dict(model.correction),
        }
    return doc


def model_from_dict(doc: Any, where: str = "the fitted model") -> SwingUpModel:
    """Rebuild a ``SwingUpModel`` from ``model_to_dict``'s output (or a ``fitted.json``).

    Raises:
        ModelFileError: an unknown kind, missing or non-numeric parameters, a malformed
            network, or a network whose sizes do not fit the kind.
    """
    kind = doc.get("kind", doc.get("model")) if isinstance(doc, dict) else None
    if kind not in MODEL_TYPES:
        raise ModelFileError(f"{where}: unknown model kind {kind!r}; refit the model")
    names = [f.name for f in dataclasses.fields(cp.SwingUpParams)]
    values = doc.get("all_parameters") or {}
    try:
        params = cp.SwingUpParams(**{n: float(values[n]) for n in names})
    except (KeyError, TypeError, ValueError) as e:
        raise ModelFileError(
            f"{where}: the physical parameters are incomplete or not numbers ({e!r}); "
            f"it needs {names}; refit the model"
        ) from None
    if kind in ("nominal", "params"):
        return SwingUpModel(kind, params)
    net = correction_from_dict(doc.get("network"), where)
    inputs, outputs = NETWORK_SIGNATURES[kind]
    sizes = (net.net.layers[0].weight.shape[1], net.net.layers[-1].weight.shape[0])
    if sizes != (len(inputs), len(outputs)):
        raise ModelFileError(
            f"{where}: a {kind} network takes {len(inputs)} inputs and gives {len(outputs)} "
            f"outputs, this one {sizes}; refit the model"
        )
    return SwingUpModel(kind, params, net)


# --- learning a model from data: the swing-up's hooks of ``identify`` -------------------------


def nominal_model(params: cp.SwingUpParams) -> SwingUpModel:
    """The frictionless physics with ``params``' masses, length and gravity."""
    return SwingUpModel("nominal", frictionless(params))


def initial_model(model_type, nominal, data, dt, hidden, key) -> SwingUpModel:
    """The model before fitting: zero friction, or a network with a zero last layer whose
    input and output scalings come from the data (inputs of order 1; an output of 1 is a
    force that changes a speed by one standard deviation per second, or for ``neural`` one
    standard deviation of the recorded accelerations)."""
    if model_type == "params":
        return SwingUpModel("params", nominal)
    y = data.observations
    std = np.maximum(np.std(y, axis=0), 1e-6)
    p = nominal
    if model_type == "hybrid":
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
    return SwingUpModel(model_type, nominal, net)


def state_error(pred: Array, target: Array) -> Array:
    """Predicted minus recorded state, the angle difference wrapped to ``[-pi, pi)``."""
    err = pred - target
    return err.at[..., 2].set(cp.wrap_angle(err[..., 2]))


def held_force_step(params: cp.SwingUpParams, dt_s: float):
    """``advance(y, f)``: the state ``y`` (x, x_dot, theta, theta_dot) of the system with
    ``params`` after ``dt_s`` seconds with the force ``f`` held, solved with Tsit5 at rtol
    1e-9 / atol 1e-9 in float64 (call it, and build it, under ``jax.enable_x64(True)``): how
    the "real" system is recorded."""
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

    return advance


def record_swingup(
    params: cp.SwingUpParams,
    episodes: int,
    *,
    seed: int = 0,
    dt_s: float = 0.02,
    duration_s: float = 5.0,
    force_max: float = 40.0,
    hold_s: float = 0.2,
) -> Any:
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
    with float64():
        advance = held_force_step(params, dt_s)

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
    names = _PHYSICAL  # (a fitted model's network is no parameter of the recorded system)
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


def fit_swingup_model(data: Any, kind: str = "hybrid", params: Any = None, **settings: Any):
    """``identify.ode.fit_vector_field`` for the swing-up (``params`` default
    ``SwingUpParams()``): a ``FitResult`` whose ``model`` is a ``SwingUpModel``."""
    return fit_vector_field(CartPoleSwingUp(), data, kind, params or cp.SwingUpParams(), **settings)


def prediction_errors(model: SwingUpModel, data: Any, horizons: Any = (1, 10, 50), substeps=2):
    """``identify.ode.prediction_errors`` of a swing-up model on recorded state data."""
    return ode_prediction_errors(CartPoleSwingUp(), model, data, horizons, substeps)
