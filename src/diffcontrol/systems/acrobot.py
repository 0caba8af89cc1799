"""Gymnasium's ``Acrobot-v1`` as a pure, differentiable JAX program.

Two links hang from a fixed pivot; only the joint between them is driven. State
``(theta1, theta2, theta1_dot, theta2_dot)``: ``theta1`` is the first link's angle from
hanging straight down, ``theta2`` the second link's angle relative to the first (rad, rad/s).
Observation ``(cos theta1, sin theta1, cos theta2, sin theta2, theta1_dot, theta2_dot)``.

One step, exactly as ``gymnasium.envs.classic_control.acrobot.AcrobotEnv.step`` with its
default ``book_or_nips = "book"`` and no torque noise:

    (theta1, theta2, theta1_dot, theta2_dot)' = rk4(dsdt, state, [0, dt]),  dt = 0.2 s
    theta1', theta2'         wrapped into [-pi, pi] (Gymnasium's ``wrap``)
    theta1_dot', theta2_dot' clipped to +-4 pi and +-9 pi rad/s (Gymnasium's ``bound``)

with one classical Runge-Kutta step (Gymnasium's own ``rk4`` over ``[0, dt]``; the torque is
held over it) of the equations of motion of Sutton & Barto's book (``dsdt``, below). The
torque ``tau`` (N m) is a real number here, so that a straight-through discrete choice can
pass a gradient into it; Gymnasium's actions 0, 1, 2 are ``tau = -1, 0, +1``.

Termination (checked on the new state): the tip is above the goal line,
``-cos theta1 - cos(theta1 + theta2) > 1`` (in link lengths; Gymnasium's test, which takes
both links to be 1 m whatever ``link_length_*`` say). The reward is -1 per step and 0 on the
terminating step; Gymnasium truncates at 500 steps.

Where the derivative is non-smooth:

- the angle wrap: a jump of ``2 pi`` in the state, but not in anything the dynamics or the
  observation compute from it (both are ``2 pi``-periodic), so its derivative is taken as 1;
- the speed clips: zero gradient through a speed while it is saturated;
- termination: a discontinuity (a boolean with no derivative);
- the torque: smooth in ``tau``; the discrete choice itself has no derivative unless the
  controller supplies one (the straight-through ``argmax`` head).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from .draws import uniform

EPISODE_LENGTH = 500
"""Gymnasium's ``max_episode_steps`` for ``Acrobot-v1``."""

TORQUES = (-1.0, 0.0, 1.0)
"""The torque (N m) of Gymnasium's actions 0, 1, 2 (``AcrobotEnv.AVAIL_TORQUE``)."""

GOAL_HEIGHT = 1.0
"""The tip height (link lengths above the pivot) that ends an episode."""


class AcrobotParams(eqx.Module):
    """Physical constants of ``Acrobot-v1`` (Gymnasium's values).

    Every field is a PyTree leaf, so a batch of parameters can be ``vmap``ped (domain
    randomisation) and differentiated (system identification).
    """

    link_length_1: Float[Array, ""] | float = 1.0
    """Length of the first link (m)."""
    link_length_2: Float[Array, ""] | float = 1.0
    """Length of the second link (m); only drawings use it (as in Gymnasium)."""
    link_mass_1: Float[Array, ""] | float = 1.0
    """Mass of the first link (kg)."""
    link_mass_2: Float[Array, ""] | float = 1.0
    """Mass of the second link (kg)."""
    link_com_pos_1: Float[Array, ""] | float = 0.5
    """Distance from the pivot to the first link's centre of mass (m)."""
    link_com_pos_2: Float[Array, ""] | float = 0.5
    """Distance from the joint to the second link's centre of mass (m)."""
    link_moi: Float[Array, ""] | float = 1.0
    """Moment of inertia of each link (kg m^2)."""
    gravity: Float[Array, ""] | float = 9.8
    """Gravity (m/s^2)."""
    dt: Float[Array, ""] | float = 0.2
    """Time step (s): one Runge-Kutta step of this length per action."""
    max_vel_1: Float[Array, ""] | float = 4 * jnp.pi
    """Clip of ``theta1_dot`` (rad/s)."""
    max_vel_2: Float[Array, ""] | float = 9 * jnp.pi
    """Clip of ``theta2_dot`` (rad/s)."""


def reset(key: PRNGKeyArray, params: AcrobotParams | None = None) -> Float[Array, 4]:
    """Gymnasium's reset distribution: each state component ``~ U(-0.1, 0.1)``."""
    del params
    return uniform(key, (4,), minval=-0.1, maxval=0.1)


def dsdt(params: AcrobotParams, state: Float[Array, 4], torque: Array) -> Float[Array, 4]:
    """The time derivative of the state under ``torque`` (N m): Gymnasium's ``_dsdt``, "book".

    Sutton & Barto (2018), section 16.1, written operation for operation as Gymnasium does
    (e.g. ``cos(theta1 - pi / 2)`` rather than ``sin(theta1)``) so that float64 results agree
    to rounding.
    """
    m1, m2 = params.link_mass_1, params.link_mass_2
    l1 = params.link_length_1
    lc1, lc2 = params.link_com_pos_1, params.link_com_pos_2
    i1 = i2 = params.link_moi
    g = params.gravity
    theta1, theta2, dtheta1, dtheta2 = state[0], state[1], state[2], state[3]
    d1 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * jnp.cos(theta2)) + i1 + i2
    d2 = m2 * (lc2**2 + l1 * lc2 * jnp.cos(theta2)) + i2
    phi2 = m2 * lc2 * g * jnp.cos(theta1 + theta2 - jnp.pi / 2.0)
    phi1 = (
        -m2 * l1 * lc2 * dtheta2**2 * jnp.sin(theta2)
        - 2 * m2 * l1 * lc2 * dtheta2 * dtheta1 * jnp.sin(theta2)
        + (m1 * lc1 + m2 * l1) * g * jnp.cos(theta1 - jnp.pi / 2)
        + phi2
    )
    ddtheta2 = (torque + d2 / d1 * phi1 - m2 * l1 * lc2 * dtheta1**2 * jnp.sin(theta2) - phi2) / (
        m2 * lc2**2 + i2 - d2**2 / d1
    )
    ddtheta1 = -(d2 * ddtheta2 + phi1) / d1
    return jnp.stack([dtheta1, dtheta2, ddtheta1, ddtheta2])


def rk4(params: AcrobotParams, state: Float[Array, 4], torque: Array) -> Float[Array, 4]:
    """One classical Runge-Kutta step of ``dsdt`` over ``[0, dt]``, the torque held (Gymnasium's
    ``rk4(self._dsdt, s_augmented, [0, self.dt])``)."""
    dt = params.dt
    dt2 = dt / 2.0
    k1 = dsdt(params, state, torque)
    k2 = dsdt(params, state + dt2 * k1, torque)
    k3 = dsdt(params, state + dt2 * k2, torque)
    k4 = dsdt(params, state + dt * k3, torque)
    return state + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def wrap(x: Array) -> Array:
    """Gymnasium's ``wrap(x, -pi, pi)``: subtract or add ``2 pi`` until ``-pi <= x <= pi``.

    Written with the number of turns, ``ceil``, so it is one expression under ``jit``; for the
    one turn that a step makes it is Gymnasium's subtraction exactly (both ends stay put:
    ``wrap(pi) = pi``). Its derivative is 1.
    """
    period = 2 * jnp.pi
    down = jnp.ceil((x - jnp.pi) / period)
    up = jnp.ceil((-jnp.pi - x) / period)
    return jnp.where(x > jnp.pi, x - down * period, jnp.where(x < -jnp.pi, x + up * period, x))


def step(params: AcrobotParams, state: Float[Array, 4], torque: Array) -> Float[Array, 4]:
    """One step under ``torque`` (N m): Runge-Kutta, wrap the angles, clip the speeds."""
    ns = rk4(params, state, torque)
    return jnp.stack(
        [
            wrap(ns[0]),
            wrap(ns[1]),
            jnp.clip(ns[2], -params.max_vel_1, params.max_vel_1),
            jnp.clip(ns[3], -params.max_vel_2, params.max_vel_2),
        ]
    )


def tip_height(state: Float[Array, 4]) -> Array:
    """Height of the tip above the pivot in link lengths, ``-cos theta1 - cos(theta1 + theta2)``
    (-2 hanging down, +2 straight up)."""
    return -jnp.cos(state[0]) - jnp.cos(state[1] + state[0])


def terminated(state: Float[Array, 4]) -> Bool[Array, ""]:
    """Gymnasium's goal test on a (new) state: the tip is above the line at height 1."""
    return tip_height(state) > GOAL_HEIGHT


def observe(state: Float[Array, 4]) -> Float[Array, 6]:
    """Gymnasium's observation ``(cos theta1, sin theta1, cos theta2, sin theta2, theta1_dot,
    theta2_dot)``."""
    theta1, theta2 = state[0], state[1]
    return jnp.stack(
        [jnp.cos(theta1), jnp.sin(theta1), jnp.cos(theta2), jnp.sin(theta2), state[2], state[3]]
    )


def energy(params: AcrobotParams, state: Float[Array, 4]) -> Array:
    """Total mechanical energy (J) of the book's model, zero hanging at rest.

    ``E = 1/2 (d11 theta1_dot^2 + 2 d12 theta1_dot theta2_dot + d22 theta2_dot^2) + V`` with the
    inertia terms of ``dsdt`` (``d11 = d1``, ``d12 = d2``, ``d22 = m2 lc2^2 + I2``) and
    ``V = g (m1 lc1 + m2 l1) (1 - cos theta1) + g m2 lc2 (1 - cos(theta1 + theta2))``. The
    torque changes it at the rate ``tau theta2_dot``; upright at rest it is
    ``2 g (m1 lc1 + m2 l1 + m2 lc2)`` (58.8 J with Gymnasium's values).
    """
    m1, m2 = params.link_mass_1, params.link_mass_2
    l1 = params.link_length_1
    lc1, lc2 = params.link_com_pos_1, params.link_com_pos_2
    i1 = i2 = params.link_moi
    g = params.gravity
    theta1, theta2, w1, w2 = state[0], state[1], state[2], state[3]
    d11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * jnp.cos(theta2)) + i1 + i2
    d12 = m2 * (lc2**2 + l1 * lc2 * jnp.cos(theta2)) + i2
    d22 = m2 * lc2**2 + i2
    kinetic = 0.5 * (d11 * w1**2 + 2 * d12 * w1 * w2 + d22 * w2**2)
    potential = g * (m1 * lc1 + m2 * l1) * (1 - jnp.cos(theta1)) + g * m2 * lc2 * (
        1 - jnp.cos(theta1 + theta2)
    )
    return kinetic + potential
