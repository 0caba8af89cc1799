"""``loop``: record -> fit -> train, a few rounds, for a system known only by acting.

Each round is made of the library's steps (``record_task``: ``record`` of Gymnasium
episodes by default; ``identify.fit_dir``, ``train`` through the fitted model,
``runs.save_run``) on files in ``out``, so every round's outputs are the ones
``diffcontrol record/fit/train`` write, and an interrupted loop continues where it stopped
(``resume``): a round's data, fitted model, controller and evaluation are each kept once
written, so nothing is recorded twice.

Round 0 is the nominal controller (the task's own physics, no real steps), judged on the real
system as every round's is: round 1 must beat it, and it is handed back if none does. The
bookkeeping is in the open (``loop.json``, one row per round): the real environment steps
used so far (every recorded transition, exploration and the controllers' episodes; the
evaluation episodes are not counted, as for RL in ``diffcontrol compare``), the model's error
on the round's new data *before* it is fitted to it (how wrong the model was where the
controller went; for an ensemble also its members' mean spread there: how unsure it was), and
the controller's return on the real system.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .. import _gym
from .._run_dir import make_dir
from .._run_files import read_run_file, release_claim, save_run
from .._shell import command as shell_command
from ..envs import env_id as own_id
from ..errors import ConfigError, RunDirectoryError
from ..evaluation import evaluate
from ..identify import fit_dir
from ..identify._rounds import NoisyPolicy, model_error, parse_start, predictor_of
from ..identify.data import concat, read_trajectories, write_trajectories
from ..identify.kinds import kind
from ..identify.recording import check_spaces, make_env, record, record_task
from ..io import now_iso, read_json, write_figure, write_json
from ..mpc._config import loop_planner, plans_best
from ..policies import read_model
from ..settings import FitConfig, LoopConfig
from ..tasks import Task
from ..training import resolve_config, train
from ..training._events import open_log
from ._open import load_policy
from ._plan import plan_run
from ._train import RunInterrupted, fitted_training

LOOP_FILE = "loop.json"


def loop(
    task: Any,
    out: str | Path,
    config: LoopConfig | None = None,
    *,
    env_id: str | None = None,
    env_kwargs: dict | None = None,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
    report: Callable[[str], None] = print,
    log_dir: str | Path | None = None,
    command: str | None = None,
) -> dict:
    """Learn a controller for a system you can only run: record ``episodes`` episodes (or
    ``real_steps`` steps) of the real environment ``env_id`` (default the task's own; random
    actions at first), fit a model of ``task``'s system to all data so far, train a controller
    through it, judge it on the real environment, record as many more with it, and repeat for
    ``rounds`` rounds.

    Writes ``out/data.csv`` (all recorded episodes), ``out/round_K/{fit,run}/``,
    ``out/loop.json`` (per round: data, fit, return on the real system) and ``out/loop.png``;
    ``report`` gets each round's line and the last one. Returns the loop's state.

    Args:
        config: the loop's settings (``LoopConfig``; default ``LoopConfig()``). Its
            ``eval_seed`` is the first reset seed of the evaluation episodes on the real system
            (not counted as real steps); ``start`` is the physics a grey box (``params``) or a
            hybrid starts from, by name (e.g. ``{"g": 8.0}``), instead of the task's nominal
            values: a loop that must not be handed the truth states a wrong start (ignored by
            ``neural``); ``explore_noise`` is the noise on the controller's actions while it
            records (``NoisyPolicy``: a fraction of the action's half range; the chance of a
            random action for a discrete space); ``real_steps``, where set, is the real
            steps recorded per round in place of whole ``episodes``: episodes until the
            budget is spent, the last one cut short (``record``'s ``total_steps``);
            ``controller="plan"`` acts with a planner through each round's fitted model
            (``runs.plan_run`` with ``loop_planner``) instead of training an MLP
            through it; by default where the task's planner does best (``plans_best``: the
            Pendulum).

    Raises:
        ConfigError: a task that records no Gymnasium episodes, an environment whose spaces
            are not the task's, an unknown ``start`` parameter.
        RunDirectoryError: ``out`` holds another loop (or, without ``resume``, any loop), or
            other files.
        RunInterrupted: Ctrl-C; the message says what was kept and the command that continues.

    ``log_dir``: write each round's training curves there as TensorBoard event files
    (``round_K``), and per round the real steps so far, the model's error on the new data and
    the return on the real system (``loop/...``, the step is the round). ``command``: the
    command line that started it, for the message of an interruption.
    """
    more = {"env_kwargs": env_kwargs, "resume": resume, "progress": progress, "report": report}
    try:
        return _loop(task, out, config, env_id=env_id, log_dir=log_dir, **more)
    except KeyboardInterrupt:  # every step's files are kept once written: say so
        out = Path(out)
        if out.is_dir() and not out.is_symlink() and not any(out.iterdir()):
            out.rmdir()  # give an empty directory back, as train does
        if not out.is_dir():
            raise RunInterrupted(
                "interrupted before anything was recorded; nothing was kept"
            ) from None
        again = command or shell_command("loop", getattr(task, "name", str(task)), "--out", out)
        raise RunInterrupted(
            f"interrupted; the recorded data, fitted models and controllers written so far are "
            f"kept in {out}. Continue with the same options and --resume: {again}"
            + ("" if resume else " --resume")
        ) from None


def _loop(
    task: Any,
    out: str | Path,
    config: LoopConfig | None = None,
    *,
    env_id: str | None = None,
    env_kwargs: dict | None = None,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
    report: Callable[[str], None] = print,
    log_dir: str | Path | None = None,
) -> dict:
    """``loop``, uninterrupted."""

    if not isinstance(task, Task):
        raise ConfigError(
            f"loop needs a discrete-time control task with a Gymnasium environment, not "
            f"{task.name!r}; e.g. pendulum"
        )
    # Gymnasium episodes (the default recorder) or the task's own data (the trebuchet's throws)
    episodes_of_env = record_task.implementation(task) is record_task.dispatch(Task)
    if episodes_of_env and not _gym.knows_state(task):
        raise ConfigError(
            f"loop cannot fit a model of {task.name!r} (it does not reconstruct its state from "
            "observations: define its state_from_observation); e.g. pendulum"
        )
    c = config or LoopConfig()
    controller = _controller(task, c, Path(out), resume)
    if controller == "plan" and c.updates is not None:
        which = "" if c.controller else f", the default for {task.name}"
        raise ConfigError(
            f"--updates sets the training of --controller train, and this loop plans "
            f"(--controller plan{which}): add --controller train, or drop --updates"
        )
    model, rounds, episodes, updates, seed = c.model, c.rounds, c.episodes, c.updates, c.seed
    steps = c.real_steps
    eval_episodes, eval_seed, explore_noise = c.eval_episodes, c.eval_seed, c.explore_noise
    names = None if c.names is None else list(c.names)
    env_kwargs = dict(env_kwargs or {})
    start = parse_start(task, c.start)
    for flag, value in (("--explore-noise", explore_noise), ("--real-steps", steps)):
        if value and not episodes_of_env:
            raise ConfigError(
                f"{flag} applies to Gymnasium episodes, not to {task.name!r}'s own recording; "
                "drop it"
            )
    if episodes_of_env:
        env_id = env_id or task.gym_id or own_id(task)
        env = make_env(env_id, env_kwargs)  # refuse other spaces before anything is written
        try:
            check_spaces(task, env_id, env)
        finally:
            env.close()
    out = Path(out)
    settings = {
        "task": task.name,
        "env_id": env_id or task.gym_id or own_id(task),
        "env_kwargs": env_kwargs,
        "model": model,
        "params": names,
        "episodes_per_round": None if steps else episodes,
        "updates": updates,
        "seed": seed,
    }
    ensemble = {"members": c.members, "uncertainty_penalty": c.uncertainty_penalty}
    kind(model).check_members(c.members)
    # new settings only where set, so a loop written before them still resumes
    settings.update({k: v for k, v in [("start", start), ("explore_noise", explore_noise),
                                       ("eval_seed", eval_seed), ("steps_per_round", steps),
                                       ("fit_steps", c.fit_steps),
                                       ("controller", controller != "train" and controller)]
                     if v})  # fmt: skip
    if c.members > 1:
        settings.update(ensemble)
    log = open_log(log_dir)  # before the directory is claimed: a missing tensorboardX
    state = _start(out, settings, resume)
    state["start"] = kind(model).start_doc(task, start)
    say = progress or (lambda line: None)
    # the reset seeds the controllers are judged on (save_run's own, 0..., by default): no
    # round records from them, so a model is never fitted to the starts it is judged on
    judged_on = range(eval_seed, eval_seed + eval_episodes)
    policies: dict[Path, Any] = {}  # each round's controller, built once (a planner's grid)

    def policy_of(run_dir: Path) -> Any:
        if run_dir not in policies:
            policies[run_dir] = load_policy(task, read_model(run_dir))  # checked as load does
        return policies[run_dir]

    def record_round(k: int, acting: int | None) -> None:
        """Record the episodes of round k (random for k = 0, else with the controller of round
        ``acting``: the one kept after round k) and append them to data.csv."""
        controller = None if acting is None else out / f"round_{acting}" / "run"
        part = out / f"round_{k}" / "recorded.csv"
        if not part.exists():
            t0 = time.perf_counter()
            if episodes_of_env:
                policy = None if controller is None else policy_of(controller)
                source = "random actions" if policy is None else f"round {acting} controller"
                if policy is not None and explore_noise:
                    policy = NoisyPolicy(
                        policy, _gym.action_space(task), explore_noise, seed + 1000 * k
                    )
                    source += f" with action noise {explore_noise:g}"
                data = record(
                    env_id,
                    None if steps else episodes,
                    policy=policy,
                    seed=seed + 1000 * k,
                    skip_seeds=judged_on,
                    env_kwargs=env_kwargs,
                    source=source,
                    task=task,
                    total_steps=steps,
                )
            else:
                data = record_task(
                    task,
                    episodes,
                    env_id=env_id,
                    env_kwargs=env_kwargs,
                    controller=None if controller is None else str(controller),
                    seed=seed + 1000 * k,
                )
            part.parent.mkdir(parents=True, exist_ok=True)
            write_json(part.parent / "recorded.json", {"seconds": time.perf_counter() - t0})
            write_trajectories(part, data)
        parts = [read_trajectories(out / f"round_{j}" / "recorded.csv") for j in range(k + 1)]
        write_trajectories(out / "data.csv", concat(parts))

    own_eval = eval_episodes if not eval_seed else 0  # seeds 0...: save_run's own

    def act(k: int, fit: Path | None) -> None:
        """Make round k's controller in round_k/run, planned or trained (``controller``)
        through the model fitted in ``fit``, or through the task's own physics where ``fit``
        is None (round 0's, the nominal controller: judged on the real system by
        ``_evaluate``). A finished one is kept; a planner cut short starts again, a training
        continues from its checkpoint."""
        here = out / f"round_{k}"
        _check_own_round(here / "run", k)
        if (here / "run" / "metrics.json").exists():  # save_run writes it last
            return
        (here / "eval.json").unlink(missing_ok=True)  # it judged another controller
        final_eval = own_eval if fit is not None else 0
        if controller == "plan":
            if (here / "run").exists():  # a planner cut short: nothing in it to continue
                shutil.rmtree(here / "run")
            run, _ = plan_run(here / "run", task, loop_planner(task), model=fit,
                              env_id=env_id if fit is not None else None,
                              final_eval=final_eval, animation=False,
                              progress=say, invocation={"loop_round": k})  # fmt: skip
            policies[here / "run"] = run.policy
            return
        if fit is None:
            trained, params, real, info = task, (), None, {"kind": "simulator"}
        else:
            trained, params, real, info = fitted_training(task, fit, None)
            say(info.pop("note"))
        # A parameter that must be >= 0 (the Pendulum's friction) fitted a hair below 0
        # where the real one is 0 (Pendulum-v1: -7e-10): trained at 0, its bound.
        floor = set(getattr(task, "nonnegative_params", ()))
        params = tuple((n, max(v, 0.0) if n in floor else v) for n, v in params)
        overrides = {"seed": seed, "updates": updates, "params": params or None}
        config = resolve_config(trained, None, **{k: v for k, v in overrides.items() if v})
        resumed = (here / "run" / "checkpoint.npz").exists()
        if not resumed:  # claimed, then cut short before its first checkpoint: start again
            release_claim(here / "run")
        logs = {"log_dir": Path(log_dir) / f"round_{k}" if log_dir else None}
        result = train(
            trained, config, out_dir=here / "run", resume=resumed, progress=say,
            invocation={"loop_round": k}, **logs,
        )  # fmt: skip
        result.metrics["model"] = info
        save_run(result, here / "run", final_eval=final_eval, animation=False, real=real,
                 overwrite=True)  # fmt: skip

    record_round(0, None)
    if episodes_of_env:  # round 0: the nominal controller, judged as every round's is
        t0 = time.perf_counter()
        say(f"round 0: {'planning' if controller == 'plan' else 'training'} through "
            f"{task.name}'s own physics (the nominal controller)")  # fmt: skip
        act(0, None)
        judged = _evaluate(task, out / "round_0", eval_episodes, eval_seed, (env_id, env_kwargs),
                           policy_of)  # fmt: skip
        state["nominal"] = {
            "round": 0, "episodes": 0, "transitions": 0, "real_steps": 0,
            "real_return": judged.get("mean_return"),
            "real_return_std": judged.get("std_return"),
            "real_returns": judged.get("returns"),
            "eval_episodes": eval_episodes, "eval_seed": eval_seed,
            "seconds": time.perf_counter() - t0,
        }  # fmt: skip
        if log is not None:
            log.scalars({"loop/real_steps": 0, "loop/real_return": judged.get("mean_return")}, 0)
        report(f"round 0: the nominal controller (no real steps); return on the real system "
               f"{state['nominal']['real_return']:.1f}")  # fmt: skip
    for k in range(1, rounds + 1):
        t0 = time.perf_counter()
        here = out / f"round_{k}"
        data = read_trajectories(out / "data.csv")
        say(f"round {k}/{rounds}: fitting {model} to {data.num_episodes} episodes")
        new = read_trajectories(out / f"round_{k - 1}" / "recorded.csv")
        before = (
            read_json(out / f"round_{k - 1}" / "fit" / "fitted.json", "fitted") if k > 1 else None
        )
        # the one-step-ahead errors of a step model; a task's own data (throws) has its own
        error = (
            model_error(predictor_of(task, before, model, start), new) if episodes_of_env else None
        )
        if not (here / "fit" / "fitted.json").exists():
            fit_config = FitConfig(names=names, holdout=0.0, steps=c.fit_steps, **ensemble)
            fitted = fit_dir(
                task, out / "data.csv", model, here / "fit", fit_config,
                progress=progress, **kind(model).start_settings(task, start),
            )  # fmt: skip
            for line in fitted.lines:
                say(line)
        act(k, here / "fit")
        metrics = read_json(here / "run" / "metrics.json", "metrics")
        fitted_doc = read_json(here / "fit" / "fitted.json", "fitted model")
        judged = metrics.get("gym_eval", {})
        if eval_seed:
            judged = _evaluate(
                task, here, eval_episodes, eval_seed, (env_id, env_kwargs), policy_of
            )
        recorded = out / f"round_{k - 1}" / "recorded.json"
        spent = {
            "record": read_json(recorded, "timing")["seconds"] if recorded.exists() else None,
            "fit": fitted_doc["fit"].get("seconds"),
            "train": metrics.get("train_seconds", metrics.get("planner", {}).get("build_seconds")),
        }
        row = {
            "round": k,
            "episodes": data.num_episodes,
            "transitions": data.num_steps,
            "real_steps": data.num_steps,
            "model_error_on_new_data": error,
            "fit_loss": fitted_doc["fit"]["loss"],
            "fitted_parameters": {
                n: p["value"] for n, p in (fitted_doc.get("parameters") or {}).items()
            },
            "real_return": judged.get("mean_return"),
            "real_return_std": judged.get("std_return"),
            "real_returns": judged.get("returns"),
            "eval_episodes": eval_episodes,
            "eval_seed": eval_seed,
            "seconds": time.perf_counter() - t0,
            "work_seconds": spent,
        }
        earlier = [r for r in state["rounds"] if r["round"] < k]
        row["kept_round"] = kept_round([*filter(None, [state.get("nominal")]), *earlier], row)
        state["rounds"] = earlier + [row] + [r for r in state["rounds"] if r["round"] > k]
        state["best_round"] = row["kept_round"]
        write_json(out / LOOP_FILE, {**state, "updated": now_iso()})
        if log is not None:
            figures = {
                "loop/real_steps": row["real_steps"],
                "loop/real_return": row["real_return"],
                "loop/model_error_1_step": error["rmse_1"] if error else None,
            }
            log.scalars(figures, k)
        ret = row["real_return"]
        fitted_txt = ", ".join(f"{n} = {v:.4g}" for n, v in row["fitted_parameters"].items())
        err = f"; model error on the new data {error['rmse_1']:.3g} (1 step)" if error else ""
        if error and error.get("spread") is not None:
            err += f", the members' spread there {error['spread']:.3g}"
        kept = row["kept_round"]
        rejected = f"; worse than round {kept}'s by more than a standard error: its controller kept"
        report(
            f"round {k}: {row['episodes']} episodes ({row['real_steps']} real steps)"
            + (f", {fitted_txt}" if fitted_txt else f", fit loss {row['fit_loss']:.3g}")
            + err
            + (f"; return on the real system {ret:.1f}" if ret is not None else "")
            + (rejected if kept != k else "")
        )
        if k < rounds:
            record_round(k, kept)
    _plot(state, out / "loop.png")
    if log is not None:
        log.close()
    best = state.get("best_round", rounds)
    report(
        f"wrote {out / LOOP_FILE}, {out / 'loop.png'} and {out / 'data.csv'}; the controller: "
        f"{out / f'round_{best}' / 'run' / 'model.json'}"
        + (f" (round {best}'s, the best on the real system)" if 0 < best < rounds else "")
        + (
            " (round 0's: the nominal controller, no round did better on the real system)"
            if best == 0
            else ""
        )
    )
    return state


def kept_round(earlier: list[dict], row: dict) -> int:
    """The round whose controller the loop keeps after ``row``'s round: that round, unless its
    controller does worse on the same evaluation episodes than the one kept before it, by more
    than the standard error of their paired differences (one per episode); then that one.

    ``earlier``: the rows of the rounds before (a row written before this rule keeps its own
    round). A round without per-episode returns is kept."""
    if not earlier:
        return row["round"]
    last = max(earlier, key=lambda r: r["round"])
    before = last.get("kept_round", last["round"])
    old = next((r for r in earlier if r["round"] == before), last).get("real_returns")
    new = row.get("real_returns")
    if not old or not new or len(old) != len(new):
        return row["round"]
    diffs = np.asarray(new, float) - np.asarray(old, float)
    se = float(np.std(diffs, ddof=1) / np.sqrt(len(diffs))) if len(diffs) > 1 else 0.0
    return before if float(np.mean(diffs)) < -se else row["round"]


def _evaluate(
    task: Any, here: Path, episodes: int, seed: int, real: tuple, policy_of: Callable
) -> dict:
    """The round's controller (``policy_of(here / "run")``) on the real system, reset seeds
    ``seed ...`` (kept in ``here/eval.json`` so that a resumed loop does not run it twice)."""

    path = here / "eval.json"
    if path.exists():
        return read_json(path, "evaluation")
    t0 = time.perf_counter()
    ev = evaluate(policy_of(here / "run"), task, episodes, seed, real=real)
    doc = {**ev.to_json(), "seconds": time.perf_counter() - t0}
    write_json(path, doc)
    return doc


def _controller(task: Any, c: LoopConfig, out: Path, resume: bool) -> str:
    """What acts: ``c.controller`` where set; else, resuming a loop, the loop's own (one that
    does not say trained: the default before ``plans_best``); else the planner where it does
    best (``plans_best``: the Pendulum) and a trained MLP elsewhere."""
    if c.controller:
        return c.controller
    path = out / LOOP_FILE
    if resume and path.is_file():
        doc = read_json(path, "loop file")  # _start refuses one that is not a loop's
        settings = doc.get("settings") if isinstance(doc, dict) else None
        return (settings.get("controller") if isinstance(settings, dict) else None) or "train"
    return "plan" if plans_best(task) else "train"


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
    make_dir(out)
    return {"format": "diffcontrol-loop", "version": 1, "settings": settings, "rounds": []}


def _check_own_round(run_dir: Path, k: int) -> None:
    """Refuse a round's run directory that holds a run this loop did not start (one that a
    command trained or planned there: its run.json records that command's invocation; the
    loop's own record their round, or, written by older loops, nothing).

    Raises:
        RunDirectoryError: one line naming the directory and the way out.
    """
    doc = read_run_file(run_dir)
    invocation = None if doc is None else doc.get("invocation")
    if invocation is None or (isinstance(invocation, dict) and invocation.get("loop_round") == k):
        return
    raise RunDirectoryError(
        f"{run_dir} holds a run this loop did not train (its run.json: {invocation!r}); move it "
        f"away to train round {k} here, or continue the loop in another --out"
    )


def _plot(state: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(state["rounds"], key=lambda r: r["round"])
    rows = [r for r in [state.get("nominal"), *rows] if r and r["real_return"] is not None]
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    if rows:
        ax.errorbar(
            [r.get("real_steps", r["transitions"]) for r in rows],
            [r["real_return"] for r in rows],
            yerr=[r["real_return_std"] or 0 for r in rows],
            marker="o",
            capsize=3,
        )
    s = state["settings"]
    for r in rows:
        label = f"round {r['round']}" + (" (nominal)" if r["round"] == 0 else "")
        ax.annotate(label, (r.get("real_steps", r["transitions"]), r["real_return"]),
                    textcoords="offset points", xytext=(4, -10), fontsize=7)  # fmt: skip
    ax.set_xlabel("real environment steps used (evaluation episodes not counted)")
    ax.set_ylabel("return on the real system")
    ax.set_title(f"{s['task']}: {s['model']} model, real system {s['env_id']}", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    write_figure(fig, path)
