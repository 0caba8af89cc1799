"""A task's open-loop stroke (``stroke``): training starts from a controller fitted to play it
in closed loop (``training._stroke``)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol.errors import ConfigError
from diffcontrol.tasks import Pendulum, Stroke
from diffcontrol.training import make_trainer
from diffcontrol.training._stroke import imitate

DRIVE = Stroke(period=40.0, amplitude=(3.0,), phase=(0.5,))
"""A square-ish torque (3 N m clipped to the pendulum's 2) near its natural period."""


class StrokedPendulum(Pendulum):
    """The pendulum with joint friction, so that the drive settles it in one cycle."""

    name = "stroked-pendulum"

    def default_params(self):
        return dataclasses.replace(super().default_params(), friction=0.5)

    def stroke(self):
        return DRIVE


def _config(task, **changes):
    small = dict(updates=2, eval_every=1, batch=2, window=10, eval_episodes=2, value_grid=0)
    return task.default_config().replace(**{**small, **changes})


def test_the_drive_is_a_clipped_sinusoid_of_the_step():
    low, high = jnp.array([-2.0]), jnp.array([2.0])
    t = jnp.arange(40)
    expected = np.clip(3.0 * np.sin(2 * np.pi * np.arange(40) / 40 + 0.5), -2, 2)[:, None]
    got = jax.vmap(lambda s: DRIVE.actions(s, low, high))(t)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)


def test_the_fitted_controller_plays_the_stroke_in_closed_loop():
    task = StrokedPendulum()
    params = task.default_params()
    controller = make_trainer(task, _config(task)).init(jax.random.key(0), params).controller
    fitted, error = imitate(
        task, controller, params, jax.random.key(1), DRIVE, episodes=4, settle=50, fit_steps=400
    )
    assert error < 0.05  # the drive's mean square is 2.9

    # Closed loop: the fitted controller alone, from a reset the fit never saw, keeps close to
    # the drive's cycle; the random controller does not make one.
    def closed_loop(c):
        def body(state, _):
            action = c(task.observe(state))
            return task.step(params, state, action)[0], action[0]

        return jax.lax.scan(body, task.reset(jax.random.key(7), params), None, 200)[1]

    played, idle = closed_loop(fitted), closed_loop(controller)
    assert np.std(played[50:]) > 1.4 and np.std(idle[50:]) < 0.5  # the drive's is 1.7
    swings = np.abs(np.fft.rfft(played[50:] - played[50:].mean()))
    assert abs(150 / np.argmax(swings) - DRIVE.period) < 4  # its period, within a bin


@pytest.fixture(scope="module")
def runs():
    lines = {}

    def run(task, **changes):
        said = lines.setdefault(task.name + str(changes), [])
        return diffcontrol.train(task, _config(task, **changes), progress=said.append), said

    return run


class UnstrokedPendulum(StrokedPendulum):
    """The same physics, no stroke: training starts from the seed's random weights."""

    name = "unstroked-pendulum"

    def stroke(self):
        return None


def test_training_starts_from_the_stroke_of_a_task_that_declares_one(runs):
    stroked, said = runs(StrokedPendulum())
    plain, plain_said = runs(UnstrokedPendulum())
    assert any(line.startswith("starting from the task's stroke (period 40") for line in said)
    assert not any("stroke" in line for line in plain_said)
    # the same physics, seed and evaluation: without the stroke these would be equal
    assert stroked.curve[0]["eval_return"] != plain.curve[0]["eval_return"]


def test_a_population_starts_from_random_weights(runs):
    _, said = runs(StrokedPendulum(), population=2)
    assert not any("stroke" in line for line in said)


@pytest.mark.parametrize(
    ("drive", "needle"),
    [
        (Stroke(40.0, (1.0, 1.0), (0.0, 0.0)), "2 amplitudes and 2 phases: give one of each per"),
        (Stroke(0.0, (1.0,), (0.0,)), "give a positive period and finite numbers"),
        (Stroke(40.0, (float("nan"),), (0.0,)), "give a positive period and finite numbers"),
        ((40.0, (1.0,), (0.0,)), "return a diffcontrol.tasks.Stroke"),
    ],
)
def test_a_stroke_that_cannot_be_played_is_one_line(drive, needle):
    class Bad(StrokedPendulum):
        name = "bad-stroke"

        def stroke(self):
            return drive

    with pytest.raises(ConfigError, match="task 'bad-stroke'") as e:
        diffcontrol.train(Bad(), _config(Bad()))
    assert needle in str(e.value) and "\n" not in str(e.value)
