"""Mountain car: Gymnasium's ``MountainCarContinuous-v0``, with an energy-shaped training loss."""

from __future__ import annotations

from typing import Any, ClassVar

import jax.numpy as jnp

from ..config import TrainConfig
from ..settings import PlanConfig
from ..systems import mountain_car as mc
from ._base import StepLoss, Task
from ._grid import GridAxis


class MountainCarContinuous(Task):
    """Drive an underpowered car out of a valley to the flag on the right hill
    (``MountainCarContinuous-v0``): the engine cannot climb the hill directly, so the car has
    to rock back and forth to build up energy.

    Gymnasium's reward is ``-0.1 a^2`` per step plus 100 on the step that reaches the flag.
    Its gradient never sees the flag (a step function of the state), so for BPTT the return
    is the action cost alone, whose minimum is to do nothing: a car that never moves keeps a
    return of 0 where reaching the flag is worth about 100. The default loss replaces the
    flag by the energy the car still lacks, which is smooth and tells every push whether it
    helped.

    Training losses (per step, averaged over a window and the batch):

    - ``energy`` (default): the action cost plus the logarithmic energy the car still lacks,

          0.1 a^2 + deficit_weight * max(0, log((1 + energy_margin) L_goal / L(s')))

      with ``L = E - E_floor`` the mechanical energy above that of the car at rest at the
      bottom of the valley (``systems.mountain_car.energy_above_floor``) and ``L_goal`` that of
      the car at rest on the flag. Every step spent short of the flag's energy costs, which
      drives the car out in finite time; the action cost keeps the pushes gentle, since energy
      grows by ``power * a`` per unit of distance and small pushes over more swings reach the
      flag for a fraction of the cost of full throttle. Why a logarithm: pumping grows the
      energy geometrically, and the linear deficit's gradient is proportional to
      the energy, so a car started near the bottom (tiny swings) hardly pulls on the weights
      and the controller learns to leave it there; ``d log L = dL / L`` gives every swing the
      same pull. Why a margin: the discrete step does not conserve ``E`` exactly, so a car
      with exactly ``L_goal`` can fall short of the flag, where an unmargined deficit is
      already 0 and stops asking for more. ``deficit_weight`` sets the trade-off between time
      and effort (a much lower weight at times learns to fall short everywhere).
    - ``cost``: Gymnasium's own ``-reward``. Its gradient is that of the action cost alone, so
      BPTT from it learns to stand still (a return of about 0), unless every window ends on
      the value of the steps left, ``V_t`` of the grid optimum (``value_grid`` with
      ``value_time``: the recipe ``grid-value``).
    """

    name = "mountain-car-continuous"
    summary = (
        "MountainCarContinuous-v0 by BPTT through the exact Gymnasium dynamics, with an "
        "energy-shaped loss (the reward's flag has no gradient)"
    )
    gym_id = "MountainCarContinuous-v0"
    episode_length = mc.EPISODE_LENGTH
    observation_size = 2
    action_size = 1
    action_head = "tanh"
    action_low = (-1.0,)
    action_high = (1.0,)
    # Positions span [-1.2, 0.6] (centre -0.3, half-width 0.9), velocities [-0.07, 0.07].
    obs_offset = (-0.3, 0.0)
    obs_scale = (1.0 / 0.9, 1.0 / 0.07)
    reward_threshold = 90.0  # Gymnasium's spec
    losses = ("energy", "cost")
    state_labels = ("position", "velocity (per step)")
    action_labels = ("force",)
    positive_params = ("power", "max_action", "max_speed")

    deficit_weight: ClassVar[float] = 0.05
    """Weight of the logarithmic energy deficit per step in the ``energy`` loss."""
    energy_margin: ClassVar[float] = 0.05
    """The ``energy`` loss aims at ``1 + energy_margin`` times the flag's energy above the
    floor, since the discrete step's energy drifts by a few per cent over a swing."""

    def default_params(self) -> mc.MountainCarParams:
        return mc.MountainCarParams()

    def reset(self, key, params):
        return mc.reset(key, params)

    def step(self, params, state, action):
        next_state = mc.step(params, state, action[0])
        terminated = mc.reached_goal(params, next_state)
        return next_state, mc.reward(params, action[0], terminated), terminated

    def observe(self, state):
        return state

    def state_grid(self, params):
        """Position in its clip ``[min_position, max_position]``, velocity in ``+-max_speed``."""
        lo, hi = float(params.min_position), float(params.max_position)
        speed = float(params.max_speed)
        return GridAxis(lo, hi), GridAxis(-speed, speed)

    def state_from_observation(self, observation):
        # The observation is the state (Gymnasium's float32 copy of it).
        return jnp.asarray(observation)

    def step_loss(self, name: str) -> StepLoss:
        if name == "energy":
            weight, margin = self.deficit_weight, self.energy_margin

            def energy_loss(params, state, action, next_state, reward):
                target = (1 + margin) * mc.goal_energy_above_floor(params)
                # The floor keeps log finite for a car exactly at rest at the bottom (measure
                # zero; its gradient is 0 there anyway: a push at rest does no work).
                lift = jnp.maximum(mc.energy_above_floor(params, next_state), 1e-30)
                deficit = jnp.maximum(jnp.log(target) - jnp.log(lift), 0.0)
                return mc.ACTION_COST * action[0] ** 2 + weight * deficit

            return energy_loss
        if name == "cost":
            return lambda params, state, action, next_state, reward: -reward
        raise KeyError(name)

    def default_config(self) -> TrainConfig:
        # Windows of 100 steps, longer than a small swing's period (2 pi / sqrt(3 gravity),
        # about 73 steps), so a window sees what a push does over a whole swing; 64 cars side
        # by side; keep_best guards against an update that overshoots.
        return TrainConfig(
            updates=500,
            batch=64,
            window=100,
            horizon=0,
            learning_rate=1e-2,
            lr_schedule="cosine",
            grad_clip=1.0,
            hidden=(32, 32),
            activation="tanh",
            eval_every=50,
            eval_episodes=64,
        )

    def loop_planner(self) -> Any:
        """The planner's default settings (``PlanConfig()``), not the grid-valued one a task with
        a state grid gets by default: its terminal cost ``-V_0`` makes waiting free here (a car
        at rest can still reach the flag within a whole episode), so that planner stays at
        rest."""
        return PlanConfig()

    def recipes(self) -> dict[str, dict[str, Any]]:
        return {
            # Gymnasium's own reward (the ``cost`` loss) with no shaping: each 20-step window
            # ends on the value V_t of the grid dynamic program (101 x 101 states, 41 forces),
            # with the steps the episode has left. V_0 would not do: with a whole episode
            # always ahead, a car at rest can still reach the flag, so standing still costs
            # nothing and BPTT learns it. 1,000 updates with keep-best on 256 simulated starts:
            # fewer updates or starts can leave some starts at rest.
            "grid-value": dict(
                loss="cost",
                window=20,
                updates=1000,
                eval_episodes=256,
                value_grid=101,
                value_time=True,
            ),
        }

    def frames(self, recording: Any, every: int):
        """Matplotlib figures of a recorded episode, one per ``every`` steps: the hill
        ``sin(3 x)`` (drawn, like Gymnasium, as ``0.45 sin(3 x) + 0.55``), the car on it and the
        flag at ``goal_position``. The same figure is redrawn and yielded each time."""
        import numpy as np
        from matplotlib.patches import Rectangle

        from ._scene import close, scene  # matplotlib

        p = self.default_params()
        lo, hi, goal = p.min_position, p.max_position, p.goal_position

        def y(x):
            return 0.45 * np.sin(3 * x) + 0.55

        fig, ax = scene(4.8, 3.0, (lo - 0.05, hi + 0.05), (-0.05, 1.35))
        xs = np.linspace(lo, hi, 200)
        ax.plot(xs, y(xs), color="k", lw=1.5)
        ax.plot([lo, lo], [y(lo), y(lo) + 0.15], color="0.4", lw=3)  # the wall
        ax.plot([goal, goal], [y(goal), y(goal) + 0.25], color="k", lw=1)
        ax.fill(
            [goal, goal, goal + 0.12],
            [y(goal) + 0.25, y(goal) + 0.19, y(goal) + 0.22],
            color="#cccc00",
        )
        car = Rectangle((0, 0), 0.14, 0.06, color="#cc4d4d")
        ax.add_patch(car)
        text = ax.text(lo, 1.25, "", fontsize=8, family="monospace")
        for i in range(0, recording.states.shape[0], every):
            x = float(recording.states[i, 0])
            angle = np.arctan(1.35 * np.cos(3 * x))  # the slope of the drawn curve
            # The car's bottom-centre sits on the curve, tilted with it.
            c, s = np.cos(angle), np.sin(angle)
            car.set_xy((x - 0.07 * c, y(x) - 0.07 * s))
            car.set_angle(np.degrees(angle))
            a = recording.actions[min(i, len(recording.actions) - 1), 0]
            text.set_text(f"step {i:4d}  force {a:+.2f}")
            yield fig
        close(fig)
