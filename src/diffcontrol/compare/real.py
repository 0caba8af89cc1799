"""``diffcontrol compare TASK --real``: diffcontrol counted in the real system's steps.

``diffcontrol compare`` counts the simulated episodes diffcontrol trains on, which is right
when the simulator is the system. Here diffcontrol may not use the task's simulator as the
system: it learns a model by acting on the real Gymnasium environment (``runs.loop``:
explore, fit, train through the fit, act) and every real environment step it takes is
counted: the random exploration and every episode its controllers record (with exploration
noise); the evaluation episodes are not, as for RL. A round records a budget of real steps
(the task's ``real_steps_per_round``: episodes until it is spent, the last cut short; one
Pendulum episode, 250 CartPole steps), so that tasks whose episodes end early (a random
CartPole episode lasts ~20 steps) and tasks whose episodes do not are asked for the same kind
of thing. Each round's controller is evaluated on the real environment over
``final_episodes`` episodes with reset seeds ``eval_seed ...`` (those of ``diffcontrol
compare``), and the loop stops at the first round whose controller reaches the task's highest
threshold (Pendulum -150, CartPole 500), or after ``max_rounds``.

Methods: ``params`` (the grey box, whose physics starts from the stated wrong ``start``: the
task's ``real_start``), ``hybrid`` (the same wrong physics plus a network) and ``neural`` (a
network alone), each with an MLP trained through the fitted model acting on the real system
(``controllers`` ``train``, the default) or a planner through it (``plan``: the task's
``loop_planner``, rows ``diffcontrol (grey box, planner)`` and so on). The RL rows are those
already recorded by ``diffcontrol compare`` (e.g. ``benchmarks/results/compare.json``, same
evaluation seeds), read, not re-run.

Writes to ``out``: ``loops/<model>-seed<S>/`` (each loop's directory; resumable),
``runs/<method>-seed<S>.json`` (each finished run, as ``compare`` writes them; ``<model>-plan``
for a planner's),
``comparison.json``, ``comparison.md`` and ``comparison.png`` (return against real steps and
against wall-clock seconds, the RL curves beside).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .. import _gym, _run_dir, io
from ..errors import ConfigError, RunDirectoryError
from ..identify.kinds import KINDS, ModelKind
from ..runs import loop
from ..settings import CONTROLLERS, LoopConfig
from ..tasks import Task, make, names, resolve
from ..tasks._hooks import task_hook
from .baselines import rl_setup
from .report import machine, plot, summarize, table
from .run import first_reached


@task_hook
def real_steps_per_round(task: Task, model: ModelKind) -> int:
    """The real environment steps a round of ``compare --real`` records to learn a model of
    the kind ``model`` (``identify.kinds``; episodes until the budget is spent, the last cut
    short). Default: one standard episode (``episode_length``), and at least the transitions
    the kind is fitted to (``min_transitions``: 1,000 for a network alone), i.e.
    200/200/1,000 on the Pendulum. A task whose episodes end early or run long chooses its
    own."""
    return max(task.episode_length, model.min_transitions)


def real_start(task: Task) -> dict[str, float]:
    """The wrong physics ``compare --real`` starts a grey box and a hybrid from: the task's
    ``real_start`` declaration of ``(name, value)`` pairs, so that they are not handed the
    truth (none: the nominal parameters, the truth when the real system is the task's own)."""
    return dict(getattr(task, "real_start", ()))


def run_real_comparison(
    task: Task | str,
    out_dir: str | Path,
    *,
    seeds: int = 5,
    models: list[str] | None = None,
    max_rounds: int = 3,
    steps: dict[str, int] | None = None,
    start: dict[str, float] | None = None,
    members: int = 1,
    controllers: tuple[str, ...] = ("train",),
    explore_noise: float = 0.1,
    updates: int | None = None,
    fit_steps: int | None = None,
    final_episodes: int = 100,
    eval_seed: int = 1000,
    rl_results: str | Path | None = None,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the loop of every model on every seed on the real environment; returns what
    ``comparison.json`` holds (with ``"table"`` and ``"files"``).

    Args:
        task: a discrete-time task with a threshold whose state can be reconstructed from
            observations (``pendulum``, ``cartpole``).
        out_dir: a new or empty directory, or a previous one with ``resume``.
        seeds: loop seeds ``0 ... seeds-1`` (recording, the networks, training).
        models: a subset of ``params``, ``hybrid``, ``neural`` (default all).
        max_rounds: the most rounds of a loop; it stops at the first controller that reaches
            the task's threshold.
        steps: real steps recorded per round by model (default the task's
            ``real_steps_per_round``: Pendulum 200/200/1,000, CartPole 250/250/1,000).
        start: the wrong physics the grey box and hybrid start from (default the task's
            ``real_start``: Pendulum g = 8, friction 0.1; CartPole gravity 12, length 0.8,
            force_mag 7).
        members: networks of the hybrid's and the neural model's ensembles (``runs.loop``;
            1, one network; the grey box has none).
        controllers: what acts on the real system each round, each a row of its own:
            ``train`` (an MLP trained through the fitted model) and/or ``plan`` (a planner
            through it, ``loop_planner``).
        explore_noise: action noise while a controller records (``runs.loop``).
        updates: gradient updates of each round's training (default the task's, which stops
            early at its target return).
        fit_steps: Adam steps of each round's fit (default the model's: ``LoopConfig``).
        final_episodes: evaluation episodes of each round's controller (not counted).
        eval_seed: their first reset seed (``diffcontrol compare``'s: 1000).
        rl_results: a ``diffcontrol compare`` result (its ``comparison.json``, or the
            benchmark's ``compare.json`` holding several tasks) whose RL runs are shown beside.
        resume: keep what ``out_dir`` already holds.

    Raises:
        ConfigError: a task without a threshold, an unknown model, an RL file of another
            evaluation protocol; RunDirectoryError: ``out_dir`` holds other things.
    """
    task = resolve(task) if isinstance(task, str) else task
    if not _can_learn(task):
        can = sorted(n for n in names() if _can_learn(make(n)))
        raise ConfigError(
            f"compare --real needs a task with a threshold whose model can be fitted to "
            f"recorded episodes, not {task.name!r}; choose {' or '.join(can)}"
        )
    thresholds = rl_setup(task).thresholds
    models = list(models or KINDS)
    bad = [m for m in models if m not in KINDS]
    if bad:
        raise ConfigError(f"unknown model(s) {bad} for --real; choose among {list(KINDS)}")
    controllers = list(dict.fromkeys(controllers))
    if not controllers or any(c not in CONTROLLERS for c in controllers):
        raise ConfigError(
            f"--controllers {','.join(controllers)}: choose among {','.join(CONTROLLERS)}"
        )
    steps = {m: real_steps_per_round(task, KINDS[m]) for m in models} | (steps or {})
    start = real_start(task) if start is None else dict(start)
    target = max(thresholds)  # returns: the highest is the hardest
    rl = _rl_runs(rl_results, task.name, eval_seed) if rl_results else []
    out = Path(out_dir)
    settings = {
        "format": "diffcontrol-compare-real",
        "task": task.name,
        "env_id": task.gym_id,
        "models": models,
        "seeds": list(range(seeds)),
        "max_rounds": max_rounds,
        "steps_per_round": {m: steps[m] for m in models},
        "start": start,
        "explore_noise": explore_noise,
        "updates": updates,
        # new settings only where not the default, so a comparison before them still resumes
        **({"members": members} if members > 1 else {}),
        **({"fit_steps": fit_steps} if fit_steps is not None else {}),
        **({"controllers": controllers} if controllers != ["train"] else {}),
        "final_episodes": final_episodes,
        "eval_seed": eval_seed,
        "threshold": target,
        "rl_results": str(rl_results) if rl_results else None,
    }
    _prepare(out, settings, resume)
    say = progress or (lambda line: None)
    results = []
    said: set[str] = set()  # a resumed loop reports its earlier rounds again: said once

    def tell(line: str) -> None:
        if line not in said:
            said.add(line)
            say(line)

    methods = [(m, c) for m in models for c in controllers]
    for seed in range(seeds):  # every model on seed 0 first: a cut-short run covers them all
        for model, controller in methods:
            name = model if controller == "train" else f"{model}-{controller}"
            path = out / "runs" / f"{name}-seed{seed}.json"
            if path.exists():
                results.append(io.read_json(path, "run"))
                continue
            where = out / "loops" / f"{name}-seed{seed}"
            label = _label(model, controller)
            t0 = time.perf_counter()
            for rounds in range(1, max_rounds + 1):
                config = LoopConfig(
                    model=model,
                    rounds=rounds,
                    real_steps=steps[model],
                    seed=seed,
                    eval_episodes=final_episodes,
                    eval_seed=eval_seed,
                    start=start if KINDS[model].physics else {},
                    explore_noise=explore_noise,
                    updates=None if controller == "plan" else updates,  # a planner: none
                    fit_steps=fit_steps,
                    members=members if KINDS[model].network else 1,
                    controller=controller,
                )
                state = loop(
                    task,
                    where,
                    config,
                    resume=True,
                    progress=None,
                    report=lambda line, m=label, s=seed: tell(f"{m} seed {s}: {line}"),
                )
                last = max(state["rounds"], key=lambda r: r["round"])
                if last["real_return"] is not None and last["real_return"] >= target:
                    break
            run = _as_run(label, seed, state, time.perf_counter() - t0, task.episode_length)
            path.parent.mkdir(parents=True, exist_ok=True)
            io.write_json(path, run)
            results.append(run)
    return _report(task, out, settings, results, rl, thresholds)


def _can_learn(task: Task) -> bool:
    """Whether ``compare --real`` can run on ``task``: a discrete-time task with a threshold
    whose state can be reconstructed from observations (a model can be fitted to them)."""
    return (
        isinstance(task, Task)
        and bool(getattr(rl_setup(task), "thresholds", ()))
        and _gym.knows_state(task)
    )


def _label(model: str, controller: str) -> str:
    """A row's name without ``diffcontrol``: ``grey box``, ``grey box, planner``, ..."""
    return KINDS[model].label + (", planner" if controller == "plan" else "")


def _as_run(
    label: str, seed: int, state: dict, wall: float, episode_length: int, point_episodes: int = 20
) -> dict:
    """A loop as a run of ``diffcontrol compare`` (``runs/<method>-seed<S>.json``): one curve
    point per round at the real steps used so far and the loop's seconds so far (recording,
    fitting and training; the evaluations left out, as in ``compare``). As there, ``episodes``
    is the real steps in standard episodes (``episode_length`` steps) and
    ``episodes_finished`` the episodes recorded (a CartPole round of 250 steps: 0.5 and ~10).
    A point's return is the mean over the first ``point_episodes`` evaluation episodes
    (``compare``'s evaluation points: 20, reset seeds 1000-1019); ``final`` and
    ``return_all`` are over all of them."""
    curve, seconds = [], 0.0
    for r in sorted(state["rounds"], key=lambda r: r["round"]):
        seconds += sum(v for v in (r.get("work_seconds") or {}).values() if v)
        returns = np.asarray(r.get("real_returns") or [r["real_return"]], float)
        curve.append(
            {
                "env_steps": r["real_steps"],
                "episodes": r["real_steps"] / episode_length,
                "episodes_finished": r["episodes"],
                "train_seconds": seconds,
                "mean_return": float(np.mean(returns[:point_episodes])),
                "std_return": float(np.std(returns[:point_episodes])),
                "return_all": r["real_return"],
                "std_all": r["real_return_std"],
                "round": r["round"],
                "model_error_on_new_data": r.get("model_error_on_new_data"),
            }
        )
    last = curve[-1]
    return {
        "method": f"diffcontrol ({label})",
        "algo": "real-system loop",
        "source": "runs.loop on the real environment",
        "seed": seed,
        "config": {**state["settings"], "start": state.get("start")},
        "env_steps": last["env_steps"],
        "episodes": last["episodes"],
        "train_seconds": last["train_seconds"],
        "wall_seconds_with_evaluation": wall,
        "curve": curve,
        "final": {
            "episodes": state["rounds"][-1]["eval_episodes"],
            "mean_return": last["return_all"],
            "std_return": last["std_all"],
        },
    }


def _rl_runs(path: str | Path, task_name: str, eval_seed: int) -> list[dict]:
    """The RL runs of a recorded ``diffcontrol compare`` (its diffcontrol rows left out: they
    count simulated steps)."""
    doc = io.read_json(Path(path), "comparison")
    doc = doc.get("tasks", {}).get(task_name, doc)
    if doc.get("task") != task_name or "runs" not in doc:
        raise ConfigError(f"{path} holds no comparison of {task_name!r}; pass --rl-results FILE")
    if doc.get("eval_seed") != eval_seed:
        raise ConfigError(
            f"{path} evaluated from reset seed {doc.get('eval_seed')}, not {eval_seed}; pass "
            f"--eval-seed {doc.get('eval_seed')}"
        )
    return [r for r in doc["runs"] if r["method"] != "diffcontrol"]


def _prepare(out: Path, settings: dict, resume: bool) -> None:
    path = out / "compare-real.json"
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out} is a file; give a directory")
    if path.exists():
        old = io.read_json(path, "comparison settings")
        if not resume:
            raise RunDirectoryError(f"{out} holds a comparison; pass --resume or another --out")
        same = ("created", "seeds")  # more (or fewer) seeds: the finished runs still hold
        if {k: v for k, v in old.items() if k not in same} != {
            k: v for k, v in settings.items() if k not in same
        }:
            raise RunDirectoryError(
                f"{out} holds a comparison with other settings; resume it with those, or choose "
                "another --out"
            )
        io.write_json(path, {**old, "seeds": settings["seeds"]})
        return
    if out.exists() and any(out.iterdir()):
        raise RunDirectoryError(f"--out {out} is not empty; choose a new or empty directory")
    _run_dir.make_dir(out)
    io.write_json(path, {**settings, "created": io.now_iso()})


def _report(task, out, settings, results, rl, thresholds) -> dict:
    summary = summarize(results + rl, thresholds)
    text = table(f"{task.name} (diffcontrol: real steps of the loop; RL: its own steps)", summary)
    per_seed, per_seed_all = {}, {}
    for r in results:
        hit = first_reached(r["curve"], settings["threshold"])
        per_seed.setdefault(r["method"], {})[r["seed"]] = hit["env_steps"] if hit else None
        hit = next((p for p in r["curve"] if p["return_all"] >= settings["threshold"]), None)
        per_seed_all.setdefault(r["method"], {})[r["seed"]] = hit["env_steps"] if hit else None
    doc = {
        **settings,
        "created": io.now_iso(),
        "machine": machine(),
        "real_steps_to_threshold": per_seed,
        "real_steps_to_threshold_over_all_episodes": per_seed_all,
        "summary": summary,
        "runs": results,
        "table": text,
    }
    io.write_json(out / "comparison.json", doc)
    (out / "comparison.md").write_text(text + "\n")
    title = f"{task.name}: diffcontrol's loop counted in real steps, against RL baselines"
    low = min(thresholds) - 0.5 * (max(thresholds) - min(thresholds) or abs(min(thresholds)))
    top = max(p["mean_return"] for r in results + rl for p in r["curve"])
    top += 0.1 * (top - low)  # room above the best point
    plot(task.name, results + rl, thresholds, out / "comparison.png", title=title, ylim=(low, top))
    doc["files"] = [str(out / f) for f in ("comparison.json", "comparison.md", "comparison.png")]
    return doc
