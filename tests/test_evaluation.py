"""The Gymnasium evaluation: a batched NumPy policy runs its episodes side by side, and the
returns are the sequential ones."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import diffcontrol
from diffcontrol import evaluation, policies
from diffcontrol.controllers import MLPController
from diffcontrol.tasks import controller_kwargs


class OneByOne:
    """The same policy, offered one observation at a time (the sequential path)."""

    def __init__(self, policy):
        self.policy = policy

    def __call__(self, obs):
        return self.policy(obs)


class Counting(policies.NumpyPolicy):
    """A NumPy policy that counts its calls and the observations in each."""

    batched = True  # declared again: a subclass is not batched unless it says so

    def __init__(self, doc):
        super().__init__(doc)
        self.rows: list[int] = []

    def __call__(self, obs):
        self.rows.append(1 if np.ndim(obs) == 1 else len(obs))
        return super().__call__(obs)


def _random_policy(name: str, seed: int) -> Counting:
    task = diffcontrol.make(name)
    kwargs = controller_kwargs(task)
    controller = MLPController(jax.random.PRNGKey(seed), hidden=(16,), **kwargs)
    return Counting(policies.controller_to_dict(controller, task, {}))


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


_MADE: list[object] = []


def _user_cartpole(**kwargs):
    """A user's own environment (an entry point outside Gymnasium and diffcontrol)."""
    from gymnasium.envs.classic_control import CartPoleEnv

    _MADE.append(1)
    return CartPoleEnv(**kwargs)


def test_a_users_own_environment_is_made_once():
    """An environment that neither Gymnasium nor diffcontrol provides may stand for a system
    that cannot be opened many times: the episodes run one by one in one environment."""
    import gymnasium

    env_id = "DiffcontrolTestUser/CartPole-v0"
    gymnasium.register(env_id, entry_point=_user_cartpole, max_episode_steps=500)
    try:
        policy = _random_policy("cartpole", seed=3)
        task = diffcontrol.make("cartpole")
        _MADE.clear()
        ours = evaluation.evaluate(policy, task, episodes=4, seed=0, real=(env_id, {}))
        assert len(_MADE) == 1 and max(policy.rows) == 1
        theirs = evaluation.evaluate(policy, task, episodes=4, seed=0, real=("CartPole-v1", {}))
        assert max(policy.rows) == 4  # Gymnasium's own: side by side, the same returns
        np.testing.assert_array_equal(ours.returns, theirs.returns)
    finally:
        gymnasium.registry.pop(env_id, None)


def test_a_subclass_that_does_not_declare_batched_gets_one_observation_at_a_time():
    class OneAtATime(policies.NumpyPolicy):
        def __call__(self, obs):
            assert np.ndim(obs) == 1, "given a batch"
            return super().__call__(obs)

    policy = _random_policy("cartpole", seed=4)
    result = evaluation.evaluate(OneAtATime(policy.doc), diffcontrol.make("cartpole"), 3, 0)
    assert result.returns.size == 3


def test_copies_made_before_a_failure_are_closed(monkeypatch):
    made, closed = [], []
    real_make = evaluation.eval_environment

    def failing(task, real):
        if len(made) == 4:
            raise RuntimeError("the fifth environment cannot be made")
        env, label = real_make(task, real)
        made.append(env)
        original = env.close
        env.close = lambda: (closed.append(env), original())
        return env, label

    monkeypatch.setattr(evaluation, "eval_environment", failing)
    with pytest.raises(RuntimeError, match="fifth"):
        evaluation.evaluate(_random_policy("cartpole", seed=5), diffcontrol.make("cartpole"), 8, 0)
    assert len(made) == 4 and len(closed) == 4  # the first by evaluate, the copies by _lockstep
