"""Learned models of a task's system, and the fitted-model file that stores them.

- ``Correction``: a multilayer perceptron with fixed input normalisation and a fixed output
  scale, ``out_scale * mlp((x - in_offset) * in_scale)``. Its last layer can start at zero, so
  a hybrid model (known physics plus a correction) starts exactly at the known physics. The
  scalings are constants (no gradient), set from the data before fitting.
  ``correction_to_dict`` / ``correction_from_dict`` store it as plain JSON lists (no pickle),
  the way ``model.json`` stores a controller.
- Discrete-time models: ``HybridModel`` (the task's step plus a correction) and
  ``NeuralModel`` (a network alone), fitted by ``fit_model`` with the grey box's multiple
  shooting (``diffcontrol.fitting``); ``model_task`` makes a task that steps one, to train or
  predict through it. (The swing-ups' continuous-time models are in ``ode_fitting`` and
  ``tasks.fitted_swingup``; the trebuchet's grey box is ``fit_throws``.)
- ``fitted.json`` (format ``diffcontrol-fitted-model``, written by ``diffcontrol fit``):
  ``read_fitted``, ``fitted_physics``, ``fitted_model``, and ``real_system`` / ``as_env`` /
  ``real_params``: the system the model's data came from, where a controller trained through
  the model is evaluated.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, PRNGKeyArray

from .controllers import ACTIVATIONS, MLPController
from .errors import ConfigError, InsufficientDataError, ModelFileError


class Correction(eqx.Module):
    """``out_scale * mlp((x - in_offset) * in_scale)``: a small network with fixed scalings.

    Attributes:
        net: the network (an ``MLPController`` with a linear head; its observation scaling is
            the input normalisation).
        out_scale: the output's scale per component (a constant).
    """

    net: MLPController
    out_scale: Float[Array, " out"]

    def __init__(
        self,
        key: PRNGKeyArray,
        in_size: int,
        out_size: int,
        hidden: Sequence[int] = (32, 32),
        *,
        activation: str = "tanh",
        in_offset: Sequence[float] | None = None,
        in_scale: Sequence[float] | None = None,
        out_scale: Sequence[float] | None = None,
        zero_output: bool = True,
    ):
        """Args:
        key: PRNG key of the weights.
        in_size, out_size: the input and output sizes.
        hidden: the hidden layers' widths.
        activation: as for controllers (``tanh``, ``relu``, ``sigmoid``, ``elu``).
        in_offset, in_scale: the network sees ``(x - in_offset) * in_scale`` (aim for inputs
            of order 1).
        out_scale: multiplies the output (the typical size of what it corrects).
        zero_output: start with a zero last layer, so the correction starts at exactly 0.
        """
        self.net = MLPController(
            key,
            in_size,
            out_size,
            tuple(hidden),
            activation=activation,
            head="linear",
            obs_offset=in_offset,
            obs_scale=in_scale,
            final_scale=0.0 if zero_output else 1.0,
        )
        scale = np.ones(out_size) if out_scale is None else np.asarray(out_scale, float)
        if scale.shape != (out_size,):
            raise ValueError(f"out_scale needs {out_size} values, got {scale.shape}")
        self.out_scale = jnp.asarray(scale, jnp.float32)

    def __call__(self, x: Float[Array, " in"]) -> Float[Array, " out"]:
        return jax.lax.stop_gradient(self.out_scale) * self.net(x)

    @property
    def num_parameters(self) -> int:
        """Number of trainable weights and biases."""
        return self.net.num_parameters


def correction_to_dict(c: Correction) -> dict[str, Any]:
    """The network as JSON-able lists: layers (weight, bias), activation and the scalings."""
    return {
        "activation": c.net.activation,
        "in_offset": np.asarray(c.net.obs_offset, float).tolist(),
        "in_scale": np.asarray(c.net.obs_scale, float).tolist(),
        "out_scale": np.asarray(c.out_scale, float).tolist(),
        "layers": [
            {
                "weight": np.asarray(l.weight, float).tolist(),
                "bias": np.asarray(l.bias, float).tolist(),
            }
            for l in c.net.layers
        ],
    }


def correction_from_dict(doc: Any, where: str = "the model file") -> Correction:
    """Rebuild a ``Correction`` from ``correction_to_dict``'s output.

    Raises:
        ModelFileError: the document is malformed (names what is wrong and where).
    """
    try:
        layers = doc["layers"]
        weights = [np.asarray(l["weight"], np.float64) for l in layers]
        biases = [np.asarray(l["bias"], np.float64) for l in layers]
        activation = doc["activation"]
        in_offset, in_scale = doc["in_offset"], doc["in_scale"]
        out_scale = doc["out_scale"]
    except (KeyError, TypeError, ValueError) as e:
        raise ModelFileError(
            f"{where}: the network is malformed ({e!r}); refit the model"
        ) from None
    shapes_ok = (
        weights
        and all(
            w.ndim == 2 and b.ndim == 1 and w.shape[0] == b.shape[0]
            for w, b in zip(weights, biases)
        )
        and all(a.shape[0] == b.shape[1] for a, b in zip(weights[:-1], weights[1:]))
        and len(in_offset) == len(in_scale) == weights[0].shape[1]
        and len(out_scale) == weights[-1].shape[0]
    )
    if not shapes_ok or activation not in ACTIVATIONS:
        raise ModelFileError(
            f"{where}: the network's layer shapes or activation {activation!r} do not fit "
            "together; refit the model"
        )
    if not all(np.all(np.isfinite(a)) for a in (*weights, *biases)):
        raise ModelFileError(f"{where}: the network has non-finite weights; refit the model")
    c = Correction(
        jax.random.PRNGKey(0),
        weights[0].shape[1],
        weights[-1].shape[0],
        tuple(w.shape[0] for w in weights[:-1]),
        activation=activation,
        in_offset=in_offset,
        in_scale=in_scale,
        out_scale=out_scale,
    )
    new = tuple(
        eqx.tree_at(
            lambda l: (l.weight, l.bias),
            l,
            (jnp.asarray(w, jnp.float32), jnp.asarray(b, jnp.float32)),
        )
        for l, w, b in zip(c.net.layers, weights, biases)
    )
    return eqx.tree_at(lambda c: c.net.layers, c, new)


# ---------------------------------------------------------------------------------------------
# Discrete-time hybrid and black-box models of a task's system, and their fit.

MODEL_KINDS = ("hybrid", "neural")

MIN_TRANSITIONS = {"hybrid": 200, "neural": 1000}
"""The fewest recorded transitions a network model is fitted to (a Pendulum-v1 episode has
200): a hybrid model only learns what the physics misses, a black box learns everything."""


class HybridModel(eqx.Module):
    """Known physics plus a learned correction: ``s' = step(params, s, a) + c(obs(s), a)``.

    Attributes:
        params: the task's physical parameters (the nominal ones unless given).
        correction: a ``Correction`` from the observation and the action to a state change.
    """

    params: Any
    correction: Correction

    def next_state(self, task: Any, state: Array, action: Array) -> Array:
        known = task.step(self.params, state, action)[0]
        return known + self.correction(jnp.concatenate([task.observe(state), action]))


class NeuralModel(eqx.Module):
    """A black box learned from data alone: ``s' = s + c(obs(s), a)``.

    Attributes:
        params: the task's nominal parameters, used only for what is not dynamics (the reward,
            the reset distribution), never to predict the next state.
        correction: a ``Correction`` from the observation and the action to the state change.
    """

    params: Any
    correction: Correction

    def next_state(self, task: Any, state: Array, action: Array) -> Array:
        return state + self.correction(jnp.concatenate([task.observe(state), action]))


def model_task(task: Any, model: HybridModel | NeuralModel) -> Any:
    """``task`` with its simulator replaced by ``model``: a task of the same class whose
    ``default_params()`` is the model and whose ``step`` predicts with it (the reward, the
    termination and the losses are the task's own, computed with ``model.params``). So
    ``diffcontrol.train(model_task(task, model), config)`` trains a controller through the
    fitted model, and ``fitting.prediction_errors(model_task(task, model), model, data)``
    measures it.
    """
    if task.kind != "control":
        raise ValueError(f"model_task needs a discrete-time control task, got {task.name!r}")
    cls = type(task)

    class _ModelTask(cls):
        base = task  # the system the model stands for

        def default_params(self):
            return model

        def reset(self, key, params):
            return cls.reset(self, key, params.params)

        def step(self, params, state, action):
            _, reward, terminated = cls.step(self, params.params, state, action)
            return params.next_state(task, state, action), reward, terminated

        def step_loss(self, name):
            inner = cls.step_loss(self, name)
            return lambda params, *rest: inner(params.params, *rest)

    _ModelTask.__name__ = _ModelTask.__qualname__ = f"{type(model).__name__}{cls.__name__}"
    return _ModelTask()


@dataclasses.dataclass(frozen=True)
class ModelFitResult:
    """The outcome of ``fit_model``.

    Attributes:
        model: the fitted ``HybridModel`` or ``NeuralModel`` (float32 weights and physics).
        kind: ``"hybrid"`` or ``"neural"``.
        loss, nominal_loss: the mean squared window prediction error of the observations at the
            fit and for the nominal physics.
        loss_history: the loss before each Adam step taken.
        diverged, message: as for ``FitResult``.
        window, windows, transitions, num_parameters: the window length, how many windows, how
            many recorded transitions and how many weights the fit used.
    """

    model: Any
    kind: str
    loss: float
    nominal_loss: float
    loss_history: np.ndarray
    diverged: bool
    message: str
    window: int
    windows: int
    transitions: int
    num_parameters: int


def _spread(x: np.ndarray) -> np.ndarray:
    """A robust standard deviation per column (half the 16-84 % range), floored at 1e-6: the
    state changes of an angle that wraps at +-pi would inflate a plain one."""
    lo, hi = np.percentile(x, [16, 84], axis=0)
    return np.maximum((hi - lo) / 2, 1e-6)


def fit_model(
    task: Any,
    data: Any,
    kind: str = "hybrid",
    *,
    params: Any = None,
    window: int = 10,
    steps: int = 2000,
    learning_rate: float = 3e-3,
    hidden: Sequence[int] = (32, 32),
    seed: int = 0,
) -> ModelFitResult:
    """Fit a hybrid or black-box model of ``task``'s system to recorded ``data``.

    The same multiple shooting as the grey box (``diffcontrol.fitting``): from every recorded
    state, ``window`` steps are predicted with the recorded actions, and Adam (cosine-decayed
    from ``learning_rate``) minimises the mean squared error of the predicted observations.
    The network sees the observation and the action normalised by the data's spread; its
    output is scaled by the spread of what it must predict (the nominal model's one-step
    error for a hybrid, the state change for a black box). A hybrid starts exactly at the
    physics (its correction's last layer is zero). Runs in float64; the model is returned
    with float32 weights.

    Args:
        task: a discrete-time task whose ``state_from_observation`` is implemented.
        data: recorded episodes of the task's system (``TrajectoryData``).
        kind: ``"hybrid"`` (physics plus correction) or ``"neural"`` (network only).
        params: the physics of a hybrid (default: the task's nominal parameters; e.g. a grey-box
            fit's ``FitResult.params``).
        window: the windows' length (steps predicted from every recorded state).
        steps: the number of Adam steps.
        learning_rate: Adam's initial step size (cosine-decayed).
        hidden: the network's hidden layer widths.
        seed: the seed of the network's initial weights.

    Raises:
        ConfigError: an unknown kind or a bad setting, or a task that cannot be fitted.
        DataFileError: data from another system.
        InsufficientDataError: fewer transitions than ``MIN_TRANSITIONS[kind]``, or no episode
            longer than ``window``.
    """
    from .fitting import check_data

    if kind not in MODEL_KINDS:
        raise ConfigError(f"unknown model kind {kind!r}; choose one of {list(MODEL_KINDS)}")
    if not isinstance(window, int) or window < 1:
        raise ConfigError(f"window must be a positive number of steps, got {window!r}")
    if not isinstance(steps, int) or steps < 0:
        raise ConfigError(f"steps must be an integer >= 0, got {steps!r}")
    if not (math.isfinite(learning_rate) and learning_rate > 0):
        raise ConfigError(f"learning_rate must be a positive number, got {learning_rate!r}")
    if not hidden or any(not isinstance(h, int) or h < 1 for h in hidden):
        raise ConfigError(f"hidden must be positive layer widths, got {list(hidden)!r}")
    check_data(task, data)
    need = MIN_TRANSITIONS[kind]
    if data.num_steps < need:
        raise InsufficientDataError(
            f"{data.num_steps} recorded transitions are too few for a {kind} model: at least "
            f"{need} are needed ({need // 200} Pendulum-v1 episodes of 200 steps); record more "
            "episodes, or fit the physical parameters (--model params) from less"
        )
    with jax.enable_x64(True):
        return _fit_model(task, data, kind, params, window, steps, learning_rate, hidden, seed)


def _fit_model(task, data, kind, params, window, steps, learning_rate, hidden, seed):
    from .fitting import _windows, adam_fit, predict

    batch = _windows(task, data, window)
    if batch is None:
        longest = max(len(e.actions) for e in data.episodes())
        raise InsufficientDataError(
            f"no episode has {window} steps to predict (the longest has {longest}); "
            f"choose a window of at most {longest} steps or record longer episodes"
        )
    f64 = lambda tree: jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), tree)  # noqa: E731
    physics = f64(task.default_params() if params is None else params)
    obs, actions, next_obs = (np.asarray(a, np.float64) for a in data.transitions())
    to_state = jax.jit(jax.vmap(task.state_from_observation))
    states, next_states = np.asarray(to_state(obs)), np.asarray(to_state(next_obs))
    if kind == "hybrid":
        step = jax.jit(jax.vmap(lambda s, a: task.step(physics, s, a)[0]))
        target = next_states - np.asarray(step(states, actions))
    else:
        target = next_states - states
    inputs = np.concatenate([obs, actions], axis=1)
    correction = Correction(
        jax.random.PRNGKey(seed),
        inputs.shape[1],
        states.shape[1],
        tuple(hidden),
        in_offset=inputs.mean(axis=0),
        in_scale=1.0 / np.maximum(inputs.std(axis=0), 1e-6),
        out_scale=_spread(target),
        zero_output=kind == "hybrid",
    )
    model_cls = HybridModel if kind == "hybrid" else NeuralModel
    model = f64(model_cls(physics, correction))
    fitted_task = model_task(task, model)
    trainable, static = eqx.partition(model, eqx.is_inexact_array)
    # only the network's weights train: the physics and the fixed scalings do not
    frozen = jax.tree.map(lambda _: False, trainable)
    train_spec = eqx.tree_at(
        lambda m: [l for layer in m.correction.net.layers for l in (layer.weight, layer.bias)],
        frozen,
        replace_fn=lambda _: True,
    )
    weights, rest = eqx.partition(trainable, train_spec)

    def residuals(w, batch):
        m = eqx.combine(w, rest, static)
        states, actions, targets = batch
        pred = jax.vmap(predict, in_axes=(None, None, 0, 0))(fitted_task, m, states, actions)
        return pred - targets

    def loss(w, batch):
        return jnp.mean(residuals(w, batch) ** 2)

    schedule = optax.cosine_decay_schedule(learning_rate, max(steps, 1), alpha=0.05)
    optimiser = optax.adam(schedule)
    nominal_loss = _nominal_loss(task, physics, batch, predict)
    best_w, best_loss, history, diverged, message = adam_fit(
        loss, weights, optimiser, steps, batch, "weights"
    )
    if not diverged:
        message = f"mean squared window error {best_loss:.3g} (nominal physics: {nominal_loss:.3g})"
    fitted = jax.tree.map(_to_f32, eqx.combine(best_w, rest, static))
    return ModelFitResult(
        model=fitted,
        kind=kind,
        loss=best_loss,
        nominal_loss=nominal_loss,
        loss_history=np.asarray(history, np.float64),
        diverged=diverged,
        message=message,
        window=window,
        windows=int(batch[0].shape[0]),
        transitions=data.num_steps,
        num_parameters=correction.num_parameters,
    )


def _to_f32(x: Any) -> Any:
    return jnp.asarray(x, jnp.float32) if eqx.is_inexact_array(x) else x


def _nominal_loss(task, physics, batch, predict) -> float:
    states, actions, targets = batch
    pred = jax.jit(jax.vmap(predict, in_axes=(None, None, 0, 0)), static_argnums=0)(
        task, physics, states, actions
    )
    return float(jnp.mean((pred - targets) ** 2))


# ---------------------------------------------------------------------------------------------
# fitted.json: the fitted model of `diffcontrol fit`, read back by `diffcontrol train --model`.

FITTED_FILE = "fitted.json"
FITTED_FORMAT = "diffcontrol-fitted-model"


def read_fitted(path: str | os.PathLike) -> dict[str, Any]:
    """Read and check a ``fitted.json`` (or the directory holding one).

    Raises:
        ModelFileError: the file is missing, not a fitted model, or malformed (says which).
    """
    from .io import read_json

    path = Path(path)
    if path.is_dir():
        path = path / FITTED_FILE
    if not path.exists():
        raise ModelFileError(
            f"no fitted model at {path}; make one with `diffcontrol fit TASK --data FILE "
            "--model {params,hybrid,neural} --out DIR`"
        )
    doc = read_json(path, "fitted model")
    if not isinstance(doc, dict) or doc.get("format") != FITTED_FORMAT:
        raise ModelFileError(f"{path} is not a {FITTED_FORMAT} file (written by `diffcontrol fit`)")
    if doc.get("version") != 1:
        raise ModelFileError(f"{path} has version {doc.get('version')!r}; this diffcontrol reads 1")
    kind = doc.get("model")
    if kind not in ("params", *MODEL_KINDS):
        raise ModelFileError(f"{path}: unknown model kind {kind!r}")
    values = doc.get("all_parameters")
    if not isinstance(values, dict) or not all(
        isinstance(v, int | float) and math.isfinite(v) for v in values.values()
    ):
        raise ModelFileError(f"{path}: 'all_parameters' must map names to finite numbers")
    if kind in MODEL_KINDS and not isinstance(doc.get("network"), dict):
        raise ModelFileError(f"{path}: a {kind} model needs its 'network'")
    doc["_path"] = str(path)
    return doc


def fitted_physics(task: Any, doc: dict[str, Any]) -> Any:
    """The task's parameters with the fitted file's ``all_parameters``.

    Raises:
        ModelFileError: the file is for another task or names a parameter the task lacks.
    """
    where = doc.get("_path", "the fitted model")
    if doc.get("task") != task.name:
        raise ModelFileError(
            f"{where} was fitted for task {doc.get('task')!r}, not {task.name!r}; train "
            f"{doc.get('task')} with it, or fit {task.name}"
        )
    params = task.default_params()
    known = {f.name for f in dataclasses.fields(params)}
    unknown = sorted(set(doc["all_parameters"]) - known)
    if unknown:
        raise ModelFileError(f"{where}: task {task.name!r} has no parameter(s) {unknown}")
    names = sorted(doc["all_parameters"])
    return eqx.tree_at(
        lambda p: tuple(getattr(p, n) for n in names),
        params,
        tuple(float(doc["all_parameters"][n]) for n in names),
    )


def fitted_model(task: Any, doc: dict[str, Any]) -> HybridModel | NeuralModel | Any:
    """The model of a fitted file: the physical parameters (``params``), or a ``HybridModel``
    / ``NeuralModel`` (use ``model_task(task, model)`` to train or predict with it)."""
    physics = fitted_physics(task, doc)
    if doc["model"] == "params":
        return physics
    correction = correction_from_dict(doc["network"], doc.get("_path", "the fitted model"))
    cls = HybridModel if doc["model"] == "hybrid" else NeuralModel
    return cls(physics, correction)


def real_system(doc: dict) -> dict | None:
    """The system a fitted model's data came from: ``{"env_id", "env_kwargs"}`` for recorded
    trajectories, ``{"params"}`` (the simulated trebuchet's) for recorded throws, or None."""
    data = doc.get("data") or {}
    if data.get("env_id"):
        return {"env_id": data["env_id"], "env_kwargs": data.get("env_kwargs") or {}}
    params = (data.get("metadata") or {}).get("params")
    return {"params": params} if isinstance(params, dict) else None


def as_env(real: dict | None) -> tuple[str, dict] | None:
    """``(env_id, env_kwargs)`` of a real system that is a Gymnasium environment, else None."""
    return (real["env_id"], real["env_kwargs"]) if real and "env_id" in real else None


def real_params(task: Any, real: dict | None) -> Any:
    """The task's parameters of a real system given by its parameters (the trebuchet's recorded
    throws), else None."""
    if not real or "params" not in real:
        return None
    return fitted_physics(task, {"task": task.name, "all_parameters": real["params"]})
