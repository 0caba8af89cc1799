"""Discrete-time hybrid and black-box (neural) models of a task's system, and their fit.

``HybridModel`` (the task's step plus a ``Correction``) and ``NeuralModel`` (a network alone)
are fitted by ``fit_network`` (for the kinds ``identify.kinds.Hybrid`` and ``Neural``) with the grey box's multiple shooting (``identify.steps``);
``model_task`` makes a task that steps one, to train or predict through it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array

from .. import _gym
from .._jax_setup import float64
from ..errors import ConfigError, InsufficientDataError
from ..tasks._base import Task
from ._shooting import FitResult, adam_fit, check_settings
from ._task import fit_parameter_names
from .ensemble import Ensemble, bootstrap_counts, check_members, make_ensemble
from .network import Correction
from .steps import _windows, check_data, masked_mean, predict, task_actions


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
    measures it. A model whose correction is an ``Ensemble`` steps with the members' mean, and
    every step's training loss gains ``penalty * spread`` (``Ensemble.spread`` at the step's
    observation and action; the reward, and so the returns reported on the model, stay the
    task's).
    """
    if not isinstance(task, Task):
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
            if not isinstance(model.correction, Ensemble) or model.correction.penalty == 0:
                return lambda params, *rest: inner(params.params, *rest)

            def penalised(params, state, action, *rest):  # the members' doubt, where it goes
                doubt = params.correction.spread(jnp.concatenate([task.observe(state), action]))
                loss = inner(params.params, state, action, *rest)
                return loss + params.correction.penalty * doubt

            return penalised

        def state_grid(self, params):  # the physical part's (a planner's terminal value)
            return cls.state_grid(self, params.params)

        def default_config(self):
            # A grid value solved through the network misleads the training through it (far
            # worse than none: docs/benchmarks.md), so the task's recipe without one.
            config = cls.default_config(self)
            if getattr(config, "value_grid", 0):
                recipe = getattr(task, "model_recipe", None)
                without = self.recipes()[recipe] if recipe else {}
                config = config.replace(**{"value_grid": 0, **without})
            return config

    _ModelTask.__name__ = _ModelTask.__qualname__ = f"{type(model).__name__}{cls.__name__}"
    return _ModelTask()


def _spread(x: np.ndarray) -> np.ndarray:
    """A robust standard deviation per column (half the 16-84 % range), floored at 1e-6: the
    state changes of an angle that wraps at +-pi would inflate a plain one."""
    lo, hi = np.percentile(x, [16, 84], axis=0)
    return np.maximum((hi - lo) / 2, 1e-6)


def fit_network(
    task: Any,
    data: Any,
    kind: Any,
    *,
    params: Any = None,
    window: int = 10,
    steps: int = 2000,
    learning_rate: float = 3e-3,
    hidden: Sequence[int] = (32, 32),
    seed: int = 0,
    members: int = 1,
    bootstrap: bool = False,
    uncertainty_penalty: float = 1.0,
) -> FitResult:
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
        kind: the model kind (``identify.kinds``): its ``residual`` (the network learns what
            the physics misses, a hybrid, or the whole state change), ``model_class``,
            ``min_transitions`` and ``name``.
        params: the physics of a hybrid (default: the task's nominal parameters; e.g. a grey-box
            fit's ``FitResult.params``).
        window: the windows' length (steps predicted from every recorded state).
        steps: the number of Adam steps.
        learning_rate: Adam's initial step size (cosine-decayed).
        hidden: the network's hidden layer widths.
        seed: the seed of the network's initial weights.
        members: the number of networks: more than 1 fits an ``Ensemble`` (each member from
            its own key, all in one compiled program; each member's loss is its own windows'
            error, and the model predicts with their mean).
        bootstrap: each member of an ensemble fits its own resample of the windows (with
            replacement), not all of them.
        uncertainty_penalty: an ensemble's weight of its spread in the training loss through
            it (``model_task``).

    Raises:
        ConfigError: an unknown model type or a bad setting, or a task that cannot be fitted.
        DataFileError: data from another system.
        InsufficientDataError: fewer transitions than ``kind.min_transitions``, or no episode
            longer than ``window``.
    """
    check_settings(window, steps, learning_rate)
    check_members(members, uncertainty_penalty)
    if not hidden or any(not isinstance(h, int) or h < 1 for h in hidden):
        raise ConfigError(f"hidden must be positive layer widths, got {list(hidden)!r}")
    check_data(task, data)
    need = kind.min_transitions
    if data.num_steps < need:
        more = "record more episodes"
        if fit_parameter_names(task):
            more += ", or fit the physical parameters (--model params) from less"
        raise InsufficientDataError(
            f"{data.num_steps} recorded transitions are too few for a {kind.name} model: at least "
            f"{need} are needed; {more}"
        )
    with float64():
        return _fit_network(
            task, data, kind, params, window, steps, learning_rate, hidden, seed,
            (members, bool(bootstrap), float(uncertainty_penalty)),
        )  # fmt: skip


def _fit_network(task, data, kind, params, window, steps, learning_rate, hidden, seed, ens):
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
    actions = np.asarray(task_actions(task, actions), np.float64)  # a Discrete index: the task's
    to_state = jax.jit(jax.vmap(_gym.state_from_observation.bound(task)))
    states, next_states = np.asarray(to_state(obs)), np.asarray(to_state(next_obs))
    if kind.residual:
        step = jax.jit(jax.vmap(lambda s, a: task.step(physics, s, a)[0]))
        target = next_states - np.asarray(step(states, actions))
    else:
        target = next_states - states
    inputs = np.concatenate([obs, actions], axis=1)
    scalings = dict(
        in_offset=inputs.mean(axis=0),
        in_scale=1.0 / np.maximum(inputs.std(axis=0), 1e-6),
        out_scale=_spread(target),
        zero_output=kind.residual,
    )
    members, bootstrap, penalty = ens
    key, sizes = jax.random.PRNGKey(seed), (inputs.shape[1], states.shape[1], tuple(hidden))
    if members == 1:
        correction = Correction(key, *sizes, **scalings)
    else:
        correction = make_ensemble(key, members, *sizes, penalty=penalty, **scalings)
    model_cls = kind.model_class
    model = f64(model_cls(physics, correction))
    fitted_task = model_task(task, model)
    trainable, static = eqx.partition(model, eqx.is_inexact_array)
    # only the network's weights train: the physics and the fixed scalings do not
    frozen = jax.tree.map(lambda _: False, trainable)
    net = lambda m: m.correction.net if members == 1 else m.correction.members.net  # noqa: E731
    train_spec = eqx.tree_at(
        lambda m: [l for layer in net(m).layers for l in (layer.weight, layer.bias)],
        frozen,
        replace_fn=lambda _: True,
    )
    weights, rest = eqx.partition(trainable, train_spec)

    def errors(m, batch):  # the mean squared error of every window [N]
        pred = jax.vmap(predict, in_axes=(None, None, 0, 0))(
            fitted_task, m, batch.states, batch.actions
        )
        return jnp.mean((pred - batch.targets) ** 2, axis=(1, 2))

    # each member's weight of every window (0 on the padding rows)
    counts = bootstrap_counts(batch.count, members, seed, bootstrap)
    counts = np.pad(counts, ((0, 0), (0, batch.mask.shape[0] - batch.count)))

    # The frozen part of the model (the physics, the data's scalings) and the members' window
    # weights are arguments, not constants: one compiled fit for every data set of a shape.
    def loss(w, args):
        (rest, counts), batch = args
        m = eqx.combine(w, rest, static)
        if members == 1:
            return masked_mean(errors(m, batch), batch.mask)

        def member_loss(member, count):  # each member alone, on its own (re)sample
            return jnp.sum(count * errors(model_cls(m.params, member), batch)) / jnp.sum(count)

        return jnp.mean(eqx.filter_vmap(member_loss)(m.correction.members, counts))

    schedule = optax.cosine_decay_schedule(learning_rate, max(steps, 1), alpha=0.05)
    optimiser = optax.adam(schedule)
    nominal_loss = _nominal_loss(task, physics, batch, predict)
    best_w, best_loss, history, diverged, message = adam_fit(
        loss, weights, optimiser, steps, ((rest, jnp.asarray(counts)), batch), "weights"
    )
    if not diverged:
        each = " (each member's, averaged)" if members > 1 else ""
        message = (
            f"mean squared window error{each} {best_loss:.3g} (nominal physics: {nominal_loss:.3g})"
        )
    fitted = jax.tree.map(_to_f32, eqx.combine(best_w, rest, static))
    return FitResult(
        model=fitted,
        model_type=kind.name,
        params=fitted.params,
        loss=best_loss,
        nominal_loss=nominal_loss,
        loss_history=np.asarray(history, np.float64),
        diverged=diverged,
        message=message,
        window=window,
        windows=batch.count,
        transitions=data.num_steps,
        num_parameters=correction.num_parameters,
    )


def _to_f32(x: Any) -> Any:
    return jnp.asarray(x, jnp.float32) if eqx.is_inexact_array(x) else x


def _nominal_loss(task, physics, batch, predict) -> float:
    pred = jax.jit(jax.vmap(predict, in_axes=(None, None, 0, 0)), static_argnums=0)(
        task, physics, batch.states, batch.actions
    )
    return float(masked_mean((pred - batch.targets) ** 2, batch.mask))


# ---------------------------------------------------------------------------------------------
