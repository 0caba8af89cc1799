"""Model-predictive control: a receding-horizon planner through the task's own simulator.

    planner = mpc.make_planner(task, mpc.ILQR(iterations=10), horizon=20)
    policy = mpc.PlannerPolicy(planner)        # obs -> Gymnasium action (needs JAX)
    states, actions, rewards, reports = eqx.filter_jit(planner.episode)(x0, 200)
    result = mpc.distil(task, planner, rounds=10)   # the MLP trained on the planner (DAgger)
    result.save("runs/distilled")                  # model.json: a NumPy policy like any other
    learned = mpc.learn_value(task, planner)        # a terminal value network, through the plan

A continuous-time task (the swing-ups) is planned through its discrete-time view,
``mpc.discretise(task, dt)`` (the action held for ``dt``, RK4), and run against its true ODE by
``mpc.ode_episode(planner, y0, steps)``; ``mpc.SampledPlannerPolicy(planner)`` is such a planner
as a controller that holds each action for ``dt`` (what ``diffcontrol.load`` gives of a
continuous-time task's planner). ``mpc.closed_loop_optimum`` solves a continuous-time task
with a state grid by dynamic programming on its discretised view: a reference to judge against.

A planner from stored settings: ``mpc.planner_from_config(task, PlanConfig(horizon=10))``;
``diffcontrol plan`` (``runs.plan_run``) writes one as a run directory that ``diffcontrol.load``
builds back. Two solvers, as values: ``ILQR`` (box-constrained iLQR, as trajax and mpc.pytorch) and
``Shooting`` (gradient descent on the actions with any optax optimiser). A plan is
differentiable in the state and the model's parameters, through the solver's iterations or, with
``make_planner(..., gradient="implicit")``, at the optimum (``_implicit``).
"""

from ._config import planner_from_config
from ._discretise import DiscretisedTask, discretise, ode_closed_loop, ode_episode
from ._distil import distil, labelled_episodes
from ._document import make_planner_policy, planner_policy, planning_model
from ._ilqr import ILQR
from ._learn import ValueResult, closed_loop_loss, learn_value, load_value
from ._optimum import ClosedLoopOptimum, closed_loop_optimum
from ._planner import Planner, make_planner
from ._policy import PlannerPolicy, SampledPlannerPolicy
from ._problem import Problem, SolveInfo
from ._shooting import Shooting
from ._value import ValueNetwork

__all__ = [
    "ClosedLoopOptimum",
    "DiscretisedTask",
    "ILQR",
    "Planner",
    "PlannerPolicy",
    "Problem",
    "SampledPlannerPolicy",
    "Shooting",
    "SolveInfo",
    "ValueNetwork",
    "ValueResult",
    "closed_loop_loss",
    "closed_loop_optimum",
    "discretise",
    "distil",
    "labelled_episodes",
    "learn_value",
    "load_value",
    "make_planner",
    "make_planner_policy",
    "ode_closed_loop",
    "ode_episode",
    "planner_from_config",
    "planner_policy",
    "planning_model",
]
