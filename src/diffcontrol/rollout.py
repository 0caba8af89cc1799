"""Closed loops: discrete-time rollouts under ``lax.scan``, and continuous-time ODE solves.

A controller in closed loop with a task's simulator, differentiable end to end: the
discrete-time rollout is the unrolled graph that BPTT differentiates; the continuous-time
solve puts the controller inside an ODE's right-hand side and is differentiated through an
adaptive solver with a chosen gradient method (``GRADIENT_METHODS``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray, PyTree

from .config import GRADIENT_METHODS
from .tasks import ContinuousTask, Task

__all__ = [
    "GRADIENT_METHODS",
    "SOLVERS",
    "ODESolution",
    "Trajectory",
    "batch_returns",
    "force_fn",
    "rollout",
    "solve_closed_loop",
    "value_and_grad",
]

Controller = Callable[[Array], Array]


class Trajectory(eqx.Module):
    """One closed-loop rollout of ``T`` steps.

    ``alive[t]`` is true for the steps that count: those up to and including the step on
    which the episode terminated. Later steps are still simulated (shapes are static under
    ``jit``) but masked out of ``total_return``.
    """

    states: Float[Array, "T+1 state"]
    observations: Float[Array, "T obs"]
    actions: Float[Array, "T act"]
    rewards: Float[Array, " T"]
    terminated: Bool[Array, " T"]
    alive: Bool[Array, " T"]

    @property
    def total_return(self) -> Array:
        """Sum of the rewards of the steps that count."""
        return jnp.sum(jnp.where(self.alive, self.rewards, 0.0))

    @property
    def length(self) -> Array:
        """Number of steps that count (the episode length)."""
        return jnp.sum(self.alive)


def rollout(
    task: Task, params: PyTree, controller: Controller, state0: Array, num_steps: int
) -> Trajectory:
    """Run ``controller`` on ``task`` from ``state0`` for ``num_steps`` steps.

    Differentiable end to end with respect to ``params``, ``state0`` and the controller's
    weights: this is the unrolled computation graph that BPTT differentiates.
    """

    def body(carry, _):
        state, alive = carry
        obs = task.observe(state)
        action = controller(obs)
        next_state, reward, term = task.step(params, state, action)
        return (next_state, alive & ~term), (state, obs, action, reward, term, alive)

    (last, _), (states, obs, actions, rewards, term, alive) = jax.lax.scan(
        body, (state0, jnp.asarray(True)), None, length=num_steps
    )
    return Trajectory(
        states=jnp.concatenate([states, last[None]], axis=0),
        observations=obs,
        actions=actions,
        rewards=rewards,
        terminated=term,
        alive=alive,
    )


def batch_returns(
    task: Task, params: PyTree, controller: Controller, keys: PRNGKeyArray, num_steps: int
) -> Float[Array, " batch"]:
    """Returns of ``len(keys)`` episodes from the task's reset distribution (one per key)."""

    def one(key):
        return rollout(task, params, controller, task.reset(key, params), num_steps).total_return

    return jax.vmap(one)(keys)


# ---------------------------------------------------------------------------------------------
# Continuous-time closed loops: one adaptive ODE solve, with the solver and the gradient method
# as values.

SOLVERS: dict[str, str] = {
    "tsit5": "Tsit5",
    "dopri5": "Dopri5",
    "dopri8": "Dopri8",
    "bosh3": "Bosh3",
    "kvaerno5": "Kvaerno5",
}
"""Adaptive solvers by name (their Diffrax classes): explicit Runge-Kutta pairs, and
``kvaerno5`` (implicit, for stiff closed loops such as sharp Coulomb friction). Diffrax is
imported by the first solve, not with this module: a discrete-time run never loads it,
and no command's start-up waits for it."""

# How a loss is differentiated through the solve (``GRADIENT_METHODS``):
#
# - ``checkpoint``: discretise-then-optimise, reverse mode through the solver's own steps with
#   recursive checkpointing (``diffrax.RecursiveCheckpointAdjoint``): the exact gradient of the
#   discretised solve, storing a few checkpoints and recomputing the steps between them. The
#   default.
# - ``backsolve``: optimise-then-discretise, the continuous adjoint ODE solved backwards in time
#   (``diffrax.BacksolveAdjoint``), the method of the neural-ODE paper. Memory ``O(1)`` in the
#   number of steps, but **the gradient is approximate**: the adjoint and the re-solved state
#   carry the solver's error (about the tolerances), and unstable backwards dynamics can make it
#   worse. Use it only when memory is what limits you.
# - ``forward``: forward mode through the solver's steps (``diffrax.ForwardMode`` under
#   ``jax.jacfwd``): one tangent per weight, so the cost grows with the number of weights; the
#   cheapest for a few dozen (the post's 41-weight controller).


class StateFeedback(eqx.Module):
    """``force_fn(t, state) = controller(observe(state))``, the weights as PyTree leaves: the
    action vector, or for a task with one action that action as a scalar (the force)."""

    controller: Any
    observe: Any = eqx.field(static=True)

    def __call__(self, t: Array, state: Array) -> Array:
        action = self.controller(self.observe(state))
        return action[0] if action.shape == (1,) else action


def force_fn(task: ContinuousTask, controller: Any) -> StateFeedback:
    """The controller as the closed loop's input ``(t, state) -> action``: state feedback
    through ``task.observe``, as a PyTree whose leaves are the controller's weights."""
    return StateFeedback(controller, task.observe)


class ODESolution(eqx.Module):
    """A closed-loop solve saved at ``ts``: ``ys[k] = y(ts[k])``.

    ``ok`` is false when the solver failed (its step limit, a step too small); the saves after
    the failure are then ``inf``, and whoever uses them must mask the sample out or report the
    failure (the ODE trainer does both).
    """

    ts: Float[Array, " N"]
    ys: Float[Array, "N state"]
    ok: Bool[Array, ""]
    max_steps_reached: Bool[Array, ""]
    num_steps: Int[Array, ""]


def _adjoint(gradient: str):
    import diffrax

    if gradient == "checkpoint":
        return diffrax.RecursiveCheckpointAdjoint()
    if gradient == "backsolve":
        return diffrax.BacksolveAdjoint()
    if gradient == "forward":
        return diffrax.ForwardMode()
    raise ValueError(f"unknown gradient method {gradient!r}; choose one of {GRADIENT_METHODS}")


def solve_closed_loop(
    vector_field: Callable[[Array, Array, PyTree], Array],
    y0: Float[Array, " state"],
    save_ts: Float[Array, " N"],
    args: PyTree,
    *,
    solver: str = "tsit5",
    rtol: float = 1e-3,
    atol: float = 1e-6,
    max_steps: int = 4096,
    gradient: str = "checkpoint",
) -> ODESolution:
    """Solve ``dy/dt = vector_field(t, y, args)`` from ``y0`` at ``save_ts[0]`` to ``save_ts[-1]``.

    Adaptive steps (a PID step-size controller at ``rtol``/``atol``) with ``solver``, saved at
    ``save_ts`` (which may be traced, so a growing horizon does not recompile). Everything to
    be differentiated must reach the vector field through ``args`` (not a closure): the
    continuous adjoint only differentiates ``y0`` and ``args``. Never raises inside ``jit``:
    a failed solve comes back with ``ok = False``.

    Args:
        vector_field: ``f(t, y, args) -> dy/dt``.
        y0: the initial state.
        save_ts: increasing save times (s); the solve spans ``[save_ts[0], save_ts[-1]]``.
        args: the PyTree passed to ``vector_field`` (physical parameters, the controller).
        solver: a name from ``SOLVERS``.
        rtol: the step-size controller's relative tolerance.
        atol: the step-size controller's absolute tolerance.
        max_steps: the step budget; reaching it fails the solve.
        gradient: a name from ``GRADIENT_METHODS`` (how reverse or forward mode goes through).
    """
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    import diffrax  # here, not at the top: see SOLVERS

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        getattr(diffrax, SOLVERS[solver])(),
        t0=save_ts[0],
        t1=save_ts[-1],
        dt0=None,
        y0=y0,
        args=args,
        saveat=diffrax.SaveAt(ts=save_ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        adjoint=_adjoint(gradient),
        max_steps=max_steps,
        throw=False,
    )
    ok = sol.result == diffrax.RESULTS.successful
    return ODESolution(
        ts=save_ts,
        ys=sol.ys,
        ok=ok,
        max_steps_reached=sol.result == diffrax.RESULTS.max_steps_reached,
        num_steps=jnp.asarray(sol.stats["num_steps"]),
    )


def value_and_grad(fun: Callable[..., tuple[Array, Any]], gradient: str) -> Callable:
    """``fun(x, *args) -> (scalar, aux)`` to ``(value, aux), grad_x`` by the named method.

    ``checkpoint`` and ``backsolve`` are reverse mode (``equinox.filter_value_and_grad``);
    ``forward`` is ``equinox.filter_jacfwd`` (one tangent per weight of ``x``). The solve
    inside ``fun`` must use the same ``gradient`` (``solve_closed_loop(..., gradient=...)``).
    """
    if gradient == "forward":

        def forward(x, *args):
            def f(x):
                value, aux = fun(x, *args)
                return value, (value, aux)

            grads, (value, aux) = eqx.filter_jacfwd(f, has_aux=True)(x)
            return (value, aux), grads

        return forward
    if gradient in ("checkpoint", "backsolve"):
        return eqx.filter_value_and_grad(fun, has_aux=True)
    raise ValueError(f"unknown gradient method {gradient!r}; choose one of {GRADIENT_METHODS}")
