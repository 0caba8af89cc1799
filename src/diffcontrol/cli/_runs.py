"""Commands on saved runs: ``list``, ``evaluate``, ``animate`` and ``aim``."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from ..errors import DiffcontrolError
from ._args import finite_float, param, positive_int


def add_parsers(sub: Any) -> None:
    sub.add_parser("list", help="list the tasks, one line each", description="List the tasks.")
    p = sub.add_parser(
        "evaluate",
        help="run a trained controller in Gymnasium's own environment",
        description=(
            "Run the controller saved in DIR in Gymnasium's own environment (Pendulum-v1, "
            "CartPole-v1) on seeds S ... S+N-1 and print the mean and std of the return. For "
            "an aiming task (trebuchet), aim at N random targets (20-100 m, wind ~ N(0, 5^2) "
            "m/s, drawn with seed S) and print the miss statistics over the reachable ones. "
            "For a continuous-time task (cartpole-swingup*), re-solve the closed loop with a "
            "float64 reference solver (dopri8 at 1e-9) and print the end state, the peak "
            "force and the swings. --env (with --env-arg) runs a discrete-time controller in "
            "another environment instead, e.g. the real system a fitted model came from "
            "(a run trained with --model is evaluated there by default)."
        ),
    )
    p.add_argument("run_dir", metavar="DIR", help="a directory written by `diffcontrol train`")
    p.add_argument(
        "--env",
        metavar="ENV_ID",
        default=None,
        help="evaluate in this Gymnasium environment instead (e.g. diffcontrol/PendulumFriction-v0)",
    )
    p.add_argument(
        "--env-arg",
        type=param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a numeric argument of --env (repeatable), e.g. g=12",
    )
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=None,
        metavar="N",
        help="episodes (default 100), or random targets for aiming tasks (default 1000)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="S",
        help="first reset seed, or the seed of the random targets (default 0)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")

    p = sub.add_parser(
        "animate",
        help="re-render the animation of a saved controller",
        description=(
            "Record one Gymnasium episode of the controller in DIR (or re-solve a swing-up, "
            "or simulate a trebuchet throw) and write it as a GIF."
        ),
    )
    p.add_argument("run_dir", metavar="DIR", help="a directory written by `diffcontrol train`")
    p.add_argument(
        "--seed", type=int, default=0, metavar="S", help="reset seed of the episode (default 0)"
    )
    p.add_argument("--out", metavar="FILE", default=None, help="GIF path (default DIR/rollout.gif)")
    p.add_argument(
        "--target", type=finite_float, default=80.0, metavar="M", help="aiming tasks: target (m)"
    )
    p.add_argument(
        "--wind", type=finite_float, default=-3.0, metavar="MPS", help="aiming tasks: wind (m/s)"
    )

    p = sub.add_parser(
        "aim",
        help="aim a trained trebuchet controller at one target",
        description=(
            "Ask the aiming controller in DIR for the release angle and counterweight that hit "
            "a target at M metres in a wind of W m/s (+ blows toward the target), simulate "
            "the throw, and print the distance and the miss. --direct also aims by gradient "
            "steps on the simulator alone, for comparison."
        ),
    )
    p.add_argument(
        "run_dir", metavar="DIR", help="a directory written by `diffcontrol train trebuchet`"
    )
    p.add_argument("--target", type=finite_float, required=True, metavar="M", help="target (m)")
    p.add_argument("--wind", type=finite_float, default=0.0, metavar="W", help="wind (m/s)")
    p.add_argument(
        "--direct", action="store_true", help="also aim by gradient descent on the simulator"
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def cmd_list(args: argparse.Namespace) -> int:
    from .. import tasks

    for name in tasks.names():
        task = tasks.make(name)
        losses = "/".join(task.losses)
        recipes = ", ".join(task.recipes()) or "-"
        print(f"{name:<26} {task.summary}  [losses: {losses}; recipes: {recipes}]")
    return 0


def example_throw(policy: Any, target: float, wind: float) -> Any:
    import jax

    from ..systems import trebuchet as tb

    angle, weight = policy(target, wind)
    return jax.jit(tb.simulate)(wind, angle, weight)


def _ode_recording(run_dir: str, task):
    """Re-solve a saved continuous-time controller (the reference solve) with the run's own
    settings (horizon, saves, loss, --param overrides) where its run.json is there."""
    from .. import io
    from ..evaluation import simulate_continuous
    from ..training import task_params

    doc = io.read_model(Path(run_dir))
    config = task.default_config()
    run_file = Path(run_dir) / io.RUN_FILE
    if Path(run_dir).is_dir() and run_file.exists():
        config = type(config).from_json(io.read_json(run_file, "run file")["config"])
    params = task_params(task, config.params)
    metrics = Path(run_dir) / "metrics.json"
    if Path(run_dir).is_dir() and metrics.exists():  # a --model run: its real system
        from ..models import real_params

        real = (io.read_json(metrics, "metrics").get("model") or {}).get("real_system")
        fitted_real = real_params(task, real)
        params = params if fitted_real is None else fitted_real
    return simulate_continuous(task, io.controller_from_dict(doc), params, config=config)


def _load_run(run_dir: str):
    from .. import load, tasks

    policy = load(run_dir)  # chooses the policy class by the task's kind
    return tasks.make(policy.task), policy


def cmd_aim(args: argparse.Namespace) -> int:
    import jax

    from ..systems import trebuchet as tb
    from ..tasks.trebuchet import aim_directly, check_target

    task, policy = _load_run(args.run_dir)
    if task.kind != "aiming":
        raise DiffcontrolError(
            f"{args.run_dir} holds a {task.name!r} controller; `aim` needs a trebuchet run"
        )
    check_target(args.target, args.wind)
    t0 = time.perf_counter()
    angle, weight = policy(args.target, args.wind)
    net_seconds = time.perf_counter() - t0
    distance = float(jax.jit(tb.shoot)(args.wind, angle, weight))
    result = {
        "target_m": args.target,
        "wind_mps": args.wind,
        "angle_deg": angle,
        "weight_lb": weight,
        "distance_m": distance,
        "miss_m": distance - args.target,
        "network_seconds": net_seconds,
    }
    lines = [
        f"network: angle {angle:.2f} deg, weight {weight:.1f} lb -> {distance:.2f} m "
        f"(miss {distance - args.target:+.3f} m; {net_seconds * 1e6:.0f} us)"
    ]
    if args.direct:
        direct = jax.jit(aim_directly)
        jax.block_until_ready(direct(args.target, args.wind))  # compile first
        t0 = time.perf_counter()
        a, w, miss = jax.block_until_ready(direct(args.target, args.wind))
        seconds = time.perf_counter() - t0
        result["direct"] = {
            "angle_deg": float(a),
            "weight_lb": float(w),
            "miss_m": float(miss),
            "seconds": seconds,
        }
        lines.append(
            f"direct:  angle {float(a):.2f} deg, weight {float(w):.1f} lb -> "
            f"{args.target + float(miss):.2f} m (miss {float(miss):+.3f} m; {seconds * 1e3:.1f} ms)"
        )
    if args.json:
        print(json.dumps(result))
    else:
        print(f"target {args.target:g} m, wind {args.wind:+g} m/s")
        print("\n".join(lines))
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from ..evaluation import evaluate
    from ..models import as_env, real_params

    task, policy = _load_run(args.run_dir)
    if task.kind == "aiming":
        from ..evaluation import evaluate_aiming

        n = args.episodes or 1000
        params = real_params(task, _real(args))
        result = evaluate_aiming(policy, task, targets=n, seed=args.seed, params=params)
        if args.json:
            print(json.dumps({"run_dir": str(args.run_dir), **result.to_json()}))
        else:
            where = (
                " on the real trebuchet of its fitted model's data" if params is not None else ""
            )
            print(f"{task.name}, {n} random targets (seed {args.seed}){where}: {result.summary()}")
        return 0
    if task.kind == "ode":
        from ..evaluation import swingup_result

        report = swingup_result(_ode_recording(args.run_dir, task))
        if args.json:
            print(json.dumps({"run_dir": str(args.run_dir), **report.to_json()}))
        else:
            print(f"{task.name} (reference solve, dopri8 at 1e-9): {report.summary()}")
        return 0
    if not task.gym_id:
        raise DiffcontrolError(f"task {task.name!r} has no Gymnasium environment to evaluate in")
    args.episodes = args.episodes or 100
    ev = evaluate(policy, task, episodes=args.episodes, seed=args.seed, real=as_env(_real(args)))
    if args.json:
        print(json.dumps({"run_dir": str(args.run_dir), "task": task.name, **ev.to_json()}))
    else:
        print(
            f"{ev.env_id}: return {ev.mean:.2f} ± {ev.std:.2f} over {args.episodes} episodes "
            f"(seeds {args.seed}-{args.seed + args.episodes - 1}; min {ev.returns.min():.1f}, "
            f"max {ev.returns.max():.1f})"
        )
    return 0


def _real(args: argparse.Namespace) -> dict | None:
    """The system to evaluate on: --env, else the real system of a run trained with --model
    (from its metrics.json), else None (the task's own)."""
    if args.env:
        return {"env_id": args.env, "env_kwargs": dict(args.env_arg)}
    if args.env_arg:
        raise DiffcontrolError("--env-arg needs --env (the environment it applies to)")
    metrics = Path(args.run_dir) / "metrics.json"
    if metrics.exists():
        from ..io import read_json

        return (read_json(metrics, "metrics").get("model") or {}).get("real_system")
    return None


def cmd_animate(args: argparse.Namespace) -> int:
    from ..animation import animate
    from ..evaluation import record_episode

    task, policy = _load_run(args.run_dir)
    path = Path(args.out) if args.out else Path(args.run_dir) / "rollout.gif"
    if task.kind == "aiming":
        from ..animation import animate_throw
        from ..tasks.trebuchet import check_target

        check_target(args.target, args.wind)
        throw = example_throw(policy, args.target, args.wind)
        animate_throw(throw, args.target, args.wind, path)
        print(f"wrote {path} (distance {float(throw.distance):.2f} m, target {args.target:g} m)")
        return 0
    if task.kind == "ode":
        from ..animation import animate_swingup

        rec = _ode_recording(args.run_dir, task)
        animate_swingup(rec, path)
        print(f"wrote {path} ({rec.t[-1]:g} s, peak |F| {abs(rec.force).max():.1f} N)")
        return 0
    rec = record_episode(policy, task, seed=args.seed)
    animate(rec, task, path)
    print(f"wrote {path} (return {rec.total_return:.1f}, {len(rec.rewards)} steps)")
    return 0
