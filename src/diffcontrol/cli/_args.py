"""The parser class, the argument types, and ``add``: options from compact specs
``(flag, form, default, metavar, help)``. ``flag`` is ``--name`` or a positional's dest; ``form``
a type function, ``FLAG`` (store_true), ``[type]`` (repeatable) or a tuple of choices;
``default`` a value or ``REQUIRED`` (a positional with a default is optional). The commands
list their specs as tables, with ruff's formatter off, so that an option is a line or two."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Callable, Iterable
from typing import Any, NoReturn

from ..config import FLOAT_FORMS, MAX_COUNT, MAX_WIDTH, int_bounds

EXIT_USAGE = 2
FLAG = "store_true"
REQUIRED = object()


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the problem and the fix) and exit status 2."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")
        raise SystemExit(EXIT_USAGE)


def add(parser: Any, *specs: tuple) -> None:
    """Add one argument to ``parser`` (or an argument group) per spec (see the module doc)."""
    for flag, form, default, metavar, help in specs:
        if form == FLAG:
            kw: dict[str, Any] = {"action": FLAG}
        elif isinstance(form, list):
            kw = {"action": "append", "type": form[0], "metavar": metavar}
        else:
            kw = {"choices" if isinstance(form, tuple) else "type": form, "metavar": metavar}
        if default is not REQUIRED:
            kw.update(default=default, **({} if flag.startswith("-") else {"nargs": "?"}))
        elif flag.startswith("-"):
            kw["required"] = True
        parser.add_argument(flag, help=help, **kw)


def config_specs(cls: type, skip: Any = (), defaults: bool = True) -> list[tuple]:
    """One ``--name`` spec per field of the config dataclass ``cls`` (``config``,
    ``settings``): its type from the field's declared type and bounds (``config._opt``), its
    help the field's, with its default if ``defaults``. An option not given is ``None``: the
    field's default (``config_of``), or the task's for a training setting."""
    specs = []
    for f in (f for f in dataclasses.fields(cls) if f.name not in skip):
        meta, declared = f.metadata, str(f.type).removesuffix(" | None")
        forms = {
            "int": (_integer(*int_bounds(f)), "N"),
            "float": (_float(meta.get("form", "finite"), meta.get("high", math.inf)), "X"),
            "str": (meta.get("choices", str), "NAME"),
            "bool": (yes_no, "yes|no"),
            "tuple[int, ...]": (widths, "W,W"),
            "tuple[str, ...]": (names, "NAMES"),
            "dict[str, float]": ([param], "NAME=VALUE"),
        }
        form, metavar = forms[declared]
        default = f"{f.default:g}" if isinstance(f.default, float) else f.default
        default = ",".join(map(str, default)) if isinstance(default, tuple) else default
        shown = defaults and default not in (None, dataclasses.MISSING)
        flag = "--" + meta.get("flag", f.name).replace("_", "-")
        required = f.default is f.default_factory is dataclasses.MISSING
        help = (meta["help"] + (f" (default {default})" if shown else "")).replace("%", "%%")
        metavar = meta.get("metavar") or (None if "choices" in meta else metavar)
        specs.append((flag, form, REQUIRED if required else None, metavar, help))
    return specs


def config_of(cls: type, args: argparse.Namespace) -> Any:
    """The settings ``cls`` of the options ``config_specs(cls)`` made: the fields given."""
    given = {}
    for f in dataclasses.fields(cls):
        value = getattr(args, f.metadata.get("flag", f.name))
        if value is not None:  # NAME=VALUE pairs make a dict
            given[f.name] = dict(value) if str(f.type).startswith("dict") else value
    return cls(**given)


def _number(cast: Callable, expected: str, ok: Callable, must: str) -> Callable[[str], Any]:
    """A type function: ``cast`` the text, refuse what is not ``ok``, saying what was expected."""

    def parse(text: str) -> Any:
        try:
            value = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not ok(value):
            got = value if cast is int else repr(text)
            raise argparse.ArgumentTypeError(f"must be {must}, got {got}")
        return value

    return parse


def _integer(low: int, high: int) -> Callable[[str], int]:
    """Integers in ``low ... high``, refused with the bound that the value breaks."""
    least = {0: "an integer >= 0", 1: "a positive integer"}.get(low, f"an integer >= {low}")
    below = _number(int, least, lambda v: v >= low, f"{least} (at most {high:,})")

    def parse(text: str) -> int:
        value = below(text)
        if value > high:
            raise argparse.ArgumentTypeError(f"must be at most {high:,}, got {value}")
        return value

    return parse


# Every integer has an upper bound, so that no flag can ask for more than a run can hold
# (MAX_COUNT: counts and seeds, 32-bit in the trainers; MAX_WIDTH: episodes, batches).
positive_int, nonneg_int = _integer(1, MAX_COUNT), _integer(0, MAX_COUNT)
episodes, episodes_or_0 = _integer(1, MAX_WIDTH), _integer(0, MAX_WIDTH)
seed = nonneg_int
finite_float = _number(float, "a number", math.isfinite, "a finite number")
positive_float = _number(float, "a number", lambda v: 0 < v < math.inf, "a finite positive number")
nonneg_float = _number(float, "a number", lambda v: 0 <= v < math.inf, "a finite number >= 0")


def _float(form: str, high: float = math.inf) -> Callable[[str], float]:
    """A config field's float, as its ``form`` (``config.FLOAT_FORMS``) and ``high`` take it."""
    ok, must = FLOAT_FORMS[form]
    upto = f" up to {high:g}" if high < math.inf else ""
    return _number(float, "a number", lambda v: ok(v) and not v > high, must + upto)


def widths(text: str) -> tuple[int, ...]:
    try:
        widths = tuple(int(w) for w in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated layer widths such as 64,64, got {text!r}"
        ) from None
    if not widths or any(w <= 0 for w in widths):
        raise argparse.ArgumentTypeError(f"layer widths must be positive, got {text!r}")
    return widths


def yes_no(text: str) -> bool:
    value = text.strip().lower()
    if value in ("yes", "true", "1", "on", "no", "false", "0", "off"):
        return value in ("yes", "true", "1", "on")
    raise argparse.ArgumentTypeError(f"expected yes or no, got {text!r}")


def param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE such as g=9.81, got {text!r}")
    return name.strip(), finite_float(value)


def names(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected comma-separated names, got {text!r}")
    return names


def pick(args: Any, names: str | Iterable[str]) -> dict[str, Any]:
    """The options (or settings) ``names`` (space-separated, or a collection) as keyword
    arguments of the library call."""
    names = names.split() if isinstance(names, str) else names
    return {name: getattr(args, name) for name in names}


def say(args: argparse.Namespace) -> Callable[[str], None] | None:
    """The progress printer of a command: ``None`` with ``--quiet``."""
    return None if args.quiet else (lambda line: print(line, flush=True))


# Options shared by several commands.
# fmt: off
TASK_HELP = ("a task name (`diffcontrol list`), or your own task as module:Class (from the "
             "current directory) or an entry point of the diffcontrol.tasks group")
TASK = ("task", str, REQUIRED, "TASK", TASK_HELP)
RUN_DIR = ("run_dir", str, REQUIRED, "DIR", "a directory written by `diffcontrol train`")
RUN_TASK = ("--task", str, None, "TASK", "the run's task when it is not a built-in one: its "
            "import path (module:Class) or entry-point name; diffcontrol never imports code "
            "because a file names it")
JSON = ("--json", FLAG, False, None, "print the result as JSON")
QUIET = ("--quiet", FLAG, False, None, "print only the final summary")
LOG_DIR = ("--log-dir", str, None, "DIR", "write the training curves to DIR as TensorBoard event "
           "files (loss, gradient norm, learning rate, evaluation return); needs tensorboardX")
NO_COMPILE_CACHE = ("--no-compile-cache", FLAG, False, None, "do not use JAX's persistent "
                    "compilation cache (also: DIFFCONTROL_NO_COMPILE_CACHE=1)")
# fmt: on


def env_arg(help: str) -> tuple:
    """``--env-arg NAME=VALUE`` (repeatable), with the command's own help."""
    return ("--env-arg", [param], [], "NAME=VALUE", help)
