"""CartPole balancing: Gymnasium's ``CartPole-v1`` with a straight-through discrete push."""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from ..config import TrainConfig
from ..systems import cartpole as cp
from ._base import StepLoss, Task


class CartPole(Task):
    """Keep the pole up and the cart on the track for 500 steps (``CartPole-v1``).

    The controller's ``sign`` head outputs ``+1`` (Gymnasium action 1, push right) or ``-1``
    (action 0, push left), with a straight-through gradient.

    Training losses (per step, on the post-step state, as in the 2019 original):

    - ``shaped``: ``(r - r_max)^2`` with ``r = max(0, 2.4 - |x|) max(0, 12 deg - |theta|)``, the
      product of two triangles (``r_max = 2.4 * 12 deg``), from cartpole/DiffRL.jl@10bd26c.
    - ``quadratic``: ``(x / 2.4)^2 + (theta / 12 deg)^2``, smooth everywhere.
    """

    name = "cartpole"
    # The evaluation keeps its bits; the chunk's weights round differently (by up to 3e-6),
    # but whole runs give the documented returns.
    fast_compile = {
        program: ("xla_backend_optimization_level", "xla_cpu_use_fusion_emitters")
        for program in ("chunk", "evaluate")
    }
    summary = "CartPole-v1 balancing with a straight-through sign push (exact Gymnasium dynamics)"
    gym_id = "CartPole-v1"
    episode_length = cp.EPISODE_LENGTH
    observation_size = 4
    action_size = 1
    action_head = "sign"
    obs_scale = (1 / 2.4, 1 / 2.0, 1 / 0.2095, 1 / 2.0)
    reward_threshold = 475.0
    losses = ("shaped", "quadratic")
    state_labels = (
        "cart position x (m)",
        "cart speed ẋ (m/s)",
        "pole angle θ (rad)",
        "pole speed θ̇ (rad/s)",
    )
    action_labels = ("push (±1 × 10 N)",)
    positive_params = (
        "masscart",
        "masspole",
        "length",
        "force_mag",
        "tau",
        "theta_threshold",
        "x_threshold",
    )

    # What a grey box fits by default: scaling both masses and the force together changes
    # nothing, so the masses stay nominal and gravity, the pole's length and the push are fitted.
    fit_parameter_names = ("gravity", "length", "force_mag")
    # compare --real's wrong start (CartPole-v1: gravity 9.8, half-length 0.5 m, push 10 N)
    real_start = (("gravity", 12.0), ("length", 0.8), ("force_mag", 7.0))

    def real_steps_per_round(self, model) -> int:
        # A random episode lasts ~20 steps, a good controller's 500: a round records real steps,
        # not episodes. 250 random steps (~12 episodes) determine the grey box's 3 parameters
        # and the hybrid's correction, so 2 rounds stay within a budget of 500 real steps; a
        # network alone needs its 1,000 transitions (2 rounds: 2,000).
        return 250 if model.physics else max(self.episode_length, model.min_transitions)

    def data_columns(self):
        return ("obs.x [m]", "obs.x_dot [m/s]", "obs.theta [rad]", "obs.theta_dot [rad/s]"), (
            "action.push [index]",
        )

    env_name = "CartPole"

    def frames(self, recording, every):
        """The cart on its track (limits in red) with the pole, time and push direction."""
        from ._scene import close, scene  # matplotlib

        fig, ax = scene(4.8, 2.4, (-2.6, 2.6), (-0.4, 1.3))
        ax.plot([-2.4, 2.4], [0, 0], color="0.5", lw=1)
        for x in (-2.4, 2.4):
            ax.plot([x, x], [-0.1, 0.1], color="r", lw=1)
        from matplotlib.patches import Rectangle

        cart = Rectangle((0, -0.1), 0.5, 0.2, color="k")
        ax.add_patch(cart)
        (pole,) = ax.plot([], [], lw=4, color="#ca9865", solid_capstyle="round")
        text = ax.text(-2.5, 1.15, "", fontsize=8, family="monospace")
        for i in range(0, recording.states.shape[0], every):
            x, _, theta, _ = recording.states[i]
            cart.set_x(x - 0.25)
            pole.set_data([x, x + np.sin(theta)], [0.0, np.cos(theta)])
            a = recording.actions[min(i, len(recording.actions) - 1), 0]
            text.set_text(f"t={i * recording.dt:5.2f} s  push {'→' if a >= 0 else '←'}")
            yield fig
        close(fig)

    def default_params(self) -> cp.CartPoleParams:
        return cp.CartPoleParams()

    def reset(self, key, params):
        return cp.reset(key, params)

    def step(self, params, state, action):
        next_state = cp.step(params, state, action[0])
        return next_state, jnp.asarray(1.0, next_state.dtype), cp.terminated(params, next_state)

    def observe(self, state):
        return cp.observe(state)

    def state_from_observation(self, observation):
        # The observation is the state (Gymnasium's float64 state rounded to float32).
        return jnp.asarray(observation)

    def step_loss(self, name: str) -> StepLoss:
        if name == "shaped":

            def shaped(params, state, action, next_state, reward):
                x, theta = next_state[0], next_state[2]
                r = jnp.maximum(0.0, params.x_threshold - jnp.abs(x)) * jnp.maximum(
                    0.0, params.theta_threshold - jnp.abs(theta)
                )
                return (r - params.x_threshold * params.theta_threshold) ** 2

            return shaped
        if name == "quadratic":

            def quadratic(params, state, action, next_state, reward):
                x, theta = next_state[0], next_state[2]
                return (x / params.x_threshold) ** 2 + (theta / params.theta_threshold) ** 2

            return quadratic
        raise KeyError(name)

    def default_config(self) -> TrainConfig:
        return TrainConfig(
            updates=150,  # 150 x 8 x 4 = 4,800 steps: 9.6 episodes of 500 steps
            batch=4,
            window=8,
            horizon=500,
            learning_rate=0.01,
            lr_schedule="cosine",
            grad_clip=1.0,
            hidden=(24, 48),
            activation="relu",
            eval_every=10,
            eval_episodes=16,
        )

    def recipes(self) -> dict[str, dict[str, Any]]:
        return {
            # cartpole/DiffRL.jl@10bd26c: Dense(4,24,relu)-Dense(24,48,relu)-Dense(48,1,tanh)-sign,
            # ADAM 0.03, shaped loss over 8-step windows, one episode at a time.
            "original": dict(
                batch=1,
                window=8,
                learning_rate=0.03,
                lr_schedule="constant",
                grad_clip=0.0,
                hidden=(24, 48),
                activation="relu",
                loss="shaped",
                keep_best=False,  # the original keeps the last weights
            )
        }

    def gym_action(self, action: np.ndarray) -> Any:
        return int(np.asarray(action).reshape(-1)[0] >= 0)
