"""The task registry's table: every built-in task by name, where its class lives, what
``diffcontrol list`` says of it and its Gymnasium id, readable without JAX.

``diffcontrol.tasks.make`` imports a built-in task's module from ``path`` when the task is
first made (the registry is lazy), ``import diffcontrol`` registers the Gymnasium ids
(``register_envs``: the environments themselves are imported by Gymnasium from the string entry
points only when one is made), and ``diffcontrol list`` prints ``listing()`` without importing
a task. Installed packages add tasks by name with an entry point in ``ENTRY_POINT_GROUP``; a
user names one by import path (``module:Class``). ``tests/test_startup.py`` keeps each row
equal to what its task says of itself. This module imports nothing of the package.
"""

from __future__ import annotations

import importlib.metadata
import sys
from typing import Any, NamedTuple

ENTRY_POINT_GROUP = "diffcontrol.tasks"
"""Packages make their tasks known by name with an entry point in this group, e.g. in
``pyproject.toml``: ``[project.entry-points."diffcontrol.tasks"] acrobot = "my_pkg:Acrobot"``."""

NAMESPACE = "diffcontrol"
VERSION = 0
ENVS = "diffcontrol.envs"


class Builtin(NamedTuple):
    """One built-in task: its name, its class (``module:Class``), what ``list`` says of it
    (``summary``, ``losses``, ``recipes``), its Gymnasium environment (the id
    ``diffcontrol/<env_name>-v0`` of ``env``, a class of ``diffcontrol.envs``, episodes of
    ``steps``, the reward ``threshold``), ``hooks``: the module that registers what the
    layers do with the task their own way, imported when a layer's hook first meets it
    (``tasks._hooks``), and ``extra``: the pip extra its simulator needs (``mujoco``), if
    any."""

    name: str
    path: str
    summary: str
    losses: tuple[str, ...]
    recipes: tuple[str, ...]
    env_name: str
    env: str
    steps: int
    threshold: float | None
    hooks: str | None = None
    extra: str | None = None


BUILTIN: tuple[Builtin, ...] = (
    Builtin(
        "pendulum",
        "diffcontrol.tasks.pendulum:Pendulum",
        "Pendulum-v1 swing-up by BPTT through the exact Gymnasium dynamics (torque |u| <= 2)",
        ("cost", "squared_cost"),
        ("original", "windows", "long-windows", "grid-value"),
        "Pendulum", "TaskEnv", 200, -200.0,
        "diffcontrol.builtin.zoo",
    ),
    Builtin(
        "pendulum-unclipped",
        "diffcontrol.tasks.pendulum:PendulumUnclipped",
        "the 2019 original's Pendulum: unclipped torque, 1000-step episodes",
        ("cost", "squared_cost"),
        ("original",),
        "PendulumUnclipped", "TaskEnv", 1000, None,
        "diffcontrol.builtin.zoo",
    ),
    Builtin(
        "cartpole",
        "diffcontrol.tasks.cartpole:CartPole",
        "CartPole-v1 balancing with a straight-through sign push (exact Gymnasium dynamics)",
        ("shaped", "quadratic"),
        ("original",),
        "CartPole", "TaskEnv", 500, 475.0,
        "diffcontrol.builtin.zoo",
    ),
    Builtin(
        "acrobot",
        "diffcontrol.tasks.acrobot:Acrobot",
        "Acrobot-v1 swing-up: a 3-way straight-through choice of torque (exact Gymnasium dynamics)",
        ("pump", "power", "reach"),
        (),
        "Acrobot", "TaskEnv", 500, -100.0,
    ),
    Builtin(
        "trebuchet",
        "diffcontrol.builtin.trebuchet.task:TrebuchetAiming",
        "aim the 2019 post's differentiable trebuchet: (target, wind) -> (angle, weight)",
        ("squared_miss", "abs_miss", "huber_miss"),
        ("original",),
        "Trebuchet", "TaskEnv", 1, None,
        "diffcontrol.builtin.trebuchet.hooks",
    ),
    Builtin(
        "cartpole-swingup",
        "diffcontrol.builtin.swingup.task:CartPoleSwingUp",
        "neural-ODE cart-pole swing-up of the 2020 post: 1 s, unbounded force",
        ("swingup", "limited", "limited_hold", "energy"),
        ("original",),
        "CartPoleSwingUp", "ContinuousTaskEnv", 49, None,
        "diffcontrol.builtin.swingup.hooks",
    ),
    Builtin(
        "cartpole-swingup-limited",
        "diffcontrol.builtin.swingup.task:CartPoleSwingUpLimited",
        "the post's 'motor can't give 60 N' swing-up: 10 s, x and peak-force penalties",
        ("limited_hold", "limited", "swingup", "energy"),
        ("original",),
        "CartPoleSwingUpLimited", "ContinuousTaskEnv", 49, None,
    ),
    Builtin(
        "cartpole-swingup-friction",
        "diffcontrol.builtin.swingup.task:CartPoleSwingUpFriction",
        "3 s swing-up with cart and joint friction; the loss adds the dissipated energy",
        ("energy", "swingup", "limited", "limited_hold"),
        ("original",),
        "CartPoleSwingUpFriction", "ContinuousTaskEnv", 49, None,
    ),
    Builtin(
        "mountain-car-continuous",
        "diffcontrol.tasks.mountain_car:MountainCarContinuous",
        "MountainCarContinuous-v0 by BPTT through the exact Gymnasium dynamics, with an "
        "energy-shaped loss (the reward's flag has no gradient)",
        ("energy", "cost"),
        ("grid-value",),
        "MountainCarContinuous", "TaskEnv", 999, 90.0,
    ),
    Builtin(
        "inverted-double-pendulum",
        "diffcontrol.builtin.mujoco.tasks:InvertedDoublePendulum",
        "InvertedDoublePendulum-v5 by BPTT through MJX on Gymnasium's own model file",
        ("cost",),
        (),
        "InvertedDoublePendulum", "TaskEnv", 1000, 9100.0,
        "diffcontrol.builtin.mujoco.zoo",
        extra="mujoco",
    ),
    Builtin(
        "reacher",
        "diffcontrol.builtin.mujoco.tasks:Reacher",
        "Reacher-v5 by BPTT through MJX on Gymnasium's own model file",
        ("cost",),
        (),
        "Reacher", "TaskEnv", 50, -3.75,
        "diffcontrol.builtin.mujoco.zoo",
        extra="mujoco",
    ),
    Builtin(
        "swimmer",
        "diffcontrol.builtin.mujoco.tasks:Swimmer",
        "Swimmer-v5 by BPTT through MJX on Gymnasium's own model file",
        ("cost",),
        (),
        "Swimmer", "TaskEnv", 1000, 360.0,
        "diffcontrol.builtin.mujoco.zoo",
        extra="mujoco",
    ),
)  # fmt: skip

OTHER_ENVS: tuple[tuple[str, str, int], ...] = (
    # (id, entry point, max_episode_steps): environments that are not a task's
    ("diffcontrol/PendulumFriction-v0", "diffcontrol.wrappers:make_pendulum_friction", 200),
    ("diffcontrol/WornPendulum-v0", "diffcontrol.wrappers:make_worn_pendulum", 200),
)


def builtin(name: str) -> Builtin | None:
    """The built-in task called ``name``, or ``None``."""
    return next((row for row in BUILTIN if row.name == name), None)


def extra_of(name: str) -> str | None:
    """The pip extra that the built-in task ``name`` needs (its row's ``extra``), or ``None``."""
    row = builtin(name)
    return None if row is None else row.extra


def hooks_of(cls: type) -> str | None:
    """The module of the built-in task class ``cls``'s overrides (its row's ``hooks``)."""
    path = f"{cls.__module__}:{cls.__qualname__}"
    return next((row.hooks for row in BUILTIN if row.path == path), None)


def env_name(task: Any) -> str:
    """The ``Name`` of ``diffcontrol/<Name>-v0`` for ``task`` (``task.env_name`` or derived)."""
    if getattr(task, "env_name", None):
        return str(task.env_name)
    return "".join(part.capitalize() for part in task.name.replace("_", "-").split("-"))


def env_id(task: Any) -> str:
    """The Gymnasium id of a task instance: ``diffcontrol/<Name>-v0``."""
    return f"{NAMESPACE}/{env_name(task)}-v{VERSION}"


def register_envs() -> None:
    """Register the Gymnasium ids of the built-in tasks and ``OTHER_ENVS`` that are not
    registered yet (without JAX)."""
    from gymnasium.envs.registration import register, registry

    for row in BUILTIN:
        eid = f"{NAMESPACE}/{row.env_name}-v{VERSION}"
        if eid not in registry:
            register(
                id=eid,
                entry_point=f"{ENVS}:{row.env}",
                kwargs={"task": row.name},
                max_episode_steps=row.steps,
                reward_threshold=row.threshold,
            )
    for eid, entry_point, steps in OTHER_ENVS:
        if eid not in registry:
            register(id=eid, entry_point=entry_point, max_episode_steps=steps)


def listing() -> list[str]:
    """The lines of ``diffcontrol list``: one per task with its summary, losses and recipes
    (and the pip extra it needs, if any).

    The built-in tasks come from ``BUILTIN`` without importing JAX, or from the registry where
    ``diffcontrol.tasks`` is already imported (so tasks registered in this process are listed
    too); then the installed entry points of ``ENTRY_POINT_GROUP``, by name only (nothing is
    imported to list them).
    """
    rows = [(r.name, r.summary, r.losses, r.recipes) for r in BUILTIN]
    tasks = sys.modules.get("diffcontrol.tasks")
    if tasks is not None:
        live = [tasks.make(name) for name in tasks.names()]
        rows = [(t.name, t.summary, tuple(t.losses), tuple(t.recipes())) for t in live]
    lines = [
        f"{name:<26} {summary}  [losses: {'/'.join(losses)}; recipes: {', '.join(recipes) or '-'}"
        + (f"; needs the {extra_of(name)!r} extra]" if extra_of(name) else "]")
        for name, summary, losses, recipes in rows
    ]
    listed = {row[0] for row in rows}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name not in listed:
            lines.append(
                f"{ep.name:<26} an installed task ({ep.value}), loaded when a command names it"
            )
    return lines
