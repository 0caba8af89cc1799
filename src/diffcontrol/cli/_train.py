"""``diffcontrol train``: train a controller and write the run's files (``runs.train_run``)."""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from pathlib import Path
from typing import Any

import diffcontrol.cli._args as a

from ..config import ODETrainConfig, TrainConfig
from ..errors import TrainingWarning
from ..settings import PlanConfig
from ._args import FLAG, REQUIRED, add

_DISCRETE = {f.name for f in dataclasses.fields(TrainConfig)}
_SETTINGS = (_DISCRETE | {f.name for f in dataclasses.fields(ODETrainConfig)}) - {"params"}
_PLAN = {f.name for f in dataclasses.fields(PlanConfig)}


def add_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "train",
        help="train a controller and write model, metrics, plots and an animation",
        description=(
            "Train a controller for TASK by differentiating through its simulator (through "
            "time steps, or an ODE solve for continuous-time tasks), with the task's tuned "
            "defaults unless options change them. Writes to DIR: model.json (the controller, "
            "runnable with NumPy alone), metrics.json, plots, an animation and checkpoint.npz "
            "(for --resume); see docs/cli.md."
        ),
    )
    # fmt: off
    shared = (  # with plan
        ("--out", str, REQUIRED, "DIR", "output directory (new or empty)"),
        ("--final-eval", a.episodes_or_0, None, "N", "evaluate the controller: Gymnasium episodes "
         "on seeds 0..N-1 (default 100), or random targets for aiming tasks (default 1000); "
         "0 skips"),
        ("--no-animation", FLAG, False, None, "skip the GIF (saves a few seconds)"),
        ("--model", str, None, "FIT_DIR", "train (plan) through the model `diffcontrol fit` "
         "wrote in FIT_DIR, and evaluate on the system its data was recorded from"),
        ("--env", str, None, "ENV_ID", "with --model: the real system's Gymnasium id where the "
         "data names one in a module of yours (module:Env-v0; imported only when named here)"),
    )
    add(p,
        ("task", str, None, "TASK", "(optional with --resume: the run's own) " + a.TASK_HELP),
        *shared,
        ("--recipe", str, None, "NAME",
         "start from a named set of settings, e.g. 'original' for the 2019 Flux recipe"),
        ("--init", str, None, "RUN_DIR", "start from the controller trained in RUN_DIR instead "
         "of random weights (fine-tuning, e.g. at a lower --learning-rate); the same network"),
        ("--resume", FLAG, False, None, "continue the interrupted run in DIR from its last "
         "checkpoint, with the settings of its run.json (a finished run is left as it is)"),
        ("--devices", a.positive_int, None, "N", "split the batch of simulations over N "
         "devices (data parallel; default 1, or every device of the hosts below)"),
        ("--coordinator", str, None, "HOST:PORT", "run on several hosts: process 0's address "
         "(every host runs the same command with its --process-id; process 0 writes DIR)"),
        ("--processes", a.positive_int, 1, "N", "the number of hosts (processes) of the run"),
        ("--process-id", a.nonneg_int, 0, "I", "this host's index, 0 ... N-1"),
        ("--join-timeout", a.positive_float, 60.0, "S", "give up joining the hosts after S s"),
        a.NO_COMPILE_CACHE,
        a.QUIET,
        a.LOG_DIR,
    )
    group = p.add_argument_group(
        "training settings (defaults depend on the task; see `diffcontrol list`)")
    add(group, *a.config_specs(TrainConfig, skip={"params"}, defaults=False))
    ode = p.add_argument_group(
        "continuous-time tasks only: the ODE solve and its gradient")
    add(ode, *a.config_specs(ODETrainConfig, skip=_DISCRETE, defaults=False))
    add(group, ("--param", [a.param], None, "NAME=VALUE", "override a physical parameter of "
                "the simulator (repeatable), e.g. --param g=9.81"))
    p = sub.add_parser("plan", help="write a planning controller (MPC) as a run", description=
        "Write a planning controller for TASK in DIR like a trained run (model.json holds its "
        "settings and model; runs with JAX); defaults are the task's. See docs/planning.md.")
    add(p, a.TASK, *shared, *a.config_specs(PlanConfig), a.QUIET, ("--value", str, None, "FILE",
        "a learned terminal value (mpc.learn_value's ValueResult.save) stored in model.json"))
    # fmt: on
    _add_sweep_parser(sub)


def cmd_train(args: argparse.Namespace) -> int:
    from ..runs import train_run  # JAX: the library, when the command runs

    with warnings.catch_warnings():
        if not args.quiet:  # training warnings come as progress lines; not twice
            warnings.simplefilter("ignore", TrainingWarning)
        outcome = train_run(
            args.out,
            args.task,
            settings=a.pick(args, _SETTINGS),
            params=tuple(args.param or ()),
            env_id=args.env,
            animation=not args.no_animation,
            hosts=args.coordinator
            and (args.coordinator, args.processes, args.process_id, args.join_timeout),
            compile_cache=not args.no_compile_cache,
            progress=a.say(args),
            command=args.command_line,
            **a.pick(args, "recipe model resume final_eval devices log_dir init"),
        )
    print(outcome.summary)
    if outcome.files:
        print(f"wrote {', '.join(str(Path(args.out) / f) for f in outcome.files)}")
    if outcome.timings:
        print(outcome.timings)
    if outcome.advice:
        print(outcome.advice)
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    from ..runs import plan_run  # JAX: the library, when the command runs

    kw = a.pick(args, "model final_eval value") | {"env_id": args.env, "progress": a.say(args)}
    kw |= {"settings": a.pick(args, _PLAN), "animation": not args.no_animation}
    run, files = plan_run(args.out, args.task, **kw)
    print(f"{run.metrics.get('headline', 'planner')}; wrote {', '.join(files)} in {args.out}")
    return 0


def _add_sweep_parser(sub: Any) -> None:
    p = sub.add_parser(
        "sweep",
        help="train a grid of runs (seeds x settings) as one vmapped program",
        description=(
            "Train every combination of --seeds and --set values of TASK as one vmapped "
            "program (sharded over the local devices); write one run directory per member, "
            "sweep.txt (the table) and sweep.png. Discrete-time tasks."
        ),
    )
    # fmt: off
    add(p,
        ("task", str, None, "TASK", "(optional with --resume) " + a.TASK_HELP),
        ("--out", str, REQUIRED, "DIR", "output directory (new or empty)"),
        ("--seeds", str, "0-7", "LIST", "training seeds, e.g. 0-63 or 0,3,7 (default 0-7)"),
        ("--set", [str], None, "NAME=V1,V2", "sweep a setting over these values (repeatable; "
         "layer widths as 64x64), e.g. --set learning_rate=1e-3,3e-3"),
        ("--devices", a.positive_int, None, "N", "local devices to shard the members over "
         "(default: all that divide the member count)"),
        ("--recipe", str, None, "NAME", "start from a named set of settings of the task"),
        ("--resume", FLAG, False, None, "train the members of the sweep in DIR not yet written"),
        ("--final-eval", a.nonneg_int, None, "N", "the best member's final evaluation size"),
        a.NO_COMPILE_CACHE, a.QUIET, a.LOG_DIR)
    add(p.add_argument_group("settings of every member (see `diffcontrol train --help`)"),
        *a.config_specs(TrainConfig, skip={"seed", "params"}, defaults=False))
    # fmt: on


def cmd_sweep(args: argparse.Namespace) -> int:
    from ..runs import sweep_dir  # JAX: the library, when the command runs

    settings = a.pick(args, _DISCRETE - {"seed", "params"})
    more = a.pick(args, "recipe devices resume final_eval log_dir") | {"values": args.set or []}
    more |= {"compile_cache": not args.no_compile_cache, "progress": a.say(args)}
    _, files = sweep_dir(args.out, args.task, seeds=args.seeds, settings=settings, **more)
    print(f"wrote {args.out}: sweep.txt, sweep.png and {len(files) - 3} run directories")
    return 0
