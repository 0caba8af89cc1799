"""The planning methods of ``compare``: the planner itself and the MLP distilled from it.

- ``planner``: ``mpc`` with Pendulum's best settings of docs/planning.md (iLQR, H = 10, three
  starts per step, terminal cost ``-V_0`` of a 401-point grid optimum). It is not trained:
  its environment steps are 0 and its "training" seconds are those of building it (the grid
  solve and the first compilation). It is deterministic, so every seed gives the same
  controller; it has a row per seed, so its rows line up with the others, but its episodes
  are run once per comparison (the later seeds reuse them).
- ``distilled``: ``mpc.distil(task, planner, seed=seed)`` with its defaults (DAgger into the
  task's default MLP); its steps are the planner's and the MLP's simulated steps, its seconds
  the distillation's. Its evaluation points are the simulator's, so its curve holds the final
  controller only.

Both are evaluated like every other method: ``eval_episodes`` episodes for the one curve point
and ``final_episodes`` for the final return, on the reset seeds ``eval_seed ...`` of the same
environment. They need no RL extra, and apply to tasks whose grid optimum the planner's
terminal value is built from (``state_grid``) and that have action bounds.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .. import _gym, policies
from ..errors import ConfigError
from ..evaluation import evaluate
from ..mpc import PlannerPolicy, distil, planner_from_config
from ..mpc._config import plans_best
from ..settings import PlanConfig
from ..tasks import Task
from .baselines import rl_setup
from .run import _final, _line, _point, evaluate_batch, numpy_policy_act

PLANNING_METHODS = ("planner", "distilled")
PLANNER = PlanConfig(horizon=10, value_grid=401)
"""The planner of ``compare`` (docs/planning.md: within 0.1 % of Pendulum's optimum)."""
DISTIL: dict = {}
"""Keyword arguments of ``mpc.distil`` (its defaults when empty)."""


def planning_methods(task: Task) -> list[str]:
    """``PLANNING_METHODS`` where the task's planner does best (``mpc._config.plans_best``)."""
    return list(PLANNING_METHODS) if plans_best(task) else []


def run_planning(
    method: str,
    task: Task,
    seed: int,
    memo: dict,
    *,
    eval_episodes: int,
    final_episodes: int,
    eval_seed: int,
    say: Callable[[str], None],
) -> dict:
    """Run ``method`` (``planner`` or ``distilled``) with ``seed``; ``memo`` keeps the planner
    (and its grid) between the calls of one comparison."""
    if "planner" not in memo:
        t0 = time.perf_counter()
        policy = PlannerPolicy(planner_from_config(task, PLANNER, progress=say))
        policy(np.asarray(_gym.observation_space(task).sample()))  # compiled here, counted here
        memo["planner"], memo["seconds"] = policy, time.perf_counter() - t0
    policy = memo["planner"]
    if method == "planner":
        steps, seconds, extra = 0, memo["seconds"], {"config": PLANNER.to_json()}

        def returns(episodes: int) -> np.ndarray:  # one planner: one episode after another
            # deterministic, so every seed's episodes are the first seed's: run them once
            key = ("returns", episodes, eval_seed)
            if key not in memo:
                memo[key] = evaluate(policy, task, episodes, eval_seed).returns
            return memo[key]

    else:
        result = distil(task, policy.planner, seed=seed, progress=say, **DISTIL)
        m = result.metrics
        steps, seconds = m["simulated_steps"], m["train_seconds"]
        extra = {"config": m["distillation"], "compile_seconds": m["compile_seconds"]}
        mlp = policies.NumpyPolicy(policies.controller_to_dict(result.controller, task, {}))

        def returns(episodes: int) -> np.ndarray:
            return evaluate_batch(numpy_policy_act(mlp), task, episodes, eval_seed)

    t0 = time.perf_counter()
    point = _point(steps, 0, seconds, returns(eval_episodes), task)
    say(_line(method, seed, point))
    final = returns(final_episodes)
    return {
        "method": method,
        "algo": _algo(method),
        "source": "diffcontrol.mpc (docs/planning.md)",
        "seed": seed,
        **extra,
        "env_steps": int(steps),
        "episodes": steps / task.episode_length,
        "train_seconds": seconds,
        "eval_seconds": time.perf_counter() - t0,
        "curve": [point],
        "final": _final(np.asarray(final)),
    }


def _algo(method: str) -> str:
    p = PLANNER
    value = f", terminal value -V_0 of a {p.value_grid}-point grid" if p.value_grid else ""
    planner = f"MPC: {p.solver}, H = {p.horizon}{value}"
    return planner if method == "planner" else f"DAgger distillation of ({planner}) into the MLP"


def methods_for(task: Task) -> list[str]:
    """The methods ``compare`` runs for ``task``: ``diffcontrol``, the planner and its distilled
    MLP where the task can take them (``compare._planning``), then its RL baselines.

    Raises:
        ConfigError: no RL baselines are defined for the task.
    """
    setup = rl_setup(task)
    if setup is None:
        from ..tasks import make, names  # the tasks that have them, for the message

        have = [n for n in names() if rl_setup(make(n)) is not None]
        raise ConfigError(
            f"no RL baselines are defined for task {task.name!r}; `compare` supports: "
            f"{', '.join(sorted(have))}"
        )
    return ["diffcontrol", *planning_methods(task), *setup.baselines]
