"""The window curriculum (``final_window``): short BPTT windows first, longer ones at the end."""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np
import pytest

import diffcontrol as dc
from diffcontrol.training import make_trainer, resolve_config, train
from diffcontrol.training._programs import _start

PENDULUM = dc.make("pendulum")
WINDOWS = resolve_config(PENDULUM, "windows")  # the curriculum's base (long-windows), no value
# 6 updates, the last half (from update 3, inside the second 2-update chunk) with 5-step windows
TINY = dict(updates=6, eval_every=2, batch=2, window=2, eval_episodes=2, hidden=(8,))
CURRICULUM = dict(final_window=5, final_window_fraction=0.5, target_return=float("nan"))


def _weights(controller):
    return [np.asarray(x) for x in jax.tree.leaves(eqx.filter(controller, eqx.is_inexact_array))]


def test_the_stages_and_the_steps_they_simulate():
    cfg = WINDOWS.replace(**TINY, **CURRICULUM)
    assert cfg.final_window_start == 3
    assert cfg.simulated_steps(2) == 2 * 2 * 2
    assert cfg.simulated_steps(6) == 2 * (3 * 2 + 3 * 5)
    stages = make_trainer(PENDULUM, cfg).stages()
    assert [(end, t.window) for end, t in stages] == [(3, 2), (6, 5)]
    # off (0, or the window itself), or the whole run
    for off in (cfg.replace(final_window=0), cfg.replace(final_window=2)):
        assert off.final_window_start == 6 and off.simulated_steps(6) == 2 * 6 * 2
        assert [(end, t.window) for end, t in make_trainer(PENDULUM, off).stages()] == [(6, 2)]
    whole = cfg.replace(final_window_fraction=1.0)
    assert [(end, t.window) for end, t in make_trainer(PENDULUM, whole).stages()] == [(6, 5)]
    population = make_trainer(PENDULUM, cfg.replace(population=2))
    assert [(end, t.base.window) for end, t in population.stages()] == [(3, 2), (6, 5)]


@pytest.mark.parametrize("fraction", [0.0, 1.5, float("nan")])
def test_a_bad_fraction_is_refused(fraction):
    with pytest.raises(dc.ConfigError, match="final_window_fraction"):
        WINDOWS.replace(final_window_fraction=fraction)


@pytest.mark.slow
def test_a_run_switches_to_the_final_window_and_resumes_across_the_switch(tmp_path):
    """``train`` takes updates 0-2 with 2-step windows and 3-5 with 5-step ones: the same
    weights as those updates taken by hand, the switch an evaluation point of its own (a
    short chunk), the steps counted per stage; a run interrupted before the switch resumes
    through it to the same weights."""
    cfg = WINDOWS.replace(**TINY, **CURRICULUM)
    result = train(PENDULUM, cfg)
    assert [p["update"] for p in result.curve] == [0, 2, 3, 5, 6]
    assert [p["simulated_steps"] for p in result.curve] == [0, 8, 12, 32, 42]
    assert result.metrics["simulated_steps"] == 42

    trainer = make_trainer(PENDULUM, cfg)
    (_, short), (_, long) = trainer.stages()
    ts, _ = _start(trainer, np.int32(cfg.seed), result.params)
    update = eqx.filter_jit(lambda t, ts: t.update(ts, result.params))
    for u in range(cfg.updates):
        ts, _ = update(short if u < 3 else long, ts)
    last = train(PENDULUM, cfg.replace(keep_best=False)).controller
    for a, b in zip(_weights(ts.controller), _weights(last), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    plain = train(PENDULUM, cfg.replace(final_window=0, keep_best=False)).controller
    assert not all(np.allclose(a, b) for a, b in zip(_weights(plain), _weights(last)))

    calls = []

    def interrupt_at_the_switch(line):
        calls.append(line)
        if len(calls) == 3:  # the point at update 3; the checkpoint is that of update 2
            raise KeyboardInterrupt

    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train(PENDULUM, cfg, out_dir=out, progress=interrupt_at_the_switch)
    resumed = train(PENDULUM, cfg, out_dir=out, resume=True)
    assert [p["update"] for p in resumed.curve] == [0, 2, 3, 5, 6]
    for a, b in zip(_weights(result.controller), _weights(resumed.controller), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_a_sweep_member_is_the_run_train_would_make():
    from diffcontrol.training import grid, sweep

    cfg = WINDOWS.replace(**TINY, **CURRICULUM)
    configs = grid(cfg, [0, 1])
    result = sweep(PENDULUM, configs)
    for config, member in zip(configs, result.members, strict=True):
        alone = train(PENDULUM, config)
        assert [p["update"] for p in member.curve] == [0, 2, 3, 5, 6]
        assert member.metrics["simulated_steps"] == alone.metrics["simulated_steps"] == 42
        for a, b in zip(_weights(member.controller), _weights(alone.controller), strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)
