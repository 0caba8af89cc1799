"""Sweeps: many training runs of one task (seeds x settings) as one compiled program.

A sweep's members are whole, independent runs: member ``i`` is what ``train(task,
configs[i])`` would do (the same keys, the same updates, its own keep-best and early stop),
but all members that share a program's shapes step together under ``vmap`` in one compiled
chunk (PureJaxRL's way), sharded over the local devices when there are several. What may
differ inside one program is listed in ``SWEPT_IN_PROGRAM`` (the seed, and the learning rate,
which sits in the optimiser's state through ``optax.inject_hyperparams``); members that differ
in anything else (a width, a batch size) form one program per distinct setting, run one after
the other.

Results are those of the separate runs up to the order of floating-point operations (a
batched matrix product may sum in another order): the same returns to noise, not bit for bit.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import PyTree

from ..checks import validate_task
from ..config import TrainConfig
from ..errors import ConfigError
from ..tasks import StepLoss, Task
from ._bptt import check_value_grid, make_optimizer, make_trainer
from ._devices import check_devices, mesh_placements, placer
from ._driver import TrainResult, _check_head, interrupts_deferred, task_params
from ._events import EventLog, learning_rates, open_log, summary
from ._interface import trainer_kind
from ._loop import Loop
from ._programs import compiled_once

MAX_MEMBERS = 2**16
"""The most members one sweep may have."""

SWEPT_IN_PROGRAM = ("seed", "learning_rate")
"""Settings whose values may differ between the members of one compiled program."""


def grid(
    config: TrainConfig, seeds: Sequence[int], values: dict[str, Sequence[Any]] | None = None
) -> list[TrainConfig]:
    """The configs of a grid sweep: every seed with every combination of ``values``.

    Args:
        config: the settings every member starts from (e.g. ``task.default_config()``).
        seeds: the training seeds.
        values: setting name -> the values to try (e.g. ``{"learning_rate": [1e-3, 3e-3]}``).

    Returns:
        The member configs, settings outermost and seeds innermost.

    Raises:
        ConfigError: an unknown setting, an empty list, or a value the setting refuses.
    """
    values = dict(values or {})
    fields = {f.name for f in dataclasses.fields(config)}
    for name, options in values.items():
        if name not in fields or name == "seed":
            raise ConfigError(
                f"cannot sweep {name!r}: not a setting of {type(config).__name__} "
                "(seeds go in seeds=, --seeds)"
            )
        if isinstance(options, str) or not isinstance(options, Sequence) or not options:
            raise ConfigError(f"sweep values of {name!r} must be a non-empty list, got {options!r}")
    seeds = list(seeds)
    if not seeds:
        raise ConfigError("a sweep needs at least one seed")
    names = list(values)
    count = len(seeds) * math.prod(len(v) for v in values.values())
    if count > MAX_MEMBERS:
        raise ConfigError(
            f"a sweep of {count:,} members is more than {MAX_MEMBERS:,}; sweep fewer seeds or "
            "values, or split the sweep"
        )
    members = []
    for combo in itertools.product(*(values[n] for n in names)):
        changed = config.replace(**dict(zip(names, combo, strict=True)))
        members += [changed.replace(seed=s) for s in seeds]
    return members


@dataclasses.dataclass
class SweepResult:
    """What ``sweep`` returns: one ``TrainResult`` per member, in the order of the configs."""

    task: Task
    members: list[TrainResult]
    metrics: dict[str, Any]

    @property
    def best(self) -> int:
        """The index of the member with the best returned in-simulator evaluation return."""
        returns = [m.metrics["final_eval_return"] for m in self.members]
        return int(np.argmax(np.where(np.isfinite(returns), returns, -np.inf)))

    def table(self, swept: Sequence[str] = ()) -> str:
        """A plain-text table: one row per member (its swept settings, the returned update
        and in-simulator return), the best marked with ``*``."""
        swept = list(swept) or self.metrics.get("swept", ["seed"])
        head = ["#", *swept, "returned update", "eval return", "stopped"]
        rows = []
        for i, m in enumerate(self.members):
            cfg = m.config
            rows.append(
                [
                    f"{i}{'*' if i == self.best else ''}",
                    *(_short(getattr(cfg, n)) for n in swept),
                    str(m.metrics["returned_update"]),
                    f"{m.metrics['final_eval_return']:.2f}",
                    "early"
                    if m.metrics["stopped_early"]
                    else "diverged"
                    if m.metrics.get("diverged")
                    else "",
                ]
            )
        widths = [max(len(r[j]) for r in [head, *rows]) for j in range(len(head))]
        lines = [
            "  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in [head, *rows]
        ]
        return "\n".join(lines)


def _short(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def sweep(
    task: Task,
    configs: Sequence[TrainConfig],
    *,
    step_loss: StepLoss | None = None,
    devices: int | None = None,
    progress: Callable[[str], None] | None = None,
    log_dir: str | Path | None = None,
    log_names: Sequence[str] | None = None,
) -> SweepResult:
    """Train every config of ``configs`` on ``task`` as a vmapped population of whole runs.

    Args:
        task: a discrete-time task (continuous-time tasks train a population of their own:
            ``ODETrainConfig.population``).
        configs: the members' settings, e.g. from ``grid``; ``population`` must be 1.
        step_loss: a training loss replacing the task's built-in one, as in ``train``.
        devices: how many local devices to shard the members over (default: as many as
            divide each program's member count).
        progress: called with one line per evaluation point.
        log_dir: write the training curves there as TensorBoard event files: one run per
            member (``log_names``, default ``member_000``, ...) up to ``LOGGED_MEMBERS``
            members, else one ``summary`` run of the members' median, best and worst.
        log_names: the members' run names under ``log_dir``.

    Returns:
        A ``SweepResult``; member ``i``'s ``TrainResult`` has the metrics ``train`` gives
        (``train_seconds`` is the wall time of its program, shared by its members).

    Raises:
        ConfigError: a continuous-time task, a member with ``population > 1``, a device count
            that is not available or does not divide the members.
    """
    configs = list(configs)
    check_members(task, configs, devices)
    say = progress or (lambda line: None)
    log = open_log(log_dir)
    names = list(log_names or (f"member_{i:03d}" for i in range(len(configs))))
    if len(configs) > LOGGED_MEMBERS:
        names = [""] * len(configs)  # the summary only
    # One program per setting that changes shapes or control flow.
    groups: dict[TrainConfig, list[int]] = {}
    for i, c in enumerate(configs):
        groups.setdefault(c.replace(seed=0, learning_rate=1.0), []).append(i)
    results: list[TrainResult | None] = [None] * len(configs)
    t0 = time.perf_counter()
    for g, members in enumerate(groups.values()):
        if len(groups) > 1:
            say(f"program {g + 1}/{len(groups)}: {len(members)} member(s)")
        group = [configs[i] for i in members]
        logged = (log, [names[i] for i in members]) if log is not None else None
        for i, result in zip(
            members, _run_program(task, group, step_loss, devices, say, logged), strict=True
        ):
            results[i] = result
    if log is not None:
        log.close()
    swept = ["seed", *_differing(configs)]
    metrics = {
        "task": task.name,
        "members": len(configs),
        "programs": len(groups),
        "swept": swept,
        "seconds": time.perf_counter() - t0,
    }
    return SweepResult(task=task, members=list(results), metrics=metrics)


def check_discrete(task: Any) -> None:
    """Refuse a task that is not trained with a ``TrainConfig``: a sweep's members are BPTT
    runs (a continuous-time task's are not).

    Raises:
        ConfigError: naming what to use instead.
    """
    config = task.default_config()
    if not isinstance(config, TrainConfig):
        raise ConfigError(
            f"task {task.name!r} is {trainer_kind(config).time}; sweep its seeds with "
            "ODETrainConfig.population (--population) or run `diffcontrol train` per setting"
        )


def check_members(task: Task, configs: Sequence[TrainConfig], devices: int | None = None) -> None:
    """Refuse what ``sweep`` cannot train, before anything is compiled.

    Raises:
        ConfigError: see ``sweep``.
    """
    check_discrete(task)
    if not configs:
        raise ConfigError("a sweep needs at least one member config")
    if len(configs) > MAX_MEMBERS:
        raise ConfigError(
            f"a sweep of {len(configs):,} members is more than {MAX_MEMBERS:,} in one program; "
            "split it into several sweeps"
        )
    expected = type(task.default_config())
    for c in configs:
        if not isinstance(c, expected):
            raise ConfigError(f"sweep members of {task.name!r} are {expected.__name__}s, got {c!r}")
        if c.population != 1:
            raise ConfigError(
                f"a sweep member trains one controller (population 1), got population "
                f"{c.population}; a sweep is itself a population of runs"
            )
        _check_head(task, c)
        if c.value_grid:
            check_value_grid(task, c)  # before any member trains
    check_devices(devices)


STATE_COPIES = 4
"""How many copies of the members' training state a sweep holds at once, at most: the state,
the chunk's new state, the best controllers and the evaluation's episodes (about one more)."""


def available_memory() -> int:
    """The bytes this process may use: the machine's memory, or less where a limit on the
    address space (``ulimit -v``) says so."""
    import resource

    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return min(total, soft) if soft != resource.RLIM_INFINITY else total


def check_memory(task: Task, members: int, state: PyTree, say: Callable[[str], None]) -> None:
    """Refuse a sweep whose members' training state (one member's ``state``, as
    ``jax.eval_shape`` gives it, ``STATE_COPIES`` times) would not fit in the memory this
    process may use, before anything is allocated; say how much it needs when that is over a
    gigabyte.

    Raises:
        ConfigError: naming the members, the memory they need and the memory there is.
    """
    one = sum(math.prod(x.shape) * x.dtype.itemsize for x in jax.tree.leaves(state))
    need, have = STATE_COPIES * one * members, available_memory()
    if need > have:
        fit = have // (STATE_COPIES * one)
        advice = (
            f"sweep at most {fit:,} members at once"
            if fit
            else "one member alone needs more: make the network or the batch smaller"
        )
        raise ConfigError(
            f"a sweep of {members:,} members of {task.name!r} needs about {need / 2**30:.2f} "
            f"GiB for their training state, more than the {have / 2**30:.2f} GiB this process "
            f"may use; {advice}"
        )
    if need > 2**30:
        say(f"{members:,} members: about {need / 2**30:.1f} GiB of training state")


def _differing(configs: Sequence[TrainConfig]) -> list[str]:
    """The settings (other than the seed) whose values differ between members."""
    first = configs[0]
    return [
        f.name
        for f in dataclasses.fields(first)
        if f.name != "seed"
        and any(not _same(getattr(c, f.name), getattr(first, f.name)) for c in configs)
    ]


def _same(a: Any, b: Any) -> bool:
    return a == b or (
        isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    )


def _member_devices(members: int, devices: int | None) -> int:
    """The device count to shard ``members`` over: ``devices`` if it divides them, else (by
    default) the largest count of local devices that does."""
    if devices is not None:
        if members % devices:
            fits = [d for d in range(1, len(jax.local_devices()) + 1) if members % d == 0]
            raise ConfigError(
                f"{members} sweep members cannot be split evenly over {devices} devices; use "
                f"--devices {fits[-1]} (or any of {', '.join(map(str, fits))}), or a multiple "
                f"of {devices} members"
            )
        return devices
    return max(d for d in range(1, len(jax.local_devices()) + 1) if members % d == 0)


def _run_program(
    task: Task,
    configs: list[TrainConfig],
    step_loss: StepLoss | None,
    devices: int | None,
    say: Callable[[str], None],
    logged: tuple[EventLog, list[str]] | None = None,
) -> list[TrainResult]:
    """The members of one program: same shapes, different seeds and learning rates (their
    curves written to ``logged``'s event log under its names; ``""``: the summary only)."""
    t_start = time.perf_counter()
    cfg = configs[0]
    _check_head(task, cfg)
    params = task_params(task, cfg.params)
    validate_task(task, params)

    def factory(learning_rate):
        return make_optimizer(cfg, learning_rate)

    swept = optax.inject_hyperparams(factory)(learning_rate=cfg.learning_rate)
    trainer = make_trainer(task, cfg, step_loss, params, say, optimizer=swept)
    n = len(configs)
    # every member's keys by one program: a key stacked per member would be a concatenation of
    # as many operands, which XLA compiles for minutes when there are thousands
    seeds = jnp.asarray(np.asarray([c.seed for c in configs], np.int32))
    keys = jax.vmap(lambda seed: jax.random.split(jax.random.PRNGKey(seed)))(seeds)
    k_train, k_eval = keys[:, 0], keys[:, 1]
    lrs = jnp.asarray([c.learning_rate for c in configs], jnp.float32)

    def init(k, lr):
        ts = trainer.init(k, params)
        return eqx.tree_at(lambda t: t.opt_state.hyperparams["learning_rate"], ts, lr)

    check_memory(task, n, jax.eval_shape(init, k_train[0], lrs[0]), say)
    per_point = n * cfg.eval_episodes * (cfg.horizon or task.episode_length)
    if per_point >= 10**8:  # minutes on a CPU before the first line of the curve
        say(
            f"each evaluation point simulates {per_point:,} steps ({n:,} members x "
            f"{cfg.eval_episodes} episodes); the first comes after compiling"
        )
    ndev = _member_devices(n, devices)
    shard, replicate = _placement(ndev)
    params = replicate(params)
    t0 = time.perf_counter()
    evaluate = jax.jit(jax.vmap(trainer.evaluate, in_axes=(0, None, 0)))
    # one chunk per stage of the window curriculum (Trainer.stages; its members share it)
    chunks = [
        (end, jax.jit(jax.vmap(t.chunk, in_axes=(0, None, 0)))) for end, t in trainer.stages()
    ]
    totals = np.full(n, cfg.updates, np.int32)
    with interrupts_deferred():
        ts = eqx.filter_jit(jax.vmap(init))(shard(k_train), shard(lrs))
        # every member's state on its member's device: left to GSPMD, most of the state
        # (the networks, the optimiser) comes out replicated, and every chunk then computes
        # it on each device, and two devices run slower than one
        arrays, rest = eqx.partition(ts, eqx.is_array)
        ts = eqx.combine(shard(arrays), rest)
        if ndev == 1:  # compiled ahead, to measure compilation apart from training
            evaluate = compiled_once(evaluate.lower(ts.controller, params, k_eval))
            chunks = [
                (e, compiled_once(c.lower(ts, params, jnp.asarray(totals)))) for e, c in chunks
            ]
    compile_seconds = time.perf_counter() - t0

    loop = SweepLoop(
        trainer,
        configs,
        params,
        evaluate,
        shard(k_eval),
        chunks,
        say,
        t_start=t_start,
        shard=shard,
        logged=logged,
    )
    nan = np.full(n, math.nan)
    loop.record(ts, nan, nan, np.ones(n, bool))
    ts = loop.run(ts)
    wall = time.perf_counter() - t_start
    results = []
    for i, c in enumerate(configs):
        curve = loop.curves[i]
        chosen = curve[loop.best_index[i]] if c.keep_best else curve[-1]
        controller = _member(loop.best if c.keep_best else ts.controller, i)
        done_updates = int(ts.update[i])
        steps = c.simulated_steps(done_updates)
        metrics = {
            "task": task.name,
            "gym_id": task.gym_id,
            "seed": c.seed,
            "train_seconds": wall,
            "compile_seconds": compile_seconds,
            "updates": done_updates,
            "simulated_steps": steps,
            "simulated_episodes": steps / task.episode_length,
            "episode_length": task.episode_length,
            "stopped_early": bool(loop.stopped[i]),
            "diverged": bool(loop.diverged[i]),
            "returned_update": chosen["update"],
            "final_eval_return": chosen["eval_return"],
            "final_eval_return_std": chosen["eval_return_std"],
            "eval_episodes": c.eval_episodes,
            "num_parameters": controller.num_parameters,
            "curve": curve,
            "warnings": [],
            "config": c.to_json(),
            "jax_version": jax.__version__,
            "device": str(jax.devices()[0].platform),
            "sweep": {"member": i, "members": n, "devices": ndev},
        }
        results.append(
            TrainResult(task=task, config=c, params=params, controller=controller, metrics=metrics)
        )
    return results


class SweepLoop(Loop):
    """A sweep program's turn of the loop: its members step together under ``vmap``, each with
    its own budget, target, keep-best and divergence (a diverged member stops; the others
    train on); one progress line per point for all of them, and their logs (``logged``)."""

    def __init__(self, *args: Any, shard: Callable[[PyTree], PyTree], logged: Any, **kw: Any):
        super().__init__(*args, **kw)
        self.shard, self.logged = shard, logged
        self._counts: tuple[Any, list[np.ndarray]] | None = None

    def per_run(self, x: np.ndarray) -> np.ndarray:
        return x

    def state_of(self, ts: Any, i: int) -> SimpleNamespace:
        if self._counts is None or self._counts[0] is not ts:  # once per point, not per member
            names = ("update", "finished_episodes", "finished_return_sum")
            self._counts = (ts, [np.asarray(getattr(ts, k)) for k in names])
        update, finished, finished_sum = self._counts[1]
        return SimpleNamespace(
            update=update[i], finished_episodes=finished[i], finished_return_sum=finished_sum[i]
        )

    def keep(self, ts: Any, returns: np.ndarray, improved: np.ndarray) -> None:
        mask = jnp.asarray(improved)
        self.best = (
            ts.controller
            if self.best is None
            else jax.tree.map(
                lambda new, old: (
                    jnp.where(mask.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)
                    if eqx.is_array(new)
                    else new
                ),
                ts.controller,
                self.best,
            )
        )

    def total(self, totals: np.ndarray) -> Any:
        return self.shard(jnp.asarray(totals.astype(np.int32)))

    def lost(self, old: Any, new: Any, losses: list[np.ndarray], means: np.ndarray) -> np.ndarray:
        lost = ~(np.isfinite(means) & _finite_members(new.controller, self.n))
        updates = self.updates(old)
        for i in np.flatnonzero(lost & (self.updates(new) > updates)):
            c = self.configs[i]
            self.say(
                f"note: member {i} (seed {c.seed}, learning rate {c.learning_rate:g}) diverged "
                f"near update {int(updates[i]) + 1}; the others train on"
            )
        return lost

    def points_made(self, ts: Any, returns: np.ndarray, points: list[dict | None]) -> None:
        updates, budget, diverged = self.updates(ts), self.configs[0].updates, self.diverged
        means = np.array([c[-1]["eval_return"] for c in self.curves])
        if self.logged is not None:
            _log_points(self.logged, points, means, int(updates.max()))
        top = int(np.nanargmax(np.where(diverged, np.nan, means))) if not diverged.all() else 0
        running = int(np.sum(~(self.stopped | diverged) & (updates < budget)))
        self.say(
            f"[{100.0 * updates.max() / max(budget, 1):5.1f}%] update {updates.max():>5}/"
            f"{budget}  members {self.n} ({running} training)  best eval return "
            f"{means[top]:9.2f} (#{top})  median {np.nanmedian(means):9.2f}  "
            f"{self.seconds():6.1f} s"
        )

    def chunk_done(
        self, updates: np.ndarray, done: np.ndarray, losses: list[np.ndarray], grads: list
    ) -> None:
        if self.logged is not None:
            _log_updates(self.logged, self.configs, updates, done, losses, grads)


LOGGED_MEMBERS = 64
"""A sweep of more members logs one summary run instead of a run per member."""


def _log_updates(
    logged: tuple[EventLog, list[str]],
    configs: Sequence[TrainConfig],
    updates: np.ndarray,
    done: np.ndarray,
    losses: list[np.ndarray],
    grads: list[np.ndarray],
) -> None:
    """Each member's updates of the chunk just run (or, for the summary, their median)."""
    log, names = logged
    rates = [learning_rates(c, int(u), int(d), c.learning_rate) for c, u, d in
             zip(configs, updates, done, strict=True)]  # fmt: skip
    if names[0]:
        for i in np.flatnonzero(done > 0):
            k = int(done[i])
            log.updates(int(updates[i]), losses[i][:k], grads[i][:k], rates[i], run=names[i])
        return
    k = int(done.max())
    members = [i for i in range(len(configs)) if done[i] == k]
    with np.errstate(all="ignore"):
        median = [
            np.nanmedian(np.stack([x[i][:k] for i in members]), axis=0) for x in (losses, grads)
        ]
    rate = np.median(np.stack([rates[i] for i in members]), axis=0)
    log.updates(int(updates[members[0]]), median[0], median[1], rate, run="summary")


def _log_points(
    logged: tuple[EventLog, list[str]],
    points: list[dict[str, Any] | None],
    means: np.ndarray,
    step: int,
) -> None:
    """Each member's evaluation point (or the members' median, best and worst)."""
    log, names = logged
    if names[0]:
        for i, point in enumerate(points):
            if point is not None:
                log.point(point, run=names[i])
        return
    stats = summary(means)
    log.scalars({f"eval/return_{k}": v for k, v in stats.items()}, step, run="summary")


def _member(stacked: Any, i: int) -> Any:
    """Member ``i`` of a stack of controllers."""
    return jax.tree.map(lambda x: x[i] if eqx.is_array(x) else x, stacked)


def _finite_members(controllers: Any, n: int) -> np.ndarray:
    """Which members' weights are all finite."""
    ok = np.ones(n, bool)
    for leaf in jax.tree.leaves(eqx.filter(controllers, eqx.is_inexact_array)):
        ok &= np.asarray(jnp.all(jnp.isfinite(leaf.reshape(n, -1)), axis=1))
    return ok


def _placement(devices: int) -> tuple[Callable[[PyTree], PyTree], Callable[[PyTree], PyTree]]:
    """Split along the leading (members) axis, and replicate, over ``devices`` devices."""
    split, whole = mesh_placements(devices)
    return placer(split), placer(whole)
