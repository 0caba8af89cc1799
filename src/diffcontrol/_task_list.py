"""The built-in tasks as `diffcontrol list` prints them, without importing JAX.

The tasks themselves (``diffcontrol.tasks``) import JAX, which takes about half a second; this
table lets ``list`` answer at once. ``tests/test_startup.py`` keeps it equal to the tasks'
own ``name``, ``summary``, ``losses`` and ``recipes()``.
"""

from __future__ import annotations

ENTRY_POINT_GROUP = "diffcontrol.tasks"
"""Packages make their tasks known by name with an entry point in this group, e.g. in
``pyproject.toml``: ``[project.entry-points."diffcontrol.tasks"] acrobot = "my_pkg:Acrobot"``."""

BUILTIN: tuple[tuple[str, str, tuple[str, ...], tuple[str, ...]], ...] = (
    # (name, summary, losses, recipes), in registration order
    (
        "pendulum",
        "Pendulum-v1 swing-up by BPTT through the exact Gymnasium dynamics (torque |u| <= 2)",
        ("cost", "squared_cost"),
        ("original", "long-windows"),
    ),
    (
        "pendulum-unclipped",
        "the 2019 original's Pendulum: unclipped torque, 1000-step episodes",
        ("cost", "squared_cost"),
        ("original",),
    ),
    (
        "cartpole",
        "CartPole-v1 balancing with a straight-through sign push (exact Gymnasium dynamics)",
        ("shaped", "quadratic"),
        ("original",),
    ),
    (
        "acrobot",
        "Acrobot-v1 swing-up: a 3-way straight-through choice of torque (exact Gymnasium dynamics)",
        ("pump", "power"),
        (),
    ),
    (
        "trebuchet",
        "aim the 2019 post's differentiable trebuchet: (target, wind) -> (angle, weight)",
        ("squared_miss", "abs_miss", "huber_miss"),
        ("original",),
    ),
    (
        "cartpole-swingup",
        "neural-ODE cart-pole swing-up of the 2020 post: 1 s, unbounded force",
        ("swingup", "limited", "limited_hold", "energy"),
        ("original",),
    ),
    (
        "cartpole-swingup-limited",
        "the post's 'motor can't give 60 N' swing-up: 10 s, x and peak-force penalties",
        ("limited_hold", "limited", "swingup", "energy"),
        ("original",),
    ),
    (
        "cartpole-swingup-friction",
        "3 s swing-up with cart and joint friction; the loss adds the dissipated energy",
        ("energy", "swingup", "limited", "limited_hold"),
        ("original",),
    ),
    (
        "mountain-car-continuous",
        "MountainCarContinuous-v0 by BPTT through the exact Gymnasium dynamics, with an energy-shaped loss (the reward's flag has no gradient)",
        ("energy", "cost"),
        (),
    ),
)
