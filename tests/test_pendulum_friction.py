"""Joint friction: ``PendulumParams.friction`` against ``PendulumFriction`` around Gymnasium.

Float64 (``jax.enable_x64``), one step from random states (angles to +-3 pi, speeds past the
clip) and torques past the clip. Tolerance 1e-12 absolute: the wrapper folds the friction into
the pre-step speed, a different order of the same float64 operations (a few ulp at speeds
~10); a wrong sign or factor of the friction shows up at 1e-4 or more (checked below).
"""

from __future__ import annotations

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol  # noqa: F401  (registers diffcontrol/PendulumFriction-v0)
from diffcontrol.systems import pendulum as pend
from diffcontrol.wrappers import PENDULUM_FRICTION_ID, PendulumFriction

ATOL = 1e-12


def _cases(n: int = 200, seed: int = 5):
    rng = np.random.default_rng(seed)
    states = np.stack([rng.uniform(-3 * np.pi, 3 * np.pi, n), rng.uniform(-10, 10, n)], axis=1)
    torques = rng.uniform(-4.0, 4.0, n)
    torques[:3] = [2.0, -2.0, 0.0]
    return states, torques


@pytest.mark.parametrize("g, friction", [(10.0, 0.0), (12.0, 0.1), (9.0, 0.5)])
def test_wrapper_matches_model_step_by_step(g, friction):
    env = gymnasium.make(PENDULUM_FRICTION_ID, g=g, friction=friction)
    env.reset(seed=0)
    params = pend.PendulumParams(g=g, friction=friction)
    states, torques = _cases()
    with jax.enable_x64(True):
        step = jax.jit(jax.vmap(pend.step, in_axes=(None, 0, 0)))
        cost = jax.jit(jax.vmap(pend.cost, in_axes=(None, 0, 0)))
        want = np.asarray(step(params, jnp.asarray(states), jnp.asarray(torques)))
        want_cost = np.asarray(cost(params, jnp.asarray(states), jnp.asarray(torques)))
    for i, (state, torque) in enumerate(zip(states, torques)):
        env.unwrapped.state = state.copy()
        _, reward, *_ = env.step(np.array([torque], np.float64))
        np.testing.assert_allclose(env.unwrapped.state, want[i], rtol=0, atol=ATOL)
        assert abs(-reward - want_cost[i]) < ATOL


def test_friction_zero_is_gymnasium_and_friction_changes_the_step():
    plain = gymnasium.make("Pendulum-v1", g=12.0).unwrapped
    wrapped = PendulumFriction(gymnasium.make("Pendulum-v1", g=12.0), friction=0.0)
    rubbing = PendulumFriction(gymnasium.make("Pendulum-v1", g=12.0), friction=0.1)
    for env in (plain, wrapped, rubbing):
        env.reset(seed=0)
    states, torques = _cases(50)
    for state, torque in zip(states, torques):
        out = []
        for env in (plain, wrapped, rubbing):
            env.unwrapped.state = state.copy()
            env.step(np.array([torque]))
            out.append(env.unwrapped.state.copy())
        np.testing.assert_array_equal(out[1], out[0])
        if abs(state[1]) > 1.0 and abs(out[0][1]) < 7.9:  # not at the speed clip
            # friction 0.1 takes 3 * 0.1 * theta_dot * dt = 0.015 theta_dot off the speed
            assert abs(out[2][1] - out[0][1]) > 1e-3


def test_bad_friction_and_env_are_refused():
    with pytest.raises(ValueError, match="friction must be finite and >= 0"):
        PendulumFriction(gymnasium.make("Pendulum-v1"), friction=-0.1)
    with pytest.raises(ValueError, match="wraps Gymnasium's Pendulum-v1"):
        PendulumFriction(gymnasium.make("CartPole-v1"), friction=0.1)


def _worn_step(state, command, g, gain, deadband, coulomb):
    """``WornPendulum``'s step written out (float64): Gymnasium's semi-implicit Euler with the
    delivered torque ``gain (u - clip(u, -deadband, deadband)) - coulomb sign(theta_dot)``."""
    theta, speed = state
    u = np.clip(command, -2.0, 2.0)
    torque = gain * (u - np.clip(u, -deadband, deadband)) - coulomb * np.sign(speed)
    speed_next = np.clip(speed + (3 * g / 2 * np.sin(theta) + 3.0 * torque) * 0.05, -8.0, 8.0)
    cost = ((theta + np.pi) % (2 * np.pi) - np.pi) ** 2 + 0.1 * speed**2 + 0.001 * u**2
    return np.array([theta + speed_next * 0.05, speed_next]), -cost


@pytest.mark.parametrize(
    "worn", [{"gain": 0.8, "deadband": 0.3, "coulomb": 0.2, "g": 11.0}, {"gain": 0.5}]
)
def test_worn_pendulum_delivers_less_with_a_dead_band_and_dry_friction(worn):
    from diffcontrol.wrappers import WORN_PENDULUM_ID

    env = gymnasium.make(WORN_PENDULUM_ID, **worn)
    env.reset(seed=0)
    full = {"g": 10.0, "gain": 1.0, "deadband": 0.0, "coulomb": 0.0, **worn}
    states, torques = _cases()
    torques[3:6] = [0.1, -0.25, 0.35]  # inside and just past a dead band
    for state, torque in zip(states, torques):
        env.unwrapped.state = state.copy()
        _, reward, *_ = env.step(np.array([torque]))
        want, want_reward = _worn_step(state, torque, **full)
        np.testing.assert_allclose(env.unwrapped.state, want, rtol=0, atol=ATOL)
        assert abs(reward - want_reward) < ATOL
    env.close()


def test_an_unworn_pendulum_is_gymnasiums_and_bad_wear_is_refused():
    from diffcontrol.wrappers import WornPendulum

    plain = gymnasium.make("Pendulum-v1").unwrapped
    unworn = WornPendulum(gymnasium.make("Pendulum-v1"))
    states, torques = _cases(50)
    for state, torque in zip(states, torques):
        rewards = []
        for env in (plain, unworn):
            env.reset(seed=0)
            env.unwrapped.state = state.copy()
            rewards.append(env.step(np.array([torque]))[1])
        np.testing.assert_array_equal(unworn.unwrapped.state, plain.state)
        assert rewards[0] == pytest.approx(rewards[1], abs=1e-12)
    for bad, match in (({"gain": 0.0}, "gain must be in"), ({"gain": 1.5}, "gain must be in"),
                       ({"deadband": -1.0}, "deadband must be in"),
                       ({"coulomb": float("nan")}, "coulomb must be finite")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            WornPendulum(gymnasium.make("Pendulum-v1"), **bad)
    with pytest.raises(ValueError, match="wraps Gymnasium's Pendulum-v1"):
        WornPendulum(gymnasium.make("CartPole-v1"))
