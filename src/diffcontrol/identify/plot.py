"""``prediction.png``: a fitted and the nominal model's predictions against recorded episodes."""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .. import _gym
from .._jax_setup import float64
from ..io import write_figure  # noqa: E402
from .data import TrajectoryData  # noqa: E402
from .ode import predict as ode_predict  # noqa: E402
from .steps import predict, task_actions  # noqa: E402

Predictor = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(first observation [k], actions [T, m]) -> predicted observations [T, k]``, open loop."""


def task_predictor(task: Any, params: Any) -> Predictor:
    """Open loop through a discrete-time task's step with ``params`` (``steps.predict``), in
    float64; ``task`` may be ``hybrid.model_task(task, model)`` with the model as ``params``."""

    @eqx.filter_jit  # one program per segment length, not one per segment
    def open_loop(p, obs0, actions):
        return predict(task, p, _gym.state_from_observation(task, obs0), actions)

    def run(obs0: np.ndarray, actions: np.ndarray) -> np.ndarray:
        with float64():
            p = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)
            acts = jnp.asarray(task_actions(task, actions))
            return np.asarray(open_loop(p, jnp.asarray(obs0), acts))

    return run


def ode_predictor(model: Any, dt: float, substeps: int) -> Predictor:
    """A continuous-time model as a ``Predictor``: the states after each held action, open
    loop in float64 (``identify.ode.predict``, as the prediction errors are measured)."""

    @eqx.filter_jit  # one program per segment length, not one per segment
    def open_loop(m, state, actions):
        return ode_predict(m, state, actions, dt, substeps)

    def run(state0: np.ndarray, actions: np.ndarray) -> np.ndarray:
        with float64():
            m = jax.tree.map(
                lambda a: jnp.asarray(a, jnp.float64) if eqx.is_inexact_array(a) else a, model
            )
            a = jnp.asarray(actions, jnp.float64)
            return np.asarray(open_loop(m, jnp.asarray(state0, jnp.float64), a))

    return run


def _segments(run: Predictor, obs: np.ndarray, actions: np.ndarray, every: int):
    """Open-loop predictions restarted from the recorded observation every ``every`` steps:
    a list of (first step, predicted observations [<= every + 1, k]) pieces."""
    out = []
    for t in range(0, len(actions), every):
        acts = actions[t : t + every]
        # padded to `every` steps (repeating the last action), so that every segment of every
        # episode is one compiled program; the prediction is causal, the padding is cut off
        padded = np.concatenate([acts, np.repeat(acts[-1:], every - len(acts), axis=0)])
        pred = run(obs[t], padded)[: len(acts)]
        out.append((t, np.concatenate([obs[t : t + 1], pred])))
    return out


def prediction_plot(
    models: dict[str, Predictor],
    data: TrajectoryData,
    path: str | Path,
    every: int = 50,
    episodes: int = 2,
    title: str = "",
) -> Path:
    """Plot each observation of the first ``episodes`` episodes of ``data`` (grey) against the
    open-loop predictions of every model in ``models`` (label -> a ``Predictor``, e.g.
    ``task_predictor(task, params)``), restarted from
    the recorded state every ``every`` steps with the recorded actions; write a PNG atomically.
    """
    eps = list(data.episodes())[:episodes]
    names = list(data.observation_columns)
    fig, axes = plt.subplots(
        len(names), len(eps), figsize=(5.5 * len(eps), 2.2 * len(names)), squeeze=False
    )
    dt = data.metadata.get("dt_s") or 1.0
    for j, ep in enumerate(eps):
        t_axis = np.arange(len(ep.observations)) * dt
        pieces = {
            label: _segments(run, ep.observations, ep.actions, every)
            for label, run in models.items()
        }
        for i, name in enumerate(names):
            ax = axes[i, j]
            ax.plot(t_axis, ep.observations[:, i], color="0.55", lw=3.0, label="recorded")
            for c, (label, segs) in enumerate(pieces.items()):
                for s, (t0, pred) in enumerate(segs):
                    ax.plot(
                        t_axis[t0 : t0 + len(pred)],
                        pred[:, i],
                        color=f"C{c}",
                        ls="--" if c else "-",
                        lw=1.0,
                        label=label if s == 0 else None,
                    )
            ax.set_ylabel(name)
            if i == 0:
                ax.set_title(f"episode {ep.id}")
        axes[-1, j].set_xlabel("time (s)" if data.metadata.get("dt_s") else "step")
    axes[0, 0].legend(loc="best", fontsize=8)
    title = title or f"open-loop predictions, restarted from the recorded state every {every} steps"
    fig.suptitle("\n".join(textwrap.wrap(title, 60 * len(eps))), fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=100)
