"""Model-predictive control: a receding-horizon planner through the task's own simulator.

    planner = mpc.make_planner(task, mpc.ILQR(iterations=10), horizon=20)
    policy = mpc.PlannerPolicy(planner)        # obs -> Gymnasium action (needs JAX)
    states, actions, rewards, reports = jax.jit(planner.episode, static_argnums=1)(x0, 200)
    result = mpc.distil(task, planner, rounds=10)   # the MLP trained on the planner (DAgger)
    result.save("runs/distilled")                  # model.json: a NumPy policy like any other

Two solvers, as values: ``ILQR`` (box-constrained iLQR, as trajax and mpc.pytorch) and
``Shooting`` (gradient descent on the actions with any optax optimiser).
"""

from ._distil import distil, labelled_episodes
from ._ilqr import ILQR
from ._planner import Planner, make_planner
from ._policy import PlannerPolicy
from ._problem import Problem, SolveInfo
from ._shooting import Shooting

__all__ = [
    "ILQR",
    "Planner",
    "PlannerPolicy",
    "Problem",
    "Shooting",
    "SolveInfo",
    "distil",
    "labelled_episodes",
    "make_planner",
]
