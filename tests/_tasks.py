"""The tasks the suite walks one by one (contracts, checks, gradients)."""

from __future__ import annotations

from diffcontrol import _registry, tasks


def walked() -> list[str]:
    """Every registered task but those whose simulator needs a pip extra: the MuJoCo tasks,
    whose programs take minutes each to compile, have their own file (tests/test_mujoco.py)."""
    return [name for name in tasks.names() if _registry.extra_of(name) is None]
