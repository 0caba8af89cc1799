"""Swing-up models learned from data, and the task that trains a controller through one.

A ``SwingUpModel`` is the cart-pole's vector field as the fitted model sees it, one of:

- ``nominal`` / ``params``: the known physics (``diffcontrol.systems.cartpole_swingup``) with
  its parameters (``params``: friction coefficients fitted from data, a grey box);
- ``hybrid``: the known **frictionless** physics plus a small network (``models.Correction``)
  that gives the generalised forces the physics leaves out, a cart force ``Q_x`` (N) and a
  joint torque ``Q_theta`` (N m), as functions of the velocities ``(x_dot, theta_dot)``
  (a universal differential equation). They enter the equations of motion exactly as the
  friction of ``cartpole_swingup`` does, through the known mass matrix ``M(theta)``:
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
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import ConfigError, ModelFileError
from ..models import Correction, correction_from_dict, correction_to_dict
from ..systems import cartpole_swingup as cp
from .swingup import CartPoleSwingUp

MODEL_KINDS = ("nominal", "params", "hybrid", "neural")
"""What a ``SwingUpModel`` can be (module docstring)."""

FRICTION_NAMES = ("cart_viscous", "cart_coulomb", "pole_viscous", "pole_coulomb")
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
    torque (N m) add, the same terms as the friction of ``cartpole_swingup.accelerations``."""
    p = params
    sin, cos = jnp.sin(theta), jnp.cos(theta)
    denom = p.cart_mass + p.pole_mass * sin**2
    x_acc = (cart_force - joint_torque * cos / p.length) / denom
    theta_acc = -x_acc * cos / p.length + joint_torque / (p.pole_mass * p.length**2)
    return x_acc, theta_acc


class SwingUpModel(eqx.Module):
    """A fitted model of the swing-up cart-pole (module docstring).

    Attributes:
        kind: one of ``MODEL_KINDS``.
        params: the physical parameters (for ``hybrid``, the frictionless nominal ones; unused
            by ``neural``).
        correction: the network of ``hybrid`` (2 inputs ``(x_dot, theta_dot)``, 2 outputs
            ``(Q_x [N], Q_theta [N m])``) or ``neural`` (5 inputs
            ``(x_dot, cos theta, sin theta, theta_dot, F)``, 2 outputs ``(x_acc, theta_acc)``);
            ``None`` for ``nominal`` and ``params``.
    """

    kind: str = eqx.field(static=True)
    params: cp.SwingUpParams
    correction: Correction | None = None

    def __check_init__(self):
        if self.kind not in MODEL_KINDS:
            raise ConfigError(f"unknown model kind {self.kind!r}; choose one of {MODEL_KINDS}")
        if (self.correction is None) != (self.kind in ("nominal", "params")):
            raise ConfigError(
                f"a {self.kind!r} model got correction={type(self.correction).__name__}: hybrid "
                "and neural models need a correction network, nominal and params models none"
            )

    def accelerations(
        self, state: Float[Array, " 4"], force: Float[Array, ""]
    ) -> tuple[Array, Array, Array]:
        """``(x_acc, theta_acc, friction_power)`` as ``cartpole_swingup.accelerations``."""
        x_dot, theta, theta_dot = state[1], state[2], state[3]
        if self.kind == "neural":
            features = jnp.stack([x_dot, jnp.cos(theta), jnp.sin(theta), theta_dot, force])
            acc = self.correction(features)
            return acc[0], acc[1], jnp.zeros_like(acc[0])
        x_acc, theta_acc, power = cp.accelerations(self.params, state, force)
        if self.kind == "hybrid":
            q = self.correction(jnp.stack([x_dot, theta_dot]))
            dx, dth = generalized_force_accelerations(self.params, theta, q[0], q[1])
            x_acc, theta_acc = x_acc + dx, theta_acc + dth
            power = power - (q[0] * x_dot + q[1] * theta_dot)
        return x_acc, theta_acc, power

    def vector_field(self, t: Array, y: Float[Array, " 6"], force_fn: Any) -> Array:
        """``dy/dt`` of the closed loop, as ``cartpole_swingup.vector_field``."""
        state = y[:4]
        force = jnp.reshape(force_fn(t, state), ())
        x_acc, theta_acc, power = self.accelerations(state, force)
        return jnp.stack([y[1], x_acc, y[3], theta_acc, force, power])


class FittedSwingUp(CartPoleSwingUp):
    """A swing-up task whose simulator is a fitted ``SwingUpModel`` (module docstring).

    Everything but the vector field is the wrapped task's: losses, horizon, training
    configuration, controller. The physical parameters that ``train`` passes (and
    ``config.params`` overrides) are the model's. The model's weights are constants of the
    training (only the controller is trained).
    """

    def __init__(self, task: CartPoleSwingUp, model: SwingUpModel):
        if not isinstance(task, CartPoleSwingUp):
            raise TypeError(f"FittedSwingUp wraps a swing-up task, got {task!r}")
        self.base = task
        self.model = model
        self.name = f"{task.name}[{model.kind}]"
        self.env_name = task.env_name
        self.summary = f"{task.summary} (through a fitted {model.kind} model)"
        self.losses = task.losses

    def default_params(self) -> cp.SwingUpParams:
        # plain floats, as every task's: the trainer makes them arrays of its own precision
        return jax.tree.map(float, self.model.params)

    def default_config(self):
        return self.base.default_config()

    def recipes(self):
        return self.base.recipes()

    def vector_field(self, t, y, args):
        params, force_fn = args
        # the model's weights in the solve's precision (fitted in float64, trained in float32)
        model = jax.tree.map(lambda a: jnp.asarray(a, y.dtype), self.model)
        model = eqx.tree_at(lambda m: m.params, model, params)
        return model.vector_field(t, y, force_fn)

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
        "kind": model.kind,
        "all_parameters": {
            f.name: float(np.asarray(getattr(model.params, f.name)))
            for f in dataclasses.fields(model.params)
        },
    }
    if model.correction is not None:
        inputs, outputs = NETWORK_SIGNATURES[model.kind]
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
    if kind not in MODEL_KINDS:
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
