"""The pictures of every run: laid out with fixed margins, their labels still inside."""

from __future__ import annotations

import types

import numpy as np


def _outside(fig) -> list[tuple[float, ...]]:
    """The drawn extents (axes with their titles, labels and tick labels) that reach outside
    the figure, in pixels."""
    fig.canvas.draw()
    renderer, box = fig.canvas.get_renderer(), fig.bbox
    out = []
    for ax in fig.axes:
        e = ax.get_tightbbox(renderer)
        if e.x0 < box.x0 - 0.5 or e.y0 < box.y0 - 0.5 or e.x1 > box.x1 + 0.5 or e.y1 > box.y1 + 0.5:
            out.append(tuple(e.bounds))
    return out


def test_a_rollout_and_a_learning_curve_keep_wide_labels_inside(monkeypatch, tmp_path):
    """Ticks of seven characters (−250000), a long state label and a title: all inside the
    figure, as ``tight_layout`` would have placed them."""
    from diffcontrol import io, plots

    kept = []
    monkeypatch.setattr(io, "write_figure", lambda fig, path: kept.append(fig) or path)
    task = types.SimpleNamespace(
        state_labels=("cart position x (m)", "a long state label, pole speed (rad/s)"),
        action_labels=("push (±1 × 10 N)",),
    )
    steps = 200
    recording = types.SimpleNamespace(
        states=np.stack([np.linspace(0, -250000, steps + 1), np.sin(np.arange(steps + 1))], 1),
        actions=np.sign(np.sin(np.arange(steps)))[:, None],
        dt=0.02,
        env_id="Some-v0",
        total_return=-12345.6,
    )
    plots.rollout(recording, task, tmp_path / "rollout.png")
    curve = [
        {
            "update": u,
            "simulated_episodes": u / 10,
            "eval_return": -200.0 + u,
            "eval_return_std": 10.0,
            "loss": -250000.0 + 1250.0 * u,  # negative: a linear axis
        }
        for u in range(0, 200, 20)
    ]
    metrics = {
        "curve": curve,
        "returned_update": 180,
        "task": "some-task",
        "simulated_episodes": 20.0,
        "train_seconds": 1.0,
        "compile_seconds": 0.5,
    }
    plots.learning_curve(metrics, tmp_path / "curve.png", threshold=-200.0)
    assert len(kept) == 2
    for fig in kept:
        assert _outside(fig) == []
