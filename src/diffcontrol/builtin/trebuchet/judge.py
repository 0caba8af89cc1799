"""The trebuchet judged: the miss of an aiming controller over random targets and winds in
the simulator (``evaluate_aiming``)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ...tasks import Task
from . import task as aim
from .task import miss_statistics


@dataclasses.dataclass
class AimResult:
    """Misses of an aiming controller over random targets and winds (seeded NumPy draws).

    Only reachable targets count in the statistics; ``unreachable`` says how many were not.
    """

    task: str
    seed: int
    targets: np.ndarray
    winds: np.ndarray
    angles: np.ndarray
    weights: np.ndarray
    distances: np.ndarray
    reachable: np.ndarray

    key = "aim_eval"  # its entry in metrics.json

    @property
    def misses(self) -> np.ndarray:
        return self.distances - self.targets

    @property
    def stats(self) -> dict[str, Any]:
        return miss_statistics(self.misses, self.reachable)

    def to_json(self) -> dict[str, Any]:
        return {"task": self.task, "seed": self.seed, **self.stats}

    def summary(self) -> str:
        s = self.stats
        head = f"{self.task}, {s['targets']} random targets (seed {self.seed}): "
        if not s["reachable"]:
            return head + f"none of the {s['targets']} targets was reachable"
        return head + (
            f"|miss| over {s['reachable']} reachable targets: mean {s['mean_miss_m']:.3g} m, "
            f"median {s['median_miss_m']:.3g} m, 95th percentile {s['p95_miss_m']:.3g} m, "
            f"worst {s['worst_miss_m']:.3g} m ({s['unreachable']} of {s['targets']} unreachable)"
        )

    def headline(self) -> str:
        """A few words for the end of ``diffcontrol train``'s last line."""
        s = self.stats
        return f"mean |miss| {s['mean_miss_m']:.3g} m" if s["reachable"] else "no reachable target"


def evaluate_aiming(
    policy: Any, task: Task, targets: int = 1000, seed: int = 0, params: Any = None
) -> AimResult:
    """Aim ``policy`` (a ``model.json`` policy) at ``targets`` random situations.

    Targets ~ U(20, 100) m and winds ~ N(0, 5^2) m/s (clipped to +-20 m/s) are drawn with
    ``numpy.random.default_rng(seed)``, so every controller meets the same situations. Each
    throw is simulated with ``system.shoot``; a target counts as
    reachable when it lies between the shortest and longest throws the heads' bounds allow
    in its wind (``reachable_range``).

    ``params`` (a ``TrebuchetParams``; default the nominal ones) is the trebuchet that throws:
    pass the "real" system's to evaluate a controller trained on a model of it. The
    reachability is then that of the real system too.
    """

    if targets <= 0:
        raise ValueError(f"targets must be positive, got {targets}")
    rng = np.random.default_rng(seed)
    target = rng.uniform(*aim.TARGET_RANGE_M, size=targets)
    wind = np.clip(
        aim.WIND_STD_MPS * rng.standard_normal(targets), -aim.WIND_LIMIT_MPS, aim.WIND_LIMIT_MPS
    )
    actions = policy.action(np.stack([target, wind], axis=-1))
    angle, weight = actions[:, 0], actions[:, 1]
    distance = aim.shoot_in_chunks(wind, angle, weight, params)
    shortest, longest = (np.asarray(x, np.float64) for x in aim.reachable_range(wind, params))
    reachable = (target >= shortest) & (target <= longest)
    return AimResult(task.name, seed, target, wind, angle, weight, distance, reachable)
