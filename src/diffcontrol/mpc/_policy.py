"""A planner as a NumPy-facing controller: ``policy(obs) -> Gymnasium action``."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._planner import Planner


class PlannerPolicy:
    """``policy(obs)``: one planner solve per call from the state behind the observation
    (``task.state_from_observation``), warm-started from the previous call's shifted plan.

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
        to_state = self.task.state_from_observation
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
        """The Gymnasium action for ``obs`` (``task.gym_action`` of ``action``). Right after
        ``action(obs)`` with the same observation (a recorder asking for both), that action,
        not a second solve: every solve advances the warm start."""
        last, self._last = self._last, None
        if last is not None and np.array_equal(last[0], np.asarray(obs, np.float32)):
            return self.task.gym_action(last[1])
        u = self.action(obs)
        self._last = None  # only an explicit action() call is reused (a pendulum at rest
        return self.task.gym_action(u)  # upright sees the same observation twice in a row)

    def summary(self) -> str:
        """One line: how many solves did not converge or fell back to the warm start."""
        n = len(self.reports)
        slow = sum(not r["converged"] for r in self.reports)
        bad = sum(not r["finite"] for r in self.reports)
        return f"{n} solves: {slow} not converged in the iteration budget, {bad} non-finite"
