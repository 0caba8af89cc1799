"""The routes of model learning: how a task's data is read, fitted, judged and drawn.

A task's route is ``model_route(task)`` (by base class: ``STEPS`` for a discrete-time
``Task``, ``ODE`` for a ``ContinuousTask``; a task with its own model, fit or plot overrides it
with its own route, a ``TrajectoryRoute`` subclass in the system's files), so
``identify.fit`` and ``identify.fit_dir`` never ask which system a task is. Each route has
the same methods: ``read(path)``, ``count(data)``, ``split(data, n)``, ``announce(...)`` (the
line said before fitting), ``fit(task, data, model_type, **settings)`` and ``outputs(...)``
(the route's part of ``fitted.json``, the lines it reports and ``prediction.png``), its
``unit`` (what ``count`` counts) and ``defaults`` (Adam's steps and learning rate by model
type); optionally ``check_model(task, model_type)`` (before anything is read) and
``check_split(task, data, train, held_out, settings)`` (after the hold-out is split off).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..tasks import Task
from ..tasks._hooks import task_hook
from ._shooting import HORIZONS, FitResult
from ._task import fit_parameter_names
from .data import read_trajectories
from .ensemble import Ensemble, ensemble_to_dict, mean_spread
from .hybrid import fit_model, model_task
from .network import correction_to_dict
from .ode import fit_vector_field, model_document, nominal_model
from .ode import prediction_errors as ode_prediction_errors
from .steps import fit_parameters, prediction_errors


def params_dict(params: Any) -> dict[str, float]:
    """Every field of a parameter PyTree as a plain float (fitted.json's ``all_parameters``)."""
    return {f.name: float(np.asarray(getattr(params, f.name))) for f in dataclasses.fields(params)}


def parameters_doc(result: FitResult) -> dict:
    """fitted.json's ``parameters``: per fitted name, its value, standard error and nominal."""
    return {
        n: {"value": v, "standard_error": result.standard_errors[n], "nominal": result.nominal[n]}
        for n, v in result.values.items()
    }


def errors_doc(what: str, errors: dict | None) -> dict | None:
    """fitted.json's ``prediction_error`` for per-horizon errors by model label."""
    if errors is None:
        return None
    by_label = {label: {str(h): e for h, e in by_h.items()} for label, by_h in errors.items()}
    return {"what": what, "horizons_steps": list(HORIZONS), **by_label}


def _title(task: Any, model_type: str, held_out: Any) -> str:
    return (
        f"{task.name} ({model_type}), {'held-out' if held_out is not None else 'fit'} "
        "episodes: open loop, restarted every 50 steps"
    )


def _data_doc(data_file: Any, train: Any, held_out: Any, **extra: Any) -> dict:
    return {
        "file": str(data_file),
        **extra,
        "fit_episodes": [e.id for e in train.episodes()],
        "held_out_episodes": [e.id for e in held_out.episodes()] if held_out else [],
        "fit_transitions": train.num_steps,
    }


class TrajectoryRoute:
    """What every route shares: the trajectory file (``read_trajectories``) and its split into
    episodes; subclasses define ``defaults``, ``fit`` and ``outputs``."""

    unit = "episode"

    def read(self, path: Any) -> Any:
        return read_trajectories(path)

    def count(self, data: Any) -> int:
        return data.num_episodes

    def split(self, data: Any, n: int) -> tuple[Any, Any]:
        return data.split(n)

    def announce(self, task, model_type, train, held_out, data_file, settings) -> str:
        names = settings.get("names") or fit_parameter_names(task)
        what = ", ".join(names) if model_type == "params" and names else f"a {model_type} model"
        return (
            f"fitting {what} of {task.name} to {train.num_episodes} episode(s) "
            f"({train.num_steps} transitions) of {data_file}, windows of "
            f"{settings.get('window', 10)} steps"
        )


class StepRoute(TrajectoryRoute):
    """A discrete-time task: its step with fitted parameters, or a hybrid or neural model."""

    defaults = {"params": (300, 0.02), "hybrid": (2000, 3e-3), "neural": (2000, 3e-3)}
    """Adam steps and learning rate by model type."""

    def fit(self, task: Any, data: Any, model_type: str, **s: Any) -> FitResult:
        if model_type == "params":
            _one_network(s, "a grey box (--model params) has no network")

            keys = ("window", "steps", "learning_rate", "lm_steps", "init")
            return fit_parameters(
                task, data, s.get("names"), **{k: s[k] for k in keys if s.get(k) is not None}
            )
        keys = ("params", "window", "steps", "learning_rate", "hidden", "seed", "members")
        keys += ("bootstrap", "uncertainty_penalty")
        return fit_model(task, data, model_type, **{k: s[k] for k in keys if s.get(k) is not None})

    def predictor(self, task: Any, result: FitResult | None) -> tuple[Any, Any]:
        """``(task, params)`` to predict with: the nominal model for ``None``."""
        if result is None:
            return task, task.default_params()
        if result.model_type == "params":
            return task, result.params
        return model_task(task, result.model), result.model

    def outputs(self, task, result, data, train, held_out, data_file, settings, out):
        from .plot import prediction_plot, task_predictor  # matplotlib

        nominal, fitted = self.predictor(task, None), self.predictor(task, result)
        errors = None
        if held_out is not None:
            errors = {
                "nominal": prediction_errors(*nominal, held_out),
                "fitted": prediction_errors(*fitted, held_out),
            }
        if result.model_type == "params":
            model_doc = {"parameters": parameters_doc(result)}
            model_doc["all_parameters"] = params_dict(result.params)
        else:
            c = result.model.correction
            net = ensemble_to_dict(c) if isinstance(c, Ensemble) else correction_to_dict(c)
            model_doc = {
                "all_parameters": params_dict(result.model.params),
                "network": {
                    "what": "hybrid: next state = the task's step with all_parameters + network("
                    "observation, action); neural: next state = state + network(observation, "
                    "action); an ensemble's members each give a network, the model uses their "
                    "mean, and training through it adds uncertainty_penalty times their spread "
                    "to every step's loss",
                    "inputs": "observation then action",
                    "parameters": result.num_parameters,
                    **net,
                },
            }
        fit_settings = dict(
            window_steps=result.window,
            windows=result.windows,
            adam_steps=settings["steps"],
            learning_rate=settings["learning_rate"],
        )
        if result.model_type == "params":
            fit_settings["lm_steps"] = settings.get("lm_steps", 20)
        else:
            fit_settings.update(hidden=list(settings["hidden"]), seed=settings["seed"])
            members = settings.get("members", 1)
            if members > 1:
                spread = {"fit": mean_spread(task, result.model, train)}
                if held_out is not None:
                    spread["held_out"] = mean_spread(task, result.model, held_out)
                fit_settings.update(
                    members=members,
                    bootstrap=bool(settings.get("bootstrap")),
                    uncertainty_penalty=settings.get("uncertainty_penalty"),
                    mean_spread=spread,
                )
        body = {
            **model_doc,
            "fit": fit_settings,
            "data": _data_doc(
                data_file,
                train,
                held_out,
                env_id=data.env_id,
                env_kwargs=data.metadata.get("env_kwargs"),
            ),
            "prediction_error": errors_doc(
                "RMS error of the observations H steps ahead, open loop from every recorded "
                "state of the held-out episodes with the recorded actions",
                errors,
            ),
        }
        prediction_plot(
            {"fitted": task_predictor(*fitted), "nominal": task_predictor(*nominal)},
            held_out if held_out is not None else train,
            out / "prediction.png",
            title=_title(task, result.model_type, held_out),
        )
        lines = []
        if result.model_type != "params":
            lines.append(
                f"{result.model_type} model: {result.num_parameters} weights, {result.message}"
            )
        if "mean_spread" in fit_settings:
            where = " / ".join(f"{v:.3g} ({k.replace('_', '-')})" for k, v in spread.items())
            lines.append(
                f"ensemble of {fit_settings['members']}: mean spread of the members {where}, "
                "in units of the typical state change"
            )
        if errors is not None:
            for h in HORIZONS:
                nom, fit = errors["nominal"][h]["rmse"], errors["fitted"][h]["rmse"]
                lines.append(
                    f"held-out RMS error {h:>2} steps ahead: nominal {nom:.3g}, fitted {fit:.3g}"
                )
        return body, lines


class ODERoute(TrajectoryRoute):
    """A continuous-time task: its vector field with fitted parameters, hybrid or neural."""

    defaults = {"params": (300, 0.02), "hybrid": (500, 1e-2), "neural": (500, 1e-2)}
    """Adam steps and learning rate by model type (``benchmarks/fit_swingup.py``)."""

    def announce(self, task, model_type, train, held_out, data_file, settings) -> str:
        return (
            f"fitting a {model_type} model of {task.name} to {train.num_episodes} episode(s) "
            f"({train.num_steps} transitions) of {data_file}, windows of "
            f"{settings.get('window', 10)} steps"
        )

    def fit(self, task: Any, data: Any, model_type: str, **s: Any) -> FitResult:
        _one_network(s, f"{task.name}'s vector-field models have no ensembles yet")

        keys = ("window", "steps", "learning_rate", "lm_steps", "hidden", "seed", "weight_decay")
        keys += ("substeps",)
        kw = {k: s[k] for k in keys if s.get(k) is not None}
        return fit_vector_field(task, data, model_type, s.get("params"), **kw)

    def outputs(self, task, result, data, train, held_out, data_file, settings, out):
        from .plot import ode_predictor, prediction_plot  # matplotlib

        nominal = nominal_model(task, task.default_params())
        errors = None
        if held_out is not None:
            errors = {
                "nominal": ode_prediction_errors(task, nominal, held_out),
                "fitted": ode_prediction_errors(task, result.model, held_out),
            }
        network = result.model_type != "params"
        body = {
            "parameters": parameters_doc(result),
            **model_document(task, result.model),
            "fit": dict(
                window_steps=result.window,
                windows=result.windows,
                dt_s=result.dt_s,
                rk4_substeps=result.substeps,
                adam_steps=settings["steps"],
                learning_rate=settings["learning_rate"],
                lm_steps=settings.get("lm_steps", 20) if not network else 0,
                num_parameters=result.num_parameters,
                hidden=list(settings["hidden"]) if network else None,
                seed=settings["seed"],
            ),
            "data": _data_doc(
                data_file,
                train,
                held_out,
                system=data.metadata.get("system"),
                metadata=data.metadata,
            ),
            "prediction_error": errors_doc(
                "RMS error of the state H steps ahead, open loop from every recorded state of "
                "the held-out episodes with the recorded actions",
                errors,
            ),
        }
        dt, substeps = result.dt_s, result.substeps
        prediction_plot(
            {
                "fitted": ode_predictor(result.model, dt, substeps),
                "nominal": ode_predictor(nominal, dt, substeps),
            },
            held_out if held_out is not None else train,
            out / "prediction.png",
            title=_title(task, result.model_type, held_out),
        )
        lines = []
        if errors is not None:
            for h in HORIZONS:
                nom, fit = errors["nominal"][h]["rmse"], errors["fitted"][h]["rmse"]
                lines.append(
                    f"held-out RMS state error {h:>2} steps ahead: nominal {nom:.3g}, "
                    f"fitted {fit:.3g}"
                )
        return body, lines


def _one_network(settings: dict, why: str) -> None:
    """Refuse ``members`` other than 1 where a route fits no ensemble.

    Raises:
        ConfigError: naming the value and why.
    """
    members = settings.get("members", 1)
    if members not in (None, 1):
        raise ConfigError(f"--members {members}: {why}; drop --members, or fit hybrid/neural")


STEPS = StepRoute()
ODE = ODERoute()


@task_hook
def model_route(task: Any) -> Any:
    """How models of ``task`` are learned (its data file, fit, prediction errors and plot):
    by base class, the discrete step (``STEPS`` for a ``Task``) or the vector field (``ODE``
    for a ``ContinuousTask``); a task with its own model, fit or plot overrides it (the
    trebuchet's throws) as ``tasks._hooks`` says."""
    return STEPS if isinstance(task, Task) else ODE
