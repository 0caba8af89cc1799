"""Trajectory files: CSV and NPZ writers (atomic) and validating readers."""

from __future__ import annotations

import csv
import io as _io
import json
import math
import os
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import DataFileError
from ...io import _finite, npz_shape, parse_json, read_limited, scalar_arguments, write_bytes
from .._progress import ticking
from ._format import FORMAT, VERSION, parse_column, validate
from ._table import TrajectoryData

MAX_CSV_BYTES = 2**30
"""The largest CSV file read (1 GiB; write more data as .npz)."""


def _header(data: TrajectoryData) -> dict:
    return {"format": FORMAT, "version": VERSION, "metadata": _finite(data.metadata)}


def _number(x: float) -> str:
    return "" if math.isnan(x) else repr(x)


def write_csv(path: str | os.PathLike, data: TrajectoryData) -> None:
    """Write ``data`` as a CSV file (atomically; see the module docstring for the format)."""
    out = _io.StringIO()
    out.write("# " + json.dumps(_header(data), allow_nan=False) + "\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(data.columns)
    values = np.concatenate([data.observations, data.actions], axis=1).tolist()
    for t, e, v in zip(data.time.tolist(), data.episode.tolist(), values):
        writer.writerow([_number(t), e, *map(_number, v)])
    write_bytes(path, out.getvalue().encode())


def write_npz(path: str | os.PathLike, data: TrajectoryData) -> None:
    """Write ``data`` as an ``.npz`` of plain arrays and a JSON header (atomically)."""
    header = {**_header(data), "columns": list(data.columns)}
    buf = _io.BytesIO()
    np.savez(
        buf,
        time=data.time,
        episode=data.episode,
        observations=data.observations,
        actions=data.actions,
        header=np.frombuffer(json.dumps(header, allow_nan=False).encode(), dtype=np.uint8),
    )
    write_bytes(path, buf.getvalue())


def write_trajectories(path: str | os.PathLike, data: TrajectoryData) -> None:
    """Write ``data`` as CSV or NPZ, by the extension of ``path`` (``.csv``, ``.npz``)."""
    {".csv": write_csv, ".npz": write_npz}[file_suffix(path)](path, data)


def file_suffix(path: str | os.PathLike, what: str = "trajectory") -> str:
    """``.csv`` or ``.npz``, from the extension of ``path`` (a ``what`` file).

    Raises:
        DataFileError: another extension.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise DataFileError(
            f"{path}: unknown {what} file type {suffix or '(none)'!r}; use a .csv or .npz file"
        )
    return suffix


def readable_suffix(path: Path, what: str, record: str) -> str:
    """The suffix of a data file to read, after refusing a missing or empty one (``record``:
    the command that makes one)."""
    suffix = file_suffix(path, what)
    if not path.is_file():
        raise DataFileError(f"{path} does not exist (or is not a file); check the path")
    if path.stat().st_size == 0:
        raise DataFileError(f"{path} is empty; record it again (`{record}`)")
    return suffix


def check_header(header: Any, path: Path, format_: str, version: int, hint: str = "") -> dict:
    """The metadata of a data file's JSON header, after checking its format and version
    (``hint``: said after "not a FORMAT file" when the format is another one).

    Raises:
        DataFileError: another format or version, or metadata that is not an object.
    """
    line = f'{{"format": "{format_}", "version": {version}}}'
    if not isinstance(header, dict) or header.get("format") != format_:
        raise DataFileError(f"{path}: not a {format_} file{hint}; its header must be {line}")
    if header.get("version") != version:
        raise DataFileError(
            f"{path}: {format_} version {header.get('version')!r} is not supported (this "
            f"diffcontrol reads version {version}); write it again with this diffcontrol"
        )
    meta = header.get("metadata", {})
    if not isinstance(meta, dict):
        raise DataFileError(f"{path}: 'metadata' in the header must be a JSON object")
    # what later steps pass on (fit -> fitted.json -> train --model, evaluate) is typed here
    env_id = meta.get("env_id")
    if env_id is not None and (not isinstance(env_id, str) or env_id.count(":") > 1):
        raise DataFileError(f"{path}: the metadata's env_id {env_id!r} is not an environment id")
    kwargs, params = meta.get("env_kwargs"), meta.get("params")
    if kwargs is not None and not scalar_arguments(kwargs):
        raise DataFileError(
            f"{path}: the metadata's env_kwargs {kwargs!r} must map names to numbers or text"
        )
    if params is not None and not (
        isinstance(params, dict)
        and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in params.values()
        )
    ):
        raise DataFileError(f"{path}: the metadata's params {params!r} must be finite numbers")
    return meta


def read_trajectories(path: str | os.PathLike) -> TrajectoryData:
    """Read and validate a trajectory file, CSV or NPZ by its extension.

    Raises:
        DataFileError: the file is missing, empty, of an unknown type or version, or breaks
            a rule of the format; the message names the file, the line or row, the column
            and the fix.
    """
    path = Path(path)
    suffix = readable_suffix(path, "trajectory", "diffcontrol record")
    return _read_csv(path) if suffix == ".csv" else _read_npz(path)


def csv_parts(path: Path, format_: str, version: int) -> tuple[Any, list[str], list]:
    """The parts of a diffcontrol CSV file (of any format): the JSON header of its
    first line (unchecked), the column names, and the other non-empty rows as ``(line number,
    cells)``.

    Raises:
        DataFileError: not text, no JSON header line, or no column names (naming the line).
    """
    try:
        text = read_limited(path, MAX_CSV_BYTES, "data file")  # not /dev/zero named .csv
        lines = text.decode("utf-8-sig").splitlines()  # -sig: a spreadsheet's BOM
    except UnicodeDecodeError:
        raise DataFileError(f"{path} is not a text file; is it an .npz named .csv?") from None
    first = lines[0] if lines else ""
    try:
        header = parse_json(first[1:]) if first.startswith("#") else None
    except ValueError as e:
        raise DataFileError(f"{path}, line 1: the header is not valid JSON ({e})") from None
    if header is None:
        raise DataFileError(
            f"{path}, line 1: no header; the first line must be "
            f'# {{"format": "{format_}", "version": {version}, "metadata": {{...}}}}'
        )
    try:
        rows = ticking(csv.reader(lines[1:]), len(lines) - 1, f"parsing {path}")
        body = [(n, row) for n, row in enumerate(rows, start=2) if row]
    except csv.Error as e:  # e.g. a field longer than the csv module's limit
        raise DataFileError(f"{path}: not a CSV table diffcontrol can read ({e})") from None
    if not body:
        raise DataFileError(f"{path}: no column names after the header line; see the format")
    return header, [c.strip() for c in body[0][1]], body[1:]


def csv_table(path: Path, columns: list[str], rows: list, rule: str) -> np.ndarray:
    """The numbers of a CSV body (``csv_parts``' rows) as a [rows, columns] array, an empty
    cell as NaN; a row of the wrong length or a cell that is not a number is a
    ``DataFileError`` naming the file, the line and the column (``rule`` says what a row
    needs)."""
    table = np.empty((len(rows), len(columns)))
    for i, (line, cells) in enumerate(ticking(rows, len(rows), f"reading the numbers of {path}")):
        if len(cells) != len(columns):
            raise DataFileError(
                f"{path}, line {line}: {len(cells)} cells but {len(columns)} columns; {rule}"
            )
        for j, cell in enumerate(cells):
            try:
                table[i, j] = float(cell) if cell.strip() else np.nan
            except ValueError:
                raise DataFileError(
                    f"{path}, line {line}, column {columns[j]!r}: {cell!r} is not a number"
                ) from None
    return table


def _read_csv(path: Path) -> TrajectoryData:
    header, columns, rows = csv_parts(path, FORMAT, VERSION)
    meta = check_header(header, path, FORMAT, VERSION)
    n_cols = len(columns)
    if not rows:
        raise DataFileError(f"{path} holds no rows; record at least one episode")
    table = csv_table(
        path,
        columns,
        rows,
        "every row needs one cell per column (an empty cell for a missing action)",
    )
    lines_of = [line for line, _ in rows]
    episode = table[:, 1] if n_cols > 1 else np.zeros(0)
    k = sum(parse_column(c)[0] in ("obs", "state") for c in columns)
    args = (table[:, 0], episode, table[:, 2 : 2 + k], table[:, 2 + k :], columns, meta)
    validate(*args, where=str(path), row=lambda i: f"line {lines_of[i]}")
    return TrajectoryData(*args[:4], columns=tuple(columns), metadata=meta)


_NPZ_ARRAYS = ("time", "episode", "observations", "actions", "header")
MAX_NPZ_ELEMENTS = 10**9
"""The most numbers one array of a data file may declare (8 GB of float64): a file that
claims more is refused before anything is read."""


def npz_arrays(npz: Any, names: tuple[str, ...], path: Path) -> dict[str, np.ndarray]:
    """The arrays ``names`` of an open ``.npz``, each refused unread if its declared size is
    beyond ``MAX_NPZ_ELEMENTS``."""
    for name in names:
        shape, _ = npz_shape(npz, name)
        if int(np.prod(shape, dtype=object)) > MAX_NPZ_ELEMENTS:
            raise DataFileError(
                f"{path}: array {name!r} claims shape {shape}, more than any recording; "
                "write it again"
            )
    return {name: npz[name] for name in names}


def read_npz(path: Path, names: Sequence[str], missing: Callable[[list[str]], str]) -> tuple:
    """The arrays ``names`` (one of them ``header``, a JSON text) of the .npz at ``path``,
    bounded in size and checked to hold real numbers: ``(arrays without the header, header)``.

    Raises:
        DataFileError: an unreadable file, a missing array (``missing(names)`` says what the
            file should hold), a header that is not JSON, an array that is not numbers.
    """
    try:
        with np.load(path, allow_pickle=False) as npz:
            absent = [name for name in names if name not in npz.files]
            if absent:
                raise DataFileError(f"{path}: missing array(s) {absent}{missing(absent)}")
            arrays = npz_arrays(npz, names, path)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise DataFileError(f"{path} is not a readable .npz ({e}); write it again") from None
    try:
        header = parse_json(arrays.pop("header").tobytes())
    except ValueError as e:
        raise DataFileError(f"{path}: the header array is not JSON ({e}); write it again") from None
    for name, arr in arrays.items():
        if not np.issubdtype(arr.dtype, np.integer) and not np.issubdtype(arr.dtype, np.floating):
            raise DataFileError(
                f"{path}: array {name!r} has dtype {arr.dtype}; it must hold real numbers"
            )
    return arrays, header


def _read_npz(path: Path) -> TrajectoryData:
    hint = (
        f"; a trajectory .npz holds {list(_NPZ_ARRAYS)} (write it with diffcontrol.data.write_npz)"
    )
    arrays, header = read_npz(path, _NPZ_ARRAYS, lambda absent: hint)
    meta = check_header(header, path, FORMAT, VERSION)
    columns = header.get("columns")
    if not isinstance(columns, list) or not all(isinstance(c, str) for c in columns):
        raise DataFileError(f"{path}: the header has no list of column names under 'columns'")
    validate(*arrays.values(), columns, meta, where=str(path))
    return TrajectoryData(**arrays, columns=tuple(columns), metadata=meta)
