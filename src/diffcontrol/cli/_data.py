"""``diffcontrol record``: record trajectories from a Gymnasium environment to CSV or NPZ."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from ..errors import ConfigError, DataFileError
from ._args import finite_float, param, positive_int


def nonneg_float(text: str) -> float:
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text!r}")
    return value


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "record",
        help="record trajectories from a Gymnasium environment (CSV or NPZ)",
        description=(
            "Record N episodes of the Gymnasium environment ENV_ID (e.g. Pendulum-v1, "
            "CartPole-v1, diffcontrol/Pendulum-v0) with the controller saved in DIR, or with "
            "random actions, and write them as a diffcontrol-trajectories file: CSV or NPZ by "
            "the extension of FILE. Episode i is reset with seed S+i. Each row is a time step "
            "(time, episode, observations, the action applied); the last row of an episode "
            "holds the final observation and no action. "
            "ENV_ID trebuchet records throws of the trebuchet instead (one episode is one "
            "throw): N throws with random inputs (wind ~ N(0, 5^2) m/s, release angle 20-70 "
            "deg, counterweight 50-450 lb), or with --controller aiming at random targets, of "
            "a trebuchet whose parameters --env-arg sets (e.g. --env-arg drag_coefficient=1.5 "
            "--env-arg wind_factor=1.5), written as a diffcontrol-throws file (columns wind "
            "[m/s], release_angle [deg], counterweight [lb], distance [m]) for `diffcontrol "
            "fit trebuchet`. ENV_ID cartpole-swingup (or another swing-up task) records the "
            "swing-up cart-pole's full state (x, x_dot, theta, theta_dot) and force at 50 Hz "
            "for `diffcontrol fit cartpole-swingup-friction`: N episodes of 5 s with random "
            "force levels in +-40 N, of a cart-pole whose parameters --env-arg sets (e.g. "
            "--env-arg cart_viscous=2)."
        ),
    )
    p.add_argument(
        "env_id",
        metavar="ENV_ID",
        help="a registered Gymnasium environment id, trebuchet for throws, or a swing-up "
        "task (cartpole-swingup...) for its state",
    )
    p.add_argument(
        "--episodes",
        type=positive_int,
        required=True,
        metavar="N",
        help="episodes (for trebuchet: throws)",
    )
    p.add_argument(
        "--controller",
        metavar="DIR",
        default=None,
        help="a run directory (or model.json) written by `diffcontrol train`; "
        "random actions if omitted",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="S",
        help="first reset seed, and the seed of the random actions (default 0)",
    )
    p.add_argument(
        "--env-arg",
        type=param,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a numeric keyword argument of gymnasium.make, e.g. g=9.0 for Pendulum-v1; "
        "for trebuchet a parameter of the trebuchet that throws, e.g. drag_coefficient=1.5 "
        "(repeatable)",
    )
    p.add_argument(
        "--noise-m",
        type=nonneg_float,
        default=None,
        metavar="SD",
        help="trebuchet only: standard deviation (m) of Gaussian noise added to the recorded "
        "distances (default 0)",
    )
    p.add_argument(
        "--max-steps",
        type=positive_int,
        default=None,
        metavar="N",
        help="cut episodes after N steps (default: the environment's own limit)",
    )
    p.add_argument(
        "--out",
        metavar="FILE",
        default=None,
        help="a .csv or .npz file (default: ENV_ID with / as -, .csv, in this directory; "
        "trebuchet-throws.csv for trebuchet)",
    )
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--quiet", action="store_true", help="print only the final summary")


def _check_out(out: Path, force: bool) -> None:
    """Refuse, before recording anything, an output the recording could not be written to."""
    if out.is_dir():
        raise DataFileError(f"--out {out} is a directory; give a file name ending in .csv/.npz")
    if out.suffix.lower() not in (".csv", ".npz"):
        raise DataFileError(
            f"--out {out}: unknown file type {out.suffix or '(none)'!r}; use a .csv or .npz file"
        )
    if out.exists() and not force:
        raise DataFileError(
            f"--out {out} already exists; pass --force to overwrite it or choose another --out"
        )
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise DataFileError(
            f"cannot write --out {out}: {parent} is not a writable directory; choose a "
            "writable --out"
        )


def write_out(write: Any, out: Path, data: Any) -> None:
    """``write(out, data)``, with a file system error as a one-line ``DataFileError``."""
    try:
        write(out, data)
    except OSError as e:
        raise DataFileError(
            f"cannot write --out {out} ({e.strerror}); choose a writable --out"
        ) from None


def cmd_record(args: argparse.Namespace) -> int:
    from ..data import write_trajectories
    from ..io import NumpyPolicy, read_model
    from ..recording import record

    if args.env_id == "trebuchet":  # the task's name: throws, not Gymnasium trajectories
        from ._throws import cmd_record_throws

        return cmd_record_throws(args, _check_out)
    if args.env_id.startswith("cartpole-swingup"):  # a swing-up task: its state, in Python
        return _record_swingup(args)
    if args.noise_m is not None:
        raise ConfigError(
            f"--noise-m applies to `diffcontrol record trebuchet` only, not {args.env_id}; drop it"
        )
    out = Path(args.out or args.env_id.replace("/", "-") + ".csv")
    _check_out(out, args.force)
    # The network alone (observations -> Gymnasium action), whatever the task's kind.
    policy = NumpyPolicy(read_model(args.controller)) if args.controller else None
    say = (lambda line: None) if args.quiet else print
    what = f"controller {args.controller}" if policy else "random actions"
    say(f"recording {args.episodes} episode(s) of {args.env_id} with {what}")
    t0 = time.perf_counter()
    data = record(
        args.env_id,
        args.episodes,
        policy=policy,
        seed=args.seed,
        env_kwargs=dict(args.env_arg),
        max_steps=args.max_steps,
        progress=say,
        source=f"controller {args.controller} (task {policy.task!r})" if policy else None,
    )
    write_out(write_trajectories, out, data)
    print(
        f"wrote {out}: {data.num_episodes} episode(s), {data.num_steps} steps, "
        f"{len(data.observation_columns)} observation and {len(data.action_columns)} action "
        f"column(s) ({time.perf_counter() - t0:.1f} s)"
    )
    return 0


def _record_swingup(args: argparse.Namespace) -> int:
    """``diffcontrol record cartpole-swingup...``: the state of the swing-up cart-pole with the
    task's parameters and ``--env-arg`` changes, under random forces (``record_swingup``)."""
    from .. import tasks
    from ..data import write_trajectories
    from ..ode_fitting import record_swingup
    from ..training import task_params

    task = tasks.make(args.env_id)
    for flag, value in (("--controller", args.controller), ("--max-steps", args.max_steps)):
        if value is not None:
            raise ConfigError(
                f"{flag} does not apply to recording {task.name}: its episodes are 5 s of "
                "random forces; drop it"
            )
    if args.noise_m is not None:
        raise ConfigError(f"--noise-m applies to the trebuchet only, not {task.name}; drop it")
    params = task_params(task, tuple(args.env_arg))
    out = Path(args.out or f"{task.name}-state.csv")
    _check_out(out, args.force)
    if not args.quiet:
        changed = ", ".join(f"{n}={v:g}" for n, v in args.env_arg) or "its parameters"
        print(f"recording {args.episodes} episode(s) of the {task.name} cart-pole ({changed})")
    t0 = time.perf_counter()
    data = record_swingup(params, args.episodes, seed=args.seed)
    write_out(write_trajectories, out, data)
    print(
        f"wrote {out}: {data.num_episodes} episode(s), {data.num_steps} steps of the state "
        f"and force ({time.perf_counter() - t0:.1f} s)"
    )
    return 0
