"""Recorded trebuchet throws: the ``ThrowData`` value and its CSV and NPZ files.

The format (``diffcontrol-throws``, version 1) is one table, a row per throw, with four
columns named with their units in brackets (``THROW_COLUMNS``):

- ``wind [m/s]``: the wind the anemometer read at the throw, ``+`` blowing toward the target,
  within +-20 m/s (``MAX_WIND_MPS``: the simulator's step budgets are checked for that range);
- ``release_angle [deg]``: degrees above the horizontal, in ``(0, 90]``;
- ``counterweight [lb]``: pounds, in ``(0, 600]`` (heavier ones make the simulator's Euler
  steps diverge; ``systems.trebuchet.check_inputs``);
- ``distance [m]``: where the projectile landed, metres from the pivot.

The columns may come in any order; other columns are refused by name (so that a
``distance [ft]`` or ``release_angle [rad]`` column is never misread). Every cell is a finite
number.

CSV: the first line is ``#`` followed by a JSON header, then the column names, then the rows::

    # {"format": "diffcontrol-throws", "version": 1, "metadata": {"system": "trebuchet", ...}}
    wind [m/s],release_angle [deg],counterweight [lb],distance [m]
    -2.0,45.0,200.0,74.81
    ...

NPZ: the float64 arrays ``wind``, ``release_angle``, ``counterweight`` and ``distance`` [N],
and ``header``: the JSON header as UTF-8 bytes (uint8). No object arrays; read with
``allow_pickle=False``. ``metadata`` is free JSON; ``record_throws`` writes ``system``,
``source``, ``seed``, ``noise_m`` (the standard deviation of the Gaussian noise added to the
distances, m), ``params`` (the physical parameters of the trebuchet that threw, where known)
and ``recorded`` (UTC time).
"""

from __future__ import annotations

import csv
import dataclasses
import io as _io
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ...errors import ConfigError, DataFileError
from ...io import _finite, write_bytes
from ._files import (
    check_header,
    csv_parts,
    csv_table,
    file_suffix,
    npz_arrays,
    readable_suffix,
)
from ._format import parse_column

THROWS_FORMAT = "diffcontrol-throws"
THROWS_VERSION = 1
THROW_COLUMNS = ("wind [m/s]", "release_angle [deg]", "counterweight [lb]", "distance [m]")
"""The columns, with the only units accepted."""
MAX_WIND_MPS = 20.0
"""Recorded winds must lie within +-this (m/s)."""
ANGLE_LIMITS_DEG = (0.0, 90.0)
"""Release angles must lie in ``(low, high]`` degrees."""
WEIGHT_LIMITS_LB = (0.0, 600.0)
"""Counterweights must lie in ``(low, high]`` pounds."""

_FIELDS = ("wind", "release_angle", "counterweight", "distance")
_UNITS = {parse_column(c)[0]: parse_column(c)[2] for c in THROW_COLUMNS}
_CONVERT = {
    "wind": {"km/h": "divide by 3.6", "mph": "multiply by 0.44704", "kn": "multiply by 0.5144"},
    "release_angle": {"rad": "multiply by 180/pi"},
    "counterweight": {"kg": "divide by 0.45359237"},
    "distance": {"ft": "multiply by 0.3048", "yd": "multiply by 0.9144", "km": "times 1000"},
}


@dataclasses.dataclass(frozen=True, eq=False)
class ThrowData:
    """Recorded throws (see the module docstring for the format and the accepted ranges).

    Args:
        wind: [N] wind (m/s), ``+`` toward the target.
        release_angle: [N] release angle (degrees).
        counterweight: [N] counterweight (pounds).
        distance: [N] where the projectile landed (m from the pivot).
        metadata: free JSON (``system``, ``params``, ``noise_m``, ``seed``, ...).

    Raises:
        DataFileError: an array of another shape, a non-finite value or an input out of its
            range (the message names the row, the column and the fix).
    """

    wind: np.ndarray
    release_angle: np.ndarray
    counterweight: np.ndarray
    distance: np.ndarray
    metadata: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        arrays = {name: np.array(getattr(self, name), np.float64) for name in _FIELDS}
        validate_throws(arrays)
        for name, arr in arrays.items():
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "metadata", dict(self.metadata))

    @property
    def num_throws(self) -> int:
        return int(self.wind.size)

    def __len__(self) -> int:
        return self.num_throws

    def select(self, index: slice | np.ndarray) -> ThrowData:
        """The throws at ``index`` (a slice, integer indices or a boolean mask)."""
        return dataclasses.replace(self, **{n: getattr(self, n)[index] for n in _FIELDS})

    def split(self, fit_throws: int) -> tuple[ThrowData, ThrowData]:
        """``(fit, held_out)``: the first ``fit_throws`` throws and the rest.

        Raises:
            ConfigError: not ``1 <= fit_throws < num_throws``.
        """
        if not 1 <= fit_throws < self.num_throws:
            raise ConfigError(
                f"cannot keep {fit_throws} of {self.num_throws} throws for fitting and hold "
                f"the rest out; choose 1 to {self.num_throws - 1} (or record more throws)"
            )
        return self.select(slice(0, fit_throws)), self.select(slice(fit_throws, None))

    def __repr__(self) -> str:
        return f"ThrowData(throws={self.num_throws}, metadata={self.metadata!r})"


def _rows(i: int) -> str:
    return f"row {i}"


def validate_throws(arrays: dict, where: str = "throw data", row=_rows) -> None:
    """Check the four arrays (by field name) against the format; ``row(i)`` names row ``i``.

    Raises:
        DataFileError: the first rule broken, naming ``where``, the row, the column and the fix.
    """
    shapes = {name: np.shape(arrays[name]) for name in _FIELDS}
    n = shapes["wind"][0] if len(shapes["wind"]) == 1 else -1
    if any(s != (n,) for s in shapes.values()):
        raise DataFileError(f"{where}: the four columns must be 1-D of one length, got {shapes}")
    if n == 0:
        raise DataFileError(
            f"{where}: holds no throws; record some (`diffcontrol record trebuchet`)"
        )
    columns = dict(zip(_FIELDS, THROW_COLUMNS))
    for name in _FIELDS:
        bad = ~np.isfinite(arrays[name])
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataFileError(
                f"{where}, {row(i)}, column {columns[name]!r}: {arrays[name][i]} (missing or "
                "not finite); every throw needs all four numbers: fill it in or drop the row"
            )
    limits = {
        "wind": (-MAX_WIND_MPS, MAX_WIND_MPS, "[{:g}, {:g}] m/s", False),
        "release_angle": (*ANGLE_LIMITS_DEG, "({:g}, {:g}] degrees", True),
        "counterweight": (*WEIGHT_LIMITS_LB, "({:g}, {:g}] lb", True),
    }
    for name, (lo, hi, text, open_low) in limits.items():
        x = arrays[name]
        out = ((x <= lo) if open_low else (x < lo)) | (x > hi)
        if out.any():
            i = int(np.flatnonzero(out)[0])
            raise DataFileError(
                f"{where}, {row(i)}, column {columns[name]!r}: {x[i]!r} is outside "
                f"{text.format(lo, hi)}; check the unit ({_UNITS[name]}) or drop the throw "
                "(the simulator is not checked there)"
            )


def _header(data: ThrowData) -> dict:
    return {
        "format": THROWS_FORMAT,
        "version": THROWS_VERSION,
        "metadata": _finite(data.metadata),
    }


def write_throws(path: str | os.PathLike, data: ThrowData) -> None:
    """Write ``data`` as CSV or NPZ by the extension of ``path`` (atomically).

    Raises:
        DataFileError: an extension other than ``.csv`` or ``.npz``.
    """
    suffix = file_suffix(path, "throws")
    if suffix == ".csv":
        out = _io.StringIO()
        out.write("# " + json.dumps(_header(data), allow_nan=False) + "\n")
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(THROW_COLUMNS)
        table = np.stack([getattr(data, n) for n in _FIELDS], axis=1).tolist()
        writer.writerows([[repr(v) for v in r] for r in table])  # repr: float64 round trip
        write_bytes(path, out.getvalue().encode())
    else:
        buf = _io.BytesIO()
        header = json.dumps({**_header(data), "columns": list(THROW_COLUMNS)}, allow_nan=False)
        arrays = {n: getattr(data, n) for n in _FIELDS}
        np.savez(buf, **arrays, header=np.frombuffer(header.encode(), dtype=np.uint8))
        write_bytes(path, buf.getvalue())


def _check_header(header: object, path: Path) -> dict:
    what = header.get("format") if isinstance(header, dict) else None
    hint = (
        " (it holds trajectories: fit a control task to it, or record throws with "
        "`diffcontrol record trebuchet --episodes N`)"
        if what == "diffcontrol-trajectories"
        else ""
    )
    return check_header(header, path, THROWS_FORMAT, THROWS_VERSION, hint)


def _column_order(columns: list[str], path: Path) -> list[int]:
    """The position of each of ``_FIELDS`` among ``columns``; refuses missing, repeated,
    unknown and wrongly-unitted columns by name."""
    found: dict[str, int] = {}
    for j, c in enumerate(columns):
        prefix, name, unit = parse_column(c)
        field = prefix if not name else f"{prefix}.{name}"
        if field not in _UNITS:
            raise DataFileError(
                f"{path}: unknown column {c!r}; a throws file has exactly the columns "
                f"{list(THROW_COLUMNS)}: rename it or remove it"
            )
        if field in found:
            raise DataFileError(f"{path}: column {field!r} appears twice; keep one")
        if unit != _UNITS[field]:
            how = _CONVERT[field].get(unit or "")
            fix = f"convert it ({how}) and" if how else "convert the values to"
            raise DataFileError(
                f"{path}: column {c!r} is in [{unit or 'no unit'}] but must be in "
                f"[{_UNITS[field]}]; {fix} write {dict(zip(_FIELDS, THROW_COLUMNS))[field]!r}"
            )
        found[field] = j
    missing = [c for c, f in zip(THROW_COLUMNS, _FIELDS) if f not in found]
    if missing:
        raise DataFileError(
            f"{path}: missing column(s) {missing}; a throws file needs {list(THROW_COLUMNS)}"
        )
    return [found[f] for f in _FIELDS]


def read_throws(path: str | os.PathLike) -> ThrowData:
    """Read and validate a throws file, CSV or NPZ by its extension.

    Raises:
        DataFileError: the file is missing, empty, of an unknown type or version, lacks a
            column or has one in the wrong unit, or holds a non-finite or out-of-range value;
            the message names the file, the line or row, the column and the fix.
    """
    path = Path(path)
    suffix = readable_suffix(path, "throws", "diffcontrol record trebuchet")
    return _read_csv(path) if suffix == ".csv" else _read_npz(path)


def _read_csv(path: Path) -> ThrowData:
    header, columns, rows = csv_parts(path, THROWS_FORMAT, THROWS_VERSION)
    meta = _check_header(header, path)
    order = _column_order(columns, path)
    table = csv_table(path, columns, rows, "every throw needs one number per column")
    arrays = {f: table[:, j] for f, j in zip(_FIELDS, order)}
    lines_of = [line for line, _ in rows]
    validate_throws(arrays, where=str(path), row=lambda i: f"line {lines_of[i]}")
    return ThrowData(**arrays, metadata=meta)


def _read_npz(path: Path) -> ThrowData:
    names = (*_FIELDS, "header")
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [n for n in names if n not in npz.files]
            if missing:
                cols = [c for c, f in zip(THROW_COLUMNS, _FIELDS) if f in missing]
                raise DataFileError(
                    f"{path}: missing array(s) {missing}"
                    + (f" (the column(s) {cols})" if cols else "")
                    + f"; a throws .npz holds {list(names)} (write it with "
                    "diffcontrol.data.write_throws)"
                )
            arrays = npz_arrays(npz, names, path)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise DataFileError(f"{path} is not a readable .npz ({e}); write it again") from None
    try:
        header = json.loads(arrays.pop("header").tobytes().decode())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DataFileError(f"{path}: the header array is not JSON ({e}); write it again") from None
    meta = _check_header(header, path)
    columns = header.get("columns", list(THROW_COLUMNS))
    if not isinstance(columns, list) or not all(isinstance(c, str) for c in columns):
        raise DataFileError(f"{path}: 'columns' in the header must be a list of column names")
    _column_order(columns, path)  # the units the header declares
    for name, arr in arrays.items():
        if not np.issubdtype(arr.dtype, np.integer) and not np.issubdtype(arr.dtype, np.floating):
            raise DataFileError(
                f"{path}: array {name!r} has dtype {arr.dtype}; it must hold real numbers"
            )
    validate_throws(arrays, where=str(path))
    return ThrowData(**arrays, metadata=meta)
