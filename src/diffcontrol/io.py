"""Files, written atomically and read back checked: ``metrics.json``, ``run.json`` and
checkpoints (``model.json`` and its policies are ``diffcontrol.policy``'s).

Nothing here loads pickle: JSON for everything people read, ``.npz`` opened with
``allow_pickle=False`` for checkpoints. Every write goes to a temporary file in the same
directory, is flushed to disk, and replaces the target with ``os.replace``, so a crash leaves
either the old file or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import io as _io
import json
import math
import os
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jax
import numpy as np

from .errors import ModelFileError, RunDirectoryError

MAX_JSON_BYTES = 256 * 2**20
"""The largest JSON file read (a model.json of a very wide network is a few MiB)."""
CHECKPOINT_FORMAT = "diffcontrol-checkpoint"
CHECKPOINT_VERSION = 1

# ---------------------------------------------------------------------------------------------
# atomic writes


_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def _atomic(path: Path, mode: str) -> Iterator[Any]:
    path = Path(path)
    with named_errors(path):
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual mode
        with os.fdopen(fd, mode) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with _atomic(Path(path), "wb") as f:
        f.write(data)


def write_figure(fig: Any, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Render a matplotlib figure to PNG, write it atomically to ``path``, and close it."""
    import matplotlib.pyplot as plt

    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    write_bytes(path, buf.getvalue())
    return Path(path)


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically. Non-finite floats become ``null``."""
    text = json.dumps(_finite(obj), indent=1, allow_nan=False)
    write_bytes(path, (text + "\n").encode())


def write_json_new(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as JSON to ``path`` only if nothing is there: the whole file appears at
    once (a hard link of a finished temporary file), and of two processes racing for the same
    path exactly one succeeds.

    Raises:
        FileExistsError: ``path`` exists (or another process created it first).
    """
    path = Path(path)
    text = json.dumps(_finite(obj), indent=1, allow_nan=False)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)
        with os.fdopen(fd, "w") as f:
            f.write(text + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.link(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


@contextlib.contextmanager
def named_errors(path: Path) -> Iterator[None]:
    """A file-system error while writing ``path`` through a temporary file names ``path``
    (the file the user asked for), not the temporary one."""
    try:
        yield
    except FileExistsError:
        raise
    except OSError as e:
        if e.filename in (None, str(path)) or e.errno is None:
            raise
        raise OSError(e.errno, e.strerror, str(path)) from None


def write_new(path: str | os.PathLike, write: Any) -> Any:
    """Create the new file ``path`` with ``write(tmp_path)`` (any writer; ``tmp_path`` keeps the
    suffix) such that of two processes racing for it exactly one succeeds, and the other's
    work is refused rather than silently replacing the first (a hard link cannot replace).

    Returns:
        What ``write`` returned.

    Raises:
        RunDirectoryError: ``path`` was created meanwhile.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}.new{path.suffix}")
    try:
        with named_errors(path):
            result = write(tmp)
            os.link(tmp, path)
    except FileExistsError:
        raise RunDirectoryError(
            f"{path} was created by another process meanwhile; choose a new file name"
        ) from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
    return result


def _finite(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray | np.generic):
        return _finite(obj.tolist())
    return obj


def parse_json(text: str | bytes) -> Any:
    """``json.loads``, with every way a hostile text breaks it as one ``ValueError`` of one
    line: malformed JSON, nesting deeper than the interpreter's stack (``RecursionError``), an
    integer of more digits than Python converts, bytes that are not UTF-8."""
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("nested too deeply to be one of ours") from None
    except ValueError as e:  # JSONDecodeError, UnicodeDecodeError, the int digit limit
        raise ValueError(" ".join(str(e).split())[:200]) from None


def read_limited(path: Path, limit: int, what: str) -> bytes:
    """The bytes of ``path``, refused past ``limit``: read ``limit + 1`` at most, so that a
    device or a pipe named as a file (``/dev/zero``) cannot exhaust the memory.

    Raises:
        ModelFileError: the file is larger than ``limit``.
    """
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise ModelFileError(
            f"{what} {path} is larger than {limit // 2**20} MiB; it is not one diffcontrol writes"
        )
    return data


def read_json(path: str | os.PathLike, what: str = "file") -> Any:
    """Read JSON, turning a missing, oversized or malformed file into a ``ModelFileError``."""
    path = Path(path)
    try:
        return parse_json(read_limited(path, MAX_JSON_BYTES, what))
    except FileNotFoundError:
        raise ModelFileError(f"{what} {path} does not exist") from None
    except IsADirectoryError:
        raise ModelFileError(f"{what} {path} is a directory, not a file") from None
    except ModelFileError:
        raise
    except ValueError as e:
        raise ModelFileError(f"{what} {path} is not valid JSON ({e}); re-create it") from None


def scalar_arguments(kwargs: Any) -> bool:
    """Whether ``kwargs`` (read from a file) maps names to JSON scalars only: finite numbers,
    text, true or false, what an environment's keyword arguments can be."""
    return isinstance(kwargs, dict) and all(
        isinstance(k, str)
        and (isinstance(v, str | bool) or (isinstance(v, int | float) and math.isfinite(v)))
        for k, v in kwargs.items()
    )


def now_iso() -> str:
    """The current UTC time, ISO 8601, to the second."""
    return _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat()


def check_new_file(path: str | os.PathLike, suffix: str) -> Path:
    """Check that ``path`` can take a new file ending in ``suffix``: its folder exists and
    nothing is there yet (nothing is overwritten).

    Raises:
        RunDirectoryError: it exists, ends otherwise, or its folder does not exist.
    """
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise RunDirectoryError(f"{path} does not end in {suffix}; choose a {suffix} file name")
    if path.exists() or path.is_symlink():
        raise RunDirectoryError(f"{path} already exists; choose a new file name")
    if not path.parent.is_dir():
        raise RunDirectoryError(f"the folder {path.parent} does not exist; create it first")
    return path


# ---------------------------------------------------------------------------------------------
# checkpoints: one .npz of arrays plus a JSON header, no pickle


def save_checkpoint(path: str | os.PathLike, tree: Any, meta: dict) -> None:
    """Save the array leaves of ``tree`` and a JSON-able ``meta`` dict to ``path`` atomically."""
    leaves = jax.tree.leaves(tree)
    header = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "leaves": len(leaves)}
    header["meta"] = _finite(meta)
    arrays = {f"leaf_{i:04d}": np.asarray(x) for i, x in enumerate(leaves)}
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    buf = _io.BytesIO()
    np.savez(buf, **arrays)
    write_bytes(path, buf.getvalue())


def npz_shape(data: Any, name: str) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype an ``.npz`` member declares, read from its header alone."""
    with data.zip.open(f"{name}.npy") as f:
        version = np.lib.format.read_magic(f)
        read = {
            (1, 0): np.lib.format.read_array_header_1_0,
            (2, 0): np.lib.format.read_array_header_2_0,
        }.get(version)
        if read is None:
            raise ValueError(f"unsupported .npy version {version}")
        shape, _, dtype = read(f)
    return tuple(shape), dtype


def _check_meta(meta: Any, bad: Any) -> None:
    """A checkpoint's ``meta``: the curve so far, the best point's index, the seconds."""
    if not isinstance(meta, dict) or not isinstance(meta.get("curve"), list):
        raise bad("holds no learning curve")
    curve = meta["curve"]
    if not all(isinstance(p, dict) and isinstance(p.get("update"), int) for p in curve):
        raise bad("holds a malformed learning curve")
    best = meta.get("best_index")
    if not isinstance(best, int) or not (0 <= best < max(1, len(curve))):
        raise bad(f"holds a best point {best!r} outside its curve")
    for name in ("seconds_before", "compile_seconds_before"):
        value = meta.get(name)
        if not isinstance(value, int | float) or not (0 <= value < math.inf):
            raise bad(f"holds a bad {name} ({value!r})")


def load_checkpoint(path: str | os.PathLike, like: Any) -> tuple[Any, dict]:
    """Load a checkpoint into the structure of ``like``; returns ``(tree, meta)``.

    Raises:
        ModelFileError: the file is missing, corrupt, or does not fit ``like`` (a different
            run's checkpoint).
    """
    path = Path(path)
    leaves_like, treedef = jax.tree.flatten(like)

    def bad(problem: str) -> ModelFileError:
        return ModelFileError(f"checkpoint {path} {problem}; start a new run in a new directory")

    try:
        with np.load(path, allow_pickle=False) as data:
            header = parse_json(bytes(data["header"]))
            if (
                header.get("format") != CHECKPOINT_FORMAT
                or header.get("version") != CHECKPOINT_VERSION
            ):
                raise bad("has an unknown format or version")
            if header["leaves"] != len(leaves_like):
                raise bad("does not match this run's configuration")
            _check_meta(header.get("meta"), bad)
            leaves = []
            for i, ref in enumerate(leaves_like):
                name = f"leaf_{i:04d}"
                ref_arr = np.asarray(ref)
                # the stored shape first: a file that claims a huge array is refused unread
                if npz_shape(data, name) != (ref_arr.shape, ref_arr.dtype):
                    raise bad("does not match this run's configuration")
                leaves.append(jax.numpy.asarray(data[name]))
    except ModelFileError:
        raise
    except FileNotFoundError:
        raise bad("does not exist") from None
    except Exception as e:  # truncated, not a zip, a list header...: never a traceback
        raise bad(f"is corrupt ({type(e).__name__}: {e})") from None
    return jax.tree.unflatten(treedef, leaves), header["meta"]


# ---------------------------------------------------------------------------------------------
# run directories

RUN_FILE = "run.json"


ADDED_SETTINGS = {"value_grid": 0, "value_time": False}
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
