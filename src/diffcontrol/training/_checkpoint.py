"""Checkpoints of a training run: one ``.npz`` of the state's arrays plus a JSON header, opened
with ``allow_pickle=False`` and written atomically (``io.write_bytes``)."""

from __future__ import annotations

import io as _io
import json
import math
import os
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ..errors import ModelFileError
from ..io import _finite, npz_shape, parse_json, write_bytes

CHECKPOINT_FORMAT = "diffcontrol-checkpoint"
CHECKPOINT_VERSION = 1


def save_checkpoint(path: str | os.PathLike, tree: Any, meta: dict) -> None:
    """Save the array leaves of ``tree`` and a JSON-able ``meta`` dict to ``path`` atomically."""
    leaves = jax.tree.leaves(tree)
    header = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "leaves": len(leaves)}
    header["meta"] = _finite(meta)
    arrays = {f"leaf_{i:04d}": np.asarray(x) for i, x in enumerate(leaves)}
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    buf = _io.BytesIO()
    np.savez(buf, **arrays)
    write_bytes(path, buf.getvalue())


def _check_meta(meta: Any, bad: Any) -> None:
    """A checkpoint's ``meta``: the curve so far, the best point's index, the seconds."""
    if not isinstance(meta, dict) or not isinstance(meta.get("curve"), list):
        raise bad("holds no learning curve")
    curve = meta["curve"]
    if not all(isinstance(p, dict) and isinstance(p.get("update"), int) for p in curve):
        raise bad("holds a malformed learning curve")
    best = meta.get("best_index")
    if not isinstance(best, int) or not (0 <= best < max(1, len(curve))):
        raise bad(f"holds a best point {best!r} outside its curve")
    for name in ("seconds_before", "compile_seconds_before"):
        value = meta.get(name)
        if not isinstance(value, int | float) or not (0 <= value < math.inf):
            raise bad(f"holds a bad {name} ({value!r})")


def load_checkpoint(path: str | os.PathLike, like: Any) -> tuple[Any, dict]:
    """Load a checkpoint into the structure of ``like``; returns ``(tree, meta)``.

    Raises:
        ModelFileError: the file is missing, corrupt, or does not fit ``like`` (a different
            run's checkpoint).
    """
    path = Path(path)
    leaves_like, treedef = jax.tree.flatten(like)

    def bad(problem: str) -> ModelFileError:
        return ModelFileError(f"checkpoint {path} {problem}; start a new run in a new directory")

    try:
        with np.load(path, allow_pickle=False) as data:
            header = parse_json(bytes(data["header"]))
            if (
                header.get("format") != CHECKPOINT_FORMAT
                or header.get("version") != CHECKPOINT_VERSION
            ):
                raise bad("has an unknown format or version")
            if header["leaves"] != len(leaves_like):
                raise bad("does not match this run's configuration")
            _check_meta(header.get("meta"), bad)
            leaves = []
            for i, ref in enumerate(leaves_like):
                name = f"leaf_{i:04d}"
                ref_arr = np.asarray(ref)
                # the stored shape first: a file that claims a huge array is refused unread
                if npz_shape(data, name) != (ref_arr.shape, ref_arr.dtype):
                    raise bad("does not match this run's configuration")
                leaves.append(jax.numpy.asarray(data[name]))
    except ModelFileError:
        raise
    except FileNotFoundError:
        raise bad("does not exist") from None
    except Exception as e:  # truncated, not a zip, a list header...: never a traceback
        raise bad(f"is corrupt ({type(e).__name__}: {e})") from None
    return jax.tree.unflatten(treedef, leaves), header["meta"]
