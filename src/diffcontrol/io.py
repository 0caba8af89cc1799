"""Files, written atomically and read back checked: JSON documents, figures and bytes (a run
directory's claim is ``_run_dir``'s, checkpoints ``training._checkpoint``'s, ``model.json``
and its policies ``diffcontrol.policies``').

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
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ModelFileError, RunDirectoryError

MAX_JSON_BYTES = 256 * 2**20
"""The largest JSON file read (a model.json of a very wide network is a few MiB)."""

# ---------------------------------------------------------------------------------------------
# atomic writes


def _temporary(path: Path) -> Path:
    """A new temporary file's name beside ``path``. The name is chosen before the file is
    created, so that a ``try`` entered first removes it whatever instant an interrupt
    (Ctrl-C, SIGTERM) lands at, even between its creation and the return of the call."""
    return path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")


def _create(tmp: Path, path: Path) -> int:
    """Create ``tmp`` exclusively with the usual mode (0666 less the umask), its errors naming
    ``path``."""
    with named_errors(path):
        return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)


@contextlib.contextmanager
def _atomic(path: Path, mode: str) -> Iterator[Any]:
    path = Path(path)
    tmp = _temporary(path)
    try:
        with os.fdopen(_create(tmp, path), mode) as f:
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
    tmp = _temporary(path)
    try:
        with os.fdopen(_create(tmp, path), "w") as f:
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
        # a regular file by its size, before a byte is read; anything else by what it yields
        too_big = os.fstat(f.fileno()).st_size > limit
        data = b"" if too_big else f.read(limit + 1)
    if too_big or len(data) > limit:
        raise ModelFileError(
            f"{what} {path} is larger than {limit // 2**20} MiB; it is not one diffcontrol writes"
        )
    return data


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
