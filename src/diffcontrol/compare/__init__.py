"""``diffcontrol compare``: diffcontrol against reinforcement learning on the same task.

``run_comparison`` trains diffcontrol (its default configuration, through ``train``), builds
the planner and distils it where the task can take them (``compare._planning``), and trains the
RL baselines of ``diffcontrol.compare.baselines`` (Stable-Baselines3 with rl-baselines3-zoo's
settings; the ``rl`` extra) with the same training seeds, evaluates them all with the same
protocol (``diffcontrol.compare.run``), and writes to its output directory:

- ``runs/<method>-seed<S>.json``: one finished (method, seed) run, written atomically as
  soon as it ends, so an interrupted comparison resumes (``resume=True``) where it stopped;
- ``comparison.json``: the settings, every run, and the summary over seeds;
- ``comparison.md``: the table; ``comparison.png``: the learning curves.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import _gym, _jax_setup, _run_dir, envs, io
from .._shell import command as shell_command
from ..errors import ConfigError, Interrupted, RunDirectoryError
from ..settings import CompareConfig
from ..tasks import Task, resolve
from ._planning import PLANNING_METHODS, methods_for, run_planning
from .baselines import INSTALL_HINT, Baseline, RLSetup, require_rl, rl_setup
from .real import run_real_comparison
from .report import machine, plot, summarize, table
from .run import (
    evaluate_batch,
    run_diffcontrol,
    run_rl,
)

SETTINGS_FILE = "compare.json"
# The fields of a CompareConfig that the comparison in real steps takes as they are.
_REAL_SETTINGS = (
    "seeds max_rounds members explore_noise updates final_episodes eval_seed rl_results "
    "controllers".split()
)


def run_comparison(
    task: Task | str,
    out_dir: str | Path | None = None,
    config: CompareConfig | None = None,
    *,
    real: bool = False,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
    compile_cache: bool = True,
    command: str | None = None,
) -> dict[str, Any]:
    """Run the comparison on ``task``; returns what ``comparison.json`` holds.

    Args:
        task: ``pendulum``, ``cartpole`` or ``trebuchet`` (the tasks with baselines), or its
            name.
        out_dir: output directory (new or empty, or a previous comparison with ``resume``);
            default ``runs/compare-TASK``.
        config: the comparison's settings (``CompareConfig``; default ``CompareConfig()``):
            training seeds ``0 ... seeds-1`` for every method; ``methods``, a subset of
            ``methods_for(task)`` (all when omitted); the RL budget ``rl_steps`` (each
            baseline's zoo budget when omitted) and diffcontrol's ``updates`` (the task's
            default); the RL evaluation interval ``eval_every`` in environment steps; the
            episodes per evaluation point ``eval_episodes`` and for each returned controller
            ``final_episodes``, on reset seeds ``eval_seed ...``; ``torch_threads`` for the RL
            baselines (``None``: PyTorch's default); and those of ``real``.
        real: count the real system's steps instead (``run_real_comparison`` with the
            config's ``seeds``, ``models``, ``max_rounds``, ``start`` (empty: the task's),
            ``explore_noise``, ``updates``, ``final_episodes``, ``eval_seed``,
            ``controllers`` and ``rl_results``; default ``out_dir`` ``runs/compare-real-TASK``).
        resume: keep the finished runs already in ``out_dir`` and run only the others.
        progress: called with one line per evaluation point and per finished run.
        compile_cache: use JAX's persistent compilation cache (unless
            ``DIFFCONTROL_NO_COMPILE_CACHE`` is set).
        command: the command line that started it, for the message of an interruption.

    Returns:
        ``comparison.json``'s document, with ``"table"`` (``comparison.md``'s text) and
        ``"files"`` (the paths written) added.

    Raises:
        ConfigError: a bad setting, an unknown method, or a task without baselines.
        RunDirectoryError: ``out_dir`` holds other files or a comparison with other settings.
        DiffcontrolError: an RL method is asked for and the ``rl`` extra is not installed.
        Interrupted: Ctrl-C; the message says where the finished runs are and how to continue.
    """
    task = resolve(task) if isinstance(task, str) else task
    config = config or CompareConfig()
    if compile_cache and not os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE"):
        _jax_setup.enable_compile_cache()
    out = Path(out_dir or f"runs/compare-{'real-' if real else ''}{task.name}")
    try:
        if real:
            return run_real_comparison(
                task,
                out,
                models=config.models,
                start=config.start or None,
                resume=resume,
                progress=progress,
                **{n: getattr(config, n) for n in _REAL_SETTINGS},
            )
        return _compare(task, out, config, resume, progress)
    except KeyboardInterrupt:  # a loop's or a run's own message names only its part
        if not out.is_dir():
            raise Interrupted("interrupted before anything was written; nothing was kept") from None
        again = command or shell_command("compare", task.name, *(["--real"] if real else []))
        kept = f"{out / 'runs'}" + (f" and the loops under way in {out / 'loops'}" if real else "")
        raise Interrupted(
            f"interrupted; the finished runs are in {kept}. Continue with the same "
            f"options and --resume: {again}" + ("" if resume else " --resume")
        ) from None


def _compare(
    task: Task,
    out_dir: Path,
    config: CompareConfig,
    resume: bool,
    progress: Callable[[str], None] | None,
) -> dict[str, Any]:
    say = progress or (lambda line: None)
    known = methods_for(task)
    methods = list(config.methods or known)
    for m in methods:
        if m not in known:
            raise ConfigError(
                f"unknown method {m!r} for task {task.name!r}; choose from {', '.join(known)}"
            )
    if any(m not in ("diffcontrol", *PLANNING_METHODS) for m in methods):
        require_rl()
    setup = rl_setup(task) or RLSetup({})  # a task without baselines: diffcontrol's rows
    every = config.eval_every or setup.eval_every
    settings = {
        "format": "diffcontrol-compare",
        "task": task.name,
        "methods": methods,
        "seeds": list(range(config.seeds)),
        "rl_steps": config.rl_steps,
        "updates": config.updates,
        "eval_every": every,
        "eval_episodes": config.eval_episodes,
        "final_episodes": config.final_episodes,
        "eval_seed": config.eval_seed,
        "eval_env": _gym.gym_label(task) if task.gym_id else envs.env_id(task),
    }
    out = _prepare(out_dir, settings, resume)
    runs_dir = out / "runs"
    results, memo = [], {}  # memo: the planner, built once for both planning methods
    for method in methods:
        for seed in range(config.seeds):
            path = runs_dir / f"{method}-seed{seed}.json"
            if resume and path.exists():
                result = io.read_json(path, "comparison run")
                say(f"{method} seed {seed}: kept the finished run in {path}")
            else:
                say(f"{method} seed {seed}: training")
                common = dict(
                    eval_episodes=config.eval_episodes,
                    final_episodes=config.final_episodes,
                    eval_seed=config.eval_seed,
                    say=say,
                )
                if method == "diffcontrol":
                    result = run_diffcontrol(task, seed, updates=config.updates, **common)
                elif method in PLANNING_METHODS:
                    result = run_planning(method, task, seed, memo, **common)
                else:
                    result = run_rl(
                        task,
                        method,
                        seed,
                        steps=config.rl_steps,
                        eval_every=every,
                        torch_threads=config.torch_threads,
                        **common,
                    )
                io.write_json(path, result)
            results.append(result)
            f = result["final"]
            say(
                f"{method} seed {seed}: {result['env_steps']:,} steps, "
                f"{result['train_seconds']:.1f} s of training; final return "
                f"{f['mean_return']:.1f} ± {f['std_return']:.1f} ({f['episodes']} episodes)"
            )
    thresholds = setup.thresholds
    summary = summarize(results, thresholds)
    doc = {
        **settings,
        "thresholds": list(thresholds),
        "created": io.now_iso(),
        "machine": machine(),
        "summary": summary,
        "runs": results,
    }
    io.write_json(out / "comparison.json", doc)
    text = table(task.name, summary)
    io.write_bytes(out / "comparison.md", (text + "\n").encode())
    plot(task.name, results, thresholds, out / "comparison.png")
    doc["table"] = text
    doc["files"] = [str(out / f) for f in ("comparison.json", "comparison.md", "comparison.png")]
    return doc


def _prepare(out: Path, settings: dict, resume: bool) -> Path:
    """Create ``out`` (and ``out/runs``), or check that it holds this comparison."""
    path = out / SETTINGS_FILE
    if path.exists():
        old = io.read_json(path, "comparison settings")
        if not resume:
            raise RunDirectoryError(
                f"{out} already holds a comparison; pass --resume to continue it, or choose "
                "another --out"
            )
        diff = [k for k in settings if old.get(k) != settings[k]]
        if diff:
            raise RunDirectoryError(
                f"{out} holds a comparison with other settings ({', '.join(diff)} differ); "
                "resume it with the same options, or choose another --out"
            )
    else:
        try:
            _run_dir.make_dir(out)
            if any(out.iterdir()):
                raise RunDirectoryError(
                    f"{out} is not empty and holds no comparison; choose a new or empty --out"
                )
            (out / "runs").mkdir(exist_ok=True)
            io.write_json(path, settings)
        except OSError as e:
            raise RunDirectoryError(
                f"cannot write to {out} ({e.strerror}); choose a writable --out"
            ) from None
    (out / "runs").mkdir(exist_ok=True)
    return out


__all__ = [
    "Baseline",
    "INSTALL_HINT",
    "RLSetup",
    "evaluate_batch",
    "machine",
    "methods_for",
    "rl_setup",
    "run_comparison",
    "run_real_comparison",
]
