"""The kinds of model ``fit`` learns, each a class with one interface, in one registry.

``KINDS`` holds them by the name the command line and the files use (``--model``,
``fitted.json``'s ``"model"``): ``params`` (a grey box: the task's physical parameters),
``hybrid`` (the physics plus a network) and ``neural`` (a network alone). A hybrid or neural
fit of ``members > 1`` networks is an ensemble of that kind: it keeps its kind's name in the
file (an ensemble of hybrids and one of black boxes predict differently), with the members
under ``network.members``. Every other module asks a kind (``kind(name)``) what it needs:

- what it is: ``network`` (it fits a network), ``physics`` (it predicts with the task's
  physics), ``label``, ``min_transitions`` (the fewest recorded transitions a discrete-time
  fit takes);
- ``fit``: a discrete-time task's fit (a continuous-time task's is ``identify.ode``'s, which
  reads the same attributes);
- ``start_settings`` / ``start_doc``: what a fit starts from when the physics given is not
  the nominal one, and how a loop records it; ``first_predictor``: the model before any data;
- ``save`` / ``load``: its part of ``fitted.json``, and the model read back from it;
- ``predictor``: ``(task, params)`` that steps the model; ``describe``: the report's lines.

A new kind is one class here and its row in ``KINDS``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ..errors import ConfigError
from ._shooting import FitResult
from .ensemble import Ensemble, ensemble_from_dict, ensemble_to_dict
from .hybrid import HybridModel, NeuralModel, fit_network, model_task
from .network import correction_from_dict, correction_to_dict
from .steps import fit_parameters

_NETWORK_NOTE = (
    "hybrid: next state = the task's step with all_parameters + network(observation, action); "
    "neural: next state = state + network(observation, action); an ensemble's members each "
    "give a network, the model uses their mean, and training through it adds "
    "uncertainty_penalty times their spread to every step's loss"
)


class ModelKind:
    """What every kind has (the class docstrings say what each one is)."""

    name: str
    label: str
    network: bool
    physics: bool
    min_transitions: int = 0
    """The fewest recorded transitions a discrete-time fit takes (0: the grey box's own rule,
    ``MIN_TRANSITIONS_PER_PARAMETER`` per fitted parameter)."""
    defaults: tuple[int, float]
    """Adam's steps and learning rate of a discrete-time fit."""

    def fit(self, task: Any, data: Any, **settings: Any) -> FitResult:
        raise NotImplementedError

    def check_members(self, members: int) -> None:
        """Refuse an ensemble where this kind fits no network."""

    def start_settings(self, task: Any, start: dict[str, float]) -> dict:
        """``fit``'s settings for physics ``start`` other than the nominal."""
        return {}

    def start_doc(self, task: Any, start: dict[str, float]) -> dict:
        """What the model starts from, for loop.json: the physics (stated) and whence."""
        nominal = {n: float(getattr(task.default_params(), n)) for n in start}
        note = f"{self.name}: the task's nominal parameters" + (
            f", except {', '.join(f'{n} = {v:g} (nominal {nominal[n]:g})' for n, v in start.items())}"
            if start
            else ""
        )
        return {"physics": start, "nominal": nominal, "note": note}

    def first_predictor(self, task: Any, start: dict[str, float]) -> tuple | None:
        """``(task, params)`` that predicts before any data: the start physics."""
        return task, dataclasses.replace(task.default_params(), **start)

    def predictor(self, task: Any, model: Any) -> tuple:
        """``(task, params)`` that steps the fitted ``model``."""
        raise NotImplementedError

    def load(self, doc: dict, physics: Any, sizes: tuple[int, int] | None, where: str) -> Any:
        """The model of a ``fitted.json`` document, given its physics and (for a network) the
        network's input and output sizes."""
        raise NotImplementedError

    def save(self, result: FitResult, settings: dict) -> tuple[dict, dict]:
        """fitted.json's part of the model, and this kind's part of its ``fit``."""
        raise NotImplementedError

    def describe(self, result: FitResult) -> list[str]:
        """The report's lines on the fitted model."""
        raise NotImplementedError


class Params(ModelKind):
    """A grey box: the task's own simulator with some physical parameters fitted."""

    name, label, network, physics = "params", "grey box", False, True
    defaults = (300, 0.02)

    def fit(self, task: Any, data: Any, **s: Any) -> FitResult:
        self.check_members(s.get("members", 1))
        keys = ("window", "steps", "learning_rate", "lm_steps", "init")
        kw = {k: s[k] for k in keys if s.get(k) is not None}
        return dataclasses.replace(
            fit_parameters(task, data, s.get("names"), **kw), model_type=self.name
        )

    def check_members(self, members: int) -> None:
        if members not in (None, 1):
            raise ConfigError(
                f"--members {members}: a grey box has no network (--model params); drop "
                "--members, or fit hybrid/neural"
            )

    def start_settings(self, task: Any, start: dict[str, float]) -> dict:
        return {"init": start} if start else {}

    def predictor(self, task: Any, model: Any) -> tuple:
        return task, model

    def load(self, doc: dict, physics: Any, sizes: tuple[int, int], where: str) -> Any:
        return physics

    def save(self, result: FitResult, settings: dict) -> tuple[dict, dict]:
        return {"parameters": parameters_doc(result)}, {"lm_steps": settings.get("lm_steps", 20)}

    def describe(self, result: FitResult) -> list[str]:
        return []


class _Network(ModelKind):
    network = True
    defaults = (2000, 3e-3)
    residual: bool
    model_class: type

    def fit(self, task: Any, data: Any, **s: Any) -> FitResult:
        keys = ("params", "window", "steps", "learning_rate", "hidden", "seed", "members")
        keys += ("bootstrap", "uncertainty_penalty")
        return fit_model(task, data, self.name, **{k: s[k] for k in keys if s.get(k) is not None})

    def predictor(self, task: Any, model: Any) -> tuple:
        return model_task(task, model), model

    def load(self, doc: dict, physics: Any, sizes: tuple[int, int], where: str) -> Any:
        if "members" in doc["network"]:  # an ensemble
            correction = ensemble_from_dict(doc["network"], where, sizes)
        else:
            correction = correction_from_dict(doc["network"], where, sizes)
        return self.model_class(physics, correction)

    def save(self, result: FitResult, settings: dict) -> tuple[dict, dict]:
        c = result.model.correction
        net = ensemble_to_dict(c) if isinstance(c, Ensemble) else correction_to_dict(c)
        network = {"what": _NETWORK_NOTE, "inputs": "observation then action"}
        network.update(parameters=result.num_parameters, **net)
        fit = {"hidden": list(settings["hidden"]), "seed": settings["seed"]}
        return {"network": network}, fit

    def describe(self, result: FitResult) -> list[str]:
        return [f"{self.name} model: {result.num_parameters} weights, {result.message}"]


class Hybrid(_Network):
    """The task's physics plus a network that learns what it misses: ``HybridModel``."""

    name, label, physics, residual, model_class = "hybrid", "hybrid", True, True, HybridModel
    min_transitions = 200  # a Pendulum-v1 episode: the network learns only what physics misses

    def start_settings(self, task: Any, start: dict[str, float]) -> dict:
        return {"params": dataclasses.replace(task.default_params(), **start)} if start else {}


class Neural(_Network):
    """A network alone, learned from data: ``NeuralModel``."""

    name, label, physics, residual, model_class = "neural", "neural", False, False, NeuralModel
    min_transitions = 1000  # five Pendulum-v1 episodes: a black box learns everything

    def start_doc(self, task: Any, start: dict[str, float]) -> dict:
        return {"physics": None, "note": "a network alone: no physics to start from"}

    def first_predictor(self, task: Any, start: dict[str, float]) -> tuple | None:
        return None  # a black box has no model before its first fit


def parameters_doc(result: FitResult) -> dict:
    """fitted.json's ``parameters``: per fitted name, its value, standard error and nominal."""
    return {
        n: {"value": v, "standard_error": result.standard_errors[n], "nominal": result.nominal[n]}
        for n, v in result.values.items()
    }


KINDS: dict[str, ModelKind] = {k.name: k for k in (Params(), Hybrid(), Neural())}
"""The model kinds by name, in the order of ``settings.MODELS`` (the command line's choices)."""
MODEL_TYPES = tuple(KINDS)
NETWORK_MODELS = tuple(name for name, k in KINDS.items() if k.network)
MIN_TRANSITIONS = {name: KINDS[name].min_transitions for name in NETWORK_MODELS}
"""The fewest recorded transitions a network kind is fitted to (``ModelKind.min_transitions``)."""


def kind(name: Any) -> ModelKind:
    """The model kind called ``name``.

    Raises:
        ConfigError: no kind has that name (naming the kinds there are).
    """
    if isinstance(name, ModelKind):
        return name
    if name not in KINDS:
        raise ConfigError(f"unknown model kind {name!r}; choose one of {list(KINDS)}")
    return KINDS[name]


def fit_model(task: Any, data: Any, model_type: str = "hybrid", **settings: Any) -> FitResult:
    """Fit a hybrid or black-box model of ``task``'s system to recorded ``data``
    (``hybrid.fit_network``, whose keywords ``settings`` are).

    Raises:
        ConfigError: ``model_type`` is not a kind with a network, or a bad setting.
        InsufficientDataError: fewer transitions than the kind's ``min_transitions``.
    """
    k = kind(model_type)
    if not k.network:
        names = [n for n, other in KINDS.items() if other.network]
        raise ConfigError(f"unknown model kind {model_type!r}; choose one of {names}")
    return fit_network(task, data, k, **settings)
