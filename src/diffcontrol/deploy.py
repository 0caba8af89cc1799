"""A trained controller as an ONNX model, for ONNX Runtime on a robot's computer, in a ROS node
or a C++ program, with no Python or diffcontrol there.

    diffcontrol.export("runs/pendulum", "pendulum.onnx")      # diffcontrol export RUN --out F

The graph is the ``model.json`` controller exactly as ``diffcontrol.load`` runs it
(``policies.NumpyPolicy``): the observation normalisation, the network, the action head, then
the Gymnasium action. Its input ``observation`` is float32 ``[batch, observation_size]``; its
output ``action`` is float32 ``[batch, action_size]`` within the action bounds for a ``Box``
action, or int64 ``[batch]`` (the index) for a discrete one (CartPole's sign head: 1 pushes
right; an N-way choice: the argmax, the first on a tie). The graph computes in float64, as
``load`` does, so that a discrete choice never flips on a near-tie, and casts at the end. A
continuous-time task's controller takes the observation built from the state (the
``features`` of ``observation_space`` in the metadata: each a name of its ``state``,
``cos(name)`` or ``sin(name)``). A controller that refines the network's action through its
model at act time (``model.json``'s ``refine``: the trebuchet) is exported as its network alone.

The model's metadata (``metadata_props``) says what it is: ``task``, ``observation_space`` and
``action_space`` (JSON), ``gym_id``, ``diffcontrol_version``, ``opset``. It is built with the ``onnx``
package's helpers alone (``pip install "diffcontrol[export]"``): a small MLP needs no
converter, and ``jax2onnx`` would pull in Flax and Orbax.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ._version import __version__
from .errors import ConfigError
from .io import write_bytes
from .policies import is_planner, read_model

OPSET = 17
"""The ONNX operator set the graph is written in (ONNX Runtime 1.14 and later read it)."""
IR_VERSION = 8
"""The ONNX file format version of opset 17, so that older runtimes read the file too."""

DISTIL_HINT = (
    "distil it into an MLP first (mpc.distil(task, planner) in Python, then result.save(dir)), "
    "and export that run"
)


def _onnx() -> Any:
    try:
        import onnx
    except ImportError:
        raise ConfigError(
            'exporting to ONNX needs the onnx package: pip install "diffcontrol[export]"'
        ) from None
    return onnx


def export(run: str | os.PathLike, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write the controller of ``run`` (a run directory or its ``model.json``) to ``path`` as
    an ONNX model; returns the path.

    Raises:
        ModelFileError: the run's ``model.json`` is missing or unusable.
        ConfigError: the run holds a planner (it solves through the model at every step:
            distil it into an MLP first), ``path`` exists (without ``overwrite``) or is a
            directory, or the ``onnx`` package is missing.
    """
    source, out = Path(run), Path(path)
    if out.is_dir() or (out.exists() and not overwrite):
        what = "a directory" if out.is_dir() else "a file"
        raise ConfigError(
            f"{out} is {what} already; choose another path, or overwrite it (--force; "
            "overwrite=True in Python)"
        )
    doc = read_model(source)
    if is_planner(doc):
        raise ConfigError(
            f"{source} holds a planner, which solves through the model at every step and has "
            f"no network to export; {DISTIL_HINT}"
        )
    write_bytes(out, model_proto(doc).SerializeToString())
    return out


def model_proto(doc: dict) -> Any:
    """The ``onnx.ModelProto`` of a network controller's ``model.json`` document."""
    onnx = _onnx()
    from onnx import TensorProto, helper, numpy_helper

    nodes: list[Any] = []
    weights: list[Any] = []

    def const(name: str, value: Any, dtype: Any = np.float64) -> str:
        weights.append(numpy_helper.from_array(np.asarray(value, dtype), name))
        return name

    def node(op: str, inputs: list[str], output: str, **attrs: Any) -> str:
        nodes.append(helper.make_node(op, inputs, [output], name=output, **attrs))
        return output

    obs, act, net = doc["observation"], doc["action"], doc["network"]
    h = node("Cast", ["observation"], "observation_f64", to=TensorProto.DOUBLE)
    h = node("Sub", [h, const("obs_offset", obs["offset"])], "centred")
    h = node("Mul", [h, const("obs_scale", obs["scale"])], "normalised")
    layers = net["layers"]
    for i, layer in enumerate(layers):
        w = const(f"layer{i}_weight_t", np.asarray(layer["weight"], np.float64).T)
        h = node("MatMul", [h, w], f"layer{i}_matmul")
        h = node("Add", [h, const(f"layer{i}_bias", layer["bias"])], f"layer{i}_out")
        if i < len(layers) - 1:
            h = _activation(net["activation"], h, f"layer{i}_act", node, const)
    out_type = _head(act, h, node, const)
    graph = helper.make_graph(
        nodes,
        f"diffcontrol_{doc['task']}",
        [helper.make_tensor_value_info("observation", TensorProto.FLOAT, ["batch", obs["size"]])],
        [out_type],
        initializer=weights,
    )
    model = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", OPSET)],
        producer_name="diffcontrol",
        producer_version=__version__,
        doc_string=f"the {doc['task']} controller trained by diffcontrol",
    )
    model.ir_version = IR_VERSION
    helper.set_model_props(model, metadata(doc))
    onnx.checker.check_model(model)
    return model


def _activation(name: str, h: str, out: str, node: Any, const: Any) -> str:
    if name == "tanh":
        return node("Tanh", [h], out)
    if name == "relu":
        return node("Relu", [h], out)
    if name == "sigmoid":
        return node("Sigmoid", [h], out)
    # elu as load computes it, x > 0 ? x : expm1(min(x, 0)) (ONNX Runtime's Elu is float32 only)
    low = node("Min", [h, const(f"{out}_zero", 0.0)], f"{out}_min")
    em1 = node("Sub", [node("Exp", [low], f"{out}_exp"), const(f"{out}_one", 1.0)], f"{out}_em1")
    positive = node("Greater", [h, const(f"{out}_zero2", 0.0)], f"{out}_positive")
    return node("Where", [positive, h, em1], out)


def _head(act: dict, z: str, node: Any, const: Any) -> Any:
    """The nodes from the last layer's ``z`` to the Gymnasium action; returns the output's
    value info."""
    from onnx import TensorProto, helper

    head, kind, size = act["head"], act.get("gym", "box"), act["size"]
    if kind == "discrete":  # the argmax head: the index of the largest logit
        node("ArgMax", [z], "action", axis=-1, keepdims=0, select_last_index=0)
        return helper.make_tensor_value_info("action", TensorProto.INT64, ["batch"])
    if kind == "discrete_sign":  # CartPole: 1 where tanh(z) >= 0 (pushes right)
        t = node("Tanh", [z], "head_tanh")
        first = node("Squeeze", [t, const("head_axis", [1], np.int64)], "head_first")
        up = node("GreaterOrEqual", [first, const("head_zero", 0.0)], "head_up")
        node("Cast", [up], "action", to=TensorProto.INT64)
        return helper.make_tensor_value_info("action", TensorProto.INT64, ["batch"])
    a = z
    if head in ("tanh", "sigmoid"):
        low = np.asarray(act["low"], np.float64)
        span = np.asarray(act["high"], np.float64) - low
        if head == "tanh":  # low + (high - low) (tanh z + 1) / 2
            t = node("Tanh", [z], "head_tanh")
            unit = node("Div", [node("Add", [t, const("head_one", 1.0)], "head_t1"),
                                const("head_two", 2.0)], "head_unit")  # fmt: skip
        else:  # low + (high - low) / (1 + exp(-z))
            unit = node("Sigmoid", [z], "head_unit")
        scaled = node("Mul", [unit, const("head_span", span)], "head_scaled")
        a = node("Add", [scaled, const("head_low", low)], "head_action")
    if act.get("low") is not None and act.get("high") is not None:
        a = node("Max", [a, const("action_low", act["low"])], "action_above_low")
        a = node("Min", [a, const("action_high", act["high"])], "action_clipped")
    node("Cast", [a], "action", to=TensorProto.FLOAT)
    return helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", size])


def metadata(doc: dict) -> dict[str, str]:
    """The model's ``metadata_props``: what it controls and the spaces it maps between."""
    obs, act = doc["observation"], doc["action"]
    observation = {"shape": [obs["size"]], "dtype": "float32"}
    if "features" in obs:
        observation.update(features=obs["features"], state=obs["state"])
    kind = act.get("gym", "box")
    if kind == "box":
        action: dict[str, Any] = {"kind": "box", "shape": [act["size"]], "dtype": "float32"}
        if act.get("low") is not None:
            action.update(low=list(act["low"]), high=list(act["high"]))
    else:
        n = 2 if kind == "discrete_sign" else act["size"]
        action = {"kind": "discrete", "n": n, "dtype": "int64"}
    return {
        "task": str(doc["task"]),
        "gym_id": str(doc.get("gym_id") or ""),
        "observation_space": json.dumps(observation),
        "action_space": json.dumps(action),
        "diffcontrol_version": __version__,
        "opset": str(OPSET),
    }
