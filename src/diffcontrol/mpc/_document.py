"""A planner built back from its ``model.json`` document (``policies.planner_document``):
the settings and the model it plans through, the task's own simulator or a fitted model."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..errors import ConfigError, ModelFileError
from ..identify.fitted import fitted_physics, fitted_task
from ..identify.kinds import kind
from ..settings import PlanConfig
from ..tasks import AnyTask, task_params
from ._config import planner_from_config
from ._discretise import DiscretisedTask
from ._policy import PlannerPolicy, SampledPlannerPolicy
from ._value import ValueNetwork

REFERENCE_GRID_WORK = 401**2 * 41
"""The work of the 401-point grid with 41 actions (points per axis squared times actions)."""
MAX_LOADED_GRID_WORK = 4 * REFERENCE_GRID_WORK
"""The largest grid a planner read from a file solves when loaded: a few minutes on one core
(an 801-point grid with 41 actions). The command line's own --value-grid may ask for more."""


def planner_policy(task: AnyTask, doc: dict, progress: Callable[[str], None] | None = None) -> Any:
    """The ``mpc.PlannerPolicy`` of a planner's ``model.json`` document, for ``task`` (needs
    JAX; a terminal value grid is solved again from the stored settings).

    Raises:
        ModelFileError: the document is of another task, or its settings do not fit the task.
    """
    if doc["task"] != task.name:
        raise ModelFileError(
            f"the planner in this model.json plans through task {doc['task']!r}'s model, not "
            f"{task.name!r}'s; open it with its own task"
        )
    config = PlanConfig.from_json(doc["controller"]["settings"])
    value = None
    if "value" in doc["controller"]:
        try:
            value = ValueNetwork.from_json(task, doc["controller"]["value"])
        except ModelFileError as e:
            raise ModelFileError(f"model.json: {e}") from None
    try:
        return make_planner_policy(task, config, doc["controller"]["model"], progress, value)
    except ConfigError as e:
        raise ModelFileError(
            f"model.json: task {task.name!r} cannot take its planner: {e}"
        ) from None


def make_planner_policy(
    task: AnyTask,
    config: PlanConfig,
    model: dict,
    progress: Callable[[str], None] | None = None,
    value: Any = None,
) -> Any:
    """A ``PlannerPolicy``, or for a planner through a continuous task's discretisation a
    ``SampledPlannerPolicy`` (``policy(state)``, held for ``dt``).

    Raises:
        ConfigError: a terminal value grid of more than ``MAX_LOADED_GRID_WORK``.
    """
    if config.value_grid is not None:
        work = config.value_grid**2 * config.value_levels
        if work > MAX_LOADED_GRID_WORK:
            raise ConfigError(
                f"a terminal value grid of {config.value_grid} points per state axis and "
                f"{config.value_levels} actions is {work / REFERENCE_GRID_WORK:.0f} times the work "
                "of a 401-point grid (about 35 s on one core), solved again at every load; "
                "choose --value-grid 401 or less"
            )
    model_task, params = planning_model(task, model)
    planner = planner_from_config(model_task, config, params, progress=progress, value=value)
    if isinstance(planner.task, DiscretisedTask):
        return SampledPlannerPolicy(planner)
    return PlannerPolicy(planner)


def planning_model(task: AnyTask, model: dict, where: str = "model.json") -> tuple[AnyTask, Any]:
    """The task (with its simulator, or a fitted hybrid/neural model's) and the parameters a
    planner's ``model`` entry names.

    Raises:
        ModelFileError: a fitted model of another task, or a malformed entry.
    """
    if model.get("kind") == "simulator":
        return task, task_params(task)
    doc = model.get("fitted")
    if model.get("kind") != "fitted" or not isinstance(doc, dict):
        raise ModelFileError(f"{where}: the planner's model is neither the simulator nor fitted")
    try:
        fitted_physics(task, doc)  # refuses a model of another task
        network = kind(doc.get("model")).network
    except ConfigError as e:
        raise ModelFileError(f"{where}: {e}") from None
    if not network:
        return task, task_params(task, tuple(sorted(doc["all_parameters"].items())))
    fitted = fitted_task(task, doc)  # its default parameters are the model
    return fitted, fitted.default_params()
