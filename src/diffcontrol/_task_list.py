"""The built-in tasks as `diffcontrol list` prints them, without importing JAX.

The tasks themselves (``diffcontrol.tasks``) import JAX, which takes about half a second; this
table lets ``list`` answer at once. ``tests/test_startup.py`` keeps it equal to the tasks'
own ``name``, ``summary``, ``losses`` and ``recipes()``.
"""

from __future__ import annotations

import importlib.metadata
import sys

ENTRY_POINT_GROUP = "diffcontrol.tasks"
"""Packages make their tasks known by name with an entry point in this group, e.g. in
``pyproject.toml``: ``[project.entry-points."diffcontrol.tasks"] acrobot = "my_pkg:Acrobot"``."""

BUILTIN: tuple[tuple[str, str, tuple[str, ...], tuple[str, ...]], ...] = (
    # (name, summary, losses, recipes), in registration order
    (
        "pendulum",
        "Pendulum-v1 swing-up by BPTT through the exact Gymnasium dynamics (torque |u| <= 2)",
        ("cost", "squared_cost"),
        ("original", "long-windows", "grid-value"),
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
        ("grid-value",),
    ),
)


def listing() -> list[str]:
    """The lines of ``diffcontrol list``: one per task with its summary, losses and recipes.

    The built-in tasks come from ``BUILTIN`` without importing JAX, or from the registry where
    ``diffcontrol.tasks`` is already imported (so tasks registered in this process are listed
    too); then the installed entry points of ``ENTRY_POINT_GROUP``, by name only (nothing is
    imported to list them).
    """
    rows = list(BUILTIN)
    tasks = sys.modules.get("diffcontrol.tasks")
    if tasks is not None:
        live = [tasks.make(name) for name in tasks.names()]
        rows = [(t.name, t.summary, tuple(t.losses), tuple(t.recipes())) for t in live]
    lines = [
        f"{name:<26} {summary}  [losses: {'/'.join(losses)}; recipes: {', '.join(recipes) or '-'}]"
        for name, summary, losses, recipes in rows
    ]
    listed = {row[0] for row in rows}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in listed:
            lines.append(
                f"{ep.name:<26} an installed task ({ep.value}), loaded when a command names it"
            )
    return lines
