"""A planner as a NumPy-facing controller: ``policy(obs) -> Gymnasium action``."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .. import _gym
from ..evaluation import REFERENCE_ATOL, REFERENCE_RTOL
from ._discretise import ode_closed_loop
from ._planner import Planner


class PlannerPolicy:
    """``policy(obs)``: one planner solve per call from the state behind the observation
    (``state_from_observation``), warm-started from the previous call's shifted plan.

    Unlike the NumPy policies of ``model.json``, this one needs JAX at run time: every call runs
    one compiled solve (compiled on the first call). Call ``reset()`` at the start of each
    episode so that the first solve starts from ``planner.initial_plan()`` rather than from
    the last episode's plan. Every call's ``SolveInfo`` is kept, as NumPy scalars, in
    ``reports`` (``summary()`` counts them): a solve that did not converge in its iteration
    budget, or whose plan was not finite (the warm start was applied instead), shows there.
    """

    def __init__(self, planner: Planner):
        self.planner = planner
        self.task = planner.task
        to_state = _gym.state_from_observation.bound(self.task)
        # The planner is closed over (its arrays become constants of the program), so a call
        # passes two small arrays instead of flattening the planner's PyTree every step.
        self._control = jax.jit(
            lambda obs, warm: planner.control(to_state(jnp.asarray(obs, jnp.float32)), warm)
        )
        self.reports: list[dict[str, Any]] = []
        self.reset()

    def reset(self) -> None:
        """Start a new episode: the next solve is warm-started from the initial plan."""
        self._warm = self.planner.initial_plan()
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def action(self, obs: np.ndarray) -> np.ndarray:
        """The planner's action for ``obs`` (within the task's bounds), as a NumPy array."""
        obs = np.asarray(obs, np.float32)
        u, self._warm, info = self._control(obs, self._warm)
        self.reports.append({k: np.asarray(v).item() for k, v in vars(info).items()})
        self._last = (obs, np.asarray(u, np.float64))
        return self._last[1]

    def __call__(self, obs: np.ndarray) -> Any:
        """The Gymnasium action for ``obs`` (``gym_action`` of ``action``). Right after
        ``action(obs)`` with the same observation (a recorder asking for both), that action,
        not a second solve: every solve advances the warm start."""
        last, self._last = self._last, None
        if last is not None and np.array_equal(last[0], np.asarray(obs, np.float32)):
            return _gym.gym_action(self.task, last[1])
        u = self.action(obs)
        self._last = None  # only an explicit action() call is reused (a pendulum at rest
        return _gym.gym_action(self.task, u)  # upright sees the same observation twice in a row)

    def summary(self) -> str:
        """One line: how many solves did not converge or fell back to the warm start."""
        return solve_summary(self.reports)


class SampledPlannerPolicy:
    """A planner of a continuous-time task (planning through ``mpc.discretise``) as a
    sampled-data controller: ``policy(state) -> action``, to be **held for** ``policy.dt``
    seconds (a zero-order hold), then asked again with the state at the end of the period.

    The state is the physical state in the order of ``policy.state_names`` (for the swing-up
    cart-pole ``(x, x_dot, theta, theta_dot)`` in m, m/s, rad with 0 upright, rad/s), as a
    ``StatePolicy`` takes it, or the task's whole ODE state; the entries of the ODE state
    beyond the physical ones (integrals such as the impulse) are those of the task's initial
    state. The action is a float where the task has one (the force, N), else an array. One
    state per call, not a batch: like ``PlannerPolicy`` it needs JAX, runs one compiled solve
    per call (float32, compiled on the first call), warm-starts from the previous call's
    shifted plan (``reset()`` starts an episode) and keeps every solve's report in
    ``reports`` (``summary()`` counts them).

    ``closed_loop(system, params, y0, ts)`` runs it against the task's ODE itself
    (``mpc.ode_closed_loop``: the planner in the dtype of ``y0``, a Dopri8 solve per period)
    and is what a continuous-time task's reference solve calls for a controller that has it
    (``evaluation.simulate_continuous``).
    """

    def __init__(self, planner: Planner):
        self.planner = planner
        self.task = planner.task.continuous
        self.dt = float(planner.task.dt)
        self.state_names = tuple(self.task.state_names)
        self._rest = np.asarray(self.task.initial_state(planner.problem.params), np.float32)
        self._control = jax.jit(lambda y, warm: planner.control(y, warm))
        self.reports: list[dict[str, Any]] = []
        self.reset()

    def reset(self) -> None:
        """Start a new episode: the next solve is warm-started from the initial plan."""
        self._warm = self.planner.initial_plan()

    def ode_state(self, state: np.ndarray) -> np.ndarray:
        """The task's ODE state of ``state`` (the physical state, or the ODE state itself)."""
        s = np.asarray(state, np.float32).reshape(-1)
        if s.shape[0] not in (len(self.state_names), self._rest.shape[0]):
            raise ValueError(
                f"expected a state of {len(self.state_names)} values {self.state_names} (or "
                f"the task's ODE state of {self._rest.shape[0]}), got shape {np.shape(state)}"
            )
        return np.concatenate([s, self._rest[s.shape[0] :]])

    def __call__(self, state: np.ndarray) -> Any:
        """The action to hold for the next ``dt`` seconds from ``state``."""
        u, self._warm, info = self._control(self.ode_state(state), self._warm)
        self.reports.append({k: np.asarray(v).item() for k, v in vars(info).items()})
        u = np.asarray(u, np.float64)
        return float(u[0]) if u.shape == (1,) else u

    def closed_loop(self, system: Any, params: Any, y0: Any, ts: Any) -> tuple[Any, Any, Any]:
        """``(states [N, d], actions [N, m], ok)`` of the closed loop on the ODE of
        ``system`` (a continuous task: the true system, which may differ from the planner's
        model) with ``params`` from ``y0``, saved at the times ``ts`` (NumPy, increasing,
        from 0), in the dtype of ``y0`` (float64 under ``jax.enable_x64`` for a reference
        solve at 1e-9); every control step's report is added to ``reports``."""
        ys, us, infos, ok = ode_closed_loop(
            self.planner, y0, ts, params, REFERENCE_RTOL, REFERENCE_ATOL, system
        )
        infos = {k: np.asarray(v) for k, v in vars(infos).items()}
        n = len(next(iter(infos.values())))
        self.reports += [{k: v[i].item() for k, v in infos.items()} for i in range(n)]
        return ys, us, ok

    def summary(self) -> str:
        """One line: how many solves did not converge or fell back to the warm start."""
        return solve_summary(self.reports)


def solve_summary(reports: list[dict[str, Any]]) -> str:
    """One line: how many of the solves ``reports`` did not converge or were not finite."""
    slow = sum(not r["converged"] for r in reports)
    bad = sum(not r["finite"] for r in reports)
    return f"{len(reports)} solves: {slow} not converged in the iteration budget, {bad} non-finite"
