"""Placing a run's arrays on several local devices (data parallelism with ``jax.sharding``).

The work is split along one axis of the arrays (the simulations of a batch, or the members of
a sweep) over a 1-D mesh of local devices; everything else (the controller, the optimiser's
state, the physical parameters) is replicated. The compiled programs are the same functions as
on one device: XLA partitions them from the inputs' placement (GSPMD) and averages the
gradient over the devices with a collective where the batch's mean is taken. Results equal
one device's up to the order of floating-point sums.
"""

from __future__ import annotations

import math
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
    available = len(jax.devices())  # a multi-host run's devices are all its hosts'
    if devices is None:
        return available if jax.process_count() > 1 else 1
    if isinstance(devices, bool) or not isinstance(devices, int) or not 1 <= devices <= available:
        more = (
            " (on a CPU, XLA_FLAGS=--xla_force_host_platform_device_count=N makes N)"
            if jax.default_backend() == "cpu"
            else ""
        )
        raise ConfigError(
            f"devices must be between 1 and the {available} {jax.default_backend()} "
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

    mesh = Mesh(np.array(jax.devices()[:devices]), ("data",))
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


def join_hosts(coordinator: str, processes: int, process_id: int, timeout_s: float = 60) -> None:
    """Join a run over several hosts (processes), with JAX's own multi-controller runtime
    (``jax.distributed.initialize``); call before anything else uses JAX. Every process runs
    the same command with its own ``process_id``; process 0's address is ``coordinator``. On
    CPUs the collectives go over Gloo (TCP).

    Raises:
        ConfigError: a malformed address or id, or the coordinator not reached within
            ``timeout_s`` (the message names the address).
    """
    host, _, port = coordinator.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"--coordinator takes HOST:PORT, e.g. 10.0.0.1:1234, got {coordinator!r}")
    if not 1 <= processes <= 65536 or not 0 <= process_id < processes:
        raise ConfigError(
            f"--process-id must be in 0 ... {processes - 1} for {processes} processes, "
            f"got {process_id}"
        )
    if process_id > 0:  # JAX aborts the process when it cannot join: look first
        _wait_for(host, int(port), timeout_s, f"process {process_id} of {processes}")
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    try:
        jax.distributed.initialize(
            coordinator,
            num_processes=processes,
            process_id=process_id,
            initialization_timeout=max(1, math.ceil(timeout_s)),
        )
    except Exception as e:  # noqa: BLE001 - JAX's runtime errors are long; one line here
        first = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise ConfigError(
            f"process {process_id} of {processes} could not join the run coordinated at "
            f"{coordinator} within {timeout_s} s ({first}); start process 0 there first, or "
            "check the address and the firewall"
        ) from None


def _wait_for(host: str, port: int, timeout_s: float, who: str) -> None:
    """Wait until something listens at ``host:port``, or raise after ``timeout_s``."""
    import socket
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with socket.create_connection((host, port), timeout=2.0):
                return
        except OSError as e:
            if time.monotonic() >= deadline:
                raise ConfigError(
                    f"{who} could not reach the coordinator at {host}:{port} within "
                    f"{timeout_s:g} s ({e.strerror or e}); start process 0 there first, or "
                    "check the address and the firewall"
                ) from None
            time.sleep(0.2)


def is_writer() -> bool:
    """Whether this process writes the run's files (process 0 of a multi-host run)."""
    return jax.process_index() == 0


def gathered(tree: PyTree) -> PyTree:
    """``tree`` with every array whole on every process (a multi-host checkpoint holds the
    global arrays, so it resumes on any number of hosts); the tree itself on one process."""
    if jax.process_count() == 1:
        return tree
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)
