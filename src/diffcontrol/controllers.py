"""Controllers: MLP policies with fixed observation scaling and bounded action heads.

A controller maps one observation (a vector) to one action (a vector). It is an
``equinox.Module``, so it is a PyTree: ``jax.grad`` of any loss of its outputs gives a
controller-shaped gradient, and ``jax.vmap`` runs it on a batch.

Action heads (the last, parameter-free stage):

- ``"linear"``: the raw output (unbounded; the 2019 Pendulum original).
- ``"tanh"``: ``low + (high - low) (tanh(z) + 1) / 2``. Bounded and smooth, so the gradient
  does not die at an actuator clip the way ``clip(z)`` would.
- ``"sigmoid"``: the same map with the logistic function (used for angles in ``[0, 90]``).
- ``"sign"``: the straight-through sign of the seed post applied to ``tanh(z)``: forward
  ``+1`` if ``tanh(z) >= 0`` else ``-1``, backward the derivative of ``tanh`` (the sign's own
  derivative is replaced by 1). This is how a discrete push is trained by backpropagation.
- ``"argmax"``: an N-way choice. The network outputs ``n`` logits ``z``; forward
  ``one_hot(argmax z)`` (a valid one-hot action vector of size ``n``, ties going to the first
  index), backward the Jacobian of ``softmax(z / T)`` with ``T = ARGMAX_TEMPERATURE``
  (straight-through softmax; see ``straight_through_argmax``). A task turns the one-hot vector
  into its physical action with a dot product (the acrobot's torque is
  ``one_hot . (-1, 0, +1)``), so the gradient reaches the logits of every choice.

The bounded heads take an optional slope floor for training (``head_floor``;
``TrainConfig.head_slope_floor``): the backward pass uses ``max(f'(z), floor x f'(0))`` in
place of the squashing function's own slope ``f'(z)``; the forward pass is unchanged. A
saturated actuator then still tells the gradient which way its raw output should move. With
the exact slope, a controller that has learned to hold an actuator at its bound gets almost
no gradient there, and stays there (``squash``).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ._jax_setup import FAST_COMPILE, FastJit
from .config import ACTIVATION_NAMES, HEADS

_FUNCTIONS = {"tanh": jnp.tanh, "relu": jax.nn.relu, "sigmoid": jax.nn.sigmoid, "elu": jax.nn.elu}
ACTIVATIONS = {name: _FUNCTIONS[name] for name in ACTIVATION_NAMES}
"""The hidden activations by name (``config.ACTIVATION_NAMES``, which configurations check)."""
ARGMAX_TEMPERATURE = 1.0
"""Temperature ``T`` of the softmax whose Jacobian is the ``"argmax"`` head's backward pass."""
INITS = ("equinox", "glorot")


@jax.custom_jvp
def straight_through_sign(x: Array) -> Array:
    """``+1`` where ``x >= 0`` and ``-1`` elsewhere, with the identity as its derivative.

    Forward: ``f(x) = 1 if x >= 0 else -1``. Backward: ``df/dx := 1``. (The 2019 Julia code used
    ``sign``, which maps 0 to 0; the post's formula, used here, maps 0 to +1, so every output
    is a valid two-action push.) Written as a ``custom_jvp`` rather than the usual
    ``x + stop_gradient(hard - x)``, whose forward value is off by rounding for large ``|x|``
    and ``nan`` at infinity.
    """
    return jnp.where(x >= 0, 1.0, -1.0).astype(jnp.result_type(x, float))


@straight_through_sign.defjvp
def _straight_through_sign_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    return straight_through_sign(x), dx


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def straight_through_argmax(z: Array, temperature: float = ARGMAX_TEMPERATURE) -> Array:
    """``one_hot(argmax z)`` over the last axis, with the derivative of ``softmax(z / T)``.

    Forward: the one-hot vector of the largest logit (the first one on a tie, as
    ``argmax``), exactly 0 and 1 whatever the logits' magnitude. Backward: the Jacobian of
    ``p = softmax(z / T)``, ``dp = (p * dz - p * sum(p * dz)) / T``, instead of argmax's zero
    derivative (straight-through softmax: Bengio et al. 2013, "Estimating or propagating
    gradients through stochastic neurons"; the Gumbel-softmax straight-through estimator of
    Jang et al. 2017 without the noise). ``T`` (static, > 0) sets how far from a tie the
    gradient still sees the other choices: small ``T`` gives a sharper, more local signal.

    Args:
        z: logits, shape ``[..., n]``.
        temperature: the softmax temperature ``T`` of the backward pass.

    Returns:
        The one-hot choice, shape ``[..., n]``, in ``z``'s float dtype.
    """
    dtype = jnp.result_type(z, float)
    return jax.nn.one_hot(jnp.argmax(z, axis=-1), z.shape[-1], dtype=dtype)


@straight_through_argmax.defjvp
def _straight_through_argmax_jvp(temperature, primals, tangents):
    (z,), (dz,) = primals, tangents
    p = jax.nn.softmax(z / temperature, axis=-1)
    dp = (p * dz - p * jnp.sum(p * dz, axis=-1, keepdims=True)) / temperature
    return straight_through_argmax(z, temperature), dp


_SQUASH = {"tanh": (jnp.tanh, 1.0), "sigmoid": (jax.nn.sigmoid, 0.25)}
"""A bounded head's squashing function and its slope at 0."""


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 2))
def squash(head: str, z: Array, floor: float) -> Array:
    """The ``"tanh"`` or ``"sigmoid"`` head's squashing function of ``z``, whose derivative in
    the backward pass is at least ``floor`` times its slope at 0 (see the module docstring)."""
    return _SQUASH[head][0](z)


@squash.defjvp
def _squash_jvp(head, floor, primals, tangents):
    (z,), (dz,) = primals, tangents
    f, peak = _SQUASH[head]
    y, slope = jax.jvp(f, (z,), (jnp.ones_like(z),))
    return y, jnp.maximum(slope, floor * peak) * dz


def apply_head(head: str, z: Array, low: Array, high: Array, floor: float = 0.0) -> Array:
    """Map the network's raw output ``z`` through an action head (see the module docstring);
    ``floor``: the bounded heads' slope floor in the backward pass (0: their own slope)."""
    if head == "linear":
        return z
    if head in _SQUASH:
        s = squash(head, z, floor) if floor else _SQUASH[head][0](z)
        if head == "tanh":
            return low + (high - low) * (s + 1) / 2
        return low + (high - low) * s
    if head == "sign":
        return straight_through_sign(jnp.tanh(z))
    if head == "argmax":
        return straight_through_argmax(z)
    raise ValueError(f"unknown action head {head!r}; choose one of {HEADS}")


def head_inverse(head: str, action: Array, low: Array, high: Array, margin: float = 1e-3) -> Array:
    """The raw output ``z`` that a continuous head maps to ``action`` (the inverse of
    ``apply_head`` for ``"linear"``, ``"tanh"`` and ``"sigmoid"``), with a bounded head's action
    first kept ``margin`` of its range inside the bounds, where ``z`` is finite."""
    if head == "linear":
        return action
    s = jnp.clip((action - low) / (high - low), margin / 2, 1 - margin / 2)
    if head == "tanh":
        return jnp.arctanh(2 * s - 1)
    if head == "sigmoid":
        return jnp.log(s) - jnp.log1p(-s)
    raise ValueError(f"the {head!r} head has no inverse; use linear, tanh or sigmoid")


class MLPController(eqx.Module):
    """A multilayer perceptron policy ``obs -> action``.

    ``action = head(W_n act(... act(W_1 ((obs - obs_offset) * obs_scale) + b_1) ...) + b_n)``.
    The observation scaling and the action bounds are fixed (they get no gradient).
    """

    layers: tuple[eqx.nn.Linear, ...]
    obs_offset: Float[Array, " obs"]
    obs_scale: Float[Array, " obs"]
    action_low: Float[Array, " act"]
    action_high: Float[Array, " act"]
    activation: str = eqx.field(static=True)
    head: str = eqx.field(static=True)
    head_floor: float = eqx.field(static=True)

    def __init__(
        self,
        key: PRNGKeyArray,
        obs_size: int,
        action_size: int,
        hidden: Sequence[int] = (64, 64),
        *,
        activation: str = "tanh",
        head: str = "tanh",
        obs_offset: Sequence[float] | None = None,
        obs_scale: Sequence[float] | None = None,
        action_low: Sequence[float] | None = None,
        action_high: Sequence[float] | None = None,
        final_scale: float = 0.1,
        init: str = "equinox",
        head_floor: float = 0.0,
    ):
        """Build a randomly initialised controller.

        Args:
            key: PRNG key for the weights.
            obs_size: the input size (observation).
            action_size: the output size (action).
            hidden: widths of the hidden layers.
            activation: one of ``"tanh"``, ``"relu"``, ``"sigmoid"``, ``"elu"``.
            head: one of ``"linear"``, ``"tanh"``, ``"sigmoid"``, ``"sign"``, ``"argmax"``.
            obs_offset: the network sees ``(obs - obs_offset) * obs_scale``.
            obs_scale: see ``obs_offset``.
            action_low: lower bounds of the ``"tanh"``/``"sigmoid"`` heads.
            action_high: upper bounds of the ``"tanh"``/``"sigmoid"`` heads.
            final_scale: the last layer's initial weights are multiplied by this, so the
                untrained controller starts near the middle of its action range.
            init: ``"equinox"`` (Equinox's default: weights and biases uniform in
                ``+-1/sqrt(fan_in)``) or ``"glorot"`` (Glorot-uniform weights, zero biases:
                the default of Flux and DiffEqFlux, used by the 2019-2020 posts).
            head_floor: the bounded heads' slope floor in training's backward pass, a
                fraction of the slope at 0 in ``[0, 1]`` (module docstring; 0: none).
        """
        if activation not in ACTIVATIONS:
            raise ValueError(
                f"unknown activation {activation!r}; choose one of {list(ACTIVATIONS)}"
            )
        if head not in HEADS:
            raise ValueError(f"unknown action head {head!r}; choose one of {HEADS}")
        if not 0 <= head_floor <= 1:
            raise ValueError(f"head_floor must be in [0, 1], got {head_floor!r}")
        if init not in INITS:
            raise ValueError(f"unknown init {init!r}; choose one of {INITS}")
        if head == "argmax" and action_size < 2:
            raise ValueError(
                f"the argmax head chooses among action_size options; got {action_size}, use >= 2"
            )
        self.layers = _initial_layers(key, (obs_size, *hidden, action_size), init, final_scale)
        self.obs_offset = _vector(obs_offset, obs_size, 0.0)
        self.obs_scale = _vector(obs_scale, obs_size, 1.0)
        self.action_low = _vector(action_low, action_size, -1.0)
        self.action_high = _vector(action_high, action_size, 1.0)
        self.activation = activation
        self.head = head
        self.head_floor = float(head_floor)

    def __call__(self, obs: Float[Array, " obs"]) -> Float[Array, " act"]:
        low, high = jax.lax.stop_gradient((self.action_low, self.action_high))
        return apply_head(self.head, self.logits(obs), low, high, self.head_floor)

    def logits(self, obs: Float[Array, " obs"]) -> Float[Array, " out"]:
        """The network's raw output ``z``, before the action head."""
        act = ACTIVATIONS[self.activation]
        # The scaling and bounds are constants of the controller, not trainable weights.
        offset, scale = jax.lax.stop_gradient((self.obs_offset, self.obs_scale))
        h = (obs - offset) * scale
        for layer in self.layers[:-1]:
            h = act(layer(h))
        return self.layers[-1](h)

    @property
    def num_parameters(self) -> int:
        """Number of trainable weights and biases."""
        return sum(l.weight.size + l.bias.size for l in self.layers)


def _draw_layers(
    key: PRNGKeyArray, sizes: tuple[int, ...], init: str, final_scale: Any
) -> tuple[eqx.nn.Linear, ...]:
    """The layers' random weights (Equinox's, or Glorot's), the last layer's scaled."""
    keys = jax.random.split(key, len(sizes) - 1)
    layers = [eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys)]
    if init == "glorot":
        layers = [_glorot(l, k) for l, k in zip(layers, jax.random.split(keys[0], len(layers)))]
    last = layers[-1]
    last = eqx.tree_at(
        lambda l: (l.weight, l.bias), last, (last.weight * final_scale, last.bias * 0)
    )
    return (*layers[:-1], last)


_DRAW_LAYERS = FastJit(_draw_layers, *FAST_COMPILE, static_argnums=(1, 2, 3))
"""``_draw_layers`` as one compiled program per shape, for a network made outside any trace (a
model to fit, a loaded file's skeleton): drawn op by op, every layer's weight and bias would
compile a program of its own. On a CPU it draws the same bits as the op-by-op code."""


def _initial_layers(
    key: PRNGKeyArray, sizes: tuple[int, ...], init: str, final_scale: Any
) -> tuple[eqx.nn.Linear, ...]:
    """``_draw_layers``: compiled once per shape (``_DRAW_LAYERS``) from a concrete key and
    scale, part of the program being traced otherwise (a training's start, a ``vmap``)."""
    if not isinstance(key, jax.core.Tracer):
        try:
            scale = float(final_scale)
        except (TypeError, jax.errors.ConcretizationTypeError):
            pass  # an array of scales, or a traced one
        else:
            return _DRAW_LAYERS(key, sizes, init, scale)
    return _draw_layers(key, sizes, init, final_scale)


def _glorot(layer: eqx.nn.Linear, key: PRNGKeyArray) -> eqx.nn.Linear:
    """The layer with Glorot-uniform weights, ``U(+-sqrt(6 / (fan_in + fan_out)))``, and zero bias."""
    fan_out, fan_in = layer.weight.shape
    limit = np.sqrt(6.0 / (fan_in + fan_out))
    weight = jax.random.uniform(key, layer.weight.shape, minval=-limit, maxval=limit)
    return eqx.tree_at(lambda l: (l.weight, l.bias), layer, (weight, jnp.zeros_like(layer.bias)))


def _vector(values: Sequence[float] | None, size: int, default: float) -> Array:
    if values is None:
        return jnp.full((size,), default, dtype=jnp.float32)
    arr = np.asarray(values, dtype=np.float32).reshape(-1)
    if arr.shape != (size,):
        raise ValueError(f"expected {size} values, got {arr.shape[0]}: {list(arr)}")
    return jnp.asarray(arr)
