"""The receding-horizon controller: plan H actions through the model, apply the first, shift."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PyTree

from ..errors import ConfigError
from ._ilqr import ILQR
from ._implicit import implicit_plan
from ._problem import Problem, SolveInfo, as_terminal_cost, stop_gradient
from ._shooting import Shooting

GRADIENTS = ("unroll", "implicit")
RELAXATIONS = {"sign": ((-1.0,), (1.0,)), "argmax": ((0.0,), (1.0,))}
"""The relaxed actions a planner plans for a head that makes a discrete action, per action
dimension: the push's sign in [-1, 1], an N-way choice's weights in [0, 1]."""
"""How a plan is differentiated (``make_planner(gradient=...)``)."""


class Planner(eqx.Module):
    """Model-predictive control of a task through its own differentiable simulator.

    At every control step the planner solves the finite-horizon problem from the current
    state, ``min sum_{k<H} loss(x_k, u_k) + terminal_weight * terminal_cost(x_H)`` with the
    task's ``step`` as the model and its step loss (``task.step_loss(loss)``, for Pendulum the
    Gymnasium cost) as the running cost, within the task's action bounds, and applies the first
    action of the plan; the next solve starts from the plan shifted by one step (its last action
    repeated). The solver is a value: ``ILQR()`` or ``Shooting(optax.adam(0.3))``. Every method
    is pure and jittable (one solve is one compiled program with a fixed iteration count);
    ``PlannerPolicy`` wraps a planner as a NumPy-facing controller for Gymnasium.

    Where a solve returns a non-finite plan, the planner applies the (finite, clipped) warm
    start instead and reports it in ``SolveInfo.finite``: never a NaN action.

    The plan is differentiable in the state and in the problem's arrays (the model's
    parameters, the terminal weight), so a planner can sit inside a trained controller or a
    closed-loop loss: ``gradient="unroll"`` differentiates through the solver's fixed
    iterations; ``gradient="implicit"`` differentiates the optimum itself by the implicit
    function theorem (``mpc._implicit``: the solver's iterations are not differentiated).

    Attributes:
        task: a ``Task`` with action bounds (``action_low``/``action_high``).
        solver: ``ILQR`` or ``Shooting`` (anything with ``solve(problem, x0, plan)``).
        horizon: H, the actions planned at every step (>= 1).
        problem: the model, costs and bounds (built from the arguments of ``make_planner``).
        bound_starts: also solve from the two constant plans at the bounds, keep the best.
        gradient: ``"unroll"`` or ``"implicit"``, how the plan is differentiated.
        warm_policy: a controller ``observation -> action`` (an ``MLPController`` or any
            ``eqx.Module``), or ``None``: every solve also starts from the plan it proposes
            (the policy run through the model for H steps) beside the shifted plan, and keeps
            the better result. Part of the PyTree, so it is trained through the planner
            (``mpc.learn_value``); with ``gradient="implicit"`` the optimum does not depend on
            where the solve started, so the policy gets no gradient there (use ``"unroll"``).
    """

    task: Any = eqx.field(static=True)
    solver: Any
    horizon: int = eqx.field(static=True)
    problem: Problem
    bound_starts: bool = eqx.field(static=True, default=False)
    gradient: str = eqx.field(static=True, default="unroll")
    warm_policy: Any = None

    @property
    def action_size(self) -> int:
        return self.problem.low.shape[0]

    def initial_plan(self) -> Float[Array, "H m"]:
        """The first warm start of an episode: the middle of the bounds (zero torque)."""
        mid = (self.problem.low + self.problem.high) / 2
        return jnp.broadcast_to(mid, (self.horizon, self.action_size))

    def proposal(self, state: Array) -> Float[Array, "H m"]:
        """The warm start ``warm_policy`` proposes from ``state``: the policy run through the
        model for H steps (its actions clipped to the bounds)."""
        problem, observe = self.problem, self.task.observe

        def one(x, _):
            u = jnp.clip(self.warm_policy(observe(x)), problem.low, problem.high)
            return problem.dynamics(x, u), u

        return jax.lax.scan(one, state, None, length=self.horizon)[1].astype(state.dtype)

    def plan(self, state: Array, warm: Float[Array, "H m"]) -> tuple[Array, SolveInfo]:
        """The plan ``[H, m]`` from ``state`` starting at the guess ``warm`` (and, where set,
        at ``warm_policy``'s proposal and the bounds: the best solve is kept), and its report."""
        problem, start = self.problem, state
        starts = [warm]
        if self.warm_policy is not None:
            starts.append(self.proposal(state))
        if self.gradient == "implicit":  # the solve itself is not differentiated
            problem, state, starts = stop_gradient((problem, state, starts))
        if self.bound_starts:
            shape = (self.horizon, self.action_size)
            starts += [jnp.broadcast_to(b, shape) for b in (problem.low, problem.high)]
        if len(starts) > 1:
            plan, info = self._best_of_starts(problem, state, jnp.stack(starts))
        else:
            plan, info = self.solver.solve(problem, state, starts[0])
        warm = starts[0]
        safe = jnp.clip(jnp.nan_to_num(warm), problem.low, problem.high)
        plan = jnp.where(info.finite, plan, safe)
        if self.gradient == "implicit":
            plan = implicit_plan(self.problem, start, plan)
        return plan, info

    def _best_of_starts(self, problem: Problem, state: Array, starts: Array):
        # Several solves at once: from the warm start, the policy's proposal and the two
        # constant plans at the bounds (full torque either way), which escape the local
        # optimum of a plan that does not swing (a pendulum hanging at rest); the lowest
        # finite cost wins. The problem is closed over (not vmapped: it may hold functions).
        plans, infos = jax.vmap(lambda s: self.solver.solve(problem, state, s))(starts)
        best = jnp.argmin(jnp.where(infos.finite, infos.cost, jnp.inf))
        return plans[best], jax.tree.map(lambda leaf: leaf[best], infos)

    def shift(self, plan: Float[Array, "H m"]) -> Float[Array, "H m"]:
        """The next warm start: ``plan[1:]`` with its last action repeated."""
        return jnp.concatenate([plan[1:], plan[-1:]])

    def control(self, state: Array, warm: Array) -> tuple[Array, Array, SolveInfo]:
        """One control step: ``(action, next warm start, report)``."""
        plan, info = self.plan(state, warm)
        return plan[0], self.shift(plan), info

    def episode(
        self, state: Array, steps: int, system: PyTree | None = None
    ) -> tuple[Array, Array, Array, SolveInfo]:
        """A closed-loop episode in the task's own simulator (``lax.scan``; jit it, ``vmap``
        it over starts): ``(states [steps+1, d], actions [steps, m], rewards [steps],
        reports stacked per step)``. ``system``: the simulated system's parameters where they
        differ from the planner's model (default the model's own)."""
        params = self.problem.params if system is None else system

        def one(carry, _):
            x, warm = carry
            u, warm, info = self.control(x, warm)
            nxt, reward, _ = self.task.step(params, x, u)
            return (nxt, warm), (nxt, u, reward, info)

        warm = self.initial_plan().astype(jnp.result_type(state, self.problem.low))
        _, (xs, us, rewards, infos) = jax.lax.scan(one, (state, warm), None, length=steps)
        return jnp.concatenate([state[None], xs]), us, rewards, infos


def _finite_nonneg(name: str, value: Any) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}={value!r} must be a number") from None
    if not math.isfinite(x) or x < 0:
        raise ConfigError(f"{name}={value!r} must be finite and >= 0")
    return x


def make_planner(
    task: Any,
    solver: Any = None,
    horizon: int = 20,
    params: PyTree | None = None,
    loss: str | None = None,
    step_loss: Callable | None = None,
    terminal_cost: Callable[[Array], Array] | None = None,
    terminal_weight: float = 1.0,
    bound_starts: bool = False,
    gradient: str = "unroll",
    bounds: tuple[Any, Any] | None = None,
    warm_policy: Any = None,
) -> Planner:
    """A ``Planner`` for ``task``, with its settings checked.

    Args:
        task: a discrete-time ``Task`` with action bounds.
        solver: ``ILQR()`` (the default) or ``Shooting(...)``.
        horizon: H >= 1, actions planned per step.
        params: the model's physical parameters (default ``task.default_params()``).
        loss: the name of the task's built-in step loss (default its first, ``task.losses[0]``).
        step_loss: a loss ``(params, state, action, next_state, reward) -> scalar`` instead.
        terminal_cost: ``cost(state) -> scalar`` of the plan's last state (e.g. minus a value
            function), or ``None``: a plain function (a constant of the solve) or an
            ``eqx.Module`` such as ``mpc.ValueNetwork``, whose arrays are part of the planner's
            PyTree and can be trained through it (``mpc.learn_value``).
        terminal_weight: its weight, finite and >= 0.
        bound_starts: also solve from the two constant plans at the action bounds at every
            step and keep the best of the three (three times the work; escapes local optima).
        gradient: how a derivative of the plan is taken: ``"unroll"`` (through the solver's
            iterations) or ``"implicit"`` (at the optimum, by the implicit function theorem).
        bounds: ``(low, high)`` of the planned actions, default the task's ``action_low`` and
            ``action_high``. A task whose head makes a discrete action has none: the planner
            then plans the relaxed action within the bounds given, by default ``RELAXATIONS``:
            [-1, 1] for a ``sign`` head (the CartPole's push, the force ``u * force_mag``),
            [0, 1] per choice for an ``argmax`` head (the Acrobot's weights of its three
            torques), and Gymnasium gets ``gym_action`` of it (the push's sign, the heaviest
            choice).
        warm_policy: a controller ``observation -> action`` whose H-step rollout through the
            model is one more start of every solve (see ``Planner``), or ``None``.

    Raises:
        ConfigError: a horizon < 1, a negative or non-finite weight or solver setting, a task
            without action bounds or without the loss named, an unknown gradient, a terminal
            cost or warm policy that is not callable.
    """
    solver = ILQR() if solver is None else solver
    for name, value in (("terminal_cost", terminal_cost), ("warm_policy", warm_policy)):
        if value is not None and not callable(value):
            raise ConfigError(f"{name}={value!r} is not callable; pass a function or a module")
    if gradient not in GRADIENTS:
        raise ConfigError(f"gradient={gradient!r} is not one of {GRADIENTS}")
    if isinstance(horizon, bool) or not isinstance(horizon, int | np.integer) or horizon < 1:
        raise ConfigError(f"horizon={horizon!r} must be an integer >= 1 (actions planned per step)")
    weight = _finite_nonneg("terminal_weight", terminal_weight)
    if isinstance(solver, ILQR | Shooting):
        if isinstance(solver.iterations, bool) or int(solver.iterations) < 1:
            raise ConfigError(f"iterations={solver.iterations!r} must be >= 1")
        _finite_nonneg("tol", solver.tol)
    if isinstance(solver, ILQR) and not _finite_nonneg("mu", solver.mu) > 0:
        raise ConfigError(f"mu={solver.mu!r} must be > 0 (the regularisation of Q_uu)")
    if not hasattr(solver, "solve"):
        raise ConfigError(f"solver={solver!r} is not a solver; use mpc.ILQR() or mpc.Shooting()")
    low, high = (task.action_low, task.action_high) if bounds is None else bounds
    if bounds is None and low is None and task.action_head in RELAXATIONS:
        low, high = (RELAXATIONS[task.action_head][i] * task.action_size for i in (0, 1))
    if low is None or high is None:
        raise ConfigError(
            f"task {task.name!r} has no action bounds; a planner needs them: pass "
            "bounds=(low, high) of the relaxed action"
        )
    try:
        low, high = (np.asarray(b, np.float32).reshape(-1) for b in (low, high))
    except (TypeError, ValueError):
        low = high = np.zeros(0, np.float32)  # refused below
    finite = np.all(np.isfinite(low)) and np.all(np.isfinite(high))
    if low.shape != (task.action_size,) or high.shape != low.shape or not finite:
        low = high = np.zeros(0, np.float32)
    if low.size == 0 or not np.all(low < high):
        raise ConfigError(
            f"bounds={bounds!r} must be two sequences of {task.action_size} finite numbers, "
            "low < high"
        )
    if step_loss is None:
        if not task.losses and loss is None:
            raise ConfigError(f"task {task.name!r} has no built-in loss; pass step_loss=...")
        name = loss or task.losses[0]
        if name not in task.losses:
            raise ConfigError(f"loss={name!r} is not one of task {task.name!r}'s {task.losses}")
        step_loss = task.step_loss(name)
    params = task.default_params() if params is None else params
    problem = Problem(
        task=task,
        step_loss=step_loss,
        terminal_cost=as_terminal_cost(terminal_cost),
        params=params,
        low=jnp.asarray(low),
        high=jnp.asarray(high),
        terminal_weight=jnp.asarray(weight, jnp.float32),
    )
    return Planner(
        task=task,
        solver=solver,
        horizon=int(horizon),
        problem=problem,
        bound_starts=bound_starts,
        gradient=gradient,
        warm_policy=warm_policy,
    )
