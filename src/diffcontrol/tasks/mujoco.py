"""A task from a MuJoCo model: the physics is MJX's step of an MJCF file (``systems.mjx``).

A subclass names the model (``model_file``: an MJCF path, or one of Gymnasium's assets), how
many physics steps an action lasts (``frame_skip``), its observation and its reward; reset,
step and the Gymnasium twin's state come from here. ``examples/mujoco_task.py`` is a user's
robot in one file; ``diffcontrol.builtin.mujoco`` holds Gymnasium's own environments.

The state is ``concat(qpos, qvel, extras)``: MuJoCo's positions and velocities, then whatever
the observation reads from a step's ``Data`` besides them (``extras``: the double pendulum's
constraint force), so that ``observe`` is a function of the state alone.
"""

from __future__ import annotations

import abc
import functools
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, PRNGKeyArray

from ..systems.mjx import MjxSystem
from ._base import Task


class MujocoParams(eqx.Module):
    """The physical parameters of a MuJoCo task: none beyond its model file (the masses,
    lengths and gears live in the ``mjx.Model``). A dataclass, as every task's parameters."""


class MujocoTask(Task):
    """A discrete-time task whose system is a MuJoCo model stepped by MJX.

    Class attributes (besides those of every task):
        model_file: the MJCF file: a path, or the name of one of Gymnasium's assets
            (``"inverted_double_pendulum.xml"``).
        frame_skip: physics steps per action (Gymnasium's ``frame_skip``).
        reset_noise_scale, reset_velocity: ``reset`` draws ``qpos0 + U(-s, s)`` and velocities
            ``s N(0, 1)`` (``"normal"``) or ``U(-s, s)`` (``"uniform"``), Gymnasium's two usual
            schemes; override ``initial_qpos_qvel`` for another.
        solver_iterations: the constraint solver's iterations (1: reverse mode needs it).
        gradient: how a step is differentiated (``systems.mjx``): ``"smooth"`` (the step
            without its constraint solver) or ``"exact"`` (forward mode).
        camera: ``animate``'s view, ``(name, value)`` pairs of MuJoCo's ``MjvCamera``
            (``("distance", 4.0)``, ``("elevation", -20)``) over its default: the whole model,
            following its centre of mass (``tasks._mujoco_frames``).

    A subclass defines ``observe(state)`` and ``reward(state, action, next_state, data)``
    (``data``: MJX's ``Data`` after the step), and ``extras(data)`` if its observation reads
    more of a step than ``qpos`` and ``qvel``.
    """

    model_file: ClassVar[str]
    frame_skip: ClassVar[int] = 1
    reset_noise_scale: ClassVar[float] = 0.1
    reset_velocity: ClassVar[str] = "normal"
    solver_iterations: ClassVar[int] = 1
    gradient: ClassVar[str] = "smooth"
    camera: ClassVar[tuple[tuple[str, Any], ...]] = ()
    extras_size: ClassVar[int] = 0
    losses: ClassVar[tuple[str, ...]] = ("cost",)

    @functools.cached_property
    def system(self) -> MjxSystem:
        """The model on the device, loaded when first stepped (not when the task is made)."""
        return MjxSystem(self.model_file, iterations=self.solver_iterations, gradient=self.gradient)

    @property
    def dt(self) -> float:
        """Seconds per action: ``frame_skip`` physics steps."""
        return self.system.dt * self.frame_skip

    def default_params(self) -> MujocoParams:
        return MujocoParams()

    def reset(self, key: PRNGKeyArray, params: Any) -> Array:
        del params
        qpos, qvel = self.initial_qpos_qvel(key)
        state = jnp.concatenate([qpos, qvel])
        if not self.extras_size:
            return state
        # What Gymnasium's reset observes: set_state's mj_forward of the new state.
        return jnp.concatenate([state, self.extras(self.system.forward(state))])

    def initial_qpos_qvel(self, key: PRNGKeyArray) -> tuple[Array, Array]:
        """``(qpos, qvel)`` of a new episode: ``qpos0 + U(-s, s)``, and ``s N(0, 1)`` or ``U(-s,
        s)`` velocities (``reset_velocity``), ``s = reset_noise_scale``."""
        sys, scale = self.system, self.reset_noise_scale
        k_pos, k_vel = jax.random.split(key)
        qpos = sys.init_qpos + jax.random.uniform(k_pos, (sys.nq,), minval=-scale, maxval=scale)
        if self.reset_velocity == "uniform":
            return qpos, jax.random.uniform(k_vel, (sys.nv,), minval=-scale, maxval=scale)
        return qpos, scale * jax.random.normal(k_vel, (sys.nv,))

    def step(self, params: Any, state: Array, action: Array) -> tuple[Array, Array, Array]:
        del params
        data = self.system.simulate(state, action, self.frame_skip)
        next_state = jnp.concatenate([data.qpos, data.qvel, self.extras(data)])
        reward, terminated = self.reward(state, action, next_state, data)
        return next_state, reward, terminated

    def extras(self, data: Any) -> Array:
        """What the observation reads from a step's ``Data`` besides ``qpos`` and ``qvel``
        (``extras_size`` numbers; none by default)."""
        # jnp's dtype of qpos: Gymnasium's data is NumPy float64, which JAX may not allow.
        return jnp.zeros((self.extras_size,), jnp.asarray(data.qpos).dtype)

    @abc.abstractmethod
    def reward(
        self, state: Array, action: Array, next_state: Array, data: Any
    ) -> tuple[Array, Array]:
        """``(reward, terminated)`` of one step; ``data`` is MJX's ``Data`` after it."""

    def step_loss(self, name: str) -> Any:
        """``cost``: minus the step's reward (a subclass adds or replaces losses)."""
        if name == "cost":
            return lambda params, state, action, next_state, reward: -reward
        raise KeyError(name)

    def frames(self, recording: Any, every: int) -> Any:
        """``animate``'s frames: MuJoCo's renderer where OpenGL is there, else matplotlib
        (``tasks._mujoco_frames``)."""
        from ._mujoco_frames import frames

        return frames(self, recording, every)

    def qpos(self, state: Array) -> Array:
        """The positions in ``state``."""
        return state[: self.system.nq]

    def qvel(self, state: Array) -> Array:
        """The velocities in ``state``."""
        nq = self.system.nq
        return state[nq : nq + self.system.nv]

    def body_id(self, name: str) -> int:
        """The index of the model's body ``name`` (for ``data.xpos[...]``)."""
        return self.system.body_id(name)

    def gym_state(self, env: Any) -> np.ndarray:
        """The state of Gymnasium's MuJoCo environment: its ``qpos``, ``qvel`` and the
        ``extras`` read from its ``MjData`` (the fields MJX's ``Data`` names alike)."""
        data = env.unwrapped.data
        extras = np.asarray(self.extras(data), np.float64).reshape(-1)
        return np.concatenate([data.qpos, data.qvel, extras]).astype(np.float64)

    def set_gym_state(self, env: Any, state: np.ndarray) -> None:
        """Put Gymnasium's MuJoCo environment into ``state`` (``set_state(qpos, qvel)``)."""
        nq, nv = self.system.nq, self.system.nv
        state = np.asarray(state, np.float64)
        env.unwrapped.set_state(state[:nq], state[nq : nq + nv])
