"""What the commands on a saved run do, as library calls: ``evaluate_dir`` (``diffcontrol
evaluate``), ``animate_dir`` (``diffcontrol animate``) and ``aim_dir`` (``diffcontrol aim``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .. import io
from ..errors import ConfigError
from ._files import Run, open_run


def evaluate_dir(
    run_dir: str | Path,
    *,
    task: Any = None,
    env_id: str | None = None,
    env_kwargs: dict | None = None,
    episodes: int | None = None,
    seed: int = 0,
) -> tuple[Run, Any]:
    """Evaluate the controller in ``run_dir`` with its task's ``evaluate_run`` hook.

    Args:
        task: the run's task where it is not registered (see ``open_run``).
        env_id: a Gymnasium environment to evaluate in instead (e.g. the real system of a
            fitted model); by default a run trained through a fitted model is evaluated on the
            real system its metrics name, any other on its task's own.
        env_kwargs: the keyword arguments of ``env_id``.
        episodes: episodes (or random targets); ``None``: the task's default number.
        seed: the first reset seed (or the seed of the random targets).

    Returns:
        The ``Run`` and the task's evaluation result (``summary()``, ``to_json()``).

    Raises:
        ConfigError: ``env_kwargs`` without ``env_id``, or a task with nothing to evaluate in.
    """
    real: Any = True
    if env_id:
        real = {"env_id": env_id, "env_kwargs": dict(env_kwargs or {})}
    elif env_kwargs:
        raise ConfigError("--env-arg needs --env (the environment it applies to)")
    run = open_run(run_dir, task=task, real=real)
    ev = run.task.evaluate_run(run, episodes=episodes, seed=seed)
    if ev is None:
        raise ConfigError(
            f"task {run.task.name!r} has no environment to evaluate in; name one with --env"
        )
    if env_id and ev.key != "gym_eval":  # the task's own evaluation, not episodes of env_id
        raise ConfigError(
            f"--env does not apply to task {run.task.name!r}, whose evaluation is its own "
            f"({ev.key}), not Gymnasium episodes; leave --env out"
        )
    return run, ev


def animate_dir(
    run_dir: str | Path,
    out: str | Path | None = None,
    *,
    task: Any = None,
    seed: int = 0,
    target: float = 80.0,
    wind: float = -3.0,
) -> tuple[Path, str]:
    """Write the animation of the controller in ``run_dir`` (its task's ``animate_run``) to
    ``out`` (a new ``.gif``; default ``run_dir/rollout.gif``, replaced). ``seed`` resets the
    episode; ``target`` and ``wind`` are an aiming task's. Returns the path and what it shows."""
    run = open_run(run_dir, task=task)
    path = Path(out) if out else Path(run_dir) / "rollout.gif"
    if not out:
        return path, run.task.animate_run(run, path, seed=seed, target=target, wind=wind)
    io.check_new_file(path, ".gif")
    draw = lambda tmp: run.task.animate_run(run, tmp, seed=seed, target=target, wind=wind)  # noqa: E731
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
            f"{run_dir} holds a {run.task.name!r} controller; `aim` needs an aiming task "
            "(the trebuchet)"
        )
    result, lines = run.task.aim(run, target, wind, direct=direct)
    return result, [f"target {target:g} m, wind {wind:+g} m/s", *lines]
