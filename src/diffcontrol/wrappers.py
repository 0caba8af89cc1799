"""Gymnasium environments that differ from our nominal models: the "real systems" of fitting.

``PendulumFriction`` adds viscous joint friction to Gymnasium's own ``Pendulum-v1`` (which has
none), exactly where ``diffcontrol.systems.pendulum`` puts it: a torque ``-friction *
theta_dot`` added to the clipped torque. With a different gravity
(``gymnasium.make("Pendulum-v1", g=12.0)``) it is the mismatched "real" pendulum of the
fitting demonstration, registered as ``diffcontrol/PendulumFriction-v0``::

    env = gymnasium.make("diffcontrol/PendulumFriction-v0", g=12.0, friction=0.1)
    # or, on an environment you already have:
    env = PendulumFriction(gymnasium.make("Pendulum-v1", g=12.0), friction=0.1)

so ``diffcontrol record diffcontrol/PendulumFriction-v0 --env-arg g=12 --env-arg friction=0.1``
records it.

``WornPendulum`` is a worn one, further from the model than a parameter can say: an actuator
that delivers a fraction of the command and nothing inside a dead band, and Coulomb (dry)
joint friction; registered as ``diffcontrol/WornPendulum-v0``::

    diffcontrol loop pendulum --env diffcontrol/WornPendulum-v0 --env-arg gain=0.8 \
        --env-arg deadband=0.3 --env-arg coulomb=0.2 --env-arg g=11 --model hybrid
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium
import numpy as np
from gymnasium.envs.classic_control.pendulum import PendulumEnv, angle_normalize

PENDULUM_FRICTION_ID = "diffcontrol/PendulumFriction-v0"
WORN_PENDULUM_ID = "diffcontrol/WornPendulum-v0"


class PendulumFriction(gymnasium.Wrapper):
    """Gymnasium's ``Pendulum-v1`` with viscous joint friction ``friction`` (N m s/rad).

    Gymnasium's step is kept (its integration, speed clip and observation): before it, the
    pre-step speed ``theta_dot`` is replaced by ``theta_dot - 3 friction theta_dot dt / (m l^2)``,
    which makes Gymnasium's ``theta_dot + (... + 3 u / (m l^2)) dt`` equal to
    ``theta_dot + (... + 3 (u - friction theta_dot) / (m l^2)) dt`` (up to float64 rounding);
    the reward is then recomputed from the true pre-step state, so it is Gymnasium's cost
    ``wrap(theta)^2 + 0.1 theta_dot^2 + 0.001 u^2`` with ``u`` the clipped torque (friction is
    not a control effort).

    Args:
        env: a ``Pendulum-v1`` environment (any wrappers around Gymnasium's ``PendulumEnv``).
        friction: the joint friction coefficient (N m s/rad), finite and >= 0.

    Raises:
        ValueError: ``env`` is not a Pendulum, or ``friction`` is negative or not finite.
    """

    def __init__(self, env: gymnasium.Env, friction: float = 0.0):
        super().__init__(env)
        if not isinstance(env.unwrapped, PendulumEnv):
            raise ValueError(
                f"PendulumFriction wraps Gymnasium's Pendulum-v1, got {env.unwrapped!r}; "
                'pass gymnasium.make("Pendulum-v1", ...)'
            )
        if not (math.isfinite(friction) and friction >= 0):
            raise ValueError(f"friction must be finite and >= 0 (N m s/rad), got {friction!r}")
        self.friction = float(friction)

    def step(self, action: Any):
        pend = self.env.unwrapped
        theta, theta_dot = (float(x) for x in pend.state)
        damping = 3.0 * self.friction * pend.dt / (pend.m * pend.l**2)
        pend.state = np.array([theta, theta_dot - damping * theta_dot])
        obs, _, terminated, truncated, info = self.env.step(action)
        u = np.clip(action, -pend.max_torque, pend.max_torque)[0]  # as PendulumEnv.step
        cost = angle_normalize(theta) ** 2 + 0.1 * theta_dot**2 + 0.001 * u**2
        return obs, -cost, terminated, truncated, info


def make_pendulum_friction(friction: float = 0.0, **kwargs: Any) -> PendulumFriction:
    """The entry point of ``diffcontrol/PendulumFriction-v0``: Gymnasium's ``PendulumEnv``
    with ``kwargs`` (``g``, ``render_mode``) and joint friction ``friction`` (N m s/rad)."""
    return PendulumFriction(PendulumEnv(**kwargs), friction=friction)


class WornPendulum(gymnasium.Wrapper):
    """Gymnasium's ``Pendulum-v1`` with a worn actuator and dry joint friction. The torque on
    the joint is

        gain * (u - clip(u, -deadband, deadband)) - coulomb * sign(theta_dot)

    with ``u`` the command after Gymnasium's clip to ``[-2, 2]`` N m: a dead zone of half
    width ``deadband`` (N m) past which the actuator delivers ``gain`` of the command, and a
    Coulomb friction torque ``coulomb`` (N m) against the pre-step speed. Gymnasium's step is
    kept as ``PendulumFriction`` keeps it (the friction folded into the pre-step speed, the
    delivered torque passed on; ``gain <= 1`` so Gymnasium's clip never cuts it); the reward is
    Gymnasium's cost of the true pre-step state and the command ``u``.

    Args:
        env: a ``Pendulum-v1`` environment (any wrappers around Gymnasium's ``PendulumEnv``).
        gain: the fraction of the command delivered past the dead band, in (0, 1].
        deadband: the dead zone's half width (N m), in [0, 2).
        coulomb: the dry friction torque (N m), >= 0.

    Raises:
        ValueError: ``env`` is not a Pendulum, or a value outside its range.
    """

    def __init__(
        self, env: gymnasium.Env, gain: float = 1.0, deadband: float = 0.0, coulomb: float = 0.0
    ):
        super().__init__(env)
        if not isinstance(env.unwrapped, PendulumEnv):
            raise ValueError(
                f"WornPendulum wraps Gymnasium's Pendulum-v1, got {env.unwrapped!r}; "
                'pass gymnasium.make("Pendulum-v1", ...)'
            )
        for name, value, ok, bounds in (
            ("gain", gain, 0 < gain <= 1, "in (0, 1]"),
            ("deadband", deadband, 0 <= deadband < 2, "in [0, 2) N m"),
            ("coulomb", coulomb, 0 <= coulomb < math.inf, "finite and >= 0 (N m)"),
        ):
            if not ok:
                raise ValueError(f"{name} must be {bounds}, got {value!r}")
        self.gain, self.deadband, self.coulomb = float(gain), float(deadband), float(coulomb)

    def step(self, action: Any):
        pend = self.env.unwrapped
        theta, theta_dot = (float(x) for x in pend.state)
        u = float(np.clip(action, -pend.max_torque, pend.max_torque)[0])  # as PendulumEnv.step
        delivered = self.gain * (u - min(max(u, -self.deadband), self.deadband))
        slowing = 3.0 * self.coulomb * float(np.sign(theta_dot)) * pend.dt / (pend.m * pend.l**2)
        pend.state = np.array([theta, theta_dot - slowing])
        obs, _, terminated, truncated, info = self.env.step(np.array([delivered]))
        cost = angle_normalize(theta) ** 2 + 0.1 * theta_dot**2 + 0.001 * u**2
        return obs, -cost, terminated, truncated, info


def make_worn_pendulum(
    gain: float = 1.0, deadband: float = 0.0, coulomb: float = 0.0, **kwargs: Any
) -> WornPendulum:
    """The entry point of ``diffcontrol/WornPendulum-v0``: Gymnasium's ``PendulumEnv`` with
    ``kwargs`` (``g``, ``render_mode``), worn as ``WornPendulum`` says."""
    return WornPendulum(PendulumEnv(**kwargs), gain=gain, deadband=deadband, coulomb=coulomb)
