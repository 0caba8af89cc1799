"""A continuous-time task of your own, from a distribution of starts: swing a damped pendulum up.

phi'' = (g/l) sin(phi) - b phi' + u/(m l^2), phi = 0 upright, g = 9.81, l = m = 1, b = 0.1,
|u| <= 3 (less than the 9.81 it takes to lift the pendulum at once, so it must pump), each
start drawn around the hanging rest (phi = pi +- 0.3, phi' +- 0.2), 8 s, 16 starts per update.
The loss is the mean over the saved points of 1 - cos(phi) + 0.01 phi'^2, plus 5 times it at the
end. The library's defaults do the rest; from this directory:

    diffcontrol train damped_pendulum:DampedPendulum --out runs/damped   # about 45 s, one core
    diffcontrol evaluate runs/damped --task damped_pendulum:DampedPendulum

``benchmarks/user_continuous.py`` judges such runs on held-out starts with SciPy's DOP853.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

import diffcontrol


class Params(eqx.Module):
    g: float = 9.81
    b: float = 0.1


class Swing(eqx.Module):
    phi: jax.Array
    phidot: jax.Array


class DampedPendulum(diffcontrol.ContinuousTask):
    name = "user-damped-pendulum"
    summary = "swing a damped pendulum up (phi = 0 upright) with |u| <= 3"
    observation_size = 3
    action_size = 1
    action_head = "tanh"
    action_low, action_high = (-3.0,), (3.0,)
    losses = ("upright",)
    state_names = ("phi", "phidot")
    feature_names = ("cos(phi)", "sin(phi)", "phidot")

    def default_params(self):
        return Params()

    def default_config(self):
        return diffcontrol.ODETrainConfig(horizon_s=8, saves=81, starts=16, updates=500)

    def initial_state(self, params):
        return jnp.array([jnp.pi, 0.0])

    def reset(self, key, params):
        k1, k2 = jax.random.split(key)
        return jnp.array(
            [
                jnp.pi + jax.random.uniform(k1, minval=-0.3, maxval=0.3),
                jax.random.uniform(k2, minval=-0.2, maxval=0.2),
            ]
        )

    def vector_field(self, t, y, args):
        p, force_fn = args
        phi, phidot = y
        u = force_fn(t, y)
        return jnp.stack([phidot, p.g * jnp.sin(phi) - p.b * phidot + u])

    def observe(self, state):
        return jnp.stack([jnp.cos(state[0]), jnp.sin(state[0]), state[1]])

    def trajectory(self, params, controller, ts, ys):
        return Swing(phi=ys[:, 0], phidot=ys[:, 1])

    def trajectory_loss(self, name):
        def loss(tr):
            c = 1 - jnp.cos(tr.phi) + 0.01 * tr.phidot**2
            return jnp.mean(c) + 5 * c[-1]

        return loss
