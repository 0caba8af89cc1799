"""A value network as a planner's terminal cost: ``cost_to_go(state)``, trainable through the
planner (``mpc.learn_value``), stored as plain JSON lists (``to_json`` / ``from_json``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, PRNGKeyArray

from ..errors import ConfigError, ModelFileError

ACTIVATIONS = {"tanh": jnp.tanh, "softplus": jax.nn.softplus, "elu": jax.nn.elu}
"""Smooth activations only: iLQR takes the terminal cost's Hessian."""

FORMAT = "diffcontrol-value-network"


class ValueNetwork(eqx.Module):
    """The cost-to-go of a state, ``scale * mlp((observe(state) - offset) / spread)``: an MLP
    of the task's observation (for Pendulum ``cos θ, sin θ, θ̇``, so the value is periodic in
    the angle), in the units of the planner's running cost. As ``make_planner(...,
    terminal_cost=network)`` its weights are part of the planner's PyTree: the plan, a
    closed-loop return and any loss of it are differentiable in them.

    Attributes:
        layers: the linear layers, the last with one output.
        offset: subtracted from the observation (fixed, not trained).
        spread: divides the offset observation (fixed, not trained).
        scale: the output's unit (e.g. the typical cost-to-go), fixed.
        activation: the hidden layers' activation, one of ``ACTIVATIONS`` (smooth).
        task: the task whose ``observe`` makes the input.
    """

    layers: tuple[eqx.nn.Linear, ...]
    offset: tuple[float, ...] = eqx.field(static=True)
    spread: tuple[float, ...] = eqx.field(static=True)
    scale: float = eqx.field(static=True)
    activation: str = eqx.field(static=True)
    task: Any = eqx.field(static=True)

    def __init__(
        self,
        key: PRNGKeyArray,
        task: Any,
        hidden: Sequence[int] = (64, 64),
        scale: float = 100.0,
        activation: str = "tanh",
        offset: Sequence[float] | None = None,
        spread: Sequence[float] | None = None,
    ):
        """A randomly initialised network (its last layer scaled by 0.01, so it starts near a
        zero cost-to-go).

        Args:
            key: PRNG key of the weights.
            task: the planner's task (its ``observe`` and ``observation_size``).
            hidden: the hidden layers' widths, each >= 1.
            scale: the output's unit, finite and > 0.
            activation: ``tanh``, ``softplus`` or ``elu``.
            offset: subtracted from the observation (default 0 per entry; fixed, not trained).
            spread: the offset observation is divided by it (default 1 per entry; > 0).

        Raises:
            ConfigError: a width < 1, a non-positive scale or spread, an unknown activation.
        """
        size = int(task.observation_size)
        hidden = tuple(hidden)
        if any(isinstance(h, bool) or not isinstance(h, int | np.integer) or h < 1 for h in hidden):
            raise ConfigError(f"hidden={hidden!r} must be widths >= 1")
        if not (isinstance(scale, int | float) and math.isfinite(scale) and scale > 0):
            raise ConfigError(f"scale={scale!r} must be a finite number > 0 (the cost's unit)")
        if activation not in ACTIVATIONS:
            raise ConfigError(f"activation={activation!r} is not one of {sorted(ACTIVATIONS)}")
        offset = (0.0,) * size if offset is None else tuple(float(v) for v in offset)
        spread = (1.0,) * size if spread is None else tuple(float(v) for v in spread)
        if len(offset) != size or len(spread) != size or not all(s > 0 for s in spread):
            raise ConfigError(f"offset and spread must be {size} numbers, spread > 0")
        sizes = (size, *hidden, 1)
        keys = jax.random.split(key, len(sizes) - 1)
        layers = [eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys)]
        last = layers[-1]
        layers[-1] = eqx.tree_at(
            lambda l: (l.weight, l.bias), last, (0.01 * last.weight, 0 * last.bias)
        )
        self.layers = tuple(layers)
        self.offset, self.spread = offset, spread
        self.scale, self.activation, self.task = float(scale), activation, task

    def __call__(self, state: Array) -> Array:
        """The cost-to-go of ``state`` (a scalar)."""
        h = self.task.observe(state)
        h = (h - jnp.asarray(self.offset, h.dtype)) / jnp.asarray(self.spread, h.dtype)
        act = ACTIVATIONS[self.activation]
        for layer in self.layers[:-1]:
            h = act(layer(h))
        return self.scale * self.layers[-1](h)[0]

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(layer.out_features for layer in self.layers[:-1])

    def to_json(self) -> dict[str, Any]:
        """The network as plain JSON (lists of numbers, no pickle)."""
        return {
            "format": FORMAT,
            "task": self.task.name,
            "hidden": list(self.hidden),
            "activation": self.activation,
            "scale": self.scale,
            "offset": list(self.offset),
            "spread": list(self.spread),
            "layers": [
                {
                    "weight": np.asarray(l.weight, float).tolist(),
                    "bias": np.asarray(l.bias, float).tolist(),
                }
                for l in self.layers
            ],
        }

    @classmethod
    def from_json(cls, task: Any, doc: Any) -> ValueNetwork:
        """Inverse of ``to_json``, for ``task``.

        Raises:
            ModelFileError: a document of another task or not of this format, or weights of the
                wrong shapes or not finite.
        """
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise ModelFileError(f"not a value network (its 'format' is not {FORMAT!r})")
        if doc.get("task") != task.name:
            raise ModelFileError(
                f"the value network is of task {doc.get('task')!r}, not {task.name!r}"
            )
        try:
            net = cls(
                jax.random.PRNGKey(0), task, tuple(doc["hidden"]), doc["scale"],
                doc["activation"], doc["offset"], doc["spread"],
            )  # fmt: skip
            layers = []
            for layer, stored in zip(net.layers, doc["layers"], strict=True):
                w, b = (np.asarray(stored[k], np.float32) for k in ("weight", "bias"))
                if w.shape != layer.weight.shape or b.shape != layer.bias.shape:
                    raise ValueError("a layer's weights have the wrong shape")
                if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                    raise ValueError("a layer's weights are not finite")
                layers.append(eqx.tree_at(lambda l: (l.weight, l.bias), layer, (w, b)))
        except (KeyError, TypeError, ValueError, ConfigError) as e:
            raise ModelFileError(f"a malformed value network: {e}") from None
        return eqx.tree_at(lambda n: n.layers, net, tuple(layers))
