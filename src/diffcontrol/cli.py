"""The ``diffcontrol`` command line. It sits on top of everything; nothing imports it."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, NoReturn

from .config import ODETrainConfig, help_of
from .errors import DiffcontrolError

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the problem and the fix) and exit status 2."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")
        raise SystemExit(EXIT_USAGE)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def _nonneg_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _widths(text: str) -> tuple[int, ...]:
    try:
        widths = tuple(int(w) for w in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated layer widths such as 64,64, got {text!r}"
        ) from None
    if not widths or any(w <= 0 for w in widths):
        raise argparse.ArgumentTypeError(f"layer widths must be positive, got {text!r}")
    return widths


def _yes_no(text: str) -> bool:
    value = text.strip().lower()
    if value in ("yes", "true", "1", "on"):
        return True
    if value in ("no", "false", "0", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected yes or no, got {text!r}")


def _positive_float(text: str) -> float:
    value = _finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE such as g=9.81, got {text!r}")
    return name.strip(), _finite_float(value)


# TrainConfig fields exposed as options: (type, metavar). Help comes from the field docs.
_CONFIG_OPTIONS: dict[str, tuple[Any, str]] = {
    "seed": (int, "N"),
    "updates": (_positive_int, "N"),
    "batch": (_positive_int, "N"),
    "window": (_positive_int, "STEPS"),
    "horizon": (_nonneg_int, "STEPS"),
    "learning_rate": (_finite_float, "LR"),
    "lr_schedule": (str, "NAME"),
    "lr_final_fraction": (_finite_float, "F"),
    "grad_clip": (_finite_float, "NORM"),
    "hidden": (_widths, "W,W"),
    "activation": (str, "NAME"),
    "head": (str, "NAME"),
    "loss": (str, "NAME"),
    "eval_every": (_positive_int, "N"),
    "eval_episodes": (_positive_int, "N"),
    "target_return": (float, "R"),
    "keep_best": (_yes_no, "yes|no"),
}
# ODETrainConfig fields that discrete-time tasks do not have.
_ODE_OPTIONS: dict[str, tuple[Any, str]] = {
    "horizon_s": (_positive_float, "S"),
    "saves": (_positive_int, "N"),
    "solver": (str, "NAME"),
    "rtol": (_positive_float, "TOL"),
    "atol": (_positive_float, "TOL"),
    "max_steps": (_positive_int, "N"),
    "gradient": (str, "METHOD"),
    "population": (_positive_int, "N"),
    "curriculum_start": (_finite_float, "F"),
    "curriculum_fraction": (_finite_float, "F"),
}


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="diffcontrol",
        description=(
            "Train controllers by differentiating through simulators. "
            "Start with `diffcontrol list`, then `diffcontrol train pendulum --out runs/pendulum`."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    sub.add_parser("list", help="list the tasks, one line each", description="List the tasks.")

    p = sub.add_parser(
        "train",
        help="train a controller and write model, metrics, plots and an animation",
        description=(
            "Train a controller for TASK by differentiating through its simulator, with the "
            "task's tuned defaults unless options change them: backpropagation through time "
            "for discrete-time tasks, through an adaptive ODE solve for continuous-time ones "
            "(cartpole-swingup*). Writes to DIR: model.json (the controller, runnable with "
            "NumPy alone), metrics.json (timings, simulated steps and episodes, learning "
            "curve, evaluation), learning_curve.png, rollout.png and rollout.gif (swing-ups: "
            "data.json with the time series, swingup.png with angle, position and force), "
            "and checkpoint.npz (for --resume)."
        ),
    )
    p.add_argument("task", metavar="TASK", help="task name (see `diffcontrol list`)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (new or empty)")
    p.add_argument(
        "--recipe",
        metavar="NAME",
        help="start from a named set of settings, e.g. 'original' for the 2019 Flux recipe",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in DIR from its last checkpoint",
    )
    p.add_argument(
        "--final-eval",
        type=_nonneg_int,
        default=None,
        metavar="N",
        help="evaluate after training: Gymnasium episodes on seeds 0..N-1 (default 100), or "
        "random targets for aiming tasks (default 1000); 0 skips",
    )
    p.add_argument("--no-animation", action="store_true", help="skip the GIF (saves a few seconds)")
    _add_common(p)
    group = p.add_argument_group(
        "training settings (defaults depend on the task; see `diffcontrol list`)"
    )
    for name, (typ, metavar) in _CONFIG_OPTIONS.items():
        group.add_argument(
            "--" + name.replace("_", "-"),
            dest=name,
            type=typ,
            metavar=metavar,
            default=None,
            help=help_of(name).replace("%", "%%"),
        )
    ode = p.add_argument_group(
        "continuous-time tasks only (cartpole-swingup*): the ODE solve and its gradient"
    )
    for name, (typ, metavar) in _ODE_OPTIONS.items():
        ode.add_argument(
            "--" + name.replace("_", "-"),
            dest=name,
            type=typ,
            metavar=metavar,
            default=None,
            help=help_of(name, ODETrainConfig).replace("%", "%%"),
        )
    group.add_argument(
        "--param",
        dest="params",
        type=_param,
        action="append",
        metavar="NAME=VALUE",
        help="override a physical parameter of the simulator (repeatable), e.g. --param g=9.81",
    )

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
            "force and the swings."
        ),
    )
    p.add_argument("run_dir", metavar="DIR", help="a directory written by `diffcontrol train`")
    p.add_argument(
        "--episodes",
        type=_positive_int,
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
        "--target", type=_finite_float, default=80.0, metavar="M", help="aiming tasks: target (m)"
    )
    p.add_argument(
        "--wind", type=_finite_float, default=-3.0, metavar="MPS", help="aiming tasks: wind (m/s)"
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
    p.add_argument("--target", type=_finite_float, required=True, metavar="M", help="target (m)")
    p.add_argument("--wind", type=_finite_float, default=0.0, metavar="W", help="wind (m/s)")
    p.add_argument(
        "--direct", action="store_true", help="also aim by gradient descent on the simulator"
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")

    p = sub.add_parser(
        "compare",
        help="compare diffcontrol with RL baselines (Stable-Baselines3) on one task",
        description=(
            "Train diffcontrol's controller (the task's defaults) and the RL baselines "
            "(Stable-Baselines3 with rl-baselines3-zoo's published settings: PPO and DQN for "
            "cartpole, SAC and TD3 for pendulum and trebuchet; `pip install "
            "'diffcontrol[rl]'`) with the same training seeds 0..N-1. Every method is "
            "evaluated at regular points during training on the same reset seeds in the same "
            "environment (Gymnasium's own Pendulum-v1 / CartPole-v1; diffcontrol/Trebuchet-v0). "
            "Training seconds leave out these evaluations. Writes to DIR: compare.json "
            "(settings), runs/METHOD-seedS.json (each finished run, as it finishes; --resume "
            "skips them), comparison.json, comparison.md (the table) and comparison.png."
        ),
    )
    p.add_argument("task", metavar="TASK", help="cartpole, pendulum or trebuchet")
    p.add_argument(
        "--out", metavar="DIR", default=None, help="output directory (default runs/compare-TASK)"
    )
    p.add_argument(
        "--seeds", type=_positive_int, default=3, metavar="N", help="training seeds (default 3)"
    )
    p.add_argument(
        "--methods",
        type=_names,
        default=None,
        metavar="M,M",
        help="a subset of the methods, e.g. diffcontrol,ppo (default: all for the task)",
    )
    p.add_argument(
        "--rl-steps",
        type=_positive_int,
        default=None,
        metavar="N",
        help="RL budget in environment steps (default: each baseline's zoo budget)",
    )
    p.add_argument(
        "--updates",
        type=_positive_int,
        default=None,
        metavar="N",
        help="diffcontrol's gradient updates (default: the task's default config)",
    )
    p.add_argument(
        "--eval-every",
        type=_positive_int,
        default=None,
        metavar="STEPS",
        help="RL evaluation interval in environment steps (default: cartpole 2000, "
        "pendulum 1000, trebuchet 1000); diffcontrol is evaluated at its own evaluation points",
    )
    p.add_argument(
        "--eval-episodes",
        type=_positive_int,
        default=20,
        metavar="N",
        help="episodes per evaluation point (default 20)",
    )
    p.add_argument(
        "--final-episodes",
        type=_positive_int,
        default=100,
        metavar="N",
        help="episodes for each method's returned controller (default 100)",
    )
    p.add_argument(
        "--eval-seed",
        type=_nonneg_int,
        default=1000,
        metavar="S",
        help="first reset seed of the evaluation episodes (default 1000)",
    )
    p.add_argument(
        "--torch-threads",
        type=_positive_int,
        default=1,
        metavar="N",
        help="PyTorch threads for the RL baselines (default 1)",
    )
    p.add_argument(
        "--resume", action="store_true", help="continue the comparison in DIR, keeping its runs"
    )
    _add_common(p)
    return parser


def _names(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected comma-separated names, got {text!r}")
    return names


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not use JAX's persistent compilation cache (also: DIFFCONTROL_NO_COMPILE_CACHE=1)",
    )
    p.add_argument("--quiet", action="store_true", help="print only the final summary")


def _cmd_list(args: argparse.Namespace) -> int:
    from . import tasks

    for name in tasks.names():
        task = tasks.make(name)
        losses = "/".join(task.losses)
        recipes = ", ".join(task.recipes()) or "-"
        print(f"{name:<26} {task.summary}  [losses: {losses}; recipes: {recipes}]")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from . import _jax_setup, io, tasks
    from .evaluation import evaluate, record_episode
    from .training import resolve_config, train

    task = tasks.make(args.task)
    config_cls = type(task.default_config())
    fields = {f.name for f in dataclasses.fields(config_cls)}
    overrides = {name: getattr(args, name) for name in {**_CONFIG_OPTIONS, **_ODE_OPTIONS}}
    foreign = sorted(n for n, v in overrides.items() if v is not None and n not in fields)
    if foreign:
        kind = "a continuous-time" if task.kind == "ode" else "a discrete-time"
        flags = ", ".join("--" + n.replace("_", "-") for n in foreign)
        raise DiffcontrolError(
            f"{flags} do{'es' if len(foreign) == 1 else ''} not apply to {task.name!r} ({kind} "
            "task); see `diffcontrol train --help` for the settings of each kind"
        )
    overrides = {n: v for n, v in overrides.items() if n in fields}
    if args.params:
        overrides["params"] = tuple(args.params)
    out = Path(args.out)
    explicit = args.recipe is not None or any(v is not None for v in overrides.values())
    if args.resume and not explicit and (out / io.RUN_FILE).exists():
        config = config_cls.from_json(io.read_json(out / io.RUN_FILE, "run file")["config"])
    else:
        config = resolve_config(task, args.recipe, **overrides)

    cache_dir = None
    if not (args.no_compile_cache or os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE")):
        cache_dir = _jax_setup.enable_compile_cache()
    say = (lambda line: None) if args.quiet else (lambda line: print(line, flush=True))
    if task.kind == "ode":
        say(
            f"training {task.name}: {config.updates} updates of {config.population} closed-loop "
            f"solve(s) over {config.horizon_s:g} s ({config.solver}, rtol {config.rtol:g}, atol "
            f"{config.atol:g}, gradient {config.gradient}; seed {config.seed}) -> {out}"
        )
    else:
        say(
            f"training {task.name}: {config.updates} updates x window {config.window} x batch "
            f"{config.batch} (seed {config.seed}) -> {out}"
        )
    try:
        result = train(task, config, out_dir=out, resume=args.resume, progress=say)
    except KeyboardInterrupt:
        print(
            f"\ninterrupted; the last checkpoint is in {out}. Continue with: "
            f"diffcontrol train {task.name} --out {out} --resume",
            file=sys.stderr,
        )
        return 130
    metrics = result.metrics
    metrics["compile_cache"] = {
        "dir": str(cache_dir) if cache_dir else None,
        **_jax_setup.cache_events(),
    }
    metrics["command"] = " ".join(["diffcontrol", *sys.argv[1:]])
    metrics["created"] = io.now_iso()

    from . import __version__

    doc = io.controller_to_dict(
        result.controller,
        task,
        {
            "diffcontrol_version": __version__,
            "created": metrics["created"],
            "seed": config.seed,
            "train_seconds": metrics["train_seconds"],
            "config": config.to_json(),
        },
    )
    io.write_json(out / "model.json", doc)
    if task.kind == "aiming":
        return _finish_aiming(args, task, out, doc, metrics, say)
    if task.kind == "ode":
        return _finish_ode(args, task, out, result, metrics, say)
    policy = io.NumpyPolicy(doc)
    final_eval = 100 if args.final_eval is None else args.final_eval
    if final_eval and task.gym_id:
        t0 = time.perf_counter()
        ev = evaluate(policy, task, episodes=final_eval, seed=0)
        metrics["gym_eval"] = {**ev.to_json(), "seconds": time.perf_counter() - t0}
        say(f"Gymnasium {ev.env_id}, seeds 0-{final_eval - 1}: return {ev.mean:.1f} ± {ev.std:.1f}")
    io.write_json(out / "metrics.json", metrics)

    from . import plots

    plots.learning_curve(metrics, out / "learning_curve.png", task.reward_threshold)
    files = ["model.json", "metrics.json", "learning_curve.png"]
    if task.gym_id:
        rec = record_episode(policy, task, seed=0)
        plots.rollout(rec, task, out / "rollout.png")
        files.append("rollout.png")
        if not args.no_animation:
            from .animation import animate

            animate(rec, task, out / "rollout.gif")
            files.append("rollout.gif")
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']:.4g} simulated episodes ({metrics['simulated_steps']} steps)"
        + (
            f"; Gymnasium return {metrics['gym_eval']['mean_return']:.1f} ± "
            f"{metrics['gym_eval']['std_return']:.1f}"
            if "gym_eval" in metrics
            else ""
        )
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0


def _example_throw(policy: Any, target: float, wind: float) -> Any:
    import jax

    from .systems import trebuchet as tb

    angle, weight = policy(target, wind)
    return jax.jit(tb.simulate)(wind, angle, weight)


def _finish_aiming(args, task, out: Path, doc: dict, metrics: dict, say) -> int:
    """The end of `train` for aiming tasks: miss statistics, the throw plot and animation."""
    from . import io, plots
    from .evaluation import evaluate_aiming

    policy = io.AimingPolicy(doc)
    n = 1000 if args.final_eval is None else args.final_eval
    if n:
        t0 = time.perf_counter()
        ev = evaluate_aiming(policy, task, targets=n, seed=0)
        metrics["aim_eval"] = {**ev.to_json(), "seconds": time.perf_counter() - t0}
        say(f"{n} random targets (seed 0): {ev.summary()}")
    io.write_json(out / "metrics.json", metrics)
    plots.learning_curve(metrics, out / "learning_curve.png", None)
    files = ["model.json", "metrics.json", "learning_curve.png", "rollout.png"]
    target, wind = 80.0, -3.0
    throw = _example_throw(policy, target, wind)
    plots.throw(throw, target, wind, out / "rollout.png")
    if not args.no_animation:
        from .animation import animate_throw

        animate_throw(throw, target, wind, out / "rollout.gif")
        files.append("rollout.gif")
    summary = f"; mean |miss| {metrics['aim_eval']['mean_miss_m']:.3f} m" if n else ""
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']:.4g} simulated throws{summary}"
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0


def _finish_ode(args, task, out: Path, result, metrics: dict, say) -> int:
    """The end of `train` for continuous-time tasks: a reference solve, data.json, plots, GIF."""
    from . import io, plots
    from .evaluation import simulate_continuous, swingup_result

    rec = simulate_continuous(task, result.controller, result.params, config=result.config)
    report = swingup_result(rec)
    metrics["swingup"] = report.to_json()
    say(f"reference solve: {report.summary()}")
    io.write_json(out / "metrics.json", metrics)
    io.write_json(out / "data.json", rec.to_json())
    plots.learning_curve(metrics, out / "learning_curve.png", None)
    plots.swingup(rec, out / "swingup.png")
    files = ["model.json", "data.json", "metrics.json", "learning_curve.png", "swingup.png"]
    if not args.no_animation:
        from .animation import animate_swingup

        animate_swingup(rec, out / "rollout.gif")
        files.append("rollout.gif")
    print(
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']} closed-loop solves ({metrics['simulated_steps']} solver "
        f"steps); final |θ| {abs(report.final_theta):.3f} rad, ẋ {report.final_x_dot:+.3f} m/s, "
        f"peak |F| {report.peak_force:.1f} N"
    )
    print(f"wrote {', '.join(str(out / f) for f in files)}")
    return 0


def _ode_recording(run_dir: str, task):
    """Re-solve a saved continuous-time controller (the reference solve) with the run's own
    settings (horizon, saves, loss, --param overrides) where its run.json is there."""
    from . import io
    from .evaluation import simulate_continuous
    from .training import task_params

    doc = io.read_model(Path(run_dir))
    config = task.default_config()
    run_file = Path(run_dir) / io.RUN_FILE
    if Path(run_dir).is_dir() and run_file.exists():
        config = type(config).from_json(io.read_json(run_file, "run file")["config"])
    params = task_params(task, config.params)
    return simulate_continuous(task, io.controller_from_dict(doc), params, config=config)


def _load_run(run_dir: str):
    from . import load, tasks

    policy = load(run_dir)  # chooses the policy class by the task's kind
    return tasks.make(policy.task), policy


def _cmd_aim(args: argparse.Namespace) -> int:
    import jax

    from .systems import trebuchet as tb
    from .tasks.trebuchet import aim_directly, check_target

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


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluation import evaluate

    task, policy = _load_run(args.run_dir)
    if task.kind == "aiming":
        from .evaluation import evaluate_aiming

        n = args.episodes or 1000
        result = evaluate_aiming(policy, task, targets=n, seed=args.seed)
        if args.json:
            print(json.dumps({"run_dir": str(args.run_dir), **result.to_json()}))
        else:
            print(f"{task.name}, {n} random targets (seed {args.seed}): {result.summary()}")
        return 0
    if task.kind == "ode":
        from .evaluation import swingup_result

        report = swingup_result(_ode_recording(args.run_dir, task))
        if args.json:
            print(json.dumps({"run_dir": str(args.run_dir), **report.to_json()}))
        else:
            print(f"{task.name} (reference solve, dopri8 at 1e-9): {report.summary()}")
        return 0
    if not task.gym_id:
        raise DiffcontrolError(f"task {task.name!r} has no Gymnasium environment to evaluate in")
    args.episodes = args.episodes or 100
    ev = evaluate(policy, task, episodes=args.episodes, seed=args.seed)
    if args.json:
        print(json.dumps({"run_dir": str(args.run_dir), "task": task.name, **ev.to_json()}))
    else:
        print(
            f"{ev.env_id}: return {ev.mean:.2f} ± {ev.std:.2f} over {args.episodes} episodes "
            f"(seeds {args.seed}-{args.seed + args.episodes - 1}; min {ev.returns.min():.1f}, "
            f"max {ev.returns.max():.1f})"
        )
    return 0


def _cmd_animate(args: argparse.Namespace) -> int:
    from .animation import animate
    from .evaluation import record_episode

    task, policy = _load_run(args.run_dir)
    path = Path(args.out) if args.out else Path(args.run_dir) / "rollout.gif"
    if task.kind == "aiming":
        from .animation import animate_throw
        from .tasks.trebuchet import check_target

        check_target(args.target, args.wind)
        throw = _example_throw(policy, args.target, args.wind)
        animate_throw(throw, args.target, args.wind, path)
        print(f"wrote {path} (distance {float(throw.distance):.2f} m, target {args.target:g} m)")
        return 0
    if task.kind == "ode":
        from .animation import animate_swingup

        rec = _ode_recording(args.run_dir, task)
        animate_swingup(rec, path)
        print(f"wrote {path} ({rec.t[-1]:g} s, peak |F| {abs(rec.force).max():.1f} N)")
        return 0
    rec = record_episode(policy, task, seed=args.seed)
    animate(rec, task, path)
    print(f"wrote {path} (return {rec.total_return:.1f}, {len(rec.rewards)} steps)")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from . import _jax_setup, tasks
    from .compare import run_comparison

    task = tasks.make(args.task)
    out = Path(args.out or f"runs/compare-{task.name}")
    if not (args.no_compile_cache or os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE")):
        _jax_setup.enable_compile_cache()
    say = (lambda line: None) if args.quiet else (lambda line: print(line, flush=True))
    try:
        doc = run_comparison(
            task,
            out,
            seeds=args.seeds,
            methods=args.methods,
            rl_steps=args.rl_steps,
            updates=args.updates,
            eval_every=args.eval_every,
            eval_episodes=args.eval_episodes,
            final_episodes=args.final_episodes,
            eval_seed=args.eval_seed,
            torch_threads=args.torch_threads,
            resume=args.resume,
            progress=say,
        )
    except KeyboardInterrupt:
        print(
            f"\ninterrupted; the finished runs are in {out / 'runs'}. Continue with the same "
            f"options and --resume: diffcontrol {' '.join(sys.argv[1:] or ['compare', task.name])}"
            + ("" if args.resume else " --resume"),
            file=sys.stderr,
        )
        return 130
    print(doc["table"])
    print(f"wrote {out / 'comparison.json'}, {out / 'comparison.md'}, {out / 'comparison.png'}")
    return 0


COMMANDS = {
    "list": _cmd_list,
    "train": _cmd_train,
    "evaluate": _cmd_evaluate,
    "animate": _cmd_animate,
    "aim": _cmd_aim,
    "compare": _cmd_compare,
}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``diffcontrol`` command; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except DiffcontrolError as e:
        print(f"diffcontrol {args.command}: error: {e}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    raise SystemExit(main())
