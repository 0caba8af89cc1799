"""Checks that a task keeps the contract the trainers rely on, and matches its Gymnasium twin.

A task is plain JAX code that the trainers compile into long ``lax.scan``s, where a state of
the wrong shape surfaces as ``scan body function carry input and carry output must have equal
types`` and a NaN reward as a diverged run hundreds of updates later. These checks say which
method broke which promise, in one line (``TaskCheckError``):

- ``validate_task``: shapes and dtypes, by ``jax.eval_shape`` (tracing only, no compilation).
  ``diffcontrol.train`` runs it before anything is compiled.
- ``check_contract``: the methods under ``jit``, ``vmap`` and ``grad`` on a batch of reset
  states and random valid actions: finite outputs and gradients, an action (or a controller's
  force) that reaches the outputs, and the same result for the same key.
- ``check_task``: both, then, for a task with a Gymnasium twin (``gym_id``, or ``env_id``),
  ``step`` against the twin's ``env.step`` from the same states (``diffcontrol._checks.parity``).

Everything runs in JAX's default precision (float32 unless ``jax_enable_x64`` is on), the
precision a task is trained in.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import PyTree

from ._checks.contract import task_contract
from ._checks.parity import check_parity
from ._checks.shapes import task_shapes
from .errors import ConfigError, TaskCheckError
from .tasks import AnyTask, ContinuousTask, as_task

__all__ = ["CheckReport", "TaskCheckError", "check_contract", "check_task", "validate_task"]

CONTRACT = ("jit", "vmap", "grad", "finite", "deterministic", "action reaches the outputs")
"""The names of the checks of ``check_contract``, as ``CheckReport.passed`` lists them."""

RTOL = 1e-5
ATOL = 1e-5
"""Default parity tolerances, those of the test suite's float32 comparisons with Gymnasium
(``tests/test_systems_vs_gymnasium.py``): the task steps in float32, Gymnasium in float64 from
the same state, and one step of a classic-control system rounds to a few float32 ulps of
quantities up to about 20."""


@dataclasses.dataclass(frozen=True)
class CheckReport:
    """What ``check_task`` verified. It raises on the first failure, so all of it passed.

    Attributes:
        task: the task's name.
        passed: the checks that passed, in order (``"shapes"``, ``"jit"``, ``"vmap"``, ...).
        skipped: the checks not run, each with why.
        dtype: the dtype of the task's state in the checks (JAX's default precision).
        env_id: the Gymnasium environment of the parity check, or ``None``.
        compared_steps: how many steps were compared with Gymnasium.
        max_errors: the largest absolute differences from Gymnasium, by quantity
            (``"observation"``, ``"reward"``); empty without a parity check.
        rtol, atol: the parity tolerances: a value passes when
            ``|ours - theirs| <= atol + rtol * |theirs|``.
    """

    task: str
    passed: tuple[str, ...]
    skipped: tuple[str, ...] = ()
    dtype: str = ""
    env_id: str | None = None
    compared_steps: int = 0
    max_errors: dict[str, float] = dataclasses.field(default_factory=dict)
    rtol: float = RTOL
    atol: float = ATOL

    def __str__(self) -> str:
        lines = [f"task {self.task} ({self.dtype}): passed {', '.join(self.passed)}"]
        if self.env_id is not None:
            errors = ", ".join(f"{k} {v:.3g}" for k, v in self.max_errors.items())
            lines.append(
                f"  parity with {self.env_id}: {self.compared_steps} steps, max |error| "
                f"{errors} (rtol {self.rtol:g}, atol {self.atol:g})"
            )
        lines += [f"  skipped {why}" for why in self.skipped]
        return "\n".join(lines)


def default_params(task: AnyTask) -> PyTree:
    """The task's nominal parameters as JAX arrays of the default float dtype, as ``train``
    passes them."""
    return jax.tree.map(lambda x: jnp.asarray(x, dtype=float), task.default_params())


def validate_task(task: AnyTask, params: PyTree | None = None) -> jax.ShapeDtypeStruct:
    """Check the shapes and dtypes of the task's methods without running or compiling them.

    A discrete-time ``Task``: ``reset(key, params)`` returns a floating-point state,
    ``observe(state)`` a vector of ``observation_size``, and ``step(params, state, action)``
    with an action of ``action_size`` returns ``(next_state, reward, terminated)``: a state of
    the same shape and dtype, a scalar reward in the state's dtype, a boolean scalar. A
    ``ContinuousTask``: ``initial_state(params)`` returns a vector ``y0``, ``observe(y0)`` a
    vector of ``observation_size``, and ``vector_field(t, y0, (params, force_fn))`` a
    ``dy/dt`` of ``y0``'s shape and dtype. Everything is traced by ``jax.eval_shape``, so the
    check costs a trace of each method and nothing is compiled.

    Args:
        task: the task.
        params: its physical parameters; the nominal ones (``default_params()`` as arrays)
            when omitted.

    Returns:
        The shape and dtype of the task's state (of ``y0`` for a continuous-time task).

    Raises:
        TaskCheckError: a method failed to trace or returned the wrong shape or dtype; the
            one-line message names the method and the shapes expected and returned.
    """
    return task_shapes(task, default_params(task) if params is None else params)


def check_contract(
    task: AnyTask, params: PyTree | None = None, *, states: int = 64, seed: int = 0
) -> tuple[str, ...]:
    """Run the task's methods under ``jit``, ``vmap`` and ``grad`` and check what they return.

    After ``validate_task``, one compiled program runs the methods batched with ``vmap``, and
    their gradients: for a discrete-time task on ``states`` reset states with random valid
    actions (the task's action head applied to random outputs), ``step`` and ``observe``
    differentiated with respect to the state and the action (what BPTT differentiates) and
    ``reset`` with respect to the parameters; for a continuous-time task, ``vector_field``
    at the initial state with ``states`` random controllers, differentiated with respect to
    the controller's weights, the state and the parameters (what an adjoint differentiates).
    Then: every output and gradient is finite; the action reaches the next state or the
    reward (the controller's force reaches ``dy/dt``); ``reset`` traced twice with the same
    key gives the same state; and the first example computed alone, in a trace of its own,
    equals (up to rounding) its row of the batch. A method that draws from NumPy's or
    Python's random numbers, or keeps state between calls, fails the last two.

    Args:
        task: the task.
        params: its physical parameters; the nominal ones when omitted.
        states: the batch size.
        seed: the seed of the keys, actions and controllers.

    Returns:
        The names of the checks that passed (``CONTRACT``).

    Raises:
        TaskCheckError: the first check that failed, in one line naming the method, the state
            (and action) and the value.
    """
    params = default_params(task) if params is None else params
    task_contract(task, params, validate_task(task, params), states, seed)
    return CONTRACT


def check_task(
    task: AnyTask,
    params: PyTree | None = None,
    *,
    env_id: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
    states: int = 64,
    steps: int = 50,
    seed: int = 0,
    rtol: float = RTOL,
    atol: float = ATOL,
) -> CheckReport:
    """Check a task against the contract every trainer relies on, and against its Gymnasium twin.

    ``validate_task`` (shapes and dtypes), ``check_contract`` (``jit``, ``vmap``, ``grad``,
    finiteness, same key same result), then, for a discrete-time task with a Gymnasium twin,
    parity: from ``states`` reset states, ``steps`` steps each with random valid actions
    while the episode lasts; before every step the twin is put into the task's state
    (``set_gym_state``) and stepped with the task's ``gym_action`` of the action, and its
    observation, reward and termination must match ``observe(next_state)``, the reward and
    ``terminated`` within ``|ours - theirs| <= atol + rtol * |theirs|`` (termination exactly).
    The trajectory goes on from the task's own next state, so errors do not accumulate.

    Args:
        task: the task (an instance, e.g. ``diffcontrol.make("pendulum")`` or your own).
        params: its physical parameters; the nominal ones when omitted. The twin must
            simulate the same system (``env_kwargs``).
        env_id: the Gymnasium id of the twin; ``make_gym_env`` (``task.gym_id``) when
            omitted. Parity is skipped for a task with neither.
        env_kwargs: keyword arguments of ``gymnasium.make`` (or ``make_gym_env``).
        states: reset states (the batch of the contract checks, the episodes of parity).
        steps: steps compared from each reset state (fewer if the episode terminates).
        seed: the seed of every key, action and controller of the checks.
        rtol: the parity's relative tolerance.
        atol: the parity's absolute tolerance.

    Returns:
        A ``CheckReport``: the checks that passed and the largest differences from the twin.

    Raises:
        TaskCheckError: the first check that failed, in one line: the method, the shapes
            expected and returned, or the state (and action) where a value is wrong or the
            twin disagrees.
        ConfigError: bad arguments (``states`` or ``steps`` not positive, ``env_id`` for a
            continuous-time task).
    """
    for arg, value in (("states", states), ("steps", steps)):
        if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
            raise ConfigError(f"{arg} must be a positive integer, got {value!r}")
    task = as_task(task, "check_task()")
    params = default_params(task) if params is None else params
    state = validate_task(task, params)
    task_contract(task, params, state, states, seed)
    passed = ["shapes", *CONTRACT]
    report = dict(task=getattr(task, "name", type(task).__name__), dtype=str(state.dtype))
    if isinstance(task, ContinuousTask):
        if env_id is not None:
            raise ConfigError(
                f"env_id={env_id!r}: parity with Gymnasium steps a discrete-time Task, and "
                f"{type(task).__name__} is continuous-time"
            )
        skipped = ("parity: a continuous-time task has no step-by-step Gymnasium twin",)
        return CheckReport(passed=tuple(passed), skipped=skipped, **report)
    if env_id is None and task.gym_id is None:
        skipped = ("parity: the task has no Gymnasium twin (set gym_id or pass env_id)",)
        return CheckReport(passed=tuple(passed), skipped=skipped, **report)

    label, compared, errors = check_parity(
        task,
        params,
        env_id,
        env_kwargs or {},
        states=states,
        steps=steps,
        seed=seed,
        rtol=rtol,
        atol=atol,
    )
    passed.append(f"parity with {label}")
    return CheckReport(
        passed=tuple(passed),
        env_id=label,
        compared_steps=compared,
        max_errors=errors,
        rtol=rtol,
        atol=atol,
        **report,
    )
