"""``Correction``: the small network of the hybrid and neural models, and its JSON form.

``out_scale * mlp((x - in_offset) * in_scale)``. Its last layer can start at zero, so a hybrid
model (known physics plus a correction) starts exactly at the known physics. The scalings are
constants (no gradient), set from the data before fitting. ``correction_to_dict`` /
``correction_from_dict`` store it as plain JSON lists (no pickle), the way ``model.json`` stores
a controller. This module imports nothing else of ``identify``, so a task's own model (the
swing-up's) can use it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..controllers import ACTIVATIONS, MLPController
from ..errors import ModelFileError


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


def correction_from_dict(
    doc: Any, where: str = "the model file", sizes: tuple[int, int] | None = None
) -> Correction:
    """Rebuild a ``Correction`` from ``correction_to_dict``'s output; ``sizes``: the inputs
    and outputs the model it serves needs.

    Raises:
        ModelFileError: the document is malformed, or of other sizes than ``sizes`` (names
            what is wrong and where).
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
    scalings = {"in_offset": in_offset, "in_scale": in_scale, "out_scale": out_scale}
    for name, value in scalings.items():
        if not np.all(np.isfinite(np.asarray(value, np.float64))):
            raise ModelFileError(f"{where}: the network's {name} is not finite; refit the model")
    if sizes is not None and (weights[0].shape[1], weights[-1].shape[0]) != tuple(sizes):
        raise ModelFileError(
            f"{where}: the network takes {weights[0].shape[1]} inputs and gives "
            f"{weights[-1].shape[0]} outputs, but this task's model needs {sizes[0]} and "
            f"{sizes[1]}; refit the model for this task"
        )
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
