"""What the driver (``train``, its ``_loop.Loop``) asks of a trainer: ``Trainer`` (BPTT, with
``PopulationTrainer`` for several controllers) and ``ODETrainer`` implement it, and a sweep
runs ``Trainer`` under ``vmap`` on the same loop. ``train`` builds a run's trainer with the
factory registered for its config's class (``register_trainer``). A planner's distillation
(``mpc.distil``) turns the same loop with the hooks it needs (``summarize``, ``pick``,
``check`` and its own points).

The trainer is an ``equinox.Module`` of pure functions (``init``, ``chunk``, ``evaluate``:
the driver compiles them once each) and plain-Python hooks that the loop calls between chunks.
Its state is a module too, with at least ``update`` (the updates done) and ``controller``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np
from jaxtyping import Array, PRNGKeyArray, PyTree


@runtime_checkable
class TrainerInterface(Protocol):
    """The methods a trainer gives the driver (see the module's docstring)."""

    config: Any
    """The run's settings (``updates``, ``eval_every``, ``target_return``, ...)."""

    @property
    def episode_length(self) -> int:
        """Simulated steps per standard episode (for ``simulated_episodes``)."""

    def init(self, key: PRNGKeyArray, params: PyTree) -> Any:
        """The first training state: random controller(s), the optimiser, the first starts."""

    def chunk(self, ts: Any, params: PyTree, total_updates: Array) -> tuple[Any, Any]:
        """``config.eval_every`` updates (those past ``total_updates`` skipped) in one program:
        the new state and per-update stats with ``loss`` and ``grad_norm``."""

    def evaluate(self, controller: Any, params: PyTree, key: PRNGKeyArray) -> Array:
        """The evaluation point's returns (one per episode, or per member)."""

    def stages(self) -> list[tuple[int, Any]]:
        """``(end update, trainer)`` in order: the run's stages, each compiled once."""

    def summarize(self, returns: np.ndarray) -> tuple[float, float]:
        """The point's return and its spread."""

    def pick(self, controller: Any, returns: np.ndarray) -> Any:
        """The controller to keep for this point (a population's best member)."""

    def counts(self, ts: Any) -> dict[str, Any]:
        """What the point records of the simulation so far (``simulated_steps``, ...)."""

    def point_extras(self, ts: Any, returns: np.ndarray) -> dict[str, Any]:
        """The point's further entries."""

    def check(self, old: Any, new: Any, losses: np.ndarray) -> list[str]:
        """Notes on the chunk from ``old`` to ``new``; raises where the run cannot go on
        (``TrainingDiverged``, ``SolverFailed``)."""

    def num_parameters(self, controller: Any) -> int:
        """The returned controller's number of weights."""

    def check_start(self, ts: Any, params: PyTree) -> None:
        """Called when the untrained controller's evaluation is not finite, before any update:
        raise ``ConfigError`` where the trainer can say why (an ODE solve that fails)."""


TrainerFactory = Callable[..., TrainerInterface]
"""``factory(task, config, loss, params, progress)``: the trainer of a run (``loss``: the
user's step or trajectory loss, or ``None`` for the task's own; ``params``: the task's
parameters; ``progress``: where to say what takes long)."""


@dataclasses.dataclass(frozen=True)
class TrainerKind:
    """A registered trainer: its factory and what ``train`` checks before building it."""

    factory: TrainerFactory
    time: str
    """The kind of task it trains, in words (``"discrete-time"``, ``"continuous-time"``)."""
    loss: str
    """``train``'s keyword for a user's loss of this trainer (``"step_loss"``, ...)."""
    one_device: str | None = None
    """Why its runs do not split over devices (``train``'s ``devices``); ``None``: they may."""


_KINDS: dict[type, TrainerKind] = {}


def register_trainer(config_class: type, kind: TrainerKind) -> None:
    """Train the runs whose config is a ``config_class`` (or a subclass) with ``kind``'s
    trainers."""
    _KINDS[config_class] = kind


def trainer_kind(config: Any) -> TrainerKind:
    """The trainer registered for ``config``'s class or its nearest base.

    Raises:
        TypeError: no trainer is registered for it.
    """
    for cls in type(config).__mro__:
        if cls in _KINDS:
            return _KINDS[cls]
    raise TypeError(f"no trainer is registered for {type(config).__name__}")
