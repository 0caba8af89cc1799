"""What model learning asks of a task: the columns of its recorded data, the file they go to,
and the parameters a grey-box fit adjusts.

Each is a function of the task with its default here; a task changes one by defining a method
(or, for ``fit_parameter_names``, an attribute) of the same name (``tasks._hooks``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from jaxtyping import PyTree

from .._registry import env_id as own_env_id
from ..tasks import ContinuousTask
from ..tasks._hooks import task_hook


@task_hook
def data_columns(task: Any) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The observation and action columns (names with units) of the task's recorded data.

    Default: ``obs.0 [?]``, ... and ``action.0 [?]``, ... (``action.0 [index]`` for a discrete
    action); for a continuous-time task ``state.NAME [?]`` of its ``state_names``. A task that
    knows its units names them, and the Gymnasium environments of a task whose columns are
    observations with known units are recorded under these names
    (``identify.data.known_columns``): its ``gym_id``, its own ``diffcontrol/<Name>-v0`` and
    the ids it declares in ``data_env_ids`` (environments that are its system with other
    physics, e.g. ``diffcontrol/PendulumFriction-v0``).
    """
    if isinstance(task, ContinuousTask):
        return tuple(f"state.{n} [?]" for n in task.state_names), tuple(
            f"action.{j} [?]" for j in range(task.action_size)
        )
    obs = tuple(f"obs.{i} [?]" for i in range(task.observation_size))
    if task.action_head in ("sign", "argmax"):
        return obs, ("action.0 [index]",)
    return obs, tuple(f"action.{j} [?]" for j in range(task.action_size))


@task_hook
def data_file_name(task: Any, env_id: str | None = None) -> str:
    """The default file ``diffcontrol record`` writes (``ENV_ID`` with ``/`` as ``-``)."""
    own = env_id or task.gym_id or own_env_id(task)
    return own.replace("/", "-").replace(":", "-") + ".csv"


@task_hook
def step_seconds(task: Any, params: PyTree) -> float | None:
    """Simulated seconds per step, for time axes and recorded data: the parameter ``dt`` or
    ``tau`` where the parameters have one, else ``None`` (time is then in steps)."""
    for name in ("dt", "tau"):
        if hasattr(params, name):
            # a float32 parameter: its shortest decimal (0.05, not 0.05000000074505806)
            return float(str(np.asarray(getattr(params, name))[()]))
    return None


def fit_parameter_names(task: Any) -> tuple[str, ...]:
    """The physical parameters a grey-box fit (``--model params``) fits by default: the task's
    ``fit_parameter_names`` declaration, none by default."""
    return tuple(getattr(task, "fit_parameter_names", ()))
