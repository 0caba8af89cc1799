"""Gymnasium's ``CartPole-v1`` as a pure, differentiable JAX program.

State ``(x, x_dot, theta, theta_dot)`` with ``theta = 0`` upright (m, m/s, rad, rad/s); the
observation is the state. The push is a real multiplier ``a`` of ``force_mag`` (Gymnasium's
action 1 is ``a = +1``, action 0 is ``a = -1``), so a straight-through sign in the controller
can pass gradients into it. One step, exactly as ``CartPoleEnv.step`` with explicit Euler:

    temp  = (F + m_p l theta_dot^2 sin theta) / (m_c + m_p)
    theta_acc = (g sin theta - cos theta temp) / (l (4/3 - m_p cos^2 theta / (m_c + m_p)))
    x_acc = temp - m_p l theta_acc cos theta / (m_c + m_p)
    x' = x + tau x_dot, x_dot' = x_dot + tau x_acc, theta' = theta + tau theta_dot,
    theta_dot' = theta_dot + tau theta_acc

Termination (``|x'| > 2.4`` or ``|theta'| > 12 deg``) is checked on the new state; the reward is
1 for every step, the failing one included. Gymnasium truncates at 500 steps.

Where the derivative is non-smooth: the dynamics are smooth in the state and in ``a``;
termination is a discontinuity (a boolean with no derivative), and the discrete action itself
has none unless the controller supplies one (the straight-through sign).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from .draws import uniform

EPISODE_LENGTH = 500
"""Gymnasium's ``max_episode_steps`` for ``CartPole-v1``."""


class CartPoleParams(eqx.Module):
    """Physical constants of ``CartPole-v1`` (Gymnasium's values)."""

    gravity: Float[Array, ""] | float = 9.8
    """Gravity (m/s^2)."""
    masscart: Float[Array, ""] | float = 1.0
    """Cart mass (kg)."""
    masspole: Float[Array, ""] | float = 0.1
    """Pole mass (kg)."""
    length: Float[Array, ""] | float = 0.5
    """Half the pole's length (m)."""
    force_mag: Float[Array, ""] | float = 10.0
    """Magnitude of the push (N)."""
    tau: Float[Array, ""] | float = 0.02
    """Time step (s)."""
    theta_threshold: Float[Array, ""] | float = 12 * 2 * math.pi / 360
    """Termination angle (rad), 12 degrees."""
    x_threshold: Float[Array, ""] | float = 2.4
    """Termination position (m)."""


def reset(key: PRNGKeyArray, params: CartPoleParams | None = None) -> Float[Array, 4]:
    """Gymnasium's reset distribution: each state component ``~ U(-0.05, 0.05)``."""
    del params
    return uniform(key, (4,), minval=-0.05, maxval=0.05)


def step(params: CartPoleParams, state: Float[Array, 4], push: Float[Array, ""]) -> Float[Array, 4]:
    """One explicit-Euler step under the force ``push * force_mag``; returns the next state."""
    x, x_dot, theta, theta_dot = state[0], state[1], state[2], state[3]
    force = push * params.force_mag
    total_mass = params.masspole + params.masscart
    polemass_length = params.masspole * params.length
    costheta, sintheta = jnp.cos(theta), jnp.sin(theta)
    temp = (force + polemass_length * theta_dot**2 * sintheta) / total_mass
    theta_acc = (params.gravity * sintheta - costheta * temp) / (
        params.length * (4.0 / 3.0 - params.masspole * costheta**2 / total_mass)
    )
    x_acc = temp - polemass_length * theta_acc * costheta / total_mass
    return jnp.stack(
        [
            x + params.tau * x_dot,
            x_dot + params.tau * x_acc,
            theta + params.tau * theta_dot,
            theta_dot + params.tau * theta_acc,
        ]
    )


def terminated(params: CartPoleParams, state: Float[Array, 4]) -> Bool[Array, ""]:
    """Gymnasium's failure test on a (new) state: the cart or the pole left its bounds."""
    return (jnp.abs(state[0]) > params.x_threshold) | (jnp.abs(state[2]) > params.theta_threshold)


def observe(state: Float[Array, 4]) -> Float[Array, 4]:
    """The observation is the state."""
    return state
