"""Pendulum swing-up: Gymnasium's ``Pendulum-v1``, and the unclipped variant of the 2019 original."""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np

from ..config import TrainConfig
from ..settings import PlanConfig
from ..systems import pendulum as pend
from ._base import StepLoss, Task
from ._grid import GridAxis


class Pendulum(Task):
    """Swing a pendulum up and hold it there with at most 2 N m of torque (``Pendulum-v1``).

    Training losses (per step, averaged over a window and the batch):

    - ``cost``: Gymnasium's cost ``wrap(theta)^2 + 0.1 theta_dot^2 + 0.001 u^2``, so the
      training objective is exactly minus the return.
    - ``squared_cost``: the cost squared, as in the 2019 Flux original (``mse(r, 0)``).
    """

    name = "pendulum"
    # The evaluation only: level 1 changes the chunk's bits in the original recipe.
    fast_compile = {"evaluate": ("xla_backend_optimization_level",)}
    summary = "Pendulum-v1 swing-up by BPTT through the exact Gymnasium dynamics (torque |u| <= 2)"
    gym_id = "Pendulum-v1"
    episode_length = pend.EPISODE_LENGTH
    observation_size = 3
    action_size = 1
    action_head = "tanh"
    action_low = (-2.0,)
    action_high = (2.0,)
    obs_scale = (1.0, 1.0, 1.0 / 8.0)
    reward_threshold = -200.0
    losses = ("cost", "squared_cost")
    state_labels = ("angle θ (rad, 0 = up)", "angular speed θ̇ (rad/s)")
    action_labels = ("torque (N m)",)
    positive_params = ("m", "l", "dt", "max_speed")
    nonnegative_params = ("max_torque", "friction")
    fit_parameter_names = ("g", "friction")
    real_start = (("g", 8.0), ("friction", 0.1))  # Pendulum-v1: g = 10, no friction
    data_env_ids = ("diffcontrol/PendulumFriction-v0",)  # Pendulum-v1 with joint friction
    model_recipe = "windows"
    """The recipe of training through a fitted network model, whose grid value would be
    solved through the network (``identify.model_task``)."""

    def data_columns(self):
        return ("obs.cos_theta [1]", "obs.sin_theta [1]", "obs.theta_dot [rad/s]"), (
            "action.torque [N m]",
        )

    def default_params(self) -> pend.PendulumParams:
        return pend.PendulumParams()

    def reset(self, key, params):
        return pend.reset(key, params)

    def step(self, params, state, action):
        torque = action[0]
        reward = -pend.cost(params, state, torque)
        return pend.step(params, state, torque), reward, jnp.asarray(False)

    def observe(self, state):
        return pend.observe(state)

    def frames(self, recording, every):
        """The pendulum from the front: the rod, the pivot, time and torque."""
        from ._scene import close, scene  # matplotlib

        fig, ax = scene(3.2, 3.2, (-1.3, 1.3), (-1.3, 1.3))
        (rod,) = ax.plot([], [], lw=6, color="#cc4d4d", solid_capstyle="round")
        ax.plot([0], [0], "ko", ms=5)
        text = ax.text(-1.25, 1.15, "", fontsize=8, family="monospace")
        for i in range(0, recording.states.shape[0], every):
            theta = recording.states[i, 0]
            rod.set_data([0, -np.sin(theta)], [0, np.cos(theta)])
            u = recording.actions[min(i, len(recording.actions) - 1), 0]
            text.set_text(f"t={i * recording.dt:5.2f} s  u={u:+.2f}")
            yield fig
        close(fig)

    def state_grid(self, params):
        """``theta`` wraps around ``[-pi, pi)``; ``theta_dot`` lies in the speed clip."""
        speed = float(np.asarray(params.max_speed))
        return GridAxis(-np.pi, np.pi, periodic=True), GridAxis(-speed, speed)

    def state_from_observation(self, observation):
        # theta = atan2(sin, cos) in [-pi, pi]: the observation cannot tell theta from
        # theta + 2 pi, and nothing downstream (dynamics, observation) can either.
        cos_theta, sin_theta, theta_dot = observation[0], observation[1], observation[2]
        return jnp.stack([jnp.arctan2(sin_theta, cos_theta), theta_dot])

    def step_loss(self, name: str) -> StepLoss:
        if name == "cost":
            return lambda params, state, action, next_state, reward: -reward
        if name == "squared_cost":
            return lambda params, state, action, next_state, reward: reward**2
        raise KeyError(name)

    def default_config(self) -> TrainConfig:
        # Truncated BPTT over 10-step windows, each ending on minus the value V_0 of the state
        # it leaves (the grid dynamic program: 201 x 201 states, 41 torques), so a push is
        # credited with the swing-up it leads to without a long window's local minima. 12,000
        # updates on 64 simulations, no early stop; the best of the evaluation points (every
        # 200 updates, on 512 simulated starts) is kept (keep_best). It ends about 2 % from the
        # grid optimum of Gymnasium's seeds 0-99 (docs/benchmarks.md).
        return TrainConfig(
            updates=12_000,
            batch=64,
            window=10,
            horizon=200,
            learning_rate=5e-3,
            lr_schedule="warmup_cosine",
            lr_final_fraction=0.05,
            grad_clip=1.0,
            hidden=(128, 128),
            activation="tanh",
            eval_every=200,
            eval_episodes=512,
            target_return=float("nan"),
            value_grid=201,
        )

    def default_plan_config(self) -> PlanConfig:
        """``diffcontrol plan pendulum``'s defaults: box-iLQR over H = 10 with the terminal
        cost ``-V_0`` of the 201-point grid optimum, the Pendulum's best planner within a
        load's seconds (docs/planning.md); ``--value-grid 0`` plans without it (H = 10 is too
        short a horizon then: add ``--horizon 20``)."""
        return PlanConfig(horizon=10, value_grid=201)

    def recipes(self) -> dict[str, dict[str, Any]]:
        return {
            # pendulum/DiffRL.jl@10bd26c: Dense(3,24,relu)-Dense(24,48,relu)-Dense(48,1), ADAM
            # 0.03, mse of the cost over 4-step windows, one update per window, one episode.
            "original": dict(
                updates=self.episode_length // 4,
                batch=1,
                window=4,
                horizon=self.episode_length,
                learning_rate=0.03,
                lr_schedule="constant",
                grad_clip=0.0,
                hidden=(24, 48),
                activation="relu",
                head="linear",
                loss="squared_cost",
                eval_every=self.episode_length // 4,
                eval_episodes=32,
                target_return=float("nan"),
                keep_best=False,  # the original keeps the last weights
                value_grid=0,
            ),
            # No terminal value: 20-step windows, shorter ones too myopic to learn the
            # swing-up, longer ones falling into the constant-torque local minimum; training
            # stops once an evaluation point reaches -145 (keep_best guards against a late
            # drift into holding starts near the bottom at the side). Faster than the
            # defaults, and further from the grid optimum (docs/benchmarks.md).
            "windows": dict(WINDOWS),
            # The window curriculum: 20-step windows alone level off below the optimum (they
            # cannot credit a push with a swing-up seconds later), so the last 2000 of 5000
            # updates use 80-step windows from the short window's controller; no early stop.
            "long-windows": dict(
                WINDOWS,
                updates=5000,
                final_window=80,
                final_window_fraction=0.4,
                target_return=float("nan"),
            ),
            # The defaults' terminal value with an evaluation point every 50 updates.
            "grid-value": dict(eval_every=50),
        }


WINDOWS: dict[str, Any] = dict(
    updates=3000,
    window=20,
    learning_rate=1e-2,
    eval_every=50,
    eval_episodes=256,
    target_return=-145.0,
    value_grid=0,
)
"""The ``windows`` recipe: what it changes in the pendulum's defaults."""


class PendulumUnclipped(Pendulum):
    """The 2019 original's variant: no torque clip, 1000-step episodes, unbounded controller.

    Evaluated in Gymnasium's own ``PendulumEnv`` with its ``max_torque`` set to infinity and a
    1000-step time limit, so the figures are comparable to the original's, not to the
    ``Pendulum-v1`` leaderboard.
    """

    name = "pendulum-unclipped"
    # The evaluation only: level 1 changes the chunk's bits in the original recipe.
    fast_compile = {"evaluate": ("xla_backend_optimization_level",)}
    summary = "the 2019 original's Pendulum: unclipped torque, 1000-step episodes"
    episode_length = 1000
    action_head = "linear"
    action_low = None
    action_high = None
    reward_threshold = None

    def default_params(self) -> pend.PendulumParams:
        return pend.PendulumParams(max_torque=float("inf"))

    def default_config(self) -> TrainConfig:
        # no action bounds, so no grid optimum: the windows recipe
        return super().default_config().replace(**WINDOWS, head="linear")

    def default_plan_config(self) -> PlanConfig:
        """No grid value (no action bounds to solve it within): ``PlanConfig``'s defaults."""
        return PlanConfig()

    def recipes(self) -> dict[str, dict[str, Any]]:
        recipe = dict(super().recipes()["original"])
        recipe.update(updates=self.episode_length // 4, horizon=self.episode_length, eval_every=50)
        return {"original": recipe}

    gym_label = "Pendulum-v1 (max_torque=inf, 1000-step limit)"

    def gym_action(self, action: np.ndarray) -> Any:
        return np.asarray(action, dtype=np.float64)

    def make_gym_env(self, **kwargs: Any):
        import gymnasium

        env = gymnasium.make(
            "Pendulum-v1",
            max_episode_steps=self.episode_length,
            disable_env_checker=True,  # actions beyond +-2 are the point of this variant
            **kwargs,
        )
        env.unwrapped.max_torque = np.inf
        return env
