"""A swing-up judged: how the reference solve of its closed loop ended (``swingup_result``)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ...evaluation import ContinuousRecording


@dataclasses.dataclass
class SwingUpResult:
    """How a swing-up ended (the reference solve): the issue's pass/fail figures and more."""

    task: str
    horizon_s: float
    final_theta: float
    final_theta_dot: float
    final_x: float
    final_x_dot: float
    peak_force: float
    dissipated_energy: float
    swings: int
    upright_time: float | None
    loss: float
    solves: str | None = None  # a planner's count of unconverged and non-finite solves

    key = "swingup"  # its entry in metrics.json

    def headline(self) -> str:
        """A few words for the end of ``diffcontrol train``'s last line."""
        return (
            f"final |θ| {abs(self.final_theta):.3f} rad, ẋ {self.final_x_dot:+.3f} m/s, "
            f"peak |F| {self.peak_force:.1f} N; loss {self.loss:.4g}"
        )

    def to_json(self) -> dict[str, Any]:
        doc = dataclasses.asdict(self)
        solves = doc.pop("solves")
        return doc if solves is None else {**doc, "planner_solves": solves}

    def summary(self) -> str:
        """One line (and, for a planner, a second with its solves)."""
        up = (
            f"upright (|θ| < 0.1 rad) from {self.upright_time:.2f} s"
            if self.upright_time is not None
            else "never upright for good"
        )
        return f"{self.task} (reference solve, dopri8 at 1e-9): " + (
            f"at t = {self.horizon_s:g} s: |θ| {abs(self.final_theta):.4f} rad, θ̇ "
            f"{self.final_theta_dot:+.3f} rad/s, ẋ {self.final_x_dot:+.3f} m/s, x "
            f"{self.final_x:+.2f} m; peak |F| {self.peak_force:.1f} N; {self.swings} swings; "
            f"{up}; loss {self.loss:.4f}"
            + (f"; dissipated {self.dissipated_energy:.2f} J" if self.dissipated_energy else "")
            + ("" if self.solves is None else f"\nplanner: {self.solves}")
        )


def swingup_result(rec: ContinuousRecording) -> SwingUpResult:
    """The end state, peak force, swings and upright time of a recorded swing-up.

    ``swings`` counts the pole's direction reversals (sign changes of ``theta_dot``) before it
    first comes within 0.1 rad of upright. ``upright_time`` is the first time from which it
    stays within 0.1 rad to the end (``None`` if it does not end there).
    """
    theta = (rec.y[:, 2] + np.pi) % (2 * np.pi) - np.pi
    up = np.abs(theta) < 0.1
    first_up = int(np.argmax(up)) if up.any() else len(theta)
    rate = rec.y[:first_up, 3]
    signs = np.sign(rate[np.abs(rate) > 1e-3])  # ignore numerical jitter at rest
    swings = int(np.sum(signs[1:] != signs[:-1])) if signs.size > 1 else 0
    upright_time = None
    if up[-1]:
        last_down = np.flatnonzero(~up)
        upright_time = float(rec.t[last_down[-1] + 1]) if last_down.size else 0.0
    return SwingUpResult(
        task=rec.task,
        horizon_s=float(rec.t[-1]),
        final_theta=float(theta[-1]),
        final_theta_dot=float(rec.y[-1, 3]),
        final_x=float(rec.y[-1, 0]),
        final_x_dot=float(rec.y[-1, 1]),
        peak_force=float(np.max(np.abs(rec.force))),
        dissipated_energy=float(rec.y[-1, 5]),
        swings=swings,
        upright_time=upright_time,
        loss=rec.loss,
    )
