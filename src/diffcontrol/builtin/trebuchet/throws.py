"""The trebuchet's recorded throws: one-step episodes of the trajectory table, read and checked.

A throw is an episode of one step in a ``diffcontrol-trajectories`` file (``identify.data``),
with the columns of ``TrebuchetAiming.data_columns()`` (``THROW_COLUMNS``)::

    time [step],episode,state.wind [m/s],state.distance [m],action.release_angle [deg],action.counterweight [lb]
    0,0,-2.0,0.0,45.0,200.0
    1,0,-2.0,74.81,,

The first row is what is known before the throw and the aim: the wind the anemometer read
(m/s, ``+`` blowing toward the target, within +-20 m/s: the simulator's step budgets are
checked for that range), the distance 0 (nothing has landed yet), the release angle (degrees
above the horizontal, in ``(0, 90]``) and the counterweight (pounds, in ``(0, 600]``: heavier
ones make the simulator's Euler steps diverge; ``system.check_inputs``). The
second row is the outcome: the same wind and the measured distance (m from the pivot), and no
action. These are the ``distance`` and ``wind`` of the task's state ``(target, wind,
distance)``; the target is the controller's, not the physics', and is not recorded.

``read_throws`` reads such a file, and also a ``diffcontrol-throws`` file (one row a throw,
the columns ``wind [m/s]``, ``release_angle [deg]``, ``counterweight [lb]`` and ``distance
[m]`` in any order, CSV or NPZ of one array a column), converted to the table. Either way a
column in another unit is refused with the conversion (``distance [ft]``: "multiply by
0.3048"), as is an input out of its range, naming the file, the line, row or episode and the
column.

``record`` records throws (``record_throws``), ``fit`` fits the
trebuchet's physics to them.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ...errors import DataFileError
from ...identify.data import TrajectoryData, parse_column, read_trajectories
from ...identify.data._files import (
    check_header,
    csv_parts,
    csv_table,
    npz_arrays,
    read_npz,
    readable_suffix,
)
from ...io import parse_json
from .task import THROW_COLUMNS

COLUMNS = (*THROW_COLUMNS[0], *THROW_COLUMNS[1])
"""The four throw columns of the table: wind, distance, release angle, counterweight."""
FIELDS = ("wind", "distance", "release_angle", "counterweight")
"""Their names in ``Throws``, in the same order."""
MAX_WIND_MPS = 20.0
"""Recorded winds must lie within +-this (m/s)."""
ANGLE_LIMITS_DEG = (0.0, 90.0)
"""Release angles must lie in ``(low, high]`` degrees."""
WEIGHT_LIMITS_LB = (0.0, 600.0)
"""Counterweights must lie in ``(low, high]`` pounds."""

OLD_FORMAT, OLD_VERSION = "diffcontrol-throws", 1
OLD_COLUMNS = ("wind [m/s]", "distance [m]", "release_angle [deg]", "counterweight [lb]")
"""A ``diffcontrol-throws`` file's columns, in the order of ``FIELDS``."""
_CONVERT = {
    "wind": {"km/h": "divide by 3.6", "mph": "multiply by 0.44704", "kn": "multiply by 0.5144"},
    "release_angle": {"rad": "multiply by 180/pi"},
    "counterweight": {"kg": "divide by 0.45359237"},
    "distance": {"ft": "multiply by 0.3048", "yd": "multiply by 0.9144", "km": "times 1000"},
}


class Throws(NamedTuple):
    """Recorded throws as four float64 arrays [N]: the wind (m/s), the measured distance (m),
    the release angle (degrees) and the counterweight (pounds)."""

    wind: np.ndarray
    distance: np.ndarray
    release_angle: np.ndarray
    counterweight: np.ndarray


def throws_table(throws: Throws, metadata: dict | None = None) -> TrajectoryData:
    """The trajectory table of ``throws``: one episode of two rows a throw (module docstring).

    Raises:
        DataFileError: a value out of its range (``check_ranges``) or not finite.
    """
    wind, distance, angle, weight = (np.asarray(x, np.float64).reshape(-1) for x in throws)
    check_ranges(
        Throws(wind, distance, angle, weight), "throw data", COLUMNS, lambda i: f"throw {i}"
    )
    n = wind.size
    before = np.stack([wind, np.zeros(n)], axis=1)
    after = np.stack([wind, distance], axis=1)
    aim = np.stack([angle, weight], axis=1)
    return TrajectoryData(
        time=np.tile([0.0, 1.0], n),
        episode=np.repeat(np.arange(n), 2),
        observations=np.stack([before, after], axis=1).reshape(2 * n, 2),
        actions=np.stack([aim, np.full((n, 2), np.nan)], axis=1).reshape(2 * n, 2),
        columns=("time [step]", "episode", *COLUMNS),
        metadata=dict(metadata or {}),
    )


def throws_of(data: TrajectoryData, where: str = "the data") -> Throws:
    """The throws of a trajectory table (module docstring), checked.

    Raises:
        DataFileError: other columns or units, an episode of more than one step, a first row
            whose distance is not 0 or whose wind differs from the second's, or an input out of
            its range; the message names ``where``, the episode and the column.
    """
    columns = [*data.observation_columns, *data.action_columns]
    order = _column_order(columns, COLUMNS, where, "the task's data_columns()")
    if data.num_steps != data.num_episodes:
        ep = next(e for e in data.episodes() if len(e.actions) != 1)
        raise DataFileError(
            f"{where}: episode {ep.id} has {len(ep.actions)} steps; a throw is an episode of "
            "one step (the aim, then the measured distance)"
        )
    x, u, x_next = data.transitions()
    before, after = np.concatenate([x, u], axis=1), np.concatenate([x_next, u], axis=1)
    throws = Throws(
        *(after[:, j] if f == "distance" else before[:, j] for f, j in zip(FIELDS, order))
    )
    ids = [e.id for e in data.episodes()]
    j_wind, j_distance = order[0], order[1]
    for bad, what in (
        (before[:, j_distance] != 0, "its first row's distance is not 0 (nothing has landed yet)"),
        (after[:, j_wind] != before[:, j_wind], "its two rows have different winds"),
    ):
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataFileError(
                f"{where}, episode {ids[i]}: {what}; write a throw as its wind and distance 0, "
                "then the same wind and the measured distance"
            )
    check_ranges(throws, where, [columns[j] for j in order], lambda i: f"episode {ids[i]}")
    return throws


def check_ranges(throws: Throws, where: str, columns: Any, row: Any) -> None:
    """Refuse non-finite values and inputs out of the simulator's checked ranges; ``columns``
    names the four fields as the data does, ``row(i)`` the throw ``i``.

    Raises:
        DataFileError: the first value refused, naming ``where``, the row, the column and the fix.
    """
    names = dict(zip(FIELDS, columns))
    if throws.wind.size == 0:
        raise DataFileError(
            f"{where}: holds no throws; record some (`diffcontrol record trebuchet`)"
        )
    for field, x in throws._asdict().items():
        if not np.all(np.isfinite(x)):
            i = int(np.flatnonzero(~np.isfinite(x))[0])
            raise DataFileError(
                f"{where}, {row(i)}, column {names[field]!r}: {x[i]} (missing or not finite); "
                "every throw needs all four numbers: fill it in or drop the throw"
            )
    limits = {
        "wind": (-MAX_WIND_MPS, MAX_WIND_MPS, "[{:g}, {:g}] m/s", False),
        "release_angle": (*ANGLE_LIMITS_DEG, "({:g}, {:g}] degrees", True),
        "counterweight": (*WEIGHT_LIMITS_LB, "({:g}, {:g}] lb", True),
    }
    for field, (lo, hi, text, open_low) in limits.items():
        x = getattr(throws, field)
        out = ((x <= lo) if open_low else (x < lo)) | (x > hi)
        if out.any():
            i = int(np.flatnonzero(out)[0])
            raise DataFileError(
                f"{where}, {row(i)}, column {names[field]!r}: {float(x[i])!r} is outside "
                f"{text.format(lo, hi)}; check the unit ({parse_column(names[field])[2]}) or drop "
                "the throw (the simulator is not checked there)"
            )


def _column_order(
    columns: list[str], expected: tuple[str, ...], where: Any, what: str
) -> list[int]:
    """The position among ``columns`` of each of ``expected`` (in ``FIELDS`` order), matched by
    name; a missing, repeated or unknown column, or one in another unit, is refused by name."""
    want = {}
    for c in expected:
        prefix, name, unit = parse_column(c)
        want[f"{prefix}.{name}" if name else prefix] = (c, unit)
    found: dict[str, int] = {}
    for j, c in enumerate(columns):
        prefix, name, unit = parse_column(c)
        key = f"{prefix}.{name}" if name else prefix
        if key not in want:
            raise DataFileError(
                f"{where}: unknown column {c!r}; throws have exactly the columns "
                f"{list(expected)} ({what}): rename it or remove it"
            )
        if key in found:
            raise DataFileError(f"{where}: column {key!r} appears twice; keep one")
        right, right_unit = want[key]
        if unit != right_unit:
            how = _CONVERT[key.rpartition(".")[2]].get(unit or "")
            fix = f"convert it ({how}) and" if how else "convert the values to"
            raise DataFileError(
                f"{where}: column {c!r} is in [{unit or 'no unit'}] but must be in "
                f"[{right_unit}]; {fix} write {right!r}"
            )
        found[key] = j
    missing = [c for key, (c, _) in want.items() if key not in found]
    if missing:
        raise DataFileError(f"{where}: missing column(s) {missing}; throws need {list(expected)}")
    return [found[key] for key in want]


def read_throws(path: str | os.PathLike) -> TrajectoryData:
    """Read recorded throws: a trajectory file of one-step episodes, or a ``diffcontrol-throws``
    file converted to one (CSV or NPZ by the extension).

    Raises:
        DataFileError: the file is missing, empty, of an unknown type, format or version, or
            breaks a rule of its format or of the throws (``throws_of``); the message names
            the file, the line, row or episode, the column and the fix.
    """
    path = Path(path)
    suffix = readable_suffix(path, "throws", "diffcontrol record trebuchet")
    if _file_format(path, suffix) == OLD_FORMAT:
        return _read_old(path, suffix)
    data = read_trajectories(path)
    throws_of(data, str(path))
    return data


def _file_format(path: Path, suffix: str) -> Any:
    """The ``format`` a data file's header names, or None where it cannot be read here (the
    reader then says why)."""
    try:
        if suffix == ".csv":
            with open(path, encoding="utf-8-sig") as f:
                first = f.readline()
            header = parse_json(first[1:]) if first.startswith("#") else None
        else:
            with np.load(path, allow_pickle=False) as npz:
                raw = npz_arrays(npz, ("header",), path)["header"] if "header" in npz else None
            header = None if raw is None else parse_json(raw.tobytes())
    except (OSError, ValueError, UnicodeDecodeError, zipfile.BadZipFile, EOFError):
        return None
    return header.get("format") if isinstance(header, dict) else None


def _read_old(path: Path, suffix: str) -> TrajectoryData:
    """A ``diffcontrol-throws`` file (one row a throw) as the throws' trajectory table."""
    if suffix == ".csv":
        header, columns, rows = csv_parts(path, OLD_FORMAT, OLD_VERSION)
        meta = check_header(header, path, OLD_FORMAT, OLD_VERSION)
        order = _column_order(columns, OLD_COLUMNS, path, f"a {OLD_FORMAT} file")
        table = csv_table(path, columns, rows, "every throw needs one number per column")
        throws = Throws(*(table[:, j] for j in order))
        lines = [line for line, _ in rows]
        check_ranges(throws, str(path), [columns[j] for j in order], lambda i: f"line {lines[i]}")
        return throws_table(throws, meta)
    names = (*FIELDS, "header")

    def missing(absent: list[str]) -> str:
        cols = [c for c, f in zip(OLD_COLUMNS, FIELDS) if f in absent]
        return (
            f" (the column(s) {cols})" if cols else ""
        ) + f"; a {OLD_FORMAT} .npz holds {list(names)}"

    arrays, header = read_npz(path, names, missing)
    meta = check_header(header, path, OLD_FORMAT, OLD_VERSION)
    columns = header.get("columns", list(OLD_COLUMNS))
    if not isinstance(columns, list) or not all(isinstance(c, str) for c in columns):
        raise DataFileError(f"{path}: 'columns' in the header must be a list of column names")
    _column_order(columns, OLD_COLUMNS, path, f"a {OLD_FORMAT} file")  # the declared units
    if any(arrays[f].shape != arrays["wind"].shape or arrays[f].ndim != 1 for f in FIELDS):
        shapes = {f: arrays[f].shape for f in FIELDS}
        raise DataFileError(f"{path}: the four columns must be 1-D of one length, got {shapes}")
    throws = Throws(*(np.asarray(arrays[f], np.float64) for f in FIELDS))
    check_ranges(throws, str(path), OLD_COLUMNS, lambda i: f"row {i}")
    return throws_table(throws, meta)
