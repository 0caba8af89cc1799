"""Placing a run's arrays on several local devices (data parallelism with ``jax.sharding``).

The work is split along one axis of the arrays (the simulations of a batch, or the members of
a sweep) over a 1-D mesh of local devices; everything else (the controller, the optimiser's
state, the physical parameters) is replicated. The compiled programs are the same functions as
on one device: XLA partitions them from the inputs' placement (GSPMD) and averages the
gradient over the devices with a collective where the batch's mean is taken. Results equal
one device's up to the order of floating-point sums.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import numpy as np
from jaxtyping import PyTree

from ..errors import ConfigError

Place = Callable[[PyTree], PyTree]


def check_devices(devices: int | None) -> int:
    """``devices`` (default 1), checked against the local devices.

    Raises:
        ConfigError: fewer local devices than asked for, or not a positive count.
    """
    available = len(jax.local_devices())
    if devices is None:
        return 1
    if isinstance(devices, bool) or not isinstance(devices, int) or not 1 <= devices <= available:
        more = (
            " (on a CPU, XLA_FLAGS=--xla_force_host_platform_device_count=N makes N)"
            if jax.default_backend() == "cpu"
            else ""
        )
        raise ConfigError(
            f"devices must be between 1 and the {available} local {jax.default_backend()} "
            f"device(s), got {devices!r}{more}"
        )
    return devices


def divisible(size: int, devices: int, what: str, flag: str) -> None:
    """Refuse a ``size`` that ``devices`` does not divide, naming the nearest sizes that work.

    Raises:
        ConfigError: ``size % devices != 0``.
    """
    if size % devices:
        below, above = size // devices * devices, (size // devices + 1) * devices
        near = " or ".join(str(n) for n in (below, above) if n > 0)
        raise ConfigError(
            f"{what} {size} cannot be split evenly over {devices} devices; use {flag} {near}"
        )


def mesh_placements(devices: int, axis: int = 0) -> tuple[Any, Any]:
    """The two shardings on a mesh of ``devices`` local devices: split along ``axis``, and
    replicated (``None, None`` for one device: leave arrays where they are)."""
    if devices == 1:
        return None, None
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    mesh = Mesh(np.array(jax.local_devices()[:devices]), ("data",))
    spec = PartitionSpec(*([None] * axis), "data")
    return NamedSharding(mesh, spec), NamedSharding(mesh, PartitionSpec())


def placer(sharding: Any) -> Place:
    """``jax.device_put`` with ``sharding``, or nothing for ``None``."""
    if sharding is None:
        return lambda tree: tree
    return lambda tree: jax.device_put(tree, sharding)


def batch_placement(state: Any, devices: int, batch_axis: int) -> tuple[PyTree, Any]:
    """Shardings for a BPTT training state: the simulations (``env_state``, ``env_time``,
    ``episode_return``) split along ``batch_axis``, everything else replicated. Returns the
    state's sharding tree and the replicated sharding (both ``None`` for one device)."""
    import equinox as eqx

    split, whole = mesh_placements(devices, batch_axis)
    if split is None:
        return None, None
    tree = jax.tree.map(lambda _: whole, state)
    members = (lambda s: s.members) if hasattr(state, "members") else (lambda s: s)
    for name in ("env_state", "env_time", "episode_return"):
        tree = eqx.tree_at(lambda s, n=name: getattr(members(s), n), tree, split)
    return tree, whole
