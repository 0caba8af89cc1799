"""The state grid a task offers to grid methods (the reference optimum of ``diffcontrol.optimal``)."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class GridAxis:
    """One state dimension of a grid: its range and whether it wraps around.

    A periodic axis (an angle) has grid points ``low + i (high - low) / n`` for ``i < n`` and
    a state outside ``[low, high)`` is wrapped into it; a bounded axis has ``n`` points from
    ``low`` to ``high`` inclusive and a state outside is clamped to the nearest edge (so the
    range should hold every state the system can reach, e.g. a speed clip).

    Attributes:
        low, high: the range, in the state's units.
        periodic: whether ``low`` and ``high`` are the same point (an angle).
    """

    low: float
    high: float
    periodic: bool = False

    def __post_init__(self) -> None:
        if not self.high > self.low:
            raise ValueError(f"a grid axis needs high > low, got [{self.low}, {self.high}]")
