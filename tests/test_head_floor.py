"""The bounded heads' slope floor (``TrainConfig.head_slope_floor``): the backward pass sees
at least a fraction of the head's slope at 0, the forward pass is the head's own."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol.controllers import MLPController, apply_head, squash
from diffcontrol.training import make_trainer
from diffcontrol.training._driver import _started_from

from ._cli import one_line

Z = jnp.linspace(-8.0, 8.0, 33)


@pytest.mark.parametrize(
    ("head", "f", "peak"), [("tanh", jnp.tanh, 1.0), ("sigmoid", jax.nn.sigmoid, 0.25)]
)
@pytest.mark.parametrize("floor", [0.05, 0.3])
def test_the_slope_is_floored_and_the_value_is_not(head, f, peak, floor):
    np.testing.assert_array_equal(squash(head, Z, floor), f(Z))
    slope = jax.vmap(jax.grad(lambda z: squash(head, z, floor)))(Z)
    exact = jax.vmap(jax.grad(f))(Z)
    np.testing.assert_allclose(slope, np.maximum(exact, floor * peak), rtol=1e-6)
    assert slope[0] == pytest.approx(floor * peak) and slope[16] == pytest.approx(peak)


def test_a_saturated_controller_still_gets_a_gradient():
    low, high = jnp.array([-2.0]), jnp.array([2.0])
    z = jnp.array([6.0])  # tanh's slope there is 2.5e-5

    def action_slope(floor):
        return jax.grad(lambda z: apply_head("tanh", z, low, high, floor)[0])(z)[0]

    assert action_slope(0.0) < 1e-4
    assert action_slope(0.2) == pytest.approx(0.2 * (high - low)[0] / 2)
    # without a floor the head is the plain function, bit for bit
    np.testing.assert_array_equal(
        apply_head("tanh", Z, low, high), low + (high - low) * (jnp.tanh(Z) + 1) / 2
    )
    with pytest.raises(ValueError, match="head_floor must be in"):
        MLPController(jax.random.key(0), 3, 1, head_floor=1.5)


def test_training_builds_its_controller_with_the_floor_and_init_ignores_it():
    task = diffcontrol.make("pendulum")
    config = task.default_config().replace(head="tanh", head_slope_floor=0.3, batch=2, value_grid=0)
    params = diffcontrol.training.task_params(task)
    ts = make_trainer(task, config).init(jax.random.key(0), params)
    assert ts.controller.head_floor == 0.3
    # --init with a controller trained without a floor: its weights, this run's floor
    other = make_trainer(task, config.replace(head_slope_floor=0.0, seed=1))
    given = other.init(jax.random.key(1), params).controller
    started = _started_from(ts, given).controller
    assert started.head_floor == 0.3
    np.testing.assert_array_equal(started.layers[0].weight, given.layers[0].weight)


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (
            ["cartpole", "--head-slope-floor", "0.1"],
            ["head_slope_floor=0.1 (--head-slope-floor) is for a tanh or sigmoid", "'sign'"],
        ),
        (
            ["pendulum", "--head-slope-floor", "1.5"],
            ["--head-slope-floor", "must be in [0, 1]", "1.5"],
        ),
    ],
)
def test_a_floor_the_head_cannot_take_is_one_line(args, needles, capsys, tmp_path):
    one_line(capsys, ["train", *args, "--out", tmp_path / "x", "--quiet"], *needles)
    assert not (tmp_path / "x").exists()
