"""``prediction.png`` of a trebuchet fit: predicted against recorded throw distances."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .data import ThrowData  # noqa: E402
from .fit_throws import predict_distances  # noqa: E402
from .io import write_figure  # noqa: E402


def throws_plot(models: dict[str, Any], data: ThrowData, path: str | Path, title: str = "") -> Path:
    """Scatter the distances each model in ``models`` (label -> ``TrebuchetParams``) predicts
    for the throws of ``data`` against the recorded ones (left), and the residuals against
    the wind (right), where a wrong wind factor shows as a slope; write a PNG atomically."""
    fig, (ax, ax_wind) = plt.subplots(1, 2, figsize=(10.0, 4.2))
    lo = min(0.0, float(np.min(data.distance)))
    hi = float(np.max(data.distance))
    for c, (label, params) in enumerate(models.items()):
        pred = predict_distances(params, data)
        rms = float(np.sqrt(np.mean((pred - data.distance) ** 2)))
        style = dict(color=f"C{c}", marker="os^"[c % 3], s=18, alpha=0.8)
        ax.scatter(data.distance, pred, label=f"{label} (RMS {rms:.2f} m)", **style)
        ax_wind.scatter(data.wind, pred - data.distance, label=label, **style)
        lo, hi = min(lo, float(np.min(pred))), max(hi, float(np.max(pred)))
    ax.plot([lo, hi], [lo, hi], color="0.5", lw=1.0, ls="--", label="predicted = recorded")
    ax.set_xlabel("recorded distance (m)")
    ax.set_ylabel("predicted distance (m)")
    ax.legend(loc="upper left", fontsize=8)
    ax_wind.axhline(0.0, color="0.5", lw=1.0, ls="--")
    ax_wind.set_xlabel("wind (m/s, + toward the target)")
    ax_wind.set_ylabel("predicted - recorded (m)")
    ax_wind.legend(loc="best", fontsize=8)
    fig.suptitle(title or f"{data.num_throws} recorded throws", fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=100)
