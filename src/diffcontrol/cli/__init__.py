"""The ``diffcontrol`` command line: each command parses its options, makes one library call and
prints what it returns (``_train``, ``_runs``, ``_compare``, ``_identify``, ``_deploy``;
``_args``: options)."""

from __future__ import annotations

import argparse
import errno
import gc
import os
import sys
from pathlib import Path

from .._interrupts import terminate_as_interrupt
from .._jax_setup import GC_THRESHOLDS, checks_as_nan
from .._shell import command
from ..errors import DiffcontrolError, Interrupted
from . import _compare, _deploy, _identify, _runs, _train
from ._args import EXIT_USAGE, Parser


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="diffcontrol",
        description=(
            "Train controllers by differentiating through simulators. "
            "Start with `diffcontrol list`, then `diffcontrol train pendulum --out runs/pendulum`."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    sub.required = True
    for module in _MODULES:
        module.add_parsers(sub)
    return parser


# Each command is the function ``cmd_<command>`` of its module.
_MODULES = (_runs, _train, _compare, _identify, _deploy)
COMMANDS = {n[4:]: f for m in _MODULES for n, f in vars(m).items() if n.startswith("cmd_")}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``diffcontrol`` command; returns the exit status."""
    checks_as_nan()  # before Equinox is imported: its programs can then be cached
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.command_line = command(*argv)  # to continue a long command
    try:
        with terminate_as_interrupt():
            return COMMANDS[args.command](args)
    except Interrupted as e:
        print(f"\n{e}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:  # a command with nothing to resume: its writes are atomic
        print(f"\ndiffcontrol {args.command}: interrupted; nothing was written", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `diffcontrol list | head`: the reader has had enough
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except DiffcontrolError as e:
        print(f"diffcontrol {args.command}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:
        if e.errno not in _FILE_SYSTEM_ERRORS:
            raise
        where = f" ({e.filename})" if e.filename else ""
        full = e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
        if _resumable(args):  # the work done so far is kept: continue it where it is
            again = args.command_line + ("" if args.resume else " --resume")
            fix = "make room" if full else "make it writable"
            msg = f"{e.strerror}{where}; {fix}, then continue with: {again}"
        else:
            msg = f"{e.strerror}{where}; {'make room or ' if full else ''}choose another place, "
            msg += "then run the command again"
        print(f"diffcontrol {args.command}: error: {msg}", file=sys.stderr)
        return EXIT_USAGE


# What a command's --resume starts from in its --out, any one of these sets of files
# (_run_dir.RUN_FILE with training's CHECKPOINT_FILE, runs.SWEEP_FILE, runs.LOOP_FILE or the first
# round's data, compare's SETTINGS_FILE or compare --real's file): named as files, so that
# the advice after an error imports nothing.
_RESUME_FROM = {
    "train": [("run.json", "checkpoint.npz")],
    "sweep": [("sweep.json",)],
    "loop": [("loop.json",), ("round_0/recorded.csv",)],
    "compare": [("compare.json",), ("compare-real.json",)],
}


def _resumable(args: argparse.Namespace) -> bool:
    """Whether the command's ``--out`` holds work that its ``--resume`` continues: only then
    does the advice after a file-system error name ``--resume``."""
    out = getattr(args, "out", None)
    try:
        return bool(out) and any(
            all((Path(out) / name).is_file() for name in names)
            for names in _RESUME_FROM.get(args.command, [])
        )
    except OSError:  # an --out that cannot be read holds nothing to continue
        return False


def run() -> int:
    """The ``diffcontrol`` console script: :func:`main`, whose status it returns for a normal
    exit, with the garbage collector at ``GC_THRESHOLDS`` while it runs and the objects made
    so far frozen out of it at the end.

    After a JAX run the interpreter's shutdown spent most of its time in its last full
    collections, each walking every object that JAX, Equinox and the run had made (measured
    in ``benchmarks/results/startup-exit-*.json``). Frozen (``gc.freeze``), they are skipped;
    everything else a normal exit does still happens (threads joined, ``atexit`` functions,
    modules torn down, files flushed and closed, a failed write of the output reported). Only
    objects in reference cycles are no longer collected at the very end, which Python never
    promised either. :func:`main` itself leaves the collector alone, for callers in Python.
    """
    gc.set_threshold(*GC_THRESHOLDS)
    status = main()
    gc.freeze()
    return status


_FILE_SYSTEM_ERRORS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EFBIG}
_FILE_SYSTEM_ERRORS |= {errno.ENOENT, errno.ENOTDIR, errno.EPERM, errno.ENAMETOOLONG}
