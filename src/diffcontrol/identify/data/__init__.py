"""Recorded data: the ``TrajectoryData`` value and its CSV and NPZ files.

The format (``diffcontrol-trajectories``, version 1) is one table, a row per time step of an
episode; every system's data is such a table, an episode of one step where the system gives
one measured outcome (what is known before, the input, the outcome). Columns, each named with
its unit in brackets:

- ``time [s]`` (or ``time [step]`` where the system has no physical time step): the time of
  the row within its episode, strictly increasing within an episode;
- ``episode``: an integer id; the rows of an episode are contiguous;
- ``obs.NAME [UNIT]`` (what the controller sees) or ``state.NAME [UNIT]`` (a physical
  state), one or more, all of one kind;
- ``action.NAME [UNIT]``, one or more: the action applied from this row's time until the
  next row's. A discrete (Gymnasium ``Discrete``) action has the unit ``[index]`` and holds
  the integer index.

Units are free text (``1`` for dimensionless, ``?`` for unknown, e.g. ``m/s``, ``N m``). For the
environments whose columns a registered task names (``known_columns()``: ``Pendulum-v1``,
``CartPole-v1``, the ``diffcontrol/`` environments of those tasks, ...) the names and units
must be exactly the task's ``data_columns()``, so a column in degrees where radians are
expected is refused by name.

**The last row of every episode holds the final observation and no action** (empty action
cells in CSV, NaN in NPZ); every other row has finite actions. So an episode of ``n`` steps
has ``n + 1`` rows, and the system-identification pairs ``(x_t, u_t, x_{t+1})`` are the rows
``t`` and ``t + 1`` of one episode (``TrajectoryData.transitions``).

CSV: the first line is ``#`` followed by a JSON header, then the column names, then the rows::

    # {"format": "diffcontrol-trajectories", "version": 1, "metadata": {"env_id": "Pendulum-v1", "dt_s": 0.05}}
    time [s],episode,obs.cos_theta [1],obs.sin_theta [1],obs.theta_dot [rad/s],action.torque [N m]
    0.0,0,-0.85,0.52,0.31,1.2
    ...
    10.0,0,0.99,-0.1,-0.4,

Numbers are written as the shortest text that reads back to the same float64. NPZ: the arrays
``time`` [T] (float64), ``episode`` [T] (int64), ``observations`` [T, k] and ``actions``
[T, m] (float64), and ``header``: the JSON header as UTF-8 bytes (uint8) with the column names
under ``"columns"``. No object arrays; it is read with ``allow_pickle=False``. ``metadata`` is
free JSON; the recorder writes ``env_id``, ``dt_s``, ``source``, ``seed`` and ``recorded``
(a task's own recording writes what describes its system, e.g. ``system`` and ``params``).
"""

from ...errors import DataFileError
from ._files import read_trajectories, write_csv, write_npz, write_trajectories
from ._format import (
    DISCRETE_UNIT,
    FORMAT,
    TIME_UNITS,
    VERSION,
    known_columns,
    parse_column,
    validate,
)
from ._table import Episode, TrajectoryData, concat

__all__ = [
    "DISCRETE_UNIT",
    "DataFileError",
    "Episode",
    "FORMAT",
    "TIME_UNITS",
    "TrajectoryData",
    "VERSION",
    "concat",
    "known_columns",
    "parse_column",
    "read_trajectories",
    "validate",
    "write_csv",
    "write_npz",
    "write_trajectories",
]
