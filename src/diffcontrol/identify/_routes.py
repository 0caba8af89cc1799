"""The routes of model learning: how a task's data is read, fitted, judged and drawn.

A task's route is ``model_route(task)`` (by base class: ``STEPS`` for a discrete-time
``Task``, ``ODE`` for a ``ContinuousTask``; a task with its own model, fit or plot overrides it
with its own route, a ``TrajectoryRoute`` subclass in the system's files), so
``identify.fit`` and ``identify.fit_dir`` never ask which system a task is. Each route has
the same methods: ``read(path)``, ``count(data)``, ``split(data, n)``, ``announce(...)`` (the
line said before fitting), ``fit(task, data, model_type, **settings)`` and ``outputs(...)``
(the route's part of ``fitted.json``, the lines it reports and ``prediction.png``), its
``unit`` (what ``count`` counts) and ``defaults(kind)`` (Adam's steps and learning rate for
a model kind, ``identify.kinds``); optionally ``check_model(task, model_type)`` (before
anything is read) and ``check_split(task, data, train, held_out, settings)`` (after the
hold-out is split off).
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
from .ensemble import mean_spread
from .kinds import kind, parameters_doc
from .ode import fit_vector_field, model_document, nominal_model
from .ode import prediction_errors as ode_prediction_errors
from .steps import prediction_errors


def params_dict(params: Any) -> dict[str, float]:
    """Every field of a parameter PyTree as a plain float (fitted.json's ``all_parameters``)."""
    return {f.name: float(np.asarray(getattr(params, f.name))) for f in dataclasses.fields(params)}


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

    def defaults(self, model: Any) -> tuple[int, float]:
        """Adam's steps and learning rate for the model kind ``model``: the kind's own."""
        return kind(model).defaults

    def announce(self, task, model_type, train, held_out, data_file, settings) -> str:
        names = settings.get("names") or fit_parameter_names(task)
        network = kind(model_type).network
        what = ", ".join(names) if not network and names else f"a {model_type} model"
        return (
            f"fitting {what} of {task.name} to {train.num_episodes} episode(s) "
            f"({train.num_steps} transitions) of {data_file}, windows of "
            f"{settings.get('window', 10)} steps"
        )


class StepRoute(TrajectoryRoute):
    """A discrete-time task: its step with fitted parameters, or a hybrid or neural model."""

    def fit(self, task: Any, data: Any, model_type: str, **s: Any) -> FitResult:
        return kind(model_type).fit(task, data, **s)

    def predictor(self, task: Any, result: FitResult | None) -> tuple[Any, Any]:
        """``(task, params)`` to predict with: the nominal model for ``None``."""
        if result is None:
            return task, task.default_params()
        return kind(result.model_type).predictor(task, result.model)

    def outputs(self, task, result, data, train, held_out, data_file, settings, out):
        from .plot import prediction_plot, task_predictor  # matplotlib

        nominal, fitted = self.predictor(task, None), self.predictor(task, result)
        errors = None
        if held_out is not None:
            errors = {
                "nominal": prediction_errors(*nominal, held_out),
                "fitted": prediction_errors(*fitted, held_out),
            }
        model_kind = kind(result.model_type)
        own, own_fit = model_kind.save(result, settings)
        parameters = {"parameters": own.pop("parameters")} if "parameters" in own else {}
        model_doc = {**parameters, "all_parameters": params_dict(result.params), **own}
        fit_settings = dict(
            window_steps=result.window,
            windows=result.windows,
            adam_steps=settings["steps"],
            learning_rate=settings["learning_rate"],
            **own_fit,
        )
        if model_kind.network:
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
        lines = model_kind.describe(result)
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

    def defaults(self, model: Any) -> tuple[int, float]:
        """Adam's steps and learning rate for the model kind ``model``: a vector field's
        network takes fewer steps at a larger rate (``benchmarks/fit_swingup.py``)."""
        return (500, 1e-2) if kind(model).network else kind(model).defaults

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
        network = kind(result.model_type).network
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
