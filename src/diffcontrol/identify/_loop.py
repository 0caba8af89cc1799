"""``loop``: record -> fit -> train, a few rounds, for a system known only by acting.

Each round is made of the library's steps (the task's ``record_data``, ``identify.fit_dir``,
``train`` through the fitted model, ``runs.save_run``) on files in ``out``, so every round's outputs are the ones
``diffcontrol record/fit/train`` write, and an interrupted loop continues where it stopped
(``resume``): a round's data, fitted model and controller are each kept once written.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import ConfigError, RunDirectoryError
from ..io import now_iso, read_json, write_figure, write_json
from ._fit import fit_dir
from .data import concat, read_trajectories, write_trajectories

LOOP_FILE = "loop.json"


def loop(
    task: Any,
    out: str | Path,
    *,
    env_id: str | None = None,
    env_kwargs: dict | None = None,
    model: str = "params",
    names: list[str] | None = None,
    rounds: int = 3,
    episodes: int = 2,
    updates: int | None = None,
    seed: int = 0,
    eval_episodes: int = 20,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
    report: Callable[[str], None] = print,
) -> dict:
    """Learn a controller for a system you can only run: record ``episodes`` episodes of the
    real system (the task's ``record_data``: by default Gymnasium episodes of ``env_id``, the
    task's own environment unless given; random actions at first), fit a model
    of ``task``'s system to all data so far, train a controller through it, judge it on the
    real environment, record ``episodes`` more with it, and repeat for ``rounds`` rounds.

    Writes ``out/data.csv`` (all recorded episodes), ``out/round_K/{fit,run}/``,
    ``out/loop.json`` (per round: data, fit, return on the real system) and ``out/loop.png``;
    ``report`` gets each round's line and the last one. Returns the loop's state.

    Raises:
        ConfigError: a task that records no Gymnasium episodes.
        RunDirectoryError: ``out`` holds another loop (or, without ``resume``, any loop), or
            other files.
    """
    from ..envs import env_id as own_id
    from ..runs import fitted_training, save_run
    from ..tasks import Task
    from ..training import resolve_config, train

    if not isinstance(task, Task):
        raise ConfigError(
            f"loop needs a discrete-time control task with a Gymnasium environment, not "
            f"{task.name!r}; e.g. pendulum"
        )
    env_kwargs = dict(env_kwargs or {})
    out = Path(out)
    settings = {
        "task": task.name,
        "env_id": env_id or task.gym_id or own_id(task),
        "env_kwargs": env_kwargs,
        "model": model,
        "params": names,
        "episodes_per_round": episodes,
        "updates": updates,
        "seed": seed,
    }
    state = _start(out, settings, resume)
    say = progress or (lambda line: None)

    def record_round(k: int, controller: Path | None) -> None:
        """Record the episodes of round k (random for k = 0, else with round k's controller
        ``controller``) and append them to data.csv."""
        part = out / f"round_{k}" / "recorded.csv"
        if not part.exists():
            data = task.record_data(
                episodes,
                env_id=env_id,
                env_kwargs=env_kwargs,
                controller=None if controller is None else str(controller),
                seed=seed + 1000 * k,
            )
            part.parent.mkdir(parents=True, exist_ok=True)
            write_trajectories(part, data)
        parts = [read_trajectories(out / f"round_{j}" / "recorded.csv") for j in range(k + 1)]
        write_trajectories(out / "data.csv", concat(parts))

    record_round(0, None)
    for k in range(1, rounds + 1):
        t0 = time.perf_counter()
        here = out / f"round_{k}"
        data = read_trajectories(out / "data.csv")
        say(f"round {k}/{rounds}: fitting {model} to {data.num_episodes} episodes")
        if not (here / "fit" / "fitted.json").exists():
            fitted = fit_dir(
                task, out / "data.csv", model, here / "fit", holdout=0.0, names=names,
                progress=progress,
            )  # fmt: skip
            for line in fitted.lines:
                say(line)
        if not (here / "run" / "model.json").exists():
            trained, params, real, info = fitted_training(task, here / "fit", None)
            say(info.pop("note"))
            overrides = {"seed": seed, "updates": updates, "params": params or None}
            config = resolve_config(trained, None, **{k: v for k, v in overrides.items() if v})
            resumed = (here / "run" / "checkpoint.npz").exists()
            result = train(trained, config, out_dir=here / "run", resume=resumed, progress=say)
            result.metrics["model"] = info
            save_run(result, here / "run", final_eval=eval_episodes, animation=False, real=real)
        metrics = read_json(here / "run" / "metrics.json", "metrics")
        fitted_doc = read_json(here / "fit" / "fitted.json", "fitted model")
        row = {
            "round": k,
            "episodes": data.num_episodes,
            "transitions": data.num_steps,
            "fit_loss": fitted_doc["fit"]["loss"],
            "fitted_parameters": {
                n: p["value"] for n, p in (fitted_doc.get("parameters") or {}).items()
            },
            "real_return": metrics.get("gym_eval", {}).get("mean_return"),
            "real_return_std": metrics.get("gym_eval", {}).get("std_return"),
            "seconds": time.perf_counter() - t0,
        }
        state["rounds"] = [r for r in state["rounds"] if r["round"] != k] + [row]
        write_json(out / LOOP_FILE, {**state, "updated": now_iso()})
        ret = row["real_return"]
        fitted_txt = ", ".join(f"{n} = {v:.4g}" for n, v in row["fitted_parameters"].items())
        report(
            f"round {k}: {row['episodes']} episodes ({row['transitions']} transitions)"
            + (f", {fitted_txt}" if fitted_txt else f", fit loss {row['fit_loss']:.3g}")
            + (f"; return on the real system {ret:.1f}" if ret is not None else "")
        )
        if k < rounds:
            record_round(k, here / "run")
    _plot(state, out / "loop.png")
    report(
        f"wrote {out / LOOP_FILE}, {out / 'loop.png'} and {out / 'data.csv'}; the controller: "
        f"{out / f'round_{rounds}' / 'run' / 'model.json'}"
    )
    return state


def _start(out: Path, settings: dict, resume: bool) -> dict:
    """The loop's state: new (refusing a DIR with another loop in it) or resumed."""
    path = out / LOOP_FILE
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out} is a file; give a directory")
    if path.exists():
        old = read_json(path, "loop file")
        if not resume:
            raise RunDirectoryError(
                f"{out} already holds a loop; pass --resume to continue it, or choose another --out"
            )
        if old.get("settings") != json.loads(json.dumps(settings)):
            raise RunDirectoryError(
                f"{out} holds a loop with other settings ({old.get('settings')}); resume it with "
                "those, or choose another --out"
            )
        return old
    if out.exists() and any(out.iterdir()) and not resume:
        raise RunDirectoryError(f"--out {out} is not empty; choose a new or empty directory")
    out.mkdir(parents=True, exist_ok=True)
    return {"format": "diffcontrol-loop", "version": 1, "settings": settings, "rounds": []}


def _plot(state: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(state["rounds"], key=lambda r: r["round"])
    rows = [r for r in rows if r["real_return"] is not None]
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    if rows:
        ax.errorbar(
            [r["round"] for r in rows],
            [r["real_return"] for r in rows],
            yerr=[r["real_return_std"] or 0 for r in rows],
            marker="o",
            capsize=3,
        )
    s = state["settings"]
    ax.set_xlabel("round (record -> fit -> train)")
    ax.set_ylabel("return on the real system")
    ax.set_title(f"{s['task']}: {s['model']} model, real system {s['env_id']}", fontsize=9)
    ax.grid(alpha=0.3)
    write_figure(fig, path)
