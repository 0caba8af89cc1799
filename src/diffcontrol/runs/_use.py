"""What the commands on a saved run do, as library calls: ``evaluate_dir`` (``diffcontrol
evaluate``), ``animate_dir`` (``diffcontrol animate``) and ``aim_dir`` (``diffcontrol aim``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .. import _gym, io
from .._run_files import Run
from ..errors import ConfigError
from ..evaluation import evaluate_run
from ..mpc import closed_loop_optimum
from ..optimal import optimal_return
from ._open import open_run


def evaluate_dir(
    run_dir: str | Path,
    *,
    task: Any = None,
    env_id: str | None = None,
    env_kwargs: dict | None = None,
    episodes: int | None = None,
    seed: int = 0,
    optimum: int | None = None,
) -> tuple[Run, Any]:
    """Evaluate the controller in ``run_dir`` with ``evaluation.evaluate_run`` (its task's, where the task has one).

    Args:
        task: the run's task where it is not registered (see ``open_run``).
        env_id: a Gymnasium environment to evaluate in instead (e.g. the real system of a
            fitted model); by default a run trained through a fitted model is evaluated on the
            real system its metrics name, any other on its task's own.
        env_kwargs: the keyword arguments of ``env_id``.
        episodes: episodes (or random targets); ``None``: the task's default number.
        seed: the first reset seed (or the seed of the random targets).
        optimum: also run the reference optimum on the same seeds (``optimal.optimal_return``
            on a grid of ``optimum`` points per state axis, 41 actions) and report the gap to
            it; for tasks with a state grid (Pendulum), on the system evaluated: the task's own,
            or a real system whose physics the task knows (``_gym.params_of_env``:
            ``diffcontrol/PendulumFriction-v0`` with ``g`` and ``friction``). A continuous-time
            task with a state grid: its discretised view's (``mpc.closed_loop_optimum``).

    Returns:
        The ``Run`` and the task's evaluation result (``summary()``, ``to_json()``; with
        ``optimum``, its ``optimum`` is the ``optimal.OptimumResult``, or for a continuous-time
        task the ``mpc.ClosedLoopOptimum``).

    Raises:
        ConfigError: ``env_kwargs`` without ``env_id``, or a task with nothing to evaluate in.
    """
    real: Any = True
    if env_id:
        real = {"env_id": env_id, "env_kwargs": dict(env_kwargs or {})}
    elif env_kwargs:
        raise ConfigError("--env-arg needs --env (the environment it applies to)")
    run = open_run(run_dir, task=task, real=real)
    ev = evaluate_run(run.task, run, episodes=episodes, seed=seed)
    if ev is None:
        raise ConfigError(
            f"task {run.task.name!r} has no environment to evaluate in; name one with --env"
        )
    if env_id and ev.key != "gym_eval":  # the task's own evaluation, not episodes of env_id
        raise ConfigError(
            f"--env does not apply to task {run.task.name!r}, whose evaluation is its own "
            f"({ev.key}), not Gymnasium episodes; leave --env out"
        )
    if hasattr(ev, "solves") and hasattr(run.policy, "reports"):  # a planner: its solves
        ev.solves = run.policy.summary()
    if optimum is not None:
        ev.optimum = _optimum(run, ev, optimum)
    return run, ev


def _optimum(run: Run, ev: Any, points: int) -> Any:
    """The grid optimum, on the seeds ``ev`` was measured on, of the system it was measured
    on: the task's own, or the run's real system (``--env``, or the one a fitted model's data
    came from) solved with its physics (the task's ``params_of_env``); for a continuous-time
    task, that of its discretised view from the same starts (``mpc.closed_loop_optimum``)."""
    if not 3 <= points <= MAX_OPTIMUM_POINTS:
        raise ConfigError(
            f"--optimum {points}: the grid needs 3 to {MAX_OPTIMUM_POINTS} points per axis "
            "(for Pendulum, 401 is within about 0.3 of the converged optimum)"
        )
    if ev.key not in ("gym_eval", "closed_loop"):  # a task's own evaluation (swing-up, aim)
        raise ConfigError(
            f"--optimum: task {run.task.name!r} is judged by its own evaluation ({ev.key}), "
            "which has no grid optimum; leave --optimum out"
        )
    if ev.key == "closed_loop":
        starts = int(ev.losses.size)
        return closed_loop_optimum(
            run.task, points, OPTIMUM_LEVELS, params=run.params, config=run.config,
            starts=starts, seed=ev.seed,
        )  # fmt: skip
    real = run.real_env
    params = None if real is None else _gym.params_of_env(run.task, *real)
    if (real is None and ev.env_id != _gym.gym_label(run.task)) or (
        real is not None and params is None
    ):
        raise ConfigError(
            f"--optimum needs the physics of the system evaluated, and task "
            f"{run.task.name!r} does not know those of {getattr(ev, 'env_id', ev.key)}; "
            "leave --optimum out"
        )
    seeds = range(ev.seed, ev.seed + int(ev.returns.size))
    return optimal_return(
        run.task, seeds, points=points, levels=OPTIMUM_LEVELS, params=params, real=real
    )


MAX_OPTIMUM_POINTS = 1001
"""The finest grid ``evaluate_dir`` solves: its value table is about 0.8 GB (Pendulum)."""
OPTIMUM_LEVELS = 41
"""Actions per action dimension of ``evaluate_dir``'s optimum (as the benchmarks' tables)."""


def animate_dir(
    run_dir: str | Path,
    out: str | Path | None = None,
    *,
    task: Any = None,
    seed: int = 0,
    target: float = 80.0,
    wind: float = -3.0,
) -> tuple[Path, str]:
    """Write the animation of the controller in ``run_dir`` (``animate_run``) to ``out`` (a
    new ``.gif``; default ``run_dir/rollout.gif``, replaced). ``seed`` resets the episode;
    ``target`` and ``wind`` are an aiming task's. Returns the path and what it shows."""
    from ..plots import animate_run  # matplotlib

    run = open_run(run_dir, task=task)
    path = Path(out) if out else Path(run_dir) / "rollout.gif"
    if not out:
        return path, animate_run(run.task, run, path, seed=seed, target=target, wind=wind)
    io.check_new_file(path, ".gif")
    draw = lambda tmp: animate_run(run.task, run, tmp, seed=seed, target=target, wind=wind)  # noqa: E731
    return path, io.write_new(path, draw)  # never replaces a file made meanwhile


def aim_dir(
    run_dir: str | Path, target: float, wind: float = 0.0, *, task: Any = None, direct: bool = False
) -> tuple[dict, list[str]]:
    """Aim the aiming controller in ``run_dir`` at ``target`` metres in ``wind`` m/s (its task's
    ``aim`` hook; ``direct`` also aims by gradient steps on the simulator alone). Returns the
    result and its printable lines, the first naming the target and the wind.

    Raises:
        ConfigError: the run's task does not aim.
    """
    run = open_run(run_dir, task=task)
    if not callable(getattr(run.task, "aim", None)):
        raise ConfigError(
            f"{run_dir} holds a {run.task.name!r} controller; `aim` needs an aiming task (one "
            "that defines aim)"
        )
    result, lines = run.task.aim(run, target, wind, direct=direct)
    return result, [f"target {target:g} m, wind {wind:+g} m/s", *lines]
