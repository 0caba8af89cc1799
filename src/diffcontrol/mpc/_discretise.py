"""A continuous-time task seen as a discrete-time one, so that a planner can take it.

``discretise(task, dt)`` holds the action constant over each control period ``dt`` (a
zero-order hold, as a digital controller applies it) and integrates the task's vector field
over the period with the classical fourth-order Runge-Kutta method in ``substeps`` fixed steps.
The result is a ``Task`` with a ``step``, the task's planning losses as step losses (by
default each trajectory loss as ``DwellingCost``), and its reset distribution, so
``make_planner(discretise(task, 0.05), ILQR(), horizon=40, bounds=((-6,), (6,)))`` plans
through the ODE model. ``ode_episode`` then runs such a planner against the continuous system
itself (the action held for ``dt`` in an adaptive solve).

Why a hand-written fixed-step RK4 rather than ``diffrax.diffeqsolve``: the step sits inside
iLQR's linearisation, where it is differentiated by ``jax.jacfwd`` and, through the loss, by
``jax.hessian`` at every step of the plan in every iteration. Four evaluations of the vector
field per substep are a short straight-line program that forward and reverse mode both go
through at the cost of the arithmetic, smooth in the state and the action (a fixed step has no
step-size decisions, which would make the model piecewise). A ``diffeqsolve`` is a
``while_loop`` with an adjoint (reverse-mode only for the default, forward-mode only for
``ForwardMode``), and diffrax 0.7 has no classical RK4 to step by hand. The error per period is
``O(dt^5)``; ``tests/test_mpc_swingup.py`` checks it against a ``Dopri8`` solve at 1e-10.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PyTree

from ..errors import ConfigError
from ..rollout import solve_closed_loop
from ..tasks._base import ContinuousTask, Task
from ..tasks._hooks import task_hook


class HeldAction(eqx.Module):
    """``force_fn(t, state) = action``: the zero-order hold, as the vector field's input, in
    the shape the training's ``force_fn`` gives (``rollout.StateFeedback``: a one-action
    task's action as a scalar)."""

    action: Array

    def __call__(self, t: Array, state: Array) -> Array:
        return self.action[0] if self.action.shape == (1,) else self.action


def rk4_hold(task: ContinuousTask, params: PyTree, y: Array, action: Array, dt: float,
             substeps: int = 1) -> Array:  # fmt: skip
    """``y`` after ``dt`` seconds of ``task``'s vector field with ``action`` held: classical
    RK4 in ``substeps`` equal steps (time starts at 0; the vector fields here are
    autonomous)."""
    args = (params, HeldAction(action))
    h = dt / substeps

    def f(y):
        return task.vector_field(0.0, y, args)

    for _ in range(substeps):  # unrolled: a handful of steps, straight-line code
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def planning_losses(task: Any) -> tuple[str, ...]:
    """The losses a planner can plan a continuous-time task with: the task's
    ``planning_losses`` declaration (each with a ``running_cost``), else its trajectory
    losses (``losses``), each planned with the cost derived from it (``DwellingCost``)."""
    declared = getattr(task, "planning_losses", None)
    return tuple(declared if declared is not None else getattr(task, "losses", ()))


@task_hook
def running_cost(task: Any, name: str) -> Callable[[PyTree, Array, Array], Array]:
    """``rate(params, y, action)``: the cost per second of the planning loss ``name``, the
    additive counterpart of the trajectory loss of that name (``discretise`` integrates it over
    each control period). Default: ``DwellingCost`` of the task's trajectory loss ``name``.

    Raises:
        ConfigError: the task has no trajectory loss of that name.
    """
    if name not in getattr(task, "losses", ()):
        raise ConfigError(f"task {task.name!r} has no planning loss {name!r} (running_cost)")
    return DwellingCost(task, name)


@dataclasses.dataclass(frozen=True)
class DwellingCost:
    """The trajectory loss ``name`` of a trajectory that stays at ``y`` under ``action`` (two
    saved points, one second apart): for a loss that averages a cost of the state and the
    action over the saved points (plus end terms), that cost, up to its weights. What a task
    that declares no ``running_cost`` is planned with (equal for equal arguments, so that
    equal planners compile once)."""

    task: Any
    name: str

    def __call__(self, params: PyTree, y: Array, action: Array) -> Array:
        ys = jnp.stack([y, y])
        trajectory = self.task.trajectory(params, _Hold(action), jnp.array([0.0, 1.0]), ys)
        return jnp.reshape(self.task.trajectory_loss(self.name)(trajectory), ())


class _Hold(eqx.Module):
    """A controller that gives ``action`` whatever it observes."""

    action: Array

    def __call__(self, observation: Array) -> Array:
        return self.action


@task_hook
def terminal_cost(task: Any, name: str) -> Callable[[PyTree, Array], Array] | None:
    """``cost(params, y)`` at the end of a plan for the planning loss ``name``, or ``None``
    (the default)."""
    return None


class DiscretisedTask(Task):
    """A ``ContinuousTask`` with its action held for ``dt`` seconds per step (``discretise``).

    ``step(params, y, action) -> (y after dt, -dt * cost rate, False)``; ``step_loss(name)``
    is ``dt`` times the task's ``running_cost(name)`` (the reward is its negative, so a
    planner's step loss and the returned reward agree); ``terminal_cost(name, params)`` is the
    continuous task's end cost, for ``make_planner(..., terminal_cost=...)``. The state is the
    continuous task's whole ODE state; ``reset`` and ``observe`` are the task's own; an episode
    is the task's horizon in periods.
    """

    episode_length = 1  # replaced per instance

    def __init__(self, task: ContinuousTask, dt: float, substeps: int = 1):
        self.continuous = task
        self.dt = dt
        self.substeps = substeps
        self.name = task.name
        self.summary = f"{task.summary} (zero-order hold, dt = {dt:g} s)"
        self.observation_size = task.observation_size
        self.action_size = task.action_size
        self.action_head = task.action_head
        self.action_low, self.action_high = task.action_low, task.action_high
        self.losses = planning_losses(task)
        self.state_labels = getattr(task, "state_labels", ())
        self.action_labels = getattr(task, "action_labels", ())
        horizon_s = getattr(task.default_config(), "horizon_s", None)
        self.episode_length = max(1, round(horizon_s / dt)) if horizon_s else 1

    # Equal views of the same task are one task, so that planners rebuilt from the same
    # settings (a run written, then loaded) share their compiled programs.
    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and (other.continuous, other.dt, other.substeps) == (
            self.continuous,
            self.dt,
            self.substeps,
        )

    def __hash__(self) -> int:
        return hash((type(self), self.continuous, self.dt, self.substeps))

    def default_params(self) -> PyTree:
        return self.continuous.default_params()

    def state_grid(self, params: PyTree) -> Any:
        grid = getattr(self.continuous, "state_grid", None)  # a ContinuousTask may define one
        return None if grid is None else grid(params)

    def default_config(self) -> Any:
        return self.continuous.default_config()

    def reset(self, key, params) -> Array:
        return self.continuous.reset(key, params)

    def observe(self, state: Array) -> Array:
        return self.continuous.observe(state)

    def step(self, params: PyTree, state: Array, action: Array):
        nxt = rk4_hold(self.continuous, params, state, action, self.dt, self.substeps)
        rate = running_cost(self.continuous, self.losses[0])(params, state, action)
        return nxt, -self.dt * rate, jnp.zeros((), bool)

    def step_loss(self, name: str):
        if name not in self.losses:
            raise ConfigError(f"loss={name!r} is not one of task {self.name!r}'s {self.losses}")
        return PeriodCost(running_cost(self.continuous, name), self.dt)

    def terminal_cost(self, name: str, params: PyTree | None = None):
        """``cost(state)`` at the end of a plan (the continuous task's ``terminal_cost`` with
        ``params``, default the task's), or ``None`` where it has none."""
        params = self.default_params() if params is None else params
        end = terminal_cost(self.continuous, name)
        return None if end is None else EndCost(end, params)


@dataclasses.dataclass(frozen=True)
class PeriodCost:
    """A step loss: ``dt`` times the cost per second ``rate(params, state, action)`` (equal
    for equal arguments, so that equal planners compile once)."""

    rate: Any
    dt: float

    def __call__(self, params, state, action, next_state, reward):
        return self.dt * self.rate(params, state, action)


class EndCost(eqx.Module):
    """``cost(state) = end(params, state)``, the parameters as the module's leaves."""

    end: Any = eqx.field(static=True)
    params: PyTree

    def __call__(self, state: Array) -> Array:
        return self.end(self.params, state)


def discretise(task: ContinuousTask, dt: float, substeps: int = 1) -> DiscretisedTask:
    """``task`` as a discrete-time ``Task`` for planning: the action held over each period of
    ``dt`` seconds and the ODE integrated by RK4 in ``substeps`` steps (see the module).

    Raises:
        ConfigError: ``dt`` not a finite number > 0, ``substeps`` not an integer >= 1, or a
            task that is not a ``ContinuousTask`` or has no planning losses.
    """
    if not isinstance(task, ContinuousTask):
        raise ConfigError(
            f"task {getattr(task, 'name', task)!r} is not a continuous-time task; plan it "
            "directly with make_planner(task, ...)"
        )
    try:
        step = float(dt)
    except (TypeError, ValueError):
        step = math.nan
    if isinstance(dt, bool) or not math.isfinite(step) or step <= 0:
        raise ConfigError(f"dt={dt!r} must be a finite number of seconds > 0, e.g. dt=0.05")
    if isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1:
        raise ConfigError(f"substeps={substeps!r} must be an integer >= 1")
    if not planning_losses(task):
        raise ConfigError(
            f"task {task.name!r} has no planning losses; define its losses (trajectory_loss), "
            "or its running_cost and planning_losses, to plan it"
        )
    return DiscretisedTask(task, step, substeps)


def ode_episode(
    planner: Any,
    y0: Float[Array, " d"],
    steps: int,
    params: PyTree | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
) -> tuple[Array, Array, Any]:
    """A closed loop of ``planner`` (planning through a ``DiscretisedTask``) against the
    continuous system itself: at each period the planner plans from the true state and its
    first action is held for ``dt`` in an adaptive ``Dopri8`` solve of the task's vector field
    (``rollout.solve_closed_loop``). One ``lax.scan``; jit it, ``vmap`` it over starts.

    Returns ``(states [steps+1, d], actions [steps, m], reports stacked per step)``. Planner
    and system both work in the dtype of ``y0`` (the planner's arrays are cast to it): float64
    under ``jax.enable_x64`` for a reference. ``params``: the system's parameters where they
    differ from the planner's model.
    """
    ys, us, infos, _, _ = _ode_loop(planner, y0, steps, params, rtol, atol, None, None)
    return jnp.concatenate([y0[None], ys]), us, infos


def ode_closed_loop(
    planner: Any,
    y0: Float[Array, " d"],
    ts: Float[Array, " N"],
    params: PyTree | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    system: ContinuousTask | None = None,
) -> tuple[Array, Array, Any, Array]:
    """``ode_episode`` over ``[0, ts[-1]]`` (``ceil(ts[-1] / dt)`` periods), saved at the
    times ``ts`` (increasing, from 0) rather than at the control instants: what a reference
    solve of a sampled-data controller reports and draws. ``ts`` is concrete (NumPy): the
    loop is compiled here (``eqx.filter_jit``), once per planner and length.

    Returns ``(states [N, d] at ts, actions [N, m] held at ts, reports stacked per control
    step, ok)``: the action at ``t`` is the one held over the period that starts at or before
    it (at the last instant, the last period's); ``ok`` is whether every period's solve
    succeeded. Each period's solve also saves the instants of ``ts`` clipped into it, so the
    states are those of the same adaptive solves as ``ode_episode``'s. ``system``: the
    continuous task whose vector field is the true system (with ``params``), where it is not
    the one the planner's model discretises (a planner through a fitted model, judged on the
    real system).
    """
    ts = np.asarray(ts)
    dt = planner.task.dt
    steps = max(1, math.ceil(float(ts[-1]) / dt - 1e-9))
    _, us, infos, saved, ok = _ode_loop_jit(
        planner, y0, steps, params, rtol, atol, jnp.asarray(ts), system
    )
    period = np.clip(np.floor(ts / dt + 1e-9).astype(int), 0, steps - 1)
    ys = saved[period, np.arange(ts.shape[0])]
    return ys, us[period], infos, jnp.all(ok)


def _ode_loop(planner, y0, steps, params, rtol, atol, save_ts, system):
    disc = planner.task
    cont, dt = system or disc.continuous, disc.dt
    params = planner.problem.params if params is None else params
    dtype = y0.dtype
    planner = jax.tree.map(lambda a: a.astype(dtype) if eqx.is_inexact_array(a) else a, planner)
    sys_params = jax.tree.map(lambda p: jnp.asarray(p, dtype), params)
    inner = jnp.zeros((0,), dtype) if save_ts is None else jnp.asarray(save_ts, dtype)

    def one(carry, k):
        y, warm = carry
        u, warm, info = planner.control(y, warm)
        t0, t1 = k * dt, (k + 1) * dt
        ts = jnp.concatenate([jnp.stack([t0]), jnp.clip(inner, t0, t1), jnp.stack([t1])])
        sol = solve_closed_loop(
            cont.vector_field,
            y,
            ts.astype(dtype),
            (sys_params, HeldAction(u)),
            solver="dopri8",
            rtol=rtol,
            atol=atol,
            max_steps=10_000,
        )
        nxt = sol.ys[-1]
        return (nxt, warm), (nxt, u, info, sol.ys[1:-1], sol.ok)

    warm = planner.initial_plan().astype(dtype)
    ks = jnp.arange(steps)
    _, out = jax.lax.scan(one, (y0, warm), ks)
    return out


_ode_loop_jit = eqx.filter_jit(_ode_loop)
"""``_ode_loop`` compiled once per planner and length, shared by every call."""
