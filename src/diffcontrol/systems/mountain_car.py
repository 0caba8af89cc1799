"""Gymnasium's ``MountainCarContinuous-v0`` as a pure, differentiable JAX program.

State ``(position, velocity)`` (Gymnasium's units: the position along the x-axis, the velocity
in position units per step). The observation is the state itself. One step, exactly as
``gymnasium.envs.classic_control.continuous_mountain_car.Continuous_MountainCarEnv.step``:

    force     = clip(a, -max_action, max_action)
    velocity' = clip(velocity + (force power - gravity cos(3 position)), -max_speed, max_speed)
    position' = clip(position + velocity', min_position, max_position)
    velocity' = 0  if position' == min_position and velocity' < 0    (the inelastic left wall)
    terminated = position' >= goal_position and velocity' >= goal_velocity
    reward    = 100 [terminated] - 0.1 a^2                             (a: the UNCLIPPED action)

The valley is the curve ``y = sin(3 x)`` (Gymnasium draws ``0.45 sin(3 x) + 0.55``); gravity's
pull along it is ``-gravity cos(3 x)``, so ``E = velocity^2 / 2 + gravity sin(3 x) / 3`` is the
mechanical energy, which the force changes by ``power * force`` per unit of distance (``energy``,
``energy_above_floor``).

Gymnasium stores the state as ``float32`` after every step (reward and termination use the
values before that rounding); this step keeps the dtype it is given, which is ``float32`` under
JAX's defaults.

Where the derivative is non-smooth:

- the force clip: zero gradient with respect to ``a`` when ``|a| > max_action`` (a ``tanh``
  head keeps actions inside); the reward's ``-0.1 a^2`` uses the unclipped action;
- the speed clip: zero gradient through ``velocity'`` while it is saturated at ``+-max_speed``;
- the position clip: zero gradient through ``position'`` at either end of ``[min_position,
  max_position]``;
- the left wall: where the car hits ``min_position`` moving left its velocity is set to 0, so
  the gradient of ``velocity'`` vanishes there (and the map jumps: a car one step short of
  the wall keeps its speed);
- the goal: ``terminated`` is a boolean with no derivative, and the +100 it brings is a step
  function of the state, so the return's gradient never sees the goal (a loss that wants the
  goal must shape it, see ``diffcontrol.tasks.mountain_car``).

Gymnasium truncates episodes at 999 steps.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from .draws import uniform

EPISODE_LENGTH = 999
"""Gymnasium's ``max_episode_steps`` for ``MountainCarContinuous-v0``."""

GOAL_REWARD = 100.0
"""The reward of the step that reaches the goal (plus that step's action cost)."""

ACTION_COST = 0.1
"""The reward's ``-ACTION_COST * a^2`` per step."""


class MountainCarParams(eqx.Module):
    """Physical constants of ``MountainCarContinuous-v0`` (Gymnasium's defaults).

    Every field is a PyTree leaf, so a batch of parameters can be ``vmap``ped (domain
    randomisation) and differentiated (system identification).
    """

    power: Float[Array, ""] | float = 0.0015
    """Velocity change per step of a unit force."""
    gravity: Float[Array, ""] | float = 0.0025
    """Amplitude of gravity's pull along the hill, ``-gravity cos(3 position)`` per step."""
    max_action: Float[Array, ""] | float = 1.0
    """The force clip: the plant applies ``clip(a, -max_action, max_action)``."""
    max_speed: Float[Array, ""] | float = 0.07
    """Velocity clip."""
    min_position: Float[Array, ""] | float = -1.2
    """The left wall: the position clip's lower end, where the car stops dead."""
    max_position: Float[Array, ""] | float = 0.6
    """The position clip's upper end."""
    goal_position: Float[Array, ""] | float = 0.45
    """The flag on the right hill: reached at ``position >= goal_position``."""
    goal_velocity: Float[Array, ""] | float = 0.0
    """...with ``velocity >= goal_velocity`` (Gymnasium's ``goal_velocity`` argument)."""
    reset_low: Float[Array, ""] | float = -0.6
    """Lower bound of the uniform initial position."""
    reset_high: Float[Array, ""] | float = -0.4
    """Upper bound of the uniform initial position (Gymnasium's ``options={"high": ...}``)."""


def reset(key: PRNGKeyArray, params: MountainCarParams | None = None) -> Float[Array, 2]:
    """Gymnasium's reset distribution: ``position ~ U(reset_low, reset_high)``, velocity 0."""
    params = MountainCarParams() if params is None else params
    position = uniform(key, (), minval=params.reset_low, maxval=params.reset_high)
    return jnp.stack([position, jnp.zeros_like(position)])


def clip_force(params: MountainCarParams, action: Array) -> Array:
    """The force the plant applies: ``clip(action, -max_action, max_action)``."""
    return jnp.clip(action, -params.max_action, params.max_action)


def step(
    params: MountainCarParams, state: Float[Array, 2], action: Float[Array, ""]
) -> Float[Array, 2]:
    """One Gymnasium step; returns the next state (module docstring for the formulas)."""
    position, velocity = state[0], state[1]
    force = clip_force(params, action)
    # Gymnasium's `velocity += force * power - 0.0025 * cos(3 * position)`: the bracket first.
    velocity = velocity + (force * params.power - params.gravity * jnp.cos(3 * position))
    velocity = jnp.clip(velocity, -params.max_speed, params.max_speed)
    position = jnp.clip(position + velocity, params.min_position, params.max_position)
    at_wall = (position == params.min_position) & (velocity < 0)
    velocity = jnp.where(at_wall, jnp.zeros_like(velocity), velocity)
    return jnp.stack([position, velocity])


def reached_goal(params: MountainCarParams, state: Float[Array, 2]) -> Bool[Array, ""]:
    """Gymnasium's termination of the step that ends in ``state``."""
    return (state[0] >= params.goal_position) & (state[1] >= params.goal_velocity)


def reward(
    params: MountainCarParams, action: Float[Array, ""], terminated: Bool[Array, ""]
) -> Float[Array, ""]:
    """Gymnasium's reward: ``100`` on reaching the goal, minus ``0.1 a^2`` (``a`` unclipped)."""
    del params
    return jnp.where(terminated, GOAL_REWARD, 0.0) - action**2 * ACTION_COST


def height(position: Array) -> Array:
    """The hill's profile ``sin(3 position)`` (Gymnasium draws ``0.45`` of it, raised by 0.55)."""
    return jnp.sin(3 * position)


def energy(params: MountainCarParams, state: Float[Array, 2]) -> Float[Array, ""]:
    """Mechanical energy ``velocity^2 / 2 + gravity sin(3 position) / 3`` per unit mass.

    Conserved by the unforced continuous-time motion ``x'' = -gravity cos(3 x)``; a force ``a``
    adds ``power * a`` per unit of distance travelled. The discrete step conserves it only
    approximately (within a few per cent of the valley's depth over a swing), and the clips
    and the wall remove energy.
    """
    return 0.5 * state[1] ** 2 + params.gravity * height(state[0]) / 3


def energy_above_floor(params: MountainCarParams, state: Float[Array, 2]) -> Float[Array, ""]:
    """``energy`` minus that of the car at rest at the bottom of the valley (``-gravity / 3``).

    Computed as ``velocity^2 / 2 + 2 gravity / 3 sin^2(3 position / 2 + pi / 4)``, the same
    number without the cancellation of ``1 + sin(3 position)`` near the bottom, so that small
    oscillations keep their relative precision in ``float32``.
    """
    swing = jnp.sin(1.5 * state[0] + jnp.pi / 4)
    return 0.5 * state[1] ** 2 + 2 * params.gravity / 3 * swing**2


def goal_energy_above_floor(params: MountainCarParams) -> Float[Array, ""]:
    """The least ``energy_above_floor`` that reaches the flag in continuous time: at rest on it
    (with ``goal_velocity`` if that is positive)."""
    v = jnp.maximum(params.goal_velocity, 0.0)
    swing = jnp.sin(1.5 * jnp.asarray(params.goal_position) + jnp.pi / 4)
    return 0.5 * v**2 + 2 * params.gravity / 3 * swing**2
