"""The Gymnasium evaluation: a batched NumPy policy runs its episodes side by side, and the
returns are the sequential ones."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol import evaluation, io
from diffcontrol.controllers import MLPController


class OneByOne:
    """The same policy, offered one observation at a time (the sequential path)."""

    def __init__(self, policy):
        self.policy = policy

    def __call__(self, obs):
        return self.policy(obs)


class Counting(io.NumpyPolicy):
    """A NumPy policy that counts its calls and the observations in each."""

    def __init__(self, doc):
        super().__init__(doc)
        self.rows: list[int] = []

    def __call__(self, obs):
        self.rows.append(1 if np.ndim(obs) == 1 else len(obs))
        return super().__call__(obs)


def _random_policy(name: str, seed: int) -> Counting:
    task = diffcontrol.make(name)
    kwargs = task.controller_kwargs()
    controller = MLPController(jax.random.PRNGKey(seed), hidden=(16,), **kwargs)
    return Counting(io.controller_to_dict(controller, task, {}))


# CartPole (the sign head: episodes of different lengths), Pendulum (continuous, clipped) and
# Acrobot (the argmax head over three torques).
@pytest.mark.parametrize("name", ["cartpole", "pendulum", "acrobot"])
def test_side_by_side_returns_are_the_sequential_ones(name, monkeypatch):
    monkeypatch.setattr(evaluation, "LOCKSTEP_WIDTH", 3)  # 7 episodes in 3 slots: slots reused
    task = diffcontrol.make(name)
    policy = _random_policy(name, seed=1)
    together = evaluation.evaluate(policy, task, episodes=7, seed=5)
    assert max(policy.rows) == 3, "the batched policy was not called with a batch"
    apart = evaluation.evaluate(OneByOne(policy), task, episodes=7, seed=5)
    np.testing.assert_array_equal(together.lengths, apart.lengths)
    np.testing.assert_array_equal(together.returns, apart.returns)
    assert together.seed == apart.seed == 5 and together.env_id == apart.env_id
    if name == "cartpole":  # the episodes differ, so a wrong seed or order would show
        assert len(set(apart.lengths.tolist())) > 1, apart.lengths


def test_a_policy_with_reset_runs_episode_by_episode():
    """A planner's warm start is reset before each episode, so it is never run side by side."""
    policy = _random_policy("cartpole", seed=2)
    resets = []
    policy.reset = lambda: resets.append(1)
    result = evaluation.evaluate(policy, diffcontrol.make("cartpole"), episodes=3, seed=0)
    assert len(resets) == 3 and max(policy.rows) == 1 and result.returns.size == 3


def test_a_users_own_environment_is_made_once(monkeypatch):
    """A ``module:Class`` environment (``real``) may stand for a system that cannot be opened
    many times: the episodes run one by one in one environment."""
    made = []
    real_make = evaluation.eval_environment

    def counting(task, real):
        made.append(real)
        return real_make(task, None)  # Gymnasium's CartPole stands in for the user's

    monkeypatch.setattr(evaluation, "eval_environment", counting)
    policy = _random_policy("cartpole", seed=3)
    task = diffcontrol.make("cartpole")
    evaluation.evaluate(policy, task, episodes=4, seed=0, real=("my_module:MyCartPole-v0", {}))
    assert len(made) == 1 and max(policy.rows) == 1
    evaluation.evaluate(policy, task, episodes=4, seed=0, real=("CartPole-v1", {}))
    assert len(made) == 1 + 4 and max(policy.rows) == 4  # a registered id: side by side
