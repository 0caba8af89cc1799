"""The rules of the trajectory format: columns, units, known environments, validation."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ... import tasks
from ..._registry import env_id as own_env_id
from ...errors import DataFileError
from .._task import data_columns

FORMAT = "diffcontrol-trajectories"
VERSION = 1
TIME_UNITS = ("s", "step")
DISCRETE_UNIT = "index"

Columns = tuple[tuple[str, ...], tuple[str, ...]]


def known_columns() -> dict[str, Columns]:
    """The observation and action columns (names with units) of the Gymnasium environments
    that a registered task names: for every task whose ``data_columns()`` are observations
    (``obs.``) with every unit known, its ``gym_id``, its own ``diffcontrol/<Name>-v0`` and
    its ``data_env_ids``. The task registered first names an id that two tasks share.

    ``diffcontrol record ENV_ID`` names its columns so, and a file whose metadata names such
    an environment (``env_id``) must have exactly these columns.
    """
    return dict(_known_columns(tuple(tasks.names())))


@functools.lru_cache(maxsize=8)
def _known_columns(names: tuple[str, ...]) -> dict[str, Columns]:
    known: dict[str, Columns] = {}
    for name in names:
        task = tasks.make(name)
        obs, act = (tuple(c) for c in data_columns(task))
        parsed = [parse_column(c) for c in (*obs, *act)]
        if any(p != "obs" for p, _, _ in parsed[: len(obs)]) or any(
            u in (None, "", "?") for _, _, u in parsed
        ):
            continue
        for eid in (task.gym_id, own_env_id(task), *getattr(task, "data_env_ids", ())):
            if eid:
                known.setdefault(eid, (obs, act))
    return known


def parse_column(text: str) -> tuple[str, str, str | None]:
    """``"obs.theta_dot [rad/s]"`` -> ``("obs", "theta_dot", "rad/s")``; ``"episode"`` ->
    ``("episode", "", None)``; the unit is ``None`` where the name has no brackets."""
    text = text.strip()
    unit = None
    if text.endswith("]") and "[" in text:
        text, _, unit = text[:-1].rpartition("[")
        text, unit = text.strip(), unit.strip()
    prefix, _, name = text.partition(".")
    return prefix, name, unit


def _episode_starts(episode: np.ndarray) -> list[int]:
    return [0, *(np.flatnonzero(episode[1:] != episode[:-1]) + 1).tolist()] if episode.size else []


def _rows(i: int) -> str:
    return f"row {i}"


def validate(
    time: np.ndarray,
    episode: np.ndarray,
    observations: np.ndarray,
    actions: np.ndarray,
    columns: Sequence[str],
    metadata: dict,
    where: str = "trajectory data",
    row: Callable[[int], str] = _rows,
) -> None:
    """Check arrays and columns against the format; ``row(i)`` names row ``i`` in messages.

    Raises:
        DataFileError: the first rule broken, naming ``where``, the row or column and the fix.
    """

    def bad(problem: str) -> DataFileError:
        return DataFileError(f"{where}: {problem}")

    _check_columns(columns, bad)
    time_col = columns[0]
    k = sum(parse_column(c)[0] in ("obs", "state") for c in columns)
    n = time.shape[0] if time.ndim == 1 else -1
    if n == 0:
        raise bad("holds no rows; record at least one episode (`diffcontrol record`)")
    shapes = {"time": (n,), "episode": (n,), "observations": (n, k)}
    shapes["actions"] = (n, len(columns) - 2 - k)
    for name, arr in zip(shapes, (time, episode, observations, actions)):
        if arr.shape != shapes[name]:
            raise bad(f"{name} has shape {arr.shape} but the columns need {shapes[name]}")
    if not np.issubdtype(episode.dtype, np.integer):
        whole = np.issubdtype(episode.dtype, np.floating) and np.all(np.isfinite(episode))
        if not whole or np.any(episode != np.round(episode)):
            raise bad("episode ids must be whole numbers; number the episodes 0, 1, 2, ...")
    large = np.flatnonzero(np.abs(episode) > 2**53)  # beyond: ids merge once cast to integers
    if large.size:
        raise bad(
            f"{row(int(large[0]))}, column 'episode': the episode id {episode[large[0]]!r} is "
            "larger than 2^53; number the episodes 0, 1, 2, ..."
        )
    _check_rows(time, episode.astype(np.int64), observations, actions, columns, bad, row)
    _check_known(metadata.get("env_id"), columns, bad)
    dt = metadata.get("dt_s")
    if time_col == "time [s]" and isinstance(dt, int | float) and not isinstance(dt, bool):
        steps = np.diff(time)[episode[1:] == episode[:-1]]
        off = np.flatnonzero(~np.isclose(steps, dt, rtol=1e-6, atol=0.0))
        if off.size:
            i = int(np.flatnonzero(episode[1:] == episode[:-1])[off[0]]) + 1
            raise bad(
                f"{row(i)}, column {time_col!r}: a time step of {float(steps[off[0]])!r} s, but the "
                f"metadata's dt_s is {dt!r} s; write time in seconds, or correct dt_s (or "
                "remove it if the steps vary)"
            )


def _check_columns(columns: Sequence[str], bad: Callable[[str], DataFileError]) -> None:
    columns = list(columns)
    if len(columns) < 2 or parse_column(columns[0])[0] != "time":
        raise bad(f"the first column must be 'time [s]' (or 'time [step]'), got {columns[:1]}")
    if parse_column(columns[1])[0] != "episode" or parse_column(columns[1])[2] is not None:
        raise bad(f"the second column must be 'episode' (no unit), got {columns[1:2]}")
    time_unit = parse_column(columns[0])[2]
    if time_unit not in TIME_UNITS:
        raise bad(
            f"column {columns[0]!r}: time must be in seconds, written 'time [s]' (or "
            "'time [step]' for step indices); convert it to seconds"
        )
    seen, kinds, order = set(), set(), []
    for c in columns[2:]:
        prefix, name, unit = parse_column(c)
        if prefix not in ("obs", "state", "action") or not name:
            raise bad(
                f"column {c!r} is not obs.NAME [UNIT], state.NAME [UNIT] or "
                "action.NAME [UNIT]; rename it or remove it"
            )
        if unit is None or not unit:
            raise bad(
                f"column {c!r} has no unit; write it as '{prefix}.{name} [UNIT]' "
                "('[1]' if dimensionless, '[?]' if unknown)"
            )
        if f"{prefix}.{name}" in seen:
            raise bad(f"column {prefix}.{name} appears twice; give each column its own name")
        seen.add(f"{prefix}.{name}")
        order.append(prefix == "action")
        if prefix != "action":
            kinds.add(prefix)
    if len(kinds) > 1:
        raise bad("mixes obs. and state. columns; a file holds one kind, rename one set")
    if not kinds or all(order) or not any(order):
        need = "action.NAME [UNIT]" if kinds else "obs.NAME [UNIT] (or state.NAME [UNIT])"
        raise bad(f"has no {need} column; every file needs observations and actions")
    if order != sorted(order):
        raise bad("the action columns must come after every obs./state. column; reorder them")


def _check_rows(time, episode, obs, act, columns, bad, row) -> None:
    starts = _episode_starts(episode)
    ends = [*starts[1:], episode.size]
    ids = episode[starts]
    if np.unique(ids).size != ids.size:
        dup = next(i for i, s in enumerate(starts) if episode[s] in ids[:i])
        raise bad(
            f"{row(starts[dup])}: episode {ids[dup]} starts again after other episodes; keep "
            "the rows of an episode together (give a new episode a new id)"
        )
    k = obs.shape[1]
    for a, b in zip(starts, ends):
        e = episode[a]
        if b - a < 2:
            raise bad(
                f"{row(a)}: episode {e} has a single row; an episode needs its first "
                "observation, at least one step and its final observation"
            )
        t = time[a:b]
        if not np.all(np.isfinite(t)):
            i = a + int(np.flatnonzero(~np.isfinite(t))[0])
            raise bad(f"{row(i)}, column {columns[0]!r}: time is {time[i]}; give every row a time")
        steps = np.diff(t)
        if np.any(steps <= 0):
            i = a + 1 + int(np.flatnonzero(steps <= 0)[0])
            what = "repeats" if time[i] == time[i - 1] else "goes back"
            raise bad(
                f"{row(i)}, column {columns[0]!r}: time {what} ({float(time[i - 1])!r} then "
                f"{float(time[i])!r}) within episode {e}; time must increase within an episode"
            )
        last = act[b - 1]
        if not np.all(np.isnan(last)):
            raise bad(
                f"{row(b - 1)}: the last row of episode {e} has an action; that row holds the "
                "final observation, so leave its action cells empty (NaN)"
            )
    for arr, offset, what in ((obs, 2, "observations"), (act, 2 + k, "actions")):
        finite = np.isfinite(arr)
        if what == "actions":
            finite[np.asarray(ends) - 1] = True
        if not np.all(finite):
            i, j = (int(x[0]) for x in np.nonzero(~finite))
            raise bad(
                f"{row(i)}, column {columns[offset + j]!r}: {arr[i, j]} (missing or not "
                f"finite); every row needs finite {what} (only an episode's last row has none)"
            )
    for j, c in enumerate(columns[2 + k :]):
        col = act[:, j]
        wrong = np.isfinite(col) & ((col < 0) | (col != np.round(col)))
        if parse_column(c)[2] == DISCRETE_UNIT and wrong.any():
            i = int(np.flatnonzero(wrong)[0])
            raise bad(
                f"{row(i)}, column {c!r}: {col[i]} is not a discrete action index (0, 1, "
                "...); write the index the environment takes, or change the unit"
            )


def _check_known(env_id: Any, columns: Sequence[str], bad: Callable) -> None:
    known = known_columns().get(env_id) if isinstance(env_id, str) else None
    if known is None:
        return
    expected = [*known[0], *known[1]]
    got = list(columns[2:])
    by_name = {parse_column(c)[:2]: c for c in expected}
    for c in got:  # compared parsed, so 'obs.x[m]' is 'obs.x [m]'
        want = by_name.get(parse_column(c)[:2])
        if want is not None and parse_column(want) != parse_column(c):
            raise bad(
                f"column {c!r}: {env_id} gives {parse_column(want)[1]} in "
                f"[{parse_column(want)[2]}]; convert the values and write {want!r}"
            )
    if [parse_column(c) for c in got] != [parse_column(c) for c in expected]:
        raise bad(
            f"columns {got} are not those of {env_id}: expected {expected}; rename them, or "
            "drop env_id from the metadata if the data is from another system"
        )
