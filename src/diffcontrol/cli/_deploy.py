"""``diffcontrol export``: a trained controller as an ONNX model (``deploy.export``)."""

from __future__ import annotations

import argparse
import json
from typing import Any

import diffcontrol.cli._args as a

from ._args import FLAG, REQUIRED, add


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "export",
        help="write a trained controller as an ONNX model",
        description=(
            "Write the controller saved in DIR as an ONNX model for ONNX Runtime (C, C++, "
            "Python, ...): input 'observation', float32 [batch, observation size]; output "
            "'action', the Gymnasium action (float32 [batch, action size] within its bounds, "
            "or the int64 index of a discrete action). The task, the spaces and the "
            "diffcontrol version are in the model's metadata. Needs the onnx package "
            '(pip install "diffcontrol[export]").'
        ),
    )
    # fmt: off
    add(p,
        a.RUN_DIR,
        ("--out", str, REQUIRED, "FILE", "the ONNX file to write, e.g. pendulum.onnx"),
        ("--force", FLAG, False, None, "overwrite FILE if it exists"),
        a.JSON,
    )
    # fmt: on


def cmd_export(args: argparse.Namespace) -> int:
    from ..deploy import export, metadata  # JAX: the library, when the command runs
    from ..policies import read_model

    path = export(args.run_dir, args.out, overwrite=args.force)
    doc = read_model(args.run_dir)
    meta = metadata(doc)
    # the file holds the network; a refinement through the task's model stays with JAX
    left_out = {"refine_left_out": doc["refine"]} if "refine" in doc else {}
    if args.json:
        print(json.dumps({"path": str(path), **meta, **left_out}))
        return 0
    obs, act = json.loads(meta["observation_space"]), json.loads(meta["action_space"])
    if act["kind"] == "box":
        bounds = f" within low {act['low']}, high {act['high']}" if "low" in act else ""
        out = f"action float32 [batch, {act['shape'][0]}]{bounds}"
    else:
        out = f"action int64 [batch] (one of {act['n']})"
    print(
        f"wrote {path}: the {meta['task']} controller, observation float32 "
        f"[batch, {obs['shape'][0]}] -> {out} (ONNX opset {meta['opset']})"
    )
    if left_out:
        print(
            "the network alone: its refinement through the simulator at act time "
            f"({json.dumps(doc['refine'])}) runs with JAX in diffcontrol.load, not in the file"
        )
    return 0
