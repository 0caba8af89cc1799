"""The start-up benchmark's user task: a planar quadrotor that must hover at the origin, in one
file as a user writes it (no ``fast_compile``: the library's choice of compile options is what
is measured).

Six states (x, z, pitch and their rates), two rotor thrusts each between 0 and the rotor's
maximum, an MLP of the default size; the dynamics are the rigid body's in the vertical plane,
stepped by semi-implicit Euler. Timed from this directory, cold and warm:

    cd benchmarks && python startup.py --tasks planar_quadrotor:PlanarQuadrotor --repeat 3 \
        --out results/startup_quadrotor.json
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

import diffcontrol


class QuadrotorParams(eqx.Module):
    mass: float = 0.5  # kg
    inertia: float = 0.01  # kg m^2, about the pitch axis
    arm: float = 0.15  # m, from the centre to each rotor
    gravity: float = 9.81  # m/s^2
    dt: float = 0.02  # s


MAX_THRUST = 4.0
"""Each rotor's largest thrust (N): together 1.6 times the weight."""


class PlanarQuadrotor(diffcontrol.Task):
    name = "planar-quadrotor"
    summary = "hover a planar quadrotor at the origin with two bounded rotor thrusts"
    episode_length = 200
    observation_size = 6
    action_size = 2
    action_head = "sigmoid"
    action_low, action_high = (0.0, 0.0), (MAX_THRUST, MAX_THRUST)
    losses = ("quadratic",)

    def default_params(self):
        return QuadrotorParams()

    def reset(self, key, params):
        # within 1 m of the origin, pitched up to 0.3 rad, moving up to 0.5 m/s
        scale = jnp.array([1.0, 1.0, 0.3, 0.5, 0.5, 0.5])
        return scale * jax.random.uniform(key, (6,), minval=-1.0, maxval=1.0)

    def step(self, params, state, action):
        x, z, pitch, vx, vz, rate = state
        thrust, torque = action[0] + action[1], (action[1] - action[0]) * params.arm
        vx = vx - thrust * jnp.sin(pitch) / params.mass * params.dt
        vz = vz + (thrust * jnp.cos(pitch) / params.mass - params.gravity) * params.dt
        rate = rate + torque / params.inertia * params.dt
        x, z, pitch = x + vx * params.dt, z + vz * params.dt, pitch + rate * params.dt
        next_state = jnp.stack([x, z, pitch, vx, vz, rate])
        reward = -(x**2 + z**2 + 0.5 * pitch**2 + 0.1 * (vx**2 + vz**2 + rate**2))
        return next_state, reward, jnp.asarray(False)

    def observe(self, state):
        return state

    def step_loss(self, name):
        return lambda params, state, action, next_state, reward: -reward

    def default_config(self):
        return diffcontrol.TrainConfig(
            updates=300, batch=32, window=50, horizon=200, learning_rate=3e-3
        )
