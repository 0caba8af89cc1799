"""The compiled programs of training runs: the XLA options each compiles with
(``compile_options``, ``START_COMPILER_OPTIONS``) and what the process keeps for the next run
of the same settings (its trainer and traced functions, its start programs, and compiled
programs by their text), so that a comparison's or a sweep's next seed compiles nothing."""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import os
from typing import Any

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, PRNGKeyArray, PyTree

from .. import _fingerprint, optimal
from .._jax_setup import FAST_COMPILE, compile_with
from ..errors import ConfigError
from ..tasks import AnyTask
from ._interface import trainer_kind


def _start(trainer: Any, seed: Array, params: PyTree) -> tuple[Any, PRNGKeyArray]:
    """The first training state and the evaluation key of the run with ``seed``."""
    k_train, k_eval = jax.random.split(jax.random.PRNGKey(seed))
    return trainer.init(k_train, params), k_eval


_START = eqx.filter_jit(_start)


START_COMPILER_OPTIONS = ("xla_backend_optimization_level", "xla_cpu_use_fusion_emitters")
"""``_jax_setup.FAST_COMPILE``'s options for the start program (the controllers' random
weights, the first resets): it runs once, and level 1 with the older CPU emitters compiles it
in about half the time of XLA's defaults (0.54 s against 1.13 s for cartpole, on one core). On
a CPU they give the defaults' bits for every built-in task (compared leaf by leaf;
``tests/test_startup.py`` keeps checking two of them); level 0 would round the uniform draws'
scaling differently. Not compared on a GPU, where only the level applies. An option named in
``XLA_FLAGS`` (the test suite names both) is left as it is."""


def _first_state(kept: _KeptTrainer, seed: int, params: PyTree) -> tuple[Any, PRNGKeyArray]:
    """``_start`` as one program (the keys too, not op by op), compiled with
    ``START_COMPILER_OPTIONS`` and kept with the trainer for the next seed (the seed is an
    argument)."""
    args = (kept.trainer, np.int32(seed), params)
    lowered = _START.lower(*args)
    key = (
        str(jax.config.jax_default_device),  # the device it runs on is fixed when lowered
        hashlib.sha256(lowered.as_text().encode()).hexdigest(),
        os.environ.get("XLA_FLAGS", ""),
    )
    if key not in kept.starts:
        kept.starts[key] = compile_with(lowered, *START_COMPILER_OPTIONS)
    return kept.starts[key](*args)


@dataclasses.dataclass
class _KeptTrainer:
    """A trainer kept for the next run of the same settings (``_kept_trainer``), with its
    stages, jitted functions and compiled start programs, so that the next seed traces
    nothing again."""

    task: Any  # held, so that its id is not reused while it is kept
    trainer: Any
    stages: list[tuple[int, Any]]
    jits: dict[Any, Any] = dataclasses.field(default_factory=dict)
    starts: dict[Any, Any] = dataclasses.field(default_factory=dict)

    def jitted(self, name: str, owner: Any, shardings: Any) -> Any:
        """``jax.jit`` of ``owner``'s method ``name`` (``"chunk N"``: stage N's chunk), made
        once per placement of its outputs."""
        key = (name, str(shardings))
        if key not in self.jits:
            method = owner.evaluate if name == "evaluate" else owner.chunk
            self.jits[key] = jax.jit(method, **_outputs(shardings))
        return self.jits[key]


_TRAINERS: collections.OrderedDict[Any, _KeptTrainer] = collections.OrderedDict()


TRAINERS_KEPT = 8
"""Trainers kept in the process by ``_kept_trainer`` (the most recently used)."""


def _kept_trainer(
    task: Any,
    config: Any,
    loss: Any,
    params: PyTree = None,
    progress: Any = None,
) -> _KeptTrainer:
    """The trainer of these settings, the same object as for an earlier run that differed only
    in its seed (trainers do not read the seed: the start program takes it as an argument),
    so that its programs are not traced again.

    Only a built-in task (its class defined in diffcontrol) with its built-in losses is kept,
    by identity and fingerprint (an attribute changed in between makes a new trainer): a
    kept trainer does not trace again, so a user's loss or task that reads a global changed
    since would run as it was. Anything else gets a new trainer every run, as before.
    """
    general = dataclasses.replace(config, seed=0)
    ours = type(task).__module__.startswith("diffcontrol.")
    builtin = ours and loss is None
    fingerprint = _fingerprint.fingerprint(task) if builtin else None
    # A built-in wrapper whose programs read of it only its plain attributes, its classes,
    # the task it wraps and what ``_programs_key`` names (``FittedSwingUp``: its network is a
    # parameter) shares its trainer with every equal wrapper of that task (kept alive by the
    # kept one); ``covered``: its attributes that the key stands for.
    shared = getattr(task, "_programs_key", None) if builtin else None
    if shared:
        inner, extra, covered = shared()
        inner_ours = type(inner).__module__.startswith("diffcontrol.")
        own = _fingerprint.fingerprint(task, covered)
        inner_print = _fingerprint.fingerprint(inner) if inner_ours and own else None
        fingerprint = inner_print and ("shared", own, id(inner), type(inner), inner_print, extra)
    fields = tuple(  # NaN (target_return's default) equal to itself, on every Python
        "nan" if isinstance(v, float) and math.isnan(v) else v for v in dataclasses.astuple(general)
    )
    if not _fingerprint.hashable(fields):
        fingerprint = None
    key = (None if shared else id(task), type(task), fingerprint, type(general), fields)
    kept = _TRAINERS.pop(key, None) if fingerprint is not None else None
    if kept is None or (kept.task is not task and not shared):
        trainer = trainer_kind(general).factory(task, general, loss, params, progress)
        kept = _KeptTrainer(task=task, trainer=trainer, stages=trainer.stages())
    if fingerprint is not None:
        _TRAINERS[key] = kept
        while len(_TRAINERS) > TRAINERS_KEPT:
            _TRAINERS.popitem(last=False)
    return kept


_EXECUTABLES: collections.OrderedDict[Any, Any] = collections.OrderedDict()


EXECUTABLES_KEPT = 16
"""Compiled programs kept in the process by ``compiled_once`` (the most recently used)."""


def compile_options(task: AnyTask, program: str) -> tuple[str, ...]:
    """The options of ``_jax_setup.FAST_COMPILE`` (XLA's level 1, the older CPU emitters) that
    the task's own class declares for ``program`` (``"chunk"``, the training updates, or
    ``"evaluate"``, an evaluation point) in its ``fast_compile`` mapping; none by default
    (XLA's defaults).

    A built-in task names those under which its programs gave the defaults' bits in its
    default settings and every recipe, or, where they did not (CartPole's chunk, the
    trebuchet's evaluation), whole runs gave the same documented results
    (``benchmarks/compile_options.py``). Other settings (another ODE solver, loss or network)
    may round differently in the last bits: the options compile faster, they do not promise
    the defaults' bits. Read from the task's own class only: a subclass (another system, a
    fitted model) compiles with XLA's defaults unless it names its own.

    Raises:
        ConfigError: the declaration names another program, or an option that is not in
            ``_jax_setup.FAST_COMPILE``.
    """
    own = vars(type(task)).get("fast_compile", {})
    for key, names in own.items():
        if (
            key not in ("chunk", "evaluate")
            or isinstance(names, str)
            or any(n not in FAST_COMPILE for n in names)
        ):
            raise ConfigError(
                f"task {task.name!r} declares fast_compile[{key!r}] = {names!r}; use "
                f"'chunk' or 'evaluate' with a tuple of {', '.join(sorted(FAST_COMPILE))}"
            )
    return tuple(own.get(program, ()))


def compiled_once(lowered: jax.stages.Lowered, *options: str) -> jax.stages.Compiled:
    """``lowered.compile()`` (with ``_jax_setup.compile_with``'s ``options``, where named),
    reused within the process for the same program.

    Each run traces its own functions, so JAX's in-memory caches do not see that the next
    seed of a comparison or a sweep's next call lowers the same program again; the persistent
    cache does, but loading from it costs about 0.15 s a program. Here the key is the
    program's text (its computation, constants included), its argument and result
    structures, and the devices and placements it was lowered for (the text does not name
    them). A program that calls back into Python (a ``jax.debug.callback`` in a user's loss)
    is compiled each time: a kept one would call the earlier run's function. Where JAX's
    lowering does not show its devices and callbacks as expected, nothing is kept.
    ``clear_compiled`` lets the kept programs go.
    """
    try:
        lowering = lowered._lowering  # JAX's own record of the lowering (not public API)
        args = lowering.compile_args
        if args["host_callbacks"] or args["keepalive"]:
            return compile_with(lowered, *options)
        placement = (
            tuple(d.id for d in lowering._device_list),
            str(args["in_shardings"]),
            str(args["out_shardings"]),
        )
    except (AttributeError, KeyError, TypeError):
        return compile_with(lowered, *options)
    text = hashlib.sha256(lowered.as_text().encode()).hexdigest()
    key = (text, placement, lowered.in_tree, lowered.out_tree, options)
    hit = _EXECUTABLES.pop(key, None)
    if hit is None:
        hit = compile_with(lowered, *options)
    _EXECUTABLES[key] = hit
    while len(_EXECUTABLES) > EXECUTABLES_KEPT:
        _EXECUTABLES.popitem(last=False)
    return hit


def clear_compiled() -> None:
    """Let go of the programs ``compiled_once`` keeps, of the kept trainers and of the
    solved terminal values (``jax.clear_caches`` does not)."""
    _EXECUTABLES.clear()
    _TRAINERS.clear()
    optimal.forget_solved()


def _outputs(shardings: Any) -> dict[str, Any]:
    """``jax.jit``'s keyword for the outputs' placement, when there is one to keep."""
    return {} if shardings is None else {"out_shardings": shardings}
