"""The neural-ODE cart-pole swing-ups of the 2020 post, a built-in system in its own folder, as
a user's task is: the cart-pole's vector field (``system``), the tasks (``task``), and what the
layers do with them their own way (``hooks``: their runs judged by a float64 reference solve
and drawn as a cart-pole, their model learnt from recorded states), imported when a layer's
hook first meets one of the tasks (the registry names it)."""

from .task import (
    CartPoleSwingUp,
    CartPoleSwingUpFriction,
    CartPoleSwingUpLimited,
    SwingUpTrajectory,
)

__all__ = [
    "CartPoleSwingUp",
    "CartPoleSwingUpFriction",
    "CartPoleSwingUpLimited",
    "SwingUpTrajectory",
]
