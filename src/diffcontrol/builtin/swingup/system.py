"""The point-mass cart-pole of the neural-ODE swing-up post, as a continuous-time vector field.

A cart of mass ``M`` on a rail, a pole of mass ``m`` concentrated at distance ``L`` from its
pivot, gravity ``g``; ``theta = 0`` is upright and the swing-up starts hanging down at
``theta = pi`` (``../shared/reference/seed-systems.md`` §7). With the force ``F`` on the cart
and ``D = M + m sin^2 theta``, the post's equations of motion are

    x_acc     = [F + m sin theta (L theta_dot^2 - g cos theta)] / D
    theta_acc = [-F cos theta - m L theta_dot^2 sin theta cos theta + (M + m) g sin theta] / (L D)

This module adds friction, which the post suggests for its energy-aware variant and which is
zero by default. The cart feels ``F_c = -b_c x_dot - mu_c tanh(x_dot / v_s)`` (viscous plus
smoothed Coulomb) and the joint a torque ``tau = -b_p theta_dot - mu_p tanh(theta_dot / w_s)``
between pole and cart. From the Lagrangian, with the cart force ``F + F_c``,

    x_acc     = [F + F_c + m sin theta (L theta_dot^2 - g cos theta) - tau cos theta / L] / D
    theta_acc = (g sin theta - x_acc cos theta) / L + tau / (m L^2)

which is the post's pair when ``F_c = tau = 0``. The power lost to friction,
``-(F_c x_dot + tau theta_dot) >= 0``, is returned too, so that a closed loop can integrate
the dissipated energy as a state.

The closed-loop state is ``y = (x, x_dot, theta, theta_dot, impulse, dissipated_energy)``
(m, m/s, rad, rad/s, N s, J). ``impulse`` integrates the force (``d impulse/dt = F``) as in the
post, so the force can be read back from a saved trajectory; ``dissipated_energy`` integrates
the friction power.

Where the derivative is non-smooth: nowhere in the state for the defaults. Coulomb friction
is smoothed by ``tanh`` with the speeds ``coulomb_speed`` (m/s) and ``coulomb_rate`` (rad/s);
the smaller they are, the closer to a true stick-slip discontinuity and the stiffer the ODE
(an adaptive solver then takes many steps near zero speed).
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

STATE_NAMES = ("x", "x_dot", "theta", "theta_dot")
"""The mechanical state, in the order of ``y[:4]``."""
STATE_SIZE = 6
"""Size of the closed-loop state ``y`` (the mechanical state, impulse, dissipated energy)."""


class SwingUpParams(eqx.Module):
    """Physical constants of the swing-up cart-pole (the post's values; no friction)."""

    pole_mass: Float[Array, ""] | float = 1.0
    """Mass of the pole, a point at distance ``length`` from the pivot (kg)."""
    cart_mass: Float[Array, ""] | float = 2.0
    """Mass of the cart (kg)."""
    length: Float[Array, ""] | float = 1.0
    """Distance from the pivot to the pole's mass (m)."""
    g: Float[Array, ""] | float = 9.8
    """Gravity (m/s^2)."""
    cart_viscous: Float[Array, ""] | float = 0.0
    """Viscous friction of the cart on the rail (N s/m)."""
    cart_coulomb: Float[Array, ""] | float = 0.0
    """Coulomb friction force of the cart (N), smoothed over ``coulomb_speed``."""
    pole_viscous: Float[Array, ""] | float = 0.0
    """Viscous friction of the pole's joint (N m s/rad)."""
    pole_coulomb: Float[Array, ""] | float = 0.0
    """Coulomb friction torque of the pole's joint (N m), smoothed over ``coulomb_rate``."""
    coulomb_speed: Float[Array, ""] | float = 0.05
    """Cart speed over which Coulomb friction builds up (m/s); ``tanh(x_dot / v_s)``."""
    coulomb_rate: Float[Array, ""] | float = 0.05
    """Pole angular speed over which Coulomb friction builds up (rad/s)."""


def initial_state(params: SwingUpParams | None = None) -> Float[Array, " 6"]:
    """The post's start: cart at rest at 0, pole hanging straight down, integrals at 0."""
    del params
    return jnp.array([0.0, 0.0, jnp.pi, 0.0, 0.0, 0.0])


def accelerations(
    params: SwingUpParams, state: Float[Array, " 4"], force: Float[Array, ""]
) -> tuple[Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """``(x_acc, theta_acc, friction_power)`` of the mechanical state under a cart force (N)."""
    p = params
    _, x_dot, theta, theta_dot = state[0], state[1], state[2], state[3]
    sin, cos = jnp.sin(theta), jnp.cos(theta)
    cart_friction = -p.cart_viscous * x_dot - p.cart_coulomb * jnp.tanh(x_dot / p.coulomb_speed)
    joint_torque = -p.pole_viscous * theta_dot - p.pole_coulomb * jnp.tanh(
        theta_dot / p.coulomb_rate
    )
    denom = p.cart_mass + p.pole_mass * sin**2
    x_acc = (
        force
        + cart_friction
        + p.pole_mass * sin * (p.length * theta_dot**2 - p.g * cos)
        - joint_torque * cos / p.length
    ) / denom
    theta_acc = (p.g * sin - x_acc * cos) / p.length + joint_torque / (p.pole_mass * p.length**2)
    power = -(cart_friction * x_dot + joint_torque * theta_dot)
    return x_acc, theta_acc, power


def vector_field(
    t: Float[Array, ""],
    y: Float[Array, " 6"],
    args: tuple[SwingUpParams, Callable[[Array, Array], Array]],
) -> Float[Array, " 6"]:
    """``dy/dt`` of the closed loop, in Diffrax's ``f(t, y, args)`` form.

    Args:
        t: time (s).
        y: ``(x, x_dot, theta, theta_dot, impulse, dissipated_energy)``.
        args: ``(params, force_fn)`` where ``force_fn(t, state4)`` is the force on the cart
            (N); pass it as a PyTree (an ``equinox.Module``) so that every gradient method,
            the continuous adjoint included, can differentiate its weights.
    """
    params, force_fn = args
    state = y[:4]
    force = jnp.reshape(force_fn(t, state), ())
    x_acc, theta_acc, power = accelerations(params, state, force)
    return jnp.stack([y[1], x_acc, y[3], theta_acc, force, power])


def energy(params: SwingUpParams, y: Float[Array, "... 6"]) -> Float[Array, ...]:
    """Mechanical energy (J) of the cart and pole, zero at rest hanging down.

    Kinetic ``(M + m) x_dot^2 / 2 + m L x_dot theta_dot cos theta + m L^2 theta_dot^2 / 2``
    plus potential ``m g L (1 + cos theta)``. Without friction its rate of change is the
    force's power ``F x_dot``; a test checks that balance.
    """
    p = params
    x_dot, theta, theta_dot = y[..., 1], y[..., 2], y[..., 3]
    kinetic = (
        0.5 * (p.cart_mass + p.pole_mass) * x_dot**2
        + p.pole_mass * p.length * x_dot * theta_dot * jnp.cos(theta)
        + 0.5 * p.pole_mass * p.length**2 * theta_dot**2
    )
    return kinetic + p.pole_mass * p.g * p.length * (1.0 + jnp.cos(theta))


def wrap_angle(theta: Array) -> Array:
    """``theta`` mapped into ``[-pi, pi)`` (the post's ``modpi``); 0 is upright."""
    return jnp.mod(theta + jnp.pi, 2 * jnp.pi) - jnp.pi
