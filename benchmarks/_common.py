"""What the benchmark scripts share: the machine's description and a pinned `diffcontrol train`."""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path


def machine() -> dict:
    """The library's description of the machine (CPU, versions), the cores used, the date and
    the XLA_FLAGS the run was given."""
    from diffcontrol.compare import machine as describe

    return {
        **describe(),
        "cores_used": 1 if shutil.which("taskset") else os.cpu_count(),
        "date": dt.date.today().isoformat(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),  # XLA's compiler settings, if any
    }


def train_cli(task: str, seed: int, out: Path, extra: list[str]) -> tuple[dict, float]:
    """Run `diffcontrol train TASK --out OUT --seed SEED ...` in a fresh process on core 0.

    The persistent compilation cache is off, so the run compiles everything from scratch.
    Returns the run's ``metrics.json`` and the whole process's wall-clock seconds (Python and
    JAX start-up, compilation, training, evaluation and the files included).
    """
    cmd = [sys.executable, "-m", "diffcontrol.cli", "train", task, "--out", str(out)]
    cmd += ["--seed", str(seed), "--quiet", *extra]
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", "0", *cmd]
    env = dict(os.environ, DIFFCONTROL_NO_COMPILE_CACHE="1")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
    seconds = time.perf_counter() - t0
    return json.loads((out / "metrics.json").read_text()), seconds


def gym_seeds_benchmark(
    task: str,
    description: str,
    default_out: Path,
    target_return: float,
    target_seconds: float,
    reference: str = "",
    note: str = "",
) -> None:
    """The benchmark of a task evaluated in Gymnasium: `diffcontrol train TASK --seed S` with
    the defaults for training seeds 0..N-1 (``train_cli``), each controller evaluated on
    Gymnasium's reset seeds 0-99; prints a table and a summary against the target (a mean
    return of at least ``target_return`` in under ``target_seconds`` of training) and writes
    the JSON (``--out``, default ``default_out``)."""
    import argparse
    import statistics
    import tempfile

    parser = argparse.ArgumentParser(
        description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=5, help="training seeds 0..N-1 (default 5)")
    parser.add_argument("--out", type=Path, default=default_out)
    args = parser.parse_args()

    header = (
        f"{'seed':>4} {'train s':>8} {'compile s':>9} {'process s':>9} {'update':>6} "
        f"{'Gymnasium return (seeds 0-99)':>30} {'min':>6} {'steps':>6}"
    )
    print(header)
    print("-" * len(header))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            extra = ["--no-animation", "--final-eval", "100"]
            metrics, process_seconds = train_cli(task, seed, Path(tmp) / f"{task}-{seed}", extra)
            ev, chosen = metrics["gym_eval"], metrics["returned_update"]
            r = {
                "seed": seed,
                "train_seconds": metrics["train_seconds"],
                "compile_seconds": metrics["compile_seconds"],
                "process_seconds": process_seconds,
                "simulated_episodes": metrics["simulated_episodes"],
                "simulated_steps": metrics["simulated_steps"],
                "returned_update": chosen,
                "returned_member": next(
                    (c.get("best_member") for c in metrics["curve"] if c["update"] == chosen),
                    None,
                ),
                "gym_env": ev["env_id"],
                "eval_episodes": ev["episodes"],
                "eval_mean": ev["mean_return"],
                "eval_std": ev["std_return"],
                "eval_min": ev["min_return"],
                "eval_mean_length": ev["mean_length"],
                "eval_returns": ev["returns"],
            }
            rows.append(r)
            print(
                f"{seed:>4} {r['train_seconds']:>8.1f} {r['compile_seconds']:>9.1f} "
                f"{r['process_seconds']:>9.1f} {r['returned_update']:>6} "
                f"{r['eval_mean']:>21.2f} ± {r['eval_std']:<6.2f} {r['eval_min']:>6.1f} "
                f"{r['eval_mean_length']:>6.1f}",
                flush=True,
            )
    means = [r["eval_mean"] for r in rows]
    seconds = [r["train_seconds"] for r in rows]
    meeting = sum(m >= target_return and s < target_seconds for m, s in zip(means, seconds))
    summary = {
        "task": task,
        "seeds": len(rows),
        "median_eval_mean": statistics.median(means),
        "worst_eval_mean": min(means),
        "best_eval_mean": max(means),
        "median_train_seconds": statistics.median(seconds),
        "max_train_seconds": max(seconds),
        "target_return": target_return,
        "target_seconds": target_seconds,
        "reference": reference,
        "seeds_meeting_target": meeting,
    }
    print(
        f"\nworst {min(means):.2f}, median {summary['median_eval_mean']:.2f}; train s median "
        f"{summary['median_train_seconds']:.1f}, max {max(seconds):.1f}; {meeting}/{len(rows)} "
        f"seeds meet >= {target_return:g} in < {target_seconds:g} s"
        + (f" ({reference})" if reference else "")
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    doc = {"machine": machine(), "note": note, "runs": rows, "summary": summary}
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


def grid_optima(
    task, points: int, levels: int, seed_sets: dict[str, list[int]], params=None, real=None
):
    """Solve ``task``'s grid dynamic program (with ``params``, default the nominal physics) and
    run its greedy controller on each seed set (in ``real``, ``(env_id, env_kwargs)``, where
    given, else the task's own environment): ``(table, {key: OptimumResult}, solve seconds)``,
    with a line of progress."""
    from diffcontrol import optimal

    print(f"solving the grid dynamic program ({points}^2 states, {levels} torques)...")
    t0 = time.perf_counter()
    table = optimal.solve(task, points, levels, params=params)
    table.values.block_until_ready()
    seconds = time.perf_counter() - t0
    optima = {
        k: optimal.optimal_return(task, s, table=table, real=real) for k, s in seed_sets.items()
    }
    return table, optima, seconds


def real_benchmark(task: str, rl_method: str, targets: dict[str, int | None], doc: str) -> None:
    """``diffcontrol compare TASK --real`` with the RL rows of ``results/compare.json``: print
    the table and, per method, the real steps to the task's highest threshold on every seed
    against ``targets`` (issue 14's; ``None``: none stated) and ``rl_method``'s steps; write
    ``results/real_TASK.json`` and ``results/real_TASK.png``. ``doc``: the script's docstring
    (its first line is the command line's description)."""
    import argparse
    import statistics

    from diffcontrol.compare import run_real_comparison

    here = Path(__file__).resolve().parent
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--models", default="params,hybrid,neural")
    parser.add_argument("--max-rounds", type=int, default=3)
    parser.add_argument("--out", default=f"runs/benchmark-real-{task}")
    parser.add_argument("--resume", action="store_true")
    parser.add_argument(
        "--controllers", default="train", help="train, plan or train,plan (compare --real's)"
    )
    parser.add_argument("--members", type=int, default=1, help="ensemble networks (hybrid/neural)")
    parser.add_argument(
        "--fit-steps", type=int, default=None, help="Adam steps of each round's fit (the model's)"
    )
    parser.add_argument(
        "--name", default="", help="suffix of the result files (real_TASK{NAME}.json), e.g. _plan"
    )
    parser.add_argument(
        "--compile-cache",
        metavar="DIR",
        default=None,
        help="JAX's persistent compilation cache in DIR, as `diffcontrol compare --real` has "
        "it (default: off, every program compiled; an empty DIR: cold for seed 0 only)",
    )
    args = parser.parse_args()
    cache = None
    if args.compile_cache:
        from diffcontrol import _jax_setup  # imports no JAX or Equinox yet

        _jax_setup.checks_as_nan()  # as the command line does, before Equinox is imported
        cache = _jax_setup.enable_compile_cache(args.compile_cache)
        if cache is None:
            parser.error(f"--compile-cache {args.compile_cache}: cannot create the directory")
    rl_file = here / "results" / "compare.json"
    t0 = time.perf_counter()
    cmp = run_real_comparison(
        task,
        args.out,
        seeds=args.seeds,
        max_rounds=args.max_rounds,
        models=args.models.split(","),
        rl_results=rl_file,
        controllers=tuple(args.controllers.split(",")),
        members=args.members,
        fit_steps=args.fit_steps,
        resume=args.resume,
        progress=lambda line: print(line, flush=True),
    )
    wall = time.perf_counter() - t0
    goal = cmp["threshold"]
    # the RL rows as the comparison summarised them: the same thresholds as diffcontrol's
    rl = next(r for r in cmp["summary"] if r["method"] == rl_method)
    rl_goal = next(t for t in rl["thresholds"] if t["threshold"] == goal)
    print(cmp["table"])
    print(
        f"\nreal steps to {goal:g} (target; {rl_method.upper()}: median "
        f"{rl_goal['env_steps']['median'] or float('nan'):,.0f} steps, "
        f"{rl_goal['train_seconds']['median'] or float('nan'):.0f} s, "
        f"{rl_goal['reached']}/{rl_goal['of']} seeds)"
    )
    rows = []
    for method, target in targets.items():
        runs = [r for r in cmp["runs"] if r["method"] == method]
        if not runs:
            continue
        steps = {int(s): v for s, v in cmp["real_steps_to_threshold"].get(method, {}).items()}
        all100 = cmp["real_steps_to_threshold_over_all_episodes"].get(method, {})
        steps100 = {int(s): v for s, v in all100.items()}
        finals = {r["seed"]: r["final"]["mean_return"] for r in runs}
        points = {r["seed"]: [round(p["mean_return"], 1) for p in r["curve"]] for r in runs}
        secs = {}
        for r in runs:
            hit = next((p for p in r["curve"] if p["mean_return"] >= goal), None)
            secs[r["seed"]] = hit["train_seconds"] if hit else None
        reached = [v for v in steps.values() if v is not None]
        rows.append(
            {
                "method": method,
                "target_steps": target,
                f"steps_to_{goal:g}_on_20_episodes": steps,
                f"steps_to_{goal:g}_on_100_episodes": steps100,
                f"seconds_to_{goal:g}_on_20_episodes": secs,
                "returns_20_episodes_by_round": points,
                "last_return_100_episodes": finals,
                "met_target_on_every_seed_20": target is not None
                and len(reached) == len(runs)
                and all(v <= target for v in reached),
                "median_steps_20": statistics.median(reached) if reached else None,
            }
        )
        for name, table in (("20 ep", steps), ("100 ep", steps100)):
            cells = ", ".join(
                f"seed {s}: {table[s] if table[s] is not None else 'missed'}" for s in sorted(table)
            )
            print(f"{method:24} ({name}) target <= {target or '-':>5}: {cells}")
        print(f"{'':24} returns by round (20 ep): {points}; last (100 ep): {finals}")
        shown = ", ".join(f"seed {s}: {'-' if v is None else f'{v:.1f}'}" for s, v in secs.items())
        print(f"{'':24} seconds to {goal:g} (20 ep): {shown}")
    if cache is not None:
        print(f"persistent compilation cache {cache}: {_jax_setup.cache_events()}")
    out = here / "results" / f"real_{task}{args.name}.json"
    png = here / "results" / f"real_{task}{args.name}.png"
    (here / "results").mkdir(exist_ok=True)
    shutil.copyfile(Path(args.out) / "comparison.png", png)
    result = {
        "command": f"python benchmarks/real_{task}.py " + " ".join(sys.argv[1:]),
        "machine": machine(),
        "benchmark_wall_seconds": wall,
        "compile_cache": None
        if cache is None
        else {"dir": str(cache), **_jax_setup.cache_events()},
        f"{rl_method}_to_{goal:g}": rl_goal,
        "rows": rows,
        "comparison": {k: v for k, v in cmp.items() if k not in ("files",)},
    }
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out} and {png}")


def planner_episodes(policy, seeds, task=None, real=None):
    """Gymnasium episodes of a planner's ``PlannerPolicy`` (reset before each) in ``task``'s
    environment (default Pendulum-v1) or ``real`` (``(env_id, env_kwargs)``): the returns and
    the wall-clock seconds of every call."""
    import numpy as np

    from diffcontrol import make
    from diffcontrol.evaluation import eval_environment

    env, _ = eval_environment(task or make("pendulum"), real)
    returns, seconds = [], []
    try:
        for seed in seeds:
            obs, _ = env.reset(seed=seed)
            policy.reset()
            total, done = 0.0, False
            while not done:
                t0 = time.perf_counter()
                action = policy(obs)
                seconds.append(time.perf_counter() - t0)
                obs, reward, terminated, truncated, _ = env.step(action)
                total += float(reward)
                done = terminated or truncated
            returns.append(total)
    finally:
        env.close()
    return np.asarray(returns), np.asarray(seconds)


def discrete_choice_steps(task, params):
    """``choice(ctrl, state)``, the index a controller's ``argmax`` head picks in a state, and
    ``step(state, index)``, the task's step under that action: what the acrobot probes roll
    out with."""
    import jax
    import jax.numpy as jnp

    def choice(ctrl, state):
        return jnp.argmax(ctrl.logits(task.observe(state)))

    def step(state, index):
        return task.step(params, state, jax.nn.one_hot(index, task.action_size))

    return choice, step
