"""``model.json``: a trained controller as a document, and the NumPy policies that run it.

Written by ``controller_to_dict`` / ``model_document`` (a planner: ``planner_document``), read
back by ``read_model`` (checked before anything is built from it), run by ``NumpyPolicy`` (and
``AimingPolicy``, ``StatePolicy``) with NumPy alone, or rebuilt as an ``MLPController`` by
``controller_from_dict``.

``model.json`` schema (version 1), runnable with NumPy alone (see ``NumpyPolicy``)::

    {
      "format": "diffcontrol-model", "version": 1,
      "task": "pendulum", "gym_id": "Pendulum-v1",
      "observation": {"size": 3, "offset": [0, 0, 0], "scale": [1, 1, 0.125]},
      "network": {"activation": "tanh",
                  "layers": [{"weight": [[...], ...], "bias": [...]}, ...]},
      "action": {"size": 1, "head": "tanh", "low": [-2.0], "high": [2.0],
                 "gym": "box"},     # or {"size": 3, "head": "argmax", "low": null,
                                    #     "high": null, "gym": "discrete"}
      "metadata": {...}
    }

Forward pass: ``h = (obs - offset) * scale``; for every layer but the last
``h = activation(W h + b)`` (``W`` has shape ``[out, in]``); ``z = W_last h + b_last``;
``action = head(z)`` with ``linear: z``, ``tanh: low + (high - low) (tanh z + 1) / 2``,
``sigmoid: low + (high - low) / (1 + exp(-z))``, ``sign: +1 if tanh(z) >= 0 else -1``,
``argmax: one_hot(argmax z)`` (the ``size`` logits pick one of ``size`` choices, the first on a
tie). The Gymnasium action is the action vector for ``"gym": "box"``,
``1 if action[0] >= 0 else 0`` for ``"gym": "discrete_sign"`` (CartPole: 1 pushes right), and
the index ``argmax z`` for ``"gym": "discrete"`` (a ``Discrete(size)`` space; only with the
``argmax`` head, and the ``argmax`` head only with it).

A continuous-time task's controller acts on the physical state: its ``observation`` also
holds ``"state"`` (the state's names, e.g. ``["x", "x_dot", "theta", "theta_dot"]``) and
``"features"`` (how the observation is computed from it, each a state name, ``cos(name)`` or
``sin(name)``, e.g. ``["cos(theta)", "sin(theta)", "theta_dot"]``); see ``StatePolicy``.
Readers that ignore the two keys still run the network on observations.

A task may refine the network's action through its model at act time (the trebuchet:
Gauss-Newton steps on the miss through its simulator); its ``model.json`` then also holds
``"refine"`` (the task's ``act_refinement``, e.g. ``{"method": "gauss-newton",
"iterations": 2}``), which the task's own policy runs with JAX. Readers that ignore the key run
the network alone: the NumPy-only (and exported) form of the same controller.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ._version import __version__
from .controllers import ACTIVATIONS, HEADS, MLPController
from .errors import ConfigError, ModelFileError
from .io import now_iso, read_json
from .settings import PlanConfig

MODEL_FORMAT = "diffcontrol-model"
GYM_KINDS = {"sign": "discrete_sign", "argmax": "discrete"}
"""The Gymnasium action kind (``action.gym``) of a head; every other head's is ``"box"``."""
MODEL_VERSION = 1


def controller_to_dict(controller: MLPController, task: Any, metadata: dict | None = None) -> dict:
    """The ``model.json`` document of a trained ``MLPController`` for ``task``."""
    gym_space = GYM_KINDS.get(controller.head, "box")
    layers = [
        {"weight": np.asarray(l.weight).tolist(), "bias": np.asarray(l.bias).tolist()}
        for l in controller.layers
    ]
    bounded = controller.head in ("tanh", "sigmoid")
    observation: dict[str, Any] = {
        "size": int(controller.obs_offset.shape[0]),
        "offset": np.asarray(controller.obs_offset).tolist(),
        "scale": np.asarray(controller.obs_scale).tolist(),
    }
    if getattr(task, "feature_names", None):  # a continuous-time task: state feedback
        observation["state"] = list(task.state_names)
        observation["features"] = list(task.feature_names)
    return {
        "format": MODEL_FORMAT,
        "version": MODEL_VERSION,
        "task": task.name,
        "gym_id": task.gym_id,
        "observation": observation,
        "network": {"activation": controller.activation, "layers": layers},
        "action": {
            "size": int(controller.action_low.shape[0]),
            "head": controller.head,
            "low": np.asarray(controller.action_low).tolist() if bounded else None,
            "high": np.asarray(controller.action_high).tolist() if bounded else None,
            "gym": gym_space,
        },
        "metadata": dict(metadata or {}),
    }


def model_document(task: Any, controller: MLPController, config: Any, metrics: dict) -> dict:
    """The ``model.json`` document of a controller trained for ``task`` with ``config``; its
    metadata records the version, the seed, the training time and the settings."""

    source = getattr(task, "source", None)  # the import path of a user's task
    doc = controller_to_dict(
        controller,
        task,
        {
            "diffcontrol_version": __version__,
            "created": metrics.get("created") or now_iso(),
            "seed": config.seed,
            "train_seconds": metrics.get("train_seconds"),
            "config": config.to_json(),
            **({"task_source": source} if isinstance(source, str) else {}),
        },
    )
    refine = getattr(task, "act_refinement", None)  # the module docstring's "refine"
    if refine:
        doc["refine"] = dict(refine)
    return doc


def is_planner(doc: dict) -> bool:
    """Whether a ``model.json`` document holds a planning controller (``planner_document``)."""
    controller = doc.get("controller")
    return isinstance(controller, dict) and controller.get("type") == "planner"


def planner_document(
    task: Any, settings: dict, model: dict, metadata: dict, value: dict | None = None
) -> dict:
    """The ``model.json`` document of a planning controller (``diffcontrol plan``)::

        {"format": "diffcontrol-model", "version": 1, "task": "pendulum", "gym_id": ...,
         "observation": {"size": 3}, "action": {"size": 1, "low": [-2.0], "high": [2.0]},
         "controller": {"type": "planner",
                        "settings": {...},     # settings.PlanConfig's fields
                        "model": {"kind": "simulator"}   # or {"kind": "fitted",
                                                         #     "fitted": {fitted.json}}
                        "value": {...}   # optional: a learned terminal value network
                       },                #   (mpc.ValueNetwork.to_json, weights as lists)
         "metadata": {...}}

    It has no ``network``: the controller is the task's model and a solver, so it runs with
    JAX and the task, not with NumPy alone (``mpc.planner_policy`` builds it back).
    """
    controller = {"type": "planner", "settings": dict(settings), "model": dict(model)}
    if value is not None:
        controller["value"] = dict(value)
    return {
        "format": MODEL_FORMAT,
        "version": MODEL_VERSION,
        "task": task.name,
        "gym_id": task.gym_id,
        "observation": {"size": int(task.observation_size)},
        "action": {
            "size": int(task.action_size),
            "low": np.asarray(task.action_low, float).reshape(-1).tolist(),
            "high": np.asarray(task.action_high, float).reshape(-1).tolist(),
        },
        "controller": controller,
        "metadata": dict(metadata),
    }


def _check_planner(doc: dict, bad: Any) -> None:
    for what in ("observation", "action"):
        size = (doc.get(what) or {}).get("size")
        if not isinstance(size, int) or isinstance(size, bool) or size < 1:
            raise bad(f"the {what} size {size!r} is not a positive integer")
    if not isinstance(doc.get("task"), str):
        raise bad("'task' is not a name")
    controller = doc["controller"]
    try:
        PlanConfig.from_json(controller.get("settings"))
    except ConfigError as e:
        raise bad(f"planner settings: {e}") from None
    model = controller.get("model")
    if not isinstance(model, dict) or model.get("kind") not in ("simulator", "fitted"):
        raise bad("the planner's model is neither {'kind': 'simulator'} nor a fitted model")
    if "value" in controller and not isinstance(controller["value"], dict):
        raise bad("the planner's value network is not an object")


def _check_model(doc: Any, path: Path) -> None:
    def bad(problem: str) -> ModelFileError:
        return ModelFileError(
            f"{path} is not a usable model.json: {problem}; re-create it with `diffcontrol train`"
        )

    if not isinstance(doc, dict) or doc.get("format") != MODEL_FORMAT:
        raise bad(f"'format' is not {MODEL_FORMAT!r}")
    if doc.get("version") != MODEL_VERSION:
        raise bad(f"version {doc.get('version')!r} is not supported (this diffcontrol reads 1)")
    if is_planner(doc):
        return _check_planner(doc, bad)
    try:
        obs, net, act = doc["observation"], doc["network"], doc["action"]
        if net["activation"] not in ACTIVATIONS:
            raise bad(f"unknown activation {net['activation']!r}")
        if act["head"] not in HEADS:
            raise bad(f"unknown action head {act['head']!r}")
        gym_space = act.get("gym", "box")
        if gym_space not in ("box", *GYM_KINDS.values()):
            raise bad(f"unknown Gymnasium action kind {gym_space!r}")
        if (act["head"] == "argmax") != (gym_space == "discrete"):
            raise bad(f"action head {act['head']!r} does not go with 'gym': {gym_space!r}")
        if act["head"] == "argmax" and act["size"] < 2:
            raise bad(f"the argmax head needs at least 2 choices, not {act['size']}")
        size = obs["size"]
        if not isinstance(size, int) or isinstance(size, bool) or size < 1:
            raise bad(f"the observation size {size!r} is not a positive integer")
        for name in ("offset", "scale"):
            v = np.asarray(obs[name], float)
            if v.shape != (size,) or not np.all(np.isfinite(v)):
                raise bad(f"observation {name} is not {size} finite numbers")
        if not np.any(np.asarray(obs["scale"], float)):  # a controller that sees nothing
            raise bad("the observation scale is 0 for every observation")
        if not isinstance(act["size"], int) or isinstance(act["size"], bool) or act["size"] < 1:
            raise bad(f"the action size {act['size']!r} is not a positive integer")
        if act["head"] in ("tanh", "sigmoid"):
            for name in ("low", "high"):
                v = np.asarray(act.get(name), float)
                if v.shape != (act["size"],) or not np.all(np.isfinite(v)):
                    raise bad(f"the {act['head']} head needs {act['size']} finite action {name}s")
            if np.any(np.asarray(act["low"], float) >= np.asarray(act["high"], float)):
                raise bad("an action bound has low >= high")
        if not net["layers"]:
            raise bad("the network has no layers")
        if "features" in obs:
            names = (obs["features"], obs["state"])
            if not all(isinstance(n, list) and all(isinstance(x, str) for x in n) for n in names):
                raise bad("observation features and state must be lists of names")
            if len(obs["features"]) != size:
                raise bad("observation features do not match its size")
            for feature in obs["features"]:
                _feature_index(feature, obs["state"])
        for i, layer in enumerate(net["layers"]):
            w, b = np.asarray(layer["weight"], float), np.asarray(layer["bias"], float)
            if w.ndim != 2 or w.shape[1] != size or b.shape != (w.shape[0],):
                raise bad(f"layer {i} has weight {w.shape} and bias {b.shape}, inconsistent")
            with np.errstate(over="ignore"):  # the JAX controller runs in float32
                if not (np.all(np.isfinite(w.astype(np.float32))) and np.all(np.isfinite(b))):
                    raise bad(f"layer {i} holds weights that are not finite in float32")
            size = w.shape[0]
        if size != act["size"]:
            raise bad(f"the network outputs {size} values but the action has {act['size']}")
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, ModelFileError):
            raise
        raise bad(f"missing or malformed field ({e!r})") from None


def read_model(path: str | os.PathLike) -> dict:
    """Read and validate a ``model.json`` (a file or a run directory holding one)."""
    path = Path(path)
    if path.is_dir():
        path = path / "model.json"
    doc = read_json(path, "model file")
    _check_model(doc, path)
    return doc


_NP_ACT = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
    "sigmoid": lambda x: 1.0 / (1.0 + np.exp(-x)),
    "elu": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0.0))),
}


class NumpyPolicy:
    """A ``model.json`` controller run with NumPy alone.

    ``policy(obs)`` takes one Gymnasium observation and returns a valid Gymnasium action, so
    it drops into a plain ``gymnasium.make(...)`` loop: for a ``Discrete`` space (the
    ``argmax`` and CartPole's ``sign`` heads) the index as a Python ``int``, or an int array
    for a batch of observations (a batch of continuous actions is an array of rows).
    ``policy.action(obs)`` returns the controller's action vector (the push multiplier ``+-1``
    for CartPole, the one-hot choice for the ``argmax`` head).
    """

    batched = True
    """``policy(obs)`` takes a batch of observations too (``evaluation.evaluate`` runs its
    episodes side by side then). Declared per class: a subclass is called one observation at
    a time unless it declares ``batched = True`` itself."""

    def __init__(self, doc: dict):
        _check_model(doc, Path("<model>"))
        if is_planner(doc):
            raise ModelFileError(
                "this model.json holds a planner, which runs with JAX and its task, not NumPy "
                "alone; load it with diffcontrol.load(dir)"
            )
        self.doc = doc
        self.task = doc["task"]
        self.gym_id = doc.get("gym_id")
        self._offset = np.asarray(doc["observation"]["offset"], np.float64)
        self._scale = np.asarray(doc["observation"]["scale"], np.float64)
        self._layers = [
            (np.asarray(l["weight"], np.float64), np.asarray(l["bias"], np.float64))
            for l in doc["network"]["layers"]
        ]
        self._act = _NP_ACT[doc["network"]["activation"]]
        a = doc["action"]
        self._head, self._gym = a["head"], a["gym"]
        self._low = None if a.get("low") is None else np.asarray(a["low"], np.float64)
        self._high = None if a.get("high") is None else np.asarray(a["high"], np.float64)

    def action(self, obs: np.ndarray) -> np.ndarray:
        """The controller's action vector for one observation (or a batch, leading axis).

        Raises:
            ValueError: the observation is not a vector (or batch) of the controller's size,
                or holds NaN or infinity.
        """
        obs = np.asarray(obs, np.float64)
        size = self._offset.shape[0]
        if obs.ndim == 0 or obs.shape[-1] != size:
            raise ValueError(
                f"the {self.task} controller takes observations of size {size}, got shape "
                f"{obs.shape}"
            )
        if not np.all(np.isfinite(obs)):
            raise ValueError(f"the observation holds NaN or infinity: {obs}")
        h = (obs - self._offset) * self._scale
        for w, b in self._layers[:-1]:
            h = self._act(h @ w.T + b)
        w, b = self._layers[-1]
        z = h @ w.T + b
        if self._head == "linear":
            return z
        if self._head == "tanh":
            return self._low + (self._high - self._low) * (np.tanh(z) + 1) / 2
        if self._head == "sigmoid":
            return self._low + (self._high - self._low) / (1 + np.exp(-z))
        if self._head == "argmax":
            return np.eye(z.shape[-1])[np.argmax(z, axis=-1)]
        return np.where(np.tanh(z) >= 0, 1.0, -1.0)

    def __call__(self, obs: np.ndarray) -> Any:
        a = self.action(obs)
        if self._gym == "discrete_sign":
            if a.ndim > 1:  # a batch: one index per row
                return (a[..., 0] >= 0).astype(np.int64)
            return int(a.reshape(-1)[0] >= 0)
        if self._gym == "discrete":
            index = np.argmax(a, axis=-1)
            return int(index) if index.ndim == 0 else index.astype(np.int64)
        if self._low is not None:
            a = np.clip(a, self._low, self._high)
        return a.astype(np.float32)

    def __repr__(self) -> str:
        sizes = [self._layers[0][0].shape[1]] + [w.shape[0] for w, _ in self._layers]
        return f"{type(self).__name__}(task={self.task!r}, sizes={sizes}, head={self._head!r})"


class AimingPolicy(NumpyPolicy):
    """A ``model.json`` aiming controller (the trebuchet) run with NumPy alone.

    ``policy(target_m, wind_mps)`` returns ``(angle_deg, weight_lb)``; scalars give floats,
    equal-length arrays give arrays. ``policy.action(obs)`` is the raw ``NumpyPolicy`` form
    on observations ``(target_m, wind_mps)``.
    """

    def __call__(self, target_m: Any, wind_mps: Any = 0.0) -> tuple[Any, Any]:  # type: ignore[override]
        target, wind = np.broadcast_arrays(
            np.asarray(target_m, np.float64), np.asarray(wind_mps, np.float64)
        )
        a = self.action(np.stack([target, wind], axis=-1))
        angle, weight = a[..., 0], a[..., 1]
        if angle.ndim == 0:
            return float(angle), float(weight)
        return angle, weight


def _feature_index(feature: str, state: list[str]) -> tuple[Any, int]:
    """``"cos(theta)"`` -> ``(np.cos, index of theta)``; ``"x"`` -> ``(None, index of x)``."""
    fn = None
    name = feature
    for prefix, f in (("cos(", np.cos), ("sin(", np.sin)):
        if feature.startswith(prefix) and feature.endswith(")"):
            fn, name = f, feature[len(prefix) : -1]
    if name not in state:
        raise ModelFileError(
            f"observation feature {feature!r} names no state variable of {state}; re-create "
            "the model with `diffcontrol train`"
        )
    return fn, state.index(name)


class StatePolicy(NumpyPolicy):
    """A continuous-time controller from ``model.json`` as a function of the physical state.

    ``policy(state)`` takes the state in the order of ``policy.state_names`` (for the swing-up
    cart-pole ``(x, x_dot, theta, theta_dot)`` in m, m/s, rad with 0 upright, rad/s), or a
    batch with the state on the last axis, and returns the force (N): a float for one state,
    an array for a batch. NumPy only, so any integrator can re-simulate the closed loop.
    The observation is built from the state by ``observation.features`` of ``model.json``:
    each is a state name, ``cos(name)`` or ``sin(name)``.
    """

    def __init__(self, doc: dict):
        super().__init__(doc)
        obs = doc["observation"]
        if "features" not in obs:
            raise ModelFileError(
                f"the {self.task!r} model takes observations, not states; load it as a "
                "NumpyPolicy (diffcontrol.load does this)"
            )
        self.state_names = tuple(obs["state"])
        self._features = [_feature_index(f, list(self.state_names)) for f in obs["features"]]

    def features(self, state: np.ndarray) -> np.ndarray:
        """The controller's input computed from ``state`` (last axis)."""
        s = np.asarray(state, np.float64)
        if s.shape[-1] != len(self.state_names):
            raise ValueError(
                f"expected a state of {len(self.state_names)} values {self.state_names}, got "
                f"shape {s.shape}"
            )
        cols = [s[..., i] if fn is None else fn(s[..., i]) for fn, i in self._features]
        return np.stack(cols, axis=-1)

    def __call__(self, state: np.ndarray) -> Any:  # type: ignore[override]
        force = self.action(self.features(state))[..., 0]
        return float(force) if force.ndim == 0 else force


def controller_from_dict(doc: dict) -> MLPController:
    """Rebuild the JAX ``MLPController`` of a ``model.json`` document."""
    _check_model(doc, Path("<model>"))
    import jax.numpy as jnp

    layers_doc = doc["network"]["layers"]
    hidden = tuple(len(l["bias"]) for l in layers_doc[:-1])
    a = doc["action"]
    ctrl = MLPController(
        jax.random.PRNGKey(0),
        doc["observation"]["size"],
        a["size"],
        hidden,
        activation=doc["network"]["activation"],
        head=a["head"],
        obs_offset=doc["observation"]["offset"],
        obs_scale=doc["observation"]["scale"],
        action_low=a.get("low"),
        action_high=a.get("high"),
    )
    new_layers = tuple(
        eqx_replace_linear(
            l, jnp.asarray(d["weight"], jnp.float32), jnp.asarray(d["bias"], jnp.float32)
        )
        for l, d in zip(ctrl.layers, layers_doc)
    )
    import equinox as eqx

    return eqx.tree_at(lambda c: c.layers, ctrl, new_layers)


def eqx_replace_linear(layer, weight, bias):
    import equinox as eqx

    return eqx.tree_at(lambda l: (l.weight, l.bias), layer, (weight, bias))
