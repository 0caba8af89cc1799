"""The ``argmax`` head: an N-way discrete choice trained by a straight-through softmax.

Forward values are compared exactly (a one-hot vector is 0s and a 1). The backward pass is
compared with ``jax.jvp`` of ``softmax(z / T)`` at ``rtol = 1e-6`` in float32: both sides
compute the same few operations, so only rounding separates them. NumPy and JAX controllers
are compared on their choices (equal indices), which are exact unless two logits tie to
within rounding; the random observations below are far from ties (checked).
"""

from __future__ import annotations

import types

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffcontrol import io, policies
from diffcontrol.controllers import (
    ARGMAX_TEMPERATURE,
    MLPController,
    apply_head,
    straight_through_argmax,
)
from diffcontrol.errors import ModelFileError

N = 5
OBS = 4


def _controller(key=0, n=N, head="argmax") -> MLPController:
    return MLPController(jax.random.key(key), OBS, n, (16, 16), head=head, final_scale=3.0)


def _fake_task(name="fake", gym_id="Fake-v0"):
    return types.SimpleNamespace(name=name, gym_id=gym_id, kind="control")


def test_forward_is_one_hot_of_argmax():
    z = jnp.asarray(np.random.default_rng(0).normal(0, 3, (200, N)), jnp.float32)
    y = np.asarray(jax.jit(straight_through_argmax)(z))
    np.testing.assert_array_equal(y, np.eye(N)[np.argmax(np.asarray(z), axis=-1)])
    assert y.dtype == np.float32
    # Exact at any magnitude, ties go to the first index.
    big = jnp.array([[1e30, -1e30, 3e38], [jnp.inf, 0.0, 1.0], [2.0, 2.0, 1.0]], jnp.float32)
    np.testing.assert_array_equal(
        np.asarray(straight_through_argmax(big)), [[0, 0, 1], [1, 0, 0], [1, 0, 0]]
    )


@pytest.mark.parametrize("temperature", [ARGMAX_TEMPERATURE, 0.3])
def test_gradient_is_softmax_jvp(temperature):
    """Backward pass = the Jacobian-vector product of ``softmax(z / T)``, non-zero.

    In float64: ``p dz - p sum(p dz)`` cancels, so float32 would need a tolerance of a few
    ulp of ``|dz| / T`` rather than of the result; in float64 1e-12 leaves only rounding.
    """
    with jax.enable_x64(True):
        rng = np.random.default_rng(1)
        z = jnp.asarray(rng.normal(0, 2, (64, N)))
        dz = jnp.asarray(rng.normal(size=(64, N)))

        def soft(z):
            return jax.nn.softmax(z / temperature, axis=-1)

        _, got = jax.jvp(lambda z: straight_through_argmax(z, temperature), (z,), (dz,))
        _, want = jax.jvp(soft, (z,), (dz,))
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12, atol=1e-12)
        assert np.all(np.abs(np.asarray(got)).sum(axis=-1) > 0)  # never argmax's zero
        # Reverse mode (what BPTT uses) agrees with the softmax's vector-Jacobian product.
        w = jnp.asarray(rng.normal(size=(64, N)))
        g_got = jax.grad(lambda z: jnp.sum(straight_through_argmax(z, temperature) * w))(z)
        g_want = jax.grad(lambda z: jnp.sum(soft(z) * w))(z)
        np.testing.assert_allclose(np.asarray(g_got), np.asarray(g_want), rtol=1e-12, atol=1e-12)


@pytest.mark.slow
def test_controller_head_gradient_reaches_the_weights():
    ctrl = _controller()
    obs = jnp.asarray(np.random.default_rng(2).normal(size=(32, OBS)), jnp.float32)
    torque = jnp.linspace(-1.0, 1.0, N)

    def loss(c):
        return jnp.sum(jax.vmap(c)(obs) @ torque)

    grads = eqx.filter_grad(loss)(ctrl)
    norms = [float(jnp.linalg.norm(l.weight)) for l in grads.layers]
    assert all(n > 0 for n in norms)
    z = jax.vmap(_controller(head="linear"))(obs)  # the same weights, the logits exposed
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(ctrl)(obs)), np.asarray(apply_head("argmax", z, None, None))
    )


def test_argmax_head_needs_two_choices():
    with pytest.raises(ValueError, match="argmax"):
        _controller(n=1)


def test_model_json_round_trip(tmp_path):
    ctrl = _controller()
    doc = policies.controller_to_dict(ctrl, _fake_task())
    assert doc["action"] == {"size": N, "head": "argmax", "low": None, "high": None,
                             "gym": "discrete"}  # fmt: skip
    io.write_json(tmp_path / "model.json", doc)
    back = policies.read_model(tmp_path)
    assert back == doc
    rebuilt = policies.controller_from_dict(back)
    obs = jnp.asarray(np.random.default_rng(3).normal(size=(50, OBS)), jnp.float32)
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(rebuilt)(obs)), np.asarray(jax.vmap(ctrl)(obs))
    )


@pytest.mark.parametrize(
    "change, problem",
    [
        ({"gym": "box"}, "does not go with"),
        ({"head": "tanh"}, "does not go with"),
        ({"gym": "multi"}, "unknown Gymnasium action kind"),
    ],
)
def test_model_json_rejects_mismatched_heads(change, problem):
    doc = policies.controller_to_dict(_controller(), _fake_task())
    doc["action"].update(change)
    with pytest.raises(ModelFileError, match=problem):
        policies.NumpyPolicy(doc)


def test_numpy_policy_equals_jax_controller():
    ctrl = _controller()
    policy = policies.NumpyPolicy(policies.controller_to_dict(ctrl, _fake_task()))
    obs = np.random.default_rng(4).normal(0, 2, (600, OBS)).astype(np.float32)
    logits = np.asarray(jax.vmap(_controller(head="linear"))(obs))
    top2 = np.sort(logits, axis=-1)[:, -2:]
    # Only unambiguous choices: a GPU's float32 matmul (TF32) may differ from NumPy's float64
    # by ~1e-3, which decides a near-tie either way.
    obs = obs[top2[:, 1] - top2[:, 0] > 1e-2][:500]
    assert len(obs) == 500
    want = np.asarray(jax.vmap(ctrl)(obs))
    assert len(np.unique(want.argmax(axis=-1))) > 1  # several choices occur
    np.testing.assert_array_equal(policy.action(obs), want)  # a batch of one-hot vectors
    index = policy(obs)
    assert index.dtype == np.int64 and index.shape == (500,)
    np.testing.assert_array_equal(index, want.argmax(axis=-1))
    one = policy(obs[7])
    assert type(one) is int and one == int(want[7].argmax())
    np.testing.assert_array_equal(policy.action(obs[7]), want[7])


def test_gymnasium_accepts_the_action():
    env = gymnasium.make("Acrobot-v1")
    ctrl = MLPController(jax.random.key(5), 6, 3, (16,), head="argmax", final_scale=3.0)
    policy = policies.NumpyPolicy(
        policies.controller_to_dict(ctrl, _fake_task("acro", "Acrobot-v1"))
    )
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        action = policy(obs)
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)
    env.close()
