"""Your robot from its MuJoCo model: a task from an MJCF file, trained by BPTT through MJX.

The robot here is Gymnasium's single inverted pendulum (its own ``inverted_pendulum.xml``);
put the path of your MJCF file in ``model_file``. A ``MujocoTask`` steps the model with MJX
``frame_skip`` physics steps per action; the task says what the controller observes, what a
step earns and what it is trained to minimise. Needs the mujoco extra:

    pip install -e ".[mujoco]"
    python examples/mujoco_task.py     # compiles (minutes on a CPU), trains, evaluates
"""

from __future__ import annotations

import jax.numpy as jnp

import diffcontrol
from diffcontrol.tasks.mujoco import MujocoTask


class Balance(MujocoTask):
    name = "balance"
    summary = "keep a pole upright on a cart (Gymnasium's InvertedPendulum-v5, through MJX)"
    gym_id = "InvertedPendulum-v5"  # judged in Gymnasium's own environment
    model_file = "inverted_pendulum.xml"  # or "path/to/your_robot.xml"
    frame_skip = 2
    reset_noise_scale = 0.01  # Gymnasium's: U(-0.01, 0.01) positions and speeds
    reset_velocity = "uniform"
    episode_length = 1000
    observation_size = 4  # cart x, pole angle, their speeds
    action_size = 1
    action_head = "tanh"
    action_low, action_high = (-3.0,), (3.0,)
    losses = ("upright",)

    def observe(self, state):
        return state  # (qpos, qvel)

    def reward(self, state, action, next_state, data):
        terminated = jnp.abs(next_state[1]) > 0.2  # the pole past 0.2 rad
        return jnp.where(terminated, 0.0, 1.0), terminated

    def step_loss(self, name):  # the reward has no gradient: train on the angle and speeds
        return lambda params, s, a, ns, r: ns[1] ** 2 + 0.1 * ns[3] ** 2 + 0.01 * ns[0] ** 2

    def default_config(self):
        return diffcontrol.TrainConfig(
            updates=200, batch=16, window=25, horizon=200, learning_rate=3e-3, eval_every=50
        )


def main(updates: int = 200) -> diffcontrol.TrainResult:
    task = diffcontrol.register(Balance())
    result = diffcontrol.train(task, task.default_config().replace(updates=updates), progress=print)
    first, last = result.curve[0]["eval_return"], result.curve[-1]["eval_return"]
    print(f"return of an episode: {first:.1f} untrained -> {last:.1f} trained")
    return result


if __name__ == "__main__":
    main()
