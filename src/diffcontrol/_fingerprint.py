"""Hashable summaries of a task and of its parameters, by which compiled programs and solved
tables are kept for reuse (``training``'s kept trainers, ``optimal.solve_first``): two tasks
with the same fingerprint run the same programs."""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from jaxtyping import PyTree

_PLAIN = (bool, int, float, complex, str, bytes, type(None))


def fingerprint(task: Any, covered: tuple[str, ...] = ()) -> tuple | None:
    """What the task's programs could depend on beyond its code: its own attributes (but
    ``covered``, which the caller keys otherwise) and the plain-valued attributes of its
    classes (arrays by their bytes). ``None`` (keep nothing) if an attribute is neither plain,
    a tuple of plain values nor an array."""

    def frozen(value: Any) -> Any:
        if isinstance(value, _PLAIN):
            return value
        if isinstance(value, tuple) and all(isinstance(v, _PLAIN) for v in value):
            return value
        if isinstance(value, np.ndarray | jax.Array):
            a = np.asarray(value)
            return ("array", a.dtype.str, a.shape, a.tobytes())
        raise TypeError

    try:
        own = tuple(sorted((k, frozen(v)) for k, v in vars(task).items() if k not in covered))
    except (TypeError, ValueError):
        return None
    return own, class_fingerprint(task)


def class_fingerprint(task: Any) -> tuple:
    """The plain-valued attributes of the task's classes, and the identity of their methods
    (a method replaced changes it)."""
    return tuple(
        (k, v if isinstance(v, _PLAIN + (tuple,)) else id(v))
        for cls in type(task).__mro__
        for k, v in sorted(vars(cls).items())
        if not k.startswith("__")
        and (isinstance(v, _PLAIN + (tuple,)) and hashable(v) or callable(v))
    )


def hashable(value: Any) -> bool:
    """Whether ``value`` can be hashed (a tuple of lists cannot)."""
    try:
        hash(value)
    except TypeError:
        return False
    return True


def physics_key(params: PyTree) -> tuple:
    """``params`` as a hashable value: its structure and every leaf's dtype, shape and bytes."""
    leaves, structure = jax.tree_util.tree_flatten(params)
    arrays = [np.asarray(leaf) for leaf in leaves]
    return str(structure), tuple((a.dtype.str, a.shape, a.tobytes()) for a in arrays)
