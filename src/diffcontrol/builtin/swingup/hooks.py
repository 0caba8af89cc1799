"""The cart-pole swing-ups beyond their tasks (``task``): their runs judged by a
float64 reference solve and drawn as a cart-pole (``runs``), and their model learnt from
recorded states (``fitted``: the swing-up's grey box, hybrid and neural models, its recording
and ``FittedSwingUp``, the task through a fitted model), registered with the layers' hooks
(``tasks._hooks``)."""

from __future__ import annotations

from typing import Any

from ...errors import ConfigError
from ...identify import ode
from ...identify.fitted import fitted_task
from ...identify.recording import record_task
from ...tasks import task_params
from . import (
    fitted,
    runs,  # noqa: F401  (registers evaluate_run, write_figures, animate_run)
)
from .task import CartPoleSwingUp

ode.nominal_model.register(CartPoleSwingUp)(lambda task, params: fitted.nominal_model(params))
ode.state_error.register(CartPoleSwingUp)(
    lambda task, pred, target: fitted.state_error(pred, target)
)


@ode.initial_model.register(CartPoleSwingUp)
def _initial_model(task, model_type, nominal, data, dt_s, hidden, key):
    """Zero friction, or a hybrid's network of the generalised forces of the velocities, or a
    neural network of the accelerations (``fitted.initial_model``)."""
    return fitted.initial_model(model_type, nominal, data, dt_s, hidden, key)


@ode.model_document.register(CartPoleSwingUp)
def _model_document(task: CartPoleSwingUp, model: Any) -> dict:
    return {k: v for k, v in fitted.model_to_dict(model).items() if k != "kind"}


@record_task.register(CartPoleSwingUp)
def _record(task, episodes, *, env_id=None, env_kwargs=None, controller=None,
            seed=0, max_steps=None, noise_m=None, progress=None):  # fmt: skip
    """The state and force at 50 Hz under random forces, of the cart-pole with this task's
    parameters changed by ``env_kwargs`` (``fitted.record_swingup``)."""
    for flag, value in (("--controller", controller), ("--max-steps", max_steps)):
        if value is not None:
            raise ConfigError(
                f"{flag} does not apply to recording {task.name}: its episodes are 5 s of "
                "random forces; drop it"
            )
    if noise_m is not None:
        raise ConfigError(f"--noise-m applies to aiming tasks only, not {task.name}; drop it")
    params = task_params(task, tuple((env_kwargs or {}).items()))
    if progress:
        changed = ", ".join(f"{n}={v:g}" for n, v in (env_kwargs or {}).items())
        progress(
            f"recording {episodes} episode(s) of the {task.name} cart-pole "
            f"({changed or 'its parameters'})"
        )
    return fitted.record_swingup(params, episodes, seed=seed)


@fitted_task.register(CartPoleSwingUp)
def _fitted_task(task: CartPoleSwingUp, doc: dict) -> fitted.FittedSwingUp:
    """The swing-up through a fitted ``SwingUpModel`` (``FittedSwingUp``), under the task's
    name (``model.json`` names the task the controller runs on)."""
    model = fitted.model_from_dict(doc, doc.get("_path", "the fitted model"))
    result = fitted.FittedSwingUp(task, model)
    result.name = task.name
    return result
