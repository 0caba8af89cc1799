"""Dynamics only: one system a module, pure JAX, constants in a parameter PyTree.

No losses, policies or I/O live here. Each system documents where its derivative is
non-smooth.
"""

from . import cartpole, pendulum
from .cartpole import CartPoleParams
from .pendulum import PendulumParams

__all__ = [
    "cartpole",
    "pendulum",
    "CartPoleParams",
    "PendulumParams",
]
