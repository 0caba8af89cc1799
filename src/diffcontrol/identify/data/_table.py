"""``TrajectoryData``: recorded episodes as one validated table."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from typing import Any, NamedTuple

import numpy as np

from ...errors import ConfigError, DataFileError
from ._format import _episode_starts, parse_column, validate


class Episode(NamedTuple):
    """One episode of ``n`` steps: ``time`` [n+1], ``observations`` [n+1, k] (the last is
    the final one), ``actions`` [n, m] (``actions[t]`` takes ``observations[t]`` to ``[t+1]``)."""

    id: int
    time: np.ndarray
    observations: np.ndarray
    actions: np.ndarray


@dataclasses.dataclass(frozen=True, eq=False)
class TrajectoryData:
    """Recorded episodes as one table (see the module docstring for the format).

    Args:
        time: [T] row times, in the unit of ``columns[0]`` (``s`` or ``step``).
        episode: [T] integer episode ids, each episode's rows contiguous.
        observations: [T, k] observations (or states); finite.
        actions: [T, m] actions; NaN on the last row of every episode, finite elsewhere.
        columns: the ``2 + k + m`` column names with units: ``time [s]``, ``episode``, the
            observation columns, the action columns.
        metadata: free JSON (``env_id``, ``dt_s``, ``source``, ...).

    Raises:
        DataFileError: the arrays or columns break a rule of the format (the message names
            the row and column and the fix).
    """

    time: np.ndarray
    episode: np.ndarray
    observations: np.ndarray
    actions: np.ndarray
    columns: tuple[str, ...]
    metadata: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        # copies, so that making them read-only never touches the caller's arrays
        fields = {
            "time": np.array(self.time, np.float64),
            "episode": np.array(self.episode),
            "observations": np.array(self.observations, np.float64),
            "actions": np.array(self.actions, np.float64),
            "columns": tuple(self.columns),
            "metadata": dict(self.metadata),
        }
        for name, value in fields.items():
            object.__setattr__(self, name, value)
        validate(*fields.values())
        object.__setattr__(self, "episode", self.episode.astype(np.int64))
        for name in ("time", "episode", "observations", "actions"):
            getattr(self, name).setflags(write=False)

    @classmethod
    def from_episodes(
        cls,
        observations: Sequence[Any],
        actions: Sequence[Any],
        observation_columns: Sequence[str],
        action_columns: Sequence[str],
        dt_s: float | None = None,
        metadata: dict | None = None,
    ) -> TrajectoryData:
        """Build the table from per-episode arrays: ``observations[i]`` [n_i + 1, k] and
        ``actions[i]`` [n_i, m]. Time is ``step * dt_s`` in s, or the step index (``time
        [step]``) when ``dt_s`` is None. Episodes are numbered 0, 1, ..."""
        if len(observations) != len(actions):
            raise DataFileError(
                f"{len(observations)} observation arrays but {len(actions)} action arrays; "
                "pass one of each per episode"
            )
        obs = [np.asarray(o, np.float64).reshape(len(o), -1) for o in observations]
        act = [np.asarray(a, np.float64).reshape(len(a), -1) for a in actions]
        m = len(action_columns)
        pad = [np.concatenate([a.reshape(-1, m), np.full((1, m), np.nan)]) for a in act]
        steps = [np.arange(len(o), dtype=np.float64) for o in obs]
        # rounded to 1e-12 s so the CSV says 9.95, not 9.950000000000001
        time = (
            np.round(np.concatenate(steps) * (1.0 if dt_s is None else dt_s), 12)
            if obs
            else np.zeros(0)
        )
        unit = "step" if dt_s is None else "s"
        meta = {"dt_s": dt_s, **(metadata or {})}
        return cls(
            time=time,
            episode=np.concatenate([np.full(len(o), i) for i, o in enumerate(obs)] or [[]]),
            observations=np.concatenate(obs) if obs else np.zeros((0, len(observation_columns))),
            actions=np.concatenate(pad) if pad else np.zeros((0, m)),
            columns=(f"time [{unit}]", "episode", *observation_columns, *action_columns),
            metadata=meta,
        )

    @property
    def observation_columns(self) -> tuple[str, ...]:
        return self.columns[2 : 2 + self.observations.shape[1]]

    @property
    def action_columns(self) -> tuple[str, ...]:
        return self.columns[2 + self.observations.shape[1] :]

    @property
    def holds(self) -> str:
        """What the table's rows hold: ``"obs"`` (observations) or ``"state"`` (physical
        states)."""
        return parse_column(self.columns[2])[0]

    @property
    def units(self) -> dict[str, str | None]:
        """The unit of every column by its name without the unit (``"obs.theta_dot"``)."""
        out = {}
        for c in self.columns:
            prefix, name, unit = parse_column(c)
            out[f"{prefix}.{name}" if name else prefix] = unit
        return out

    @property
    def env_id(self) -> str | None:
        return self.metadata.get("env_id")

    @property
    def num_episodes(self) -> int:
        return int(np.unique(self.episode).size)

    @property
    def num_steps(self) -> int:
        """Transitions ``(x_t, u_t, x_{t+1})`` over all episodes: rows minus episodes."""
        return int(self.time.size) - self.num_episodes

    def episodes(self) -> Iterator[Episode]:
        """The episodes in file order, each with the final row's NaN action dropped."""
        starts = _episode_starts(self.episode)
        for a, b in zip(starts, [*starts[1:], self.episode.size]):
            yield Episode(
                int(self.episode[a]),
                self.time[a:b],
                self.observations[a:b],
                self.actions[a : b - 1],
            )

    def transitions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x, u, x_next)``: [N, k], [N, m], [N, k] over every step of every episode."""
        eps = list(self.episodes())
        return (
            np.concatenate([e.observations[:-1] for e in eps]),
            np.concatenate([e.actions for e in eps]),
            np.concatenate([e.observations[1:] for e in eps]),
        )

    def select(self, ids: Sequence[int]) -> TrajectoryData:
        """The episodes with the given ids, in file order."""
        keep = np.isin(self.episode, np.asarray(ids, np.int64))
        return dataclasses.replace(
            self,
            time=self.time[keep],
            episode=self.episode[keep],
            observations=self.observations[keep],
            actions=self.actions[keep],
        )

    def split(self, train_episodes: int) -> tuple[TrajectoryData, TrajectoryData]:
        """``(train, held_out)``: the first ``train_episodes`` episodes and the rest.

        Raises:
            ConfigError: not ``1 <= train_episodes < num_episodes``.
        """
        ids = [e.id for e in self.episodes()]
        if not 1 <= train_episodes < len(ids):
            raise ConfigError(
                f"cannot keep {train_episodes} of {len(ids)} episodes for training and hold "
                f"the rest out; choose 1 to {len(ids) - 1} (or record more episodes)"
            )
        return self.select(ids[:train_episodes]), self.select(ids[train_episodes:])

    def __repr__(self) -> str:
        return (
            f"TrajectoryData(env_id={self.env_id!r}, episodes={self.num_episodes}, "
            f"steps={self.num_steps}, columns={list(self.columns)})"
        )


def concat(parts: Sequence[TrajectoryData]) -> TrajectoryData:
    """The episodes of every table in ``parts``, in order, renumbered 0, 1, ... (the metadata is
    the first table's, with ``sources``: each part's ``source``).

    Raises:
        DataFileError: no tables, or tables with different columns.
    """
    if not parts:
        raise DataFileError("nothing to concatenate: pass at least one table")
    first = parts[0]
    for p in parts[1:]:
        if p.columns != first.columns:
            raise DataFileError(
                f"cannot join tables with the columns {list(first.columns)} and "
                f"{list(p.columns)}; record the same system"
            )
    episodes, offset = [], 0
    for p in parts:
        order = {int(e): i for i, e in enumerate(dict.fromkeys(p.episode.tolist()))}
        episodes.append(np.array([order[int(e)] for e in p.episode]) + offset)
        offset += len(order)
    meta = {**first.metadata, "sources": [p.metadata.get("source") for p in parts]}
    return TrajectoryData(
        time=np.concatenate([p.time for p in parts]),
        episode=np.concatenate(episodes),
        observations=np.concatenate([p.observations for p in parts]),
        actions=np.concatenate([p.actions for p in parts]),
        columns=first.columns,
        metadata=meta,
    )
