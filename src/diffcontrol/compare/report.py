"""The comparison's summary over seeds, its table, and its plots."""

from __future__ import annotations

import math
import os
import platform
import statistics
from pathlib import Path
from typing import Any

import numpy as np

from ..io import write_figure
from .run import first_reached


def _spread(values: list[float]) -> dict[str, Any]:
    """Median, min and max of the finite ``values`` (``None`` when there are none)."""
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return {"median": None, "min": None, "max": None, "n": 0}
    return {"median": statistics.median(vals), "min": min(vals), "max": max(vals), "n": len(vals)}


def summarize(results: list[dict], thresholds: tuple[float, ...]) -> list[dict]:
    """One summary per method: medians and ranges over seeds.

    For every threshold: how many seeds reached it, and the environment steps, episodes,
    finished episodes and training seconds at the first evaluation point that did (median
    and range over the seeds that reached it). Then the final return: each seed's mean over
    the final episodes, its median and range over seeds, and the mean of the per-seed
    standard deviations.
    """
    methods: list[str] = []
    for r in results:
        if r["method"] not in methods:
            methods.append(r["method"])
    out = []
    for method in methods:
        group = sorted((r for r in results if r["method"] == method), key=lambda r: r["seed"])
        row: dict[str, Any] = {
            "method": method,
            "algo": group[0]["algo"],
            "source": group[0]["source"],
            "seeds": [r["seed"] for r in group],
            "env_steps": _spread([r["env_steps"] for r in group]),
            "train_seconds": _spread([r["train_seconds"] for r in group]),
            "final_mean_return": _spread([r["final"]["mean_return"] for r in group]),
            "final_std_return_mean": float(np.mean([r["final"]["std_return"] for r in group])),
            "final_episodes": group[0]["final"]["episodes"],
            "thresholds": [],
        }
        for threshold in thresholds:
            hits = [first_reached(r["curve"], threshold) for r in group]
            reached = [h for h in hits if h is not None]
            row["thresholds"].append(
                {
                    "threshold": threshold,
                    "reached": len(reached),
                    "of": len(group),
                    **{
                        key: _spread([h[key] for h in reached])
                        for key in ("env_steps", "episodes", "episodes_finished", "train_seconds")
                    },
                }
            )
        out.append(row)
    return out


def _fmt(s: dict, fmt: str) -> str:
    if s["median"] is None:
        return "—"
    if s["n"] == 1 or s["min"] == s["max"]:
        return format(s["median"], fmt)
    return f"{format(s['median'], fmt)} [{format(s['min'], fmt)}–{format(s['max'], fmt)}]"


def table(task_name: str, summary: list[dict]) -> str:
    """A Markdown table: per method and threshold, the first-reached figures; the final return."""
    lines = [
        "| method | threshold | seeds reaching | episodes | env steps | train s | "
        "final return (median [range] over seeds; ± mean std) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in summary:
        final = f"{_fmt(row['final_mean_return'], '.1f')} ± {row['final_std_return_mean']:.1f}"
        label = (
            f"{row['method']} ({row['algo']})" if row["method"] != "diffcontrol" else "diffcontrol"
        )
        entries = row["thresholds"] or [None]
        for i, t in enumerate(entries):
            if t is None:
                cells = ["—", "—", "—", "—", "—"]
            else:
                cells = [
                    f"{t['threshold']:g}",
                    f"{t['reached']}/{t['of']}",
                    _fmt(t["episodes"], ",.1f"),
                    _fmt(t["env_steps"], ",.0f"),
                    _fmt(t["train_seconds"], ".1f"),
                ]
            lines.append(
                "| " + " | ".join([label if i == 0 else "", *cells, final if i == 0 else ""]) + " |"
            )
    return f"{task_name}\n\n" + "\n".join(lines)


def _median_curve(curves: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, ...]:
    """Median, min and max over seeds of step functions ``x -> return`` on a common grid.

    Each seed's return at ``x`` is that of its last evaluation at or before ``x``; past its
    last evaluation it keeps that value (the controller it ended with); before its first
    it has none, and the statistics are over the seeds evaluated by then.
    """
    grid = np.unique(np.concatenate([x for x, _ in curves]))
    rows = []
    for x, y in curves:
        i = np.searchsorted(x, grid, side="right") - 1
        rows.append(np.where(i >= 0, y[np.maximum(i, 0)], np.nan))
    vals = np.stack(rows)
    return grid, np.nanmedian(vals, axis=0), np.nanmin(vals, axis=0), np.nanmax(vals, axis=0)


def plot(
    task_name: str,
    results: list[dict],
    thresholds: tuple[float, ...],
    path: str | Path,
    *,
    title: str | None = None,
    ylim: tuple[float, float] | None = None,
):
    """Return against environment steps and against training seconds, all methods on one
    figure, log-scaled x, the median over seeds drawn and its min–max range shaded (over the
    seeds evaluated by then); ``ylim`` zooms in on the returns (e.g. near the thresholds).

    Points at zero steps or seconds are left out (log scale). Written atomically.
    """
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    methods: list[str] = []
    for r in results:
        if r["method"] not in methods:
            methods.append(r["method"])
    for axis, key, label in (
        (axes[0], "env_steps", "environment steps (training)"),
        (axes[1], "train_seconds", "wall-clock seconds of training (evaluation excluded)"),
    ):
        for i, method in enumerate(methods):
            curves = []
            for r in results:
                if r["method"] != method:
                    continue
                pts = [p for p in r["curve"] if p[key] > 0]
                if pts:
                    x = np.array([p[key] for p in pts], float)
                    order = np.argsort(x, kind="stable")
                    y = np.array([p["mean_return"] for p in pts], float)
                    curves.append((x[order], y[order]))
            if not curves:
                continue
            grid, med, lo, hi = _median_curve(curves)
            n = len(curves)
            few = len(grid) <= 4  # a loop's few rounds: mark them
            axis.step(grid, med, where="post", color=f"C{i}", label=f"{method} ({n} seeds)",
                      marker="o" if few else None, markersize=4)  # fmt: skip
            axis.fill_between(grid, lo, hi, step="post", color=f"C{i}", alpha=0.2)
        for t in thresholds:
            axis.axhline(t, color="k", ls="--", lw=0.8)
        axis.set_xscale("log")
        axis.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        axis.set_xlabel(label)
        axis.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("evaluation return (median; shaded: min–max over seeds)")
    axes[0].legend(loc="lower right")
    if ylim is not None:
        axes[0].set_ylim(*ylim)
    fig.suptitle(title or f"{task_name}: diffcontrol against RL baselines")
    fig.tight_layout()
    return write_figure(fig, path)


def machine() -> dict[str, Any]:
    """The CPU, cores this process may use, and the versions that shape the timings."""

    import jax

    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info: dict[str, Any] = {
        "cpu": cpu,
        "cores_allowed": sorted(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else None,
        "python": platform.python_version(),
        "jax": jax.__version__,
    }
    try:
        import stable_baselines3
        import torch

        info.update(
            stable_baselines3=stable_baselines3.__version__,
            torch=torch.__version__,
            torch_threads=torch.get_num_threads(),
        )
    except ImportError:
        pass
    return info
