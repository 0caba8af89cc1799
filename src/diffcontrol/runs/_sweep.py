"""Sweeping into a directory: what ``diffcontrol sweep`` does, as one library call.

A sweep directory holds ``sweep.json`` (the task, the base settings, the seeds and swept
values; ``"complete"`` once every member is written), one run directory per member (named by
its index and swept values; ``diffcontrol evaluate`` and ``diffcontrol.load`` read each), the
table ``sweep.txt`` and the plot ``sweep.png``. The best member (by its returned in-simulator
evaluation return) also gets the task's final evaluation and pictures.

Resuming trains only the members whose directories are not complete: a member is the unit of
work that is kept (an interrupted program's members start again; members are independent, so
their results are the same to noise).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .. import _jax_setup, _run_dir, io, policies
from .._run_files import METRICS_FILE, MODEL_FILE, mark_complete, read_run_file, save_run
from .._shell import command as shell_command
from ..errors import ConfigError, RunDirectoryError
from ..tasks import named_by_file, resolve
from ..training import TrainResult, resolve_config
from ..training._sweep import MAX_MEMBERS, check_discrete, check_members, grid, sweep
from ._open import open_run
from ._train import RunInterrupted

SWEEP_FILE = "sweep.json"
SWEEP_FORMAT = "diffcontrol-sweep"


def member_name(index: int, config: Any, swept: Sequence[str]) -> str:
    """The directory name of member ``index``: its index and swept values."""
    parts = [f"{index:03d}"]
    for name in swept:
        value = getattr(config, name)
        parts.append(f"{name}{value:g}" if isinstance(value, float) else f"{name}{value}")
    return "-".join(parts).replace("/", "_")


def sweep_dir(
    out_dir: str | Path,
    task: str | None = None,
    *,
    seeds: Sequence[int] | str = (0,),
    values: dict[str, Sequence[Any]] | Sequence[str] | None = None,
    settings: dict[str, Any] | None = None,
    recipe: str | None = None,
    devices: int | None = None,
    resume: bool = False,
    final_eval: int | None = None,
    compile_cache: bool = True,
    progress: Callable[[str], None] | None = None,
    log_dir: str | Path | None = None,
) -> tuple[Any, list[str]]:
    """Train a grid of runs of ``task`` as one program and write them into ``out_dir``.

    Args:
        out_dir: the sweep directory (new or empty; with ``resume``, the sweep to continue).
        task: a registered task name or an import path ``module:Class`` (``None`` with
            ``resume``: the sweep's own).
        seeds: the training seeds, or their text (``"0-63"``, ``"0,3,7"``: ``parse_seeds``).
        values: setting name -> values to try (e.g. ``{"learning_rate": [1e-3, 3e-3]}``),
            or ``NAME=V1,V2`` items as the command line writes them (``parse_values``).
        settings: overrides of the base settings (``None`` values skipped).
        recipe: a named set of settings of the task to start from.
        devices: local devices to shard the members over (default: all that divide them).
        resume: continue the sweep in ``out_dir`` with its own settings (``seeds``,
            ``values``, ``settings`` and ``recipe`` are then not used): only the members not
            yet written are trained.
        final_eval: the best member's final evaluation size (``None``: the task's default).
        compile_cache: use JAX's persistent compilation cache (unless
            ``DIFFCONTROL_NO_COMPILE_CACHE`` is set).
        progress: called with each progress line.
        log_dir: write the training curves there as TensorBoard event files, one run per
            member named as its directory (a sweep of more than 64 members: their summary).

    Returns:
        The ``SweepResult`` of the members trained now (``None`` if none were left) and the
        names of the files and directories written.

    Raises:
        ConfigError, RunDirectoryError: bad settings, or a directory that holds something else.
    """
    say = progress or (lambda line: None)
    out = Path(out_dir)
    if task is None and resume:  # the sweep's own task: registered ones only
        stored_task = stored_sweep(out)["task"]
        fix = shell_command("sweep", str(stored_task), "--out", out, "--resume")
        task = named_by_file(stored_task, str(out / SWEEP_FILE), fix).name
    if task is None:
        raise ConfigError("name the TASK to sweep (or --resume the sweep in --out)")
    seeds = parse_seeds(seeds) if isinstance(seeds, str) else seeds
    the_task = resolve(task)
    check_discrete(the_task)  # before a continuous task's config is given BPTT's settings
    given = sorted(n for n, v in (settings or {}).items() if v is not None)
    if not resume:  # the settings every member starts from; values checked against them
        base = resolve_config(the_task, recipe, **(settings or {}))
        if values is not None and not isinstance(values, dict):
            values = parse_values(values, base)
        both = [n for n in given if n in (values or {})]
        if both:  # one would silently win over the other
            name, value = both[0], settings[both[0]]
            shown = ",".join(map(str, value)) if isinstance(value, tuple | list) else value
            raise ConfigError(
                f"{_flag(name)} {shown} and --set {name}=... both set {name}; give it once: "
                f"its values in --set, or one value in {_flag(name)}"
            )
    elif given or values or recipe:  # a resumed sweep keeps its own settings
        dropped = [_flag(n) for n in given] + ["--set"] * bool(values) + ["--recipe"] * bool(recipe)
        raise ConfigError(
            f"--resume continues the sweep in {out} with the settings in its {SWEEP_FILE}; "
            f"drop {', '.join(dropped)}"
        )
    if compile_cache and not os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE"):
        _jax_setup.enable_compile_cache()
    if resume:  # the sweep's own settings, from its directory alone
        stored = stored_sweep(out)
        base = type(the_task.default_config()).from_json(stored["config"])
        seeds, values = stored["seeds"], stored["values"]
    configs = grid(base, seeds, values)
    swept = ["seed", *(values or {})]
    doc = {
        "format": SWEEP_FORMAT,
        "task": the_task.name,
        "config": base.to_json(),
        "seeds": list(seeds),
        "values": {k: list(v) for k, v in (values or {}).items()},
        "members": [member_name(i, c, swept) for i, c in enumerate(configs)],
    }
    check_members(the_task, configs, devices)
    _claim(out, doc, resume)
    todo = [i for i, name in enumerate(doc["members"]) if not _complete(out / name)]
    if resume:
        say(f"resuming the sweep in {out}: {len(todo)} of {len(configs)} member(s) left")
    result = None
    named = [task] if ":" in task else []
    try:
        if todo:
            say(
                f"sweeping {the_task.name}: {len(todo)} member(s) ({', '.join(swept)}) x "
                f"{base.updates} updates -> {out}"
            )
            members = [configs[i] for i in todo]
            logged = {"log_dir": log_dir, "log_names": [doc["members"][i] for i in todo]}
            result = sweep(the_task, members, devices=devices, progress=say, **logged)
            for i, member in zip(todo, result.members, strict=True):
                _write_member(out / doc["members"][i], member, task)
    except BaseException as e:
        written = any(_complete(out / name) for name in doc["members"])
        if not written:  # nothing kept: give the directory back
            (out / SWEEP_FILE).unlink(missing_ok=True)
            if not any(out.iterdir()):
                out.rmdir()
        if not isinstance(e, KeyboardInterrupt):
            raise
        if not written:
            raise RunInterrupted(
                "interrupted before any member was written; nothing was kept"
            ) from None
        raise RunInterrupted(
            f"interrupted; the members written are kept in {out}. Train the others with: "
            f"{shell_command('sweep', *named, '--out', out, '--resume')}"
        ) from None
    try:
        _finish(out, doc, the_task, configs, swept, final_eval, say)
    except KeyboardInterrupt:  # every member is written: a resume trains none again
        raise RunInterrupted(
            f"interrupted after every member was trained; they are kept in {out}. Evaluate "
            f"the best and write the table with: "
            f"{shell_command('sweep', *named, '--out', out, '--resume')}"
        ) from None
    return result, [SWEEP_FILE, "sweep.txt", "sweep.png", *doc["members"]]


def _finish(
    out: Path,
    doc: dict,
    the_task: Any,
    configs: Sequence[Any],
    swept: Sequence[str],
    final_eval: int | None,
    say: Callable[[str], None],
) -> None:
    """The end of a sweep whose members are all written: the best member's final evaluation
    and pictures, ``sweep.txt``, ``sweep.png`` and ``sweep.json`` marked complete."""
    rows = [_row(out / name, configs[i], swept) for i, name in enumerate(doc["members"])]
    best = max(range(len(rows)), key=lambda i: _rank(rows[i]["eval_return"]))
    best_dir = out / doc["members"][best]
    if not (best_dir / "learning_curve.png").exists():
        run = open_run(best_dir, the_task, real=None)
        member = _as_result(run)
        save_run(  # the member's own directory, evaluated and drawn now
            member, best_dir, final_eval=final_eval, animation=False, progress=say, overwrite=True
        )
    table = _table(rows, swept, best)
    io.write_bytes(out / "sweep.txt", (table + "\n").encode())
    from ..plots import sweep_plot  # matplotlib

    sweep_plot(rows, swept, best, the_task.name, out / "sweep.png")
    io.write_json(out / SWEEP_FILE, {**doc, "best": doc["members"][best], "complete": True})
    say(table)


def _flag(name: str) -> str:
    """The command-line option of the setting ``name``."""
    return "--" + name.replace("_", "-")


def _claim(out: Path, doc: dict, resume: bool) -> None:
    """Create ``out`` with its ``sweep.json`` (exclusively), or check it holds this sweep."""
    path = out / SWEEP_FILE
    if resume:
        if not path.is_file():
            raise RunDirectoryError(f"{out} holds no sweep to resume; start one without --resume")
        stored = io.read_json(path, "sweep file")
        same = isinstance(stored, dict) and all(
            stored.get(k) == doc[k] for k in ("format", "task", "seeds", "values")
        )
        same = same and _run_dir.stored_config(stored.get("config")) == _run_dir.stored_config(
            doc["config"]
        )
        if not same:
            raise RunDirectoryError(
                f"{out} holds a different sweep; resume it with its own settings "
                f"(`{shell_command('sweep', '--out', out, '--resume')}` alone) or choose another --out"
            )
        return
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise RunDirectoryError(f"--out {out} exists and is not an empty directory; choose another")
    _run_dir.make_dir(out)
    try:
        io.write_json_new(path, doc)
    except FileExistsError:
        raise RunDirectoryError(f"another process claimed {out}; choose another --out") from None


def stored_sweep(out_dir: str | Path) -> dict:
    """The settings of the sweep in ``out_dir`` (to resume it from its directory alone)."""
    path = Path(out_dir) / SWEEP_FILE
    if not path.is_file():
        raise RunDirectoryError(f"{out_dir} holds no sweep to resume; start one without --resume")
    doc = io.read_json(path, "sweep file")
    ok = (
        isinstance(doc, dict)
        and doc.get("format") == SWEEP_FORMAT
        and isinstance(doc.get("config"), dict)
        and isinstance(doc.get("seeds"), list)
        and isinstance(doc.get("values"), dict)
        and isinstance(doc.get("task"), str)
    )
    if not ok:
        raise RunDirectoryError(f"{path} is not a diffcontrol sweep file; choose another --out")
    return doc


def _complete(member_dir: Path) -> bool:
    """Whether a member is written whole: its run.json says so and its model.json and
    metrics.json read back (a damaged member is trained again)."""
    try:
        run = read_run_file(member_dir)
        if not (run and run.get("complete")):
            return False
        policies.read_model(member_dir / MODEL_FILE)
        return isinstance(io.read_json(member_dir / METRICS_FILE, "metrics"), dict)
    except Exception:  # noqa: BLE001 - a damaged member is trained again
        return False


def _write_member(member_dir: Path, result: Any, task_spec: str) -> None:
    """A member's run directory: ``run.json`` (complete), ``model.json``, ``metrics.json``."""
    member_dir.mkdir(parents=True, exist_ok=True)
    metrics = {**result.metrics, "created": io.now_iso()}
    io.write_json(
        member_dir / _run_dir.RUN_FILE,
        {
            "format": "diffcontrol-run",
            "task": result.task.name,
            "config": result.config.to_json(),
            "invocation": {"task": task_spec, "sweep": str(member_dir.parent)},
        },
    )
    io.write_json(
        member_dir / MODEL_FILE,
        policies.model_document(result.task, result.controller, result.config, metrics),
    )
    io.write_json(member_dir / METRICS_FILE, metrics)
    mark_complete(member_dir)


def _as_result(run: Any) -> Any:
    return TrainResult(
        task=run.task,
        config=run.config,
        params=run.params,
        controller=run.controller,
        metrics=run.metrics,
    )


def _row(member_dir: Path, config: Any, swept: Sequence[str]) -> dict[str, Any]:
    metrics = io.read_json(member_dir / METRICS_FILE, "metrics")
    return {
        "dir": member_dir.name,
        **{name: getattr(config, name) for name in swept},
        "returned_update": metrics.get("returned_update"),
        "eval_return": metrics.get("final_eval_return"),
        "stopped_early": metrics.get("stopped_early"),
        "diverged": metrics.get("diverged"),
    }


def _rank(value: Any) -> float:
    return value if isinstance(value, (int, float)) and math.isfinite(value) else -math.inf


def _table(rows: list[dict[str, Any]], swept: Sequence[str], best: int) -> str:
    head = ["member", *swept, "returned update", "eval return (simulator)", ""]
    body = []
    for i, r in enumerate(rows):
        value = r["eval_return"]
        body.append(
            [
                r["dir"],
                *(f"{r[n]:g}" if isinstance(r[n], float) else str(r[n]) for n in swept),
                str(r["returned_update"]),
                f"{value:.2f}" if isinstance(value, (int, float)) else "-",
                ("best " if i == best else "")
                + ("early stop" if r["stopped_early"] else "diverged" if r["diverged"] else ""),
            ]
        )
    widths = [max(len(row[j]) for row in [head, *body]) for j in range(len(head))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
        for row in [head, *body]
    )


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-63"``, ``"0,3,7"`` or ``"0-3,8"`` (ranges include both ends).

    Raises:
        ConfigError: not such a list, a negative or huge seed, a range that runs
            downwards, more than ``MAX_MEMBERS`` seeds, or a repeated one.
    """
    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            first, last = int(lo), int(hi) if hi else int(lo)
        except ValueError:
            if not lo and hi.strip().isdigit():  # "-1": a negative seed, not a range
                raise ConfigError(
                    f"--seeds {part.strip()!r}: a seed must be in 0 ... {2**31 - 1:,}"
                ) from None
            raise ConfigError(
                f"--seeds takes seeds and ranges such as 0-63 or 0,3,7, got {text!r}"
            ) from None
        # Each rule its own message: the one that the text breaks is the one named.
        if not (0 <= first < 2**31 and 0 <= last < 2**31):
            raise ConfigError(f"--seeds {part.strip()!r}: a seed must be in 0 ... {2**31 - 1:,}")
        if first > last:
            raise ConfigError(
                f"--seeds {part.strip()!r}: a range runs upwards; write it as {last}-{first}"
            )
        if len(seeds) + last - first >= MAX_MEMBERS:  # counted before the list is made
            raise ConfigError(
                f"--seeds {text!r} names more than {MAX_MEMBERS:,} seeds, the most members a "
                "sweep may have; sweep fewer seeds, or split the sweep"
            )
        seeds += range(first, last + 1)
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"--seeds {text!r} names a seed twice; name each once")
    return seeds


def parse_values(items: Sequence[str], config: Any) -> dict[str, list[Any]]:
    """Swept settings from ``NAME=V1,V2,...`` items (layer widths as ``64x64``), each value
    of the setting's own type, checked by the config.

    Raises:
        ConfigError: an unknown setting, a value of the wrong type, or a setting given twice.
    """
    fields = {f.name: f for f in dataclasses.fields(config)}
    values: dict[str, list[Any]] = {}
    for item in items:
        name, eq, text = item.partition("=")
        name = name.strip().replace("-", "_")
        if not eq or name not in fields or name in ("seed", "params"):
            known = ", ".join(n for n in fields if n not in ("seed", "params"))
            raise ConfigError(
                f"--set takes NAME=V1,V2 with NAME one of {known} (seeds go in --seeds), "
                f"got {item!r}"
            )
        if name in values:
            raise ConfigError(f"--set {name} is given twice; list all its values in one --set")
        options = [parse_field_value(config, name, v.strip()) for v in text.split(",")]
        for v in options:
            config.replace(**{name: v})  # the config's own checks, with their messages
        values[name] = options
    return values


def parse_field_value(config: Any, name: str, text: str) -> Any:
    """The value of field ``name`` of ``config`` written as ``text`` (command-line form:
    ``3e-3``, ``64x64`` for layer widths, ``yes``/``no``), of the field's declared type.

    Raises:
        ConfigError: ``text`` is not a value of that type.
    """
    declared = next(str(f.type) for f in dataclasses.fields(config) if f.name == name)
    try:
        if declared == "int":
            return int(text)
        if declared == "float":
            return float(text)
        if declared == "bool":
            return {"yes": True, "true": True, "no": False, "false": False}[text.lower()]
        if declared == "tuple[int, ...]":
            return tuple(int(w) for w in text.split("x"))
        return text
    except (ValueError, KeyError):
        form = {"int": "an integer", "float": "a number", "bool": "yes or no"}
        raise ConfigError(
            f"{name} takes {form.get(declared, 'layer widths such as 64x64')}, got {text!r}"
        ) from None
