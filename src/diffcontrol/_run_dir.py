"""A run directory: its ``run.json`` (what the run is), claimed before anything is written,
and checked when a run resumes in it or another command would write there."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .errors import RunDirectoryError
from .io import read_json, write_json_new

RUN_FILE = "run.json"


ADDED_SETTINGS = {"value_grid": 0, "value_time": False, "window_s": 0.0}
"""Settings added to the configs after runs were stored, each with the value that trains as
before it existed: a stored config without one is read as having that value, so that its run
can still be resumed (``check_same_run``, and the sweeps' claim)."""


def stored_config(config: Any) -> Any:
    """A stored config (a dict from ``run.json`` or ``sweep.json``) with the settings added
    since it was written (``ADDED_SETTINGS``) at their old behaviour; anything else as is."""
    if not isinstance(config, dict):
        return config
    return {**{k: v for k, v in ADDED_SETTINGS.items() if k not in config}, **config}


def check_same_run(out: Path, old: dict, run: dict) -> None:
    """Refuse to resume ``old`` (a ``run.json``) as ``run``: another task or other settings.

    Raises:
        RunDirectoryError: naming what differs.
    """
    old = {**old, "config": stored_config(old.get("config"))}
    run = {**run, "config": stored_config(run["config"])}
    if old.get("task") != run["task"] or old.get("config") != run["config"]:
        stored = old.get("config") if isinstance(old.get("config"), dict) else {}
        changed = sorted(
            k for k in set(stored) | set(run["config"]) if stored.get(k) != run["config"].get(k)
        )
        what = "task" if old.get("task") != run["task"] else ", ".join(changed)
        raise RunDirectoryError(
            f"{out} holds a different run (differs in: {what}); resume it with the same "
            "options or choose a new --out"
        )


def check_no_dangling_link(out: Path) -> None:
    """Refuse an output directory ``out`` that is, or lies under, a symbolic link to nothing:
    creating it would fail with "File exists", which reads as another process's claim.

    Raises:
        RunDirectoryError: naming the link, where it points, and what to do.
    """
    for link in (out, *out.parents):
        if link.is_symlink() and not link.exists():
            target = os.readlink(link)
            where = f"--out {out} is" if link == out else f"--out {out} lies under {link},"
            raise RunDirectoryError(
                f"{where} a symbolic link to {target}, which does not exist; create "
                f"{link.parent / target} first, or choose another --out"
            )


def make_dir(out: Path) -> None:
    """Create the output directory ``out`` and its parents (``check_no_dangling_link``)."""
    check_no_dangling_link(out)
    out.mkdir(parents=True, exist_ok=True)


def check_run_dir(out_dir: str | os.PathLike, run: dict, resume: bool) -> None:
    """Refuse a directory that cannot take this run (``prepare_run_dir``'s checks), writing
    nothing: a run with work to do before it claims its directory (a grid to solve) calls it
    first, so that a directory it cannot have is named before that work.

    Raises:
        RunDirectoryError: as ``prepare_run_dir``.
    """
    out = Path(out_dir)
    check_no_dangling_link(out)
    if out.exists() and not out.is_dir():
        raise RunDirectoryError(f"--out {out} is a file, not a directory; choose a directory")
    existing = out / RUN_FILE
    if existing.exists():
        old = read_json(existing, "run file")
        if not resume:
            seed = (old.get("config") or {}).get("seed")  # a planner's run has none
            seed = "" if seed is None else f", seed {seed!r}"
            raise RunDirectoryError(
                f"{out} already holds a run (task {old.get('task')!r}{seed}); pass --resume to "
                "continue it or choose a new --out"
            )
        check_same_run(out, old, run)
        if old.get("complete"):
            raise RunDirectoryError(f"{out} holds a finished run; there is nothing to resume")
        return
    if resume:
        raise RunDirectoryError(f"nothing to resume: {out} holds no {RUN_FILE}; drop --resume")
    if out.exists() and any(out.iterdir()):
        raise RunDirectoryError(
            f"{out} is not empty and holds no diffcontrol run; choose a new or empty --out"
        )


def prepare_run_dir(out_dir: str | os.PathLike, run: dict, resume: bool) -> Path:
    """Check that ``out_dir`` can take this run (``check_run_dir``), create it, and write
    ``run.json``.

    ``run`` identifies the run (task and config). Without ``resume`` the directory must be
    new or empty; with it, it must hold the same run. Nothing existing is overwritten.

    Raises:
        RunDirectoryError: the directory is not writable, holds something else, or holds a
            different run.
    """
    check_run_dir(out_dir, run, resume)
    out = Path(out_dir)
    existing = out / RUN_FILE
    if resume and existing.exists():  # the same run (check_run_dir compared them)
        return out
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_json_new(existing, run)  # the claim: of two processes, one gets the directory
    except FileExistsError:
        raise RunDirectoryError(
            f"another process has just claimed {out}; choose a new --out"
        ) from None
    except OSError as e:
        raise RunDirectoryError(
            f"cannot write to {out} ({e.strerror}); choose a writable --out"
        ) from None
    return out
