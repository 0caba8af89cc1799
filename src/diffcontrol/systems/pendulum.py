"""Gymnasium's ``Pendulum-v1`` as a pure, differentiable JAX program.

State ``(theta, theta_dot)`` with ``theta = 0`` upright (radians, rad/s). Observation
``(cos theta, sin theta, theta_dot)``. One step, exactly as ``gymnasium.envs.classic_control.
pendulum.PendulumEnv.step``:

    u        = clip(u, -max_torque, max_torque)
    cost     = wrap(theta)^2 + 0.1 theta_dot^2 + 0.001 u^2          (on the pre-step state)
    theta_dot' = clip(theta_dot + (3 g / (2 l) sin theta + 3 / (m l^2) (u - b theta_dot)) dt,
                      -max_speed, max_speed)
    theta'   = theta + theta_dot' dt

``b = friction`` is viscous joint friction (N m s/rad), which Gymnasium's ``Pendulum-v1`` does not
have: a torque ``-b theta_dot`` (on the pre-step speed) added to the applied torque **after** the
torque clip, so the motor's limit does not limit the friction. With ``b = 0`` (the default) the
step is Gymnasium's, operation for operation. ``diffcontrol.wrappers.PendulumFriction`` adds the
same friction to Gymnasium's own environment (the "real system" of the fitting demonstration).

Where the derivative is non-smooth:

- the torque clip: zero gradient with respect to ``u`` when ``|u| > max_torque`` (use a bounded
  controller head, e.g. ``tanh``, so the gradient does not die there);
- the speed clip: zero gradient through ``theta_dot'`` while it is saturated at ``+-max_speed``;
- ``wrap`` in the cost: the cost is continuous at ``theta = +-pi`` but its slope flips sign there.

There is no termination; Gymnasium truncates episodes at 200 steps.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from .draws import uniform

EPISODE_LENGTH = 200
"""Gymnasium's ``max_episode_steps`` for ``Pendulum-v1``."""


class PendulumParams(eqx.Module):
    """Physical constants of ``Pendulum-v1`` (Gymnasium's defaults).

    Every field is a PyTree leaf, so a batch of parameters can be ``vmap``ped (domain
    randomisation) and differentiated (system identification).
    """

    g: Float[Array, ""] | float = 10.0
    """Gravity (m/s^2). Gymnasium's default is 10, not 9.81."""
    m: Float[Array, ""] | float = 1.0
    """Mass at the tip (kg)."""
    l: Float[Array, ""] | float = 1.0
    """Length (m)."""
    dt: Float[Array, ""] | float = 0.05
    """Time step (s)."""
    max_speed: Float[Array, ""] | float = 8.0
    """Angular speed clip (rad/s)."""
    max_torque: Float[Array, ""] | float = 2.0
    """Torque clip (N m). ``jnp.inf`` gives the unclipped variant of the 2019 original."""
    friction: Float[Array, ""] | float = 0.0
    """Viscous joint friction (N m s/rad): the torque ``-friction * theta_dot`` is added to the
    applied torque after the torque clip. 0 (Gymnasium's ``Pendulum-v1``) by default."""


def angle_normalize(theta: Array) -> Array:
    """Wrap an angle into ``[-pi, pi)``, as Gymnasium's ``angle_normalize``."""
    return ((theta + jnp.pi) % (2 * jnp.pi)) - jnp.pi


def reset(key: PRNGKeyArray, params: PendulumParams | None = None) -> Float[Array, 2]:
    """Gymnasium's reset distribution: ``theta ~ U(-pi, pi)``, ``theta_dot ~ U(-1, 1)``."""
    del params
    high = jnp.array([jnp.pi, 1.0])
    return uniform(key, (2,), minval=-high, maxval=high)


def clip_torque(params: PendulumParams, torque: Array) -> Array:
    """The torque the plant applies: ``clip(torque, -max_torque, max_torque)``."""
    return jnp.clip(torque, -params.max_torque, params.max_torque)


def cost(params: PendulumParams, state: Float[Array, 2], torque: Float[Array, ""]) -> Array:
    """Gymnasium's per-step cost (the reward is its negative), on the pre-step state."""
    theta, theta_dot = state[0], state[1]
    u = clip_torque(params, torque)
    return angle_normalize(theta) ** 2 + 0.1 * theta_dot**2 + 0.001 * u**2


def step(
    params: PendulumParams, state: Float[Array, 2], torque: Float[Array, ""]
) -> Float[Array, 2]:
    """One Gymnasium step (semi-implicit Euler with the speed clip); returns the next state.

    The joint friction ``-friction * theta_dot`` is added to the clipped torque (module
    docstring); with ``friction = 0`` the result is Gymnasium's to the last bit.
    """
    theta, theta_dot = state[0], state[1]
    u = clip_torque(params, torque) - params.friction * theta_dot
    accel = 3 * params.g / (2 * params.l) * jnp.sin(theta) + 3.0 / (params.m * params.l**2) * u
    new_theta_dot = jnp.clip(theta_dot + accel * params.dt, -params.max_speed, params.max_speed)
    new_theta = theta + new_theta_dot * params.dt
    return jnp.stack([new_theta, new_theta_dot])


def observe(state: Float[Array, 2]) -> Float[Array, 3]:
    """Gymnasium's observation ``(cos theta, sin theta, theta_dot)``."""
    return jnp.stack([jnp.cos(state[0]), jnp.sin(state[0]), state[1]])
