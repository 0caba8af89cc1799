"""The mountain car against Gymnasium's own ``MountainCarContinuous-v0``, its gradients, its
loss, its drawing, and a small learning run.

One-step comparisons set ``env.unwrapped.state`` and call ``env.step`` as
``test_systems_vs_gymnasium.py`` does. Tolerances:

- float64 (``jax.enable_x64(True)``): the reward to ``ATOL_F64 = 1e-12`` and the terminated flag
  exactly. Gymnasium computes the step in float64 and then stores the state as float32, so the
  next state is compared after the same rounding: JAX's float64 next state rounded to float32
  must equal Gymnasium's bit for bit (an error in a constant or the order of the clips shows
  up at 1e-4 or more; a one-ulp difference of ``cos`` moves a rounding only if it sits within
  1e-16 of a float32 rounding boundary).
- float32 (JAX's default): ``ATOL_F32 = 5e-7`` absolute on states of magnitude <= 1.2 (a few
  float32 ulps, eps 1.2e-7), the reward (up to 100) to ``1e-4``; terminated equal where the state is not
  within rounding of the goal.
"""

from __future__ import annotations

import math

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffcontrol
from diffcontrol import _gym, policies
from diffcontrol.evaluation import Recording, evaluate
from diffcontrol.systems import mountain_car as mc
from diffcontrol.training import resolve_config, train

ATOL_F64 = 1e-12
ATOL_F32 = 5e-7
N_STATES = 600
SEED = 20240612
TASK = "mountain-car-continuous"


def _env():
    env = gymnasium.make("MountainCarContinuous-v0").unwrapped
    env.reset(seed=0)
    return env


def _cases(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """States over the whole box and a little past it, actions past the force clip, and the
    edges: the wall, the speed clip, the flag."""
    position = rng.uniform(-1.25, 0.65, n)
    velocity = rng.uniform(-0.08, 0.08, n)
    action = rng.uniform(-2.0, 2.0, n)
    # A quarter near the wall moving left, a quarter just short of the flag moving right.
    k = n // 4
    position[:k] = rng.uniform(-1.2, -1.1, k)
    velocity[:k] = rng.uniform(-0.07, 0.0, k)
    position[k : 2 * k] = rng.uniform(0.38, 0.45, k)
    velocity[k : 2 * k] = rng.uniform(-0.01, 0.07, k)
    # Exact edges: at the wall at rest and moving, on the flag at rest, the force bounds.
    position[:4] = [-1.2, -1.2, 0.45, 0.45]
    velocity[:4] = [0.0, -0.01, 0.0025 * math.cos(1.35), 0.0]
    action[:6] = [0.0, -1.0, 0.0, 1.0, 2.0, -2.0]
    return np.stack([position, velocity], axis=1), action[:, None]


def _gym_steps(env, states, actions):
    next_states, rewards, terms = [], [], []
    for state, action in zip(states, actions):
        env.state = np.array(state, dtype=np.float64)
        _, reward, terminated, truncated, _ = env.step(np.array(action, dtype=np.float64))
        assert not truncated
        next_states.append(env.state.copy())
        rewards.append(reward)
        terms.append(terminated)
    return np.array(next_states), np.array(rewards), np.array(terms)


def _batched_step(task):
    return jax.jit(jax.vmap(task.step, in_axes=(None, 0, 0)))


def test_default_params_are_gymnasiums():
    p = mc.MountainCarParams()
    env = _env()
    assert (
        p.power,
        p.max_action,
        p.max_speed,
        p.min_position,
        p.max_position,
        p.goal_position,
        p.goal_velocity,
    ) == (
        env.power,
        env.max_action,
        env.max_speed,
        env.min_position,
        env.max_position,
        env.goal_position,
        env.goal_velocity,
    )
    assert -env.min_action == env.max_action
    spec = gymnasium.spec("MountainCarContinuous-v0")
    task = diffcontrol.make(TASK)
    assert mc.EPISODE_LENGTH == task.episode_length == spec.max_episode_steps == 999
    assert task.reward_threshold == spec.reward_threshold == 90.0
    assert task.gym_id == spec.id
    # The gravity constant is a literal in Gymnasium's step: an unforced step from rest.
    env.state = np.array([0.1, 0.0])
    env.step(np.array([0.0]))
    assert env.state[1] == np.float32(-p.gravity * math.cos(0.3))


@pytest.mark.parametrize("x64", [True, False], ids=["float64", "float32"])
def test_one_step(x64):
    rng = np.random.default_rng(SEED)
    states, actions = _cases(rng, N_STATES)
    if not x64:
        states = states.astype(np.float32).astype(np.float64)
        actions = actions.astype(np.float32).astype(np.float64)
    env = _env()
    gym_next, gym_reward, gym_term = _gym_steps(env, states, actions)
    # The coverage the docstring promises: every non-smooth place is visited.
    assert np.mean(np.abs(actions) > 1) > 0.25
    assert np.mean(np.abs(gym_next[:, 1]) == np.float32(env.max_speed)) > 0.02
    assert np.sum((gym_next[:, 0] == np.float32(env.min_position)) & (gym_next[:, 1] == 0)) > 10
    assert np.sum(gym_next[:, 0] == np.float32(env.max_position)) > 5
    assert 0.05 < gym_term.mean() < 0.5

    task = diffcontrol.make(TASK)
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        next_state, reward, terminated = _batched_step(task)(
            task.default_params(), jnp.asarray(states, dtype), jnp.asarray(actions, dtype)
        )
        assert next_state.dtype == dtype and reward.dtype == dtype
        assert terminated.dtype == jnp.bool_
    next_state, reward, terminated = map(np.asarray, (next_state, reward, terminated))
    if x64:
        np.testing.assert_array_equal(next_state.astype(np.float32), gym_next)
        np.testing.assert_allclose(reward, gym_reward, rtol=0, atol=ATOL_F64)
        np.testing.assert_array_equal(terminated, gym_term)
        # The exact edges: at the wall at rest it is pushed off by gravity; moving left into
        # it, it stops dead; resting on the flag (velocity 0 >= goal_velocity) terminates.
        assert next_state[0, 0] > -1.2 and next_state[1, 1] == 0.0
        assert terminated[2] and terminated[3] and reward[3] == 100.0 - 0.1
    else:
        np.testing.assert_allclose(next_state, gym_next, rtol=0, atol=ATOL_F32)
        np.testing.assert_allclose(
            reward, gym_reward, rtol=0, atol=1e-4
        )  # a float32 ulp at 100 is 7.6e-6
        clear = (np.abs(gym_next[:, 0] - env.goal_position) > 1e-5) & (
            np.abs(gym_next[:, 1]) > 1e-6
        )
        assert clear.mean() > 0.9
        np.testing.assert_array_equal(terminated[clear], gym_term[clear])


def test_feedback_episodes_match():
    """Whole float32 episodes of a bang-bang controller from Gymnasium's own starts: the same
    number of steps to the flag and the same return (float32 states differ by a few ulps)."""
    task = diffcontrol.make(TASK)
    params = task.default_params()
    env = gymnasium.make("MountainCarContinuous-v0")

    def controller(obs):  # half throttle along the velocity: about 170 steps to the flag
        return jnp.where(obs[1:] >= 0, 0.5, -0.5)

    @jax.jit
    def run(state0):
        def body(carry, _):
            state, done, ret, steps = carry
            next_state, reward, term = task.step(params, state, controller(task.observe(state)))
            return (next_state, done | term, ret + jnp.where(done, 0.0, reward), steps + ~done), 0

        init = (state0, jnp.asarray(False), jnp.zeros(()), jnp.zeros((), jnp.int32))
        return jax.lax.scan(body, init, None, length=task.episode_length)[0][2:]

    for seed in range(8):
        obs, _ = env.reset(seed=seed)
        start = np.array(env.unwrapped.state)
        ret, n, done = 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(np.asarray(controller(obs)))
            ret, n, done = ret + reward, n + 1, terminated or truncated
        assert terminated and n < 300
        jax_ret, jax_n = run(jnp.asarray(start, jnp.float32))
        assert int(jax_n) == n
        assert float(jax_ret) == pytest.approx(ret, abs=1e-4)


N_RESETS = 4096


def test_reset_distribution():
    """Position ~ U(-0.6, -0.4) and velocity 0, as Gymnasium draws them (two-sample KS test
    against Gymnasium's own resets, and the bounds)."""
    task = diffcontrol.make(TASK)
    keys = jax.random.split(jax.random.key(7), N_RESETS)
    ours = np.asarray(jax.jit(jax.vmap(task.reset, in_axes=(0, None)))(keys, task.default_params()))
    assert ours.shape == (N_RESETS, 2)
    assert np.all(ours[:, 1] == 0.0)
    assert np.all((ours[:, 0] >= -0.6) & (ours[:, 0] <= -0.4))
    # Filling the box: with 4096 uniform draws a gap of 1% of the range has probability ~1e-18.
    assert ours[:, 0].min() < -0.598 and ours[:, 0].max() > -0.402
    env = _env()
    theirs = np.array([env.reset(seed=s)[0] for s in range(1000)])
    assert np.all(theirs[:, 1] == 0.0)
    assert np.all((theirs[:, 0] >= -0.6) & (theirs[:, 0] <= -0.4))
    from scipy import stats  # here: SciPy's import costs every test run half a second

    assert stats.ks_2samp(ours[:, 0], theirs[:, 0]).pvalue > 1e-3
    assert len(np.unique(ours[:, 0])) > 0.99 * N_RESETS  # distinct keys, distinct starts


def test_observation_is_the_state():
    task = diffcontrol.make(TASK)
    env = _env()
    for seed in range(8):
        obs, _ = env.reset(seed=seed)
        for _ in range(5):
            obs, *_ = env.step(np.array([0.7], np.float32))
        state = env.unwrapped.state
        np.testing.assert_array_equal(np.asarray(task.observe(jnp.asarray(state))), obs)
        np.testing.assert_array_equal(np.asarray(_gym.state_from_observation(task, obs)), state)


# --- gradients ---------------------------------------------------------------------------------


def _smooth_cases(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """States and actions at least a finite-difference step away from every clip, the wall
    and the flag."""
    states, actions = [], []
    while len(states) < n:
        x, v, a = rng.uniform(-1.1, 0.35), rng.uniform(-0.05, 0.05), rng.uniform(-0.9, 0.9)
        v_next = v + a * 0.0015 - 0.0025 * math.cos(3 * x)
        if abs(v_next) < 0.065 and -1.15 < x + v_next < 0.4:
            states.append([x, v])
            actions.append([a])
    return np.array(states), np.array(actions)


def test_step_gradient_matches_finite_differences():
    """The Jacobian of (next state, reward) in state, action and the physical constants,
    against float64 central differences, where the step is smooth."""
    task = diffcontrol.make(TASK)
    rng = np.random.default_rng(SEED + 1)
    states, actions = _smooth_cases(rng, 24)
    eps = 1e-6
    with jax.enable_x64(True):
        params = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), task.default_params())

        def out(params, state, action):
            next_state, reward, _ = task.step(params, state, action)
            return jnp.concatenate([next_state, reward[None]])

        jac = jax.jit(jax.jacfwd(out, argnums=(0, 1, 2)))
        for state, action in zip(states, actions):
            s, a = jnp.asarray(state), jnp.asarray(action)
            j_params, j_state, j_action = jac(params, s, a)
            for i in range(2):
                e = jnp.zeros(2).at[i].set(eps)
                fd = (out(params, s + e, a) - out(params, s - e, a)) / (2 * eps)
                np.testing.assert_allclose(j_state[:, i], fd, rtol=1e-6, atol=1e-9)
            fd = (out(params, s, a + eps) - out(params, s, a - eps)) / (2 * eps)
            np.testing.assert_allclose(j_action[:, 0], fd, rtol=1e-6, atol=1e-9)
            for name in ("power", "gravity"):
                value = getattr(params, name)

                def at(x, name=name, s=s, a=a):
                    return out(eqx.tree_at(lambda p: getattr(p, name), params, x), s, a)

                # The step is linear in power and gravity, so a wide relative step is exact
                # but for rounding (a 1e-6 relative step of 0.0015 would lose 7 digits).
                rel = 1e-3
                fd = (at(value * (1 + rel)) - at(value * (1 - rel))) / (2 * rel * value)
                np.testing.assert_allclose(getattr(j_params, name), fd, rtol=1e-6, atol=1e-9)
            # And the gradient is not trivially zero: the action moves the velocity by power.
            assert float(j_action[1, 0]) == pytest.approx(0.0015)


def test_documented_zero_gradients():
    """Where the docstring says the derivative vanishes: the force clip (not the reward's
    action cost), the speed clip and the wall."""
    task = diffcontrol.make(TASK)
    params = task.default_params()

    def out(state, action):
        next_state, reward, _ = task.step(params, state, action)
        return jnp.concatenate([next_state, reward[None]])

    jac = jax.jit(jax.jacfwd(out, argnums=(0, 1)))
    # Force clip: a = 1.5 does not move the state, but costs -0.2 a in reward.
    _, j_a = jac(jnp.array([-0.5, 0.01]), jnp.array([1.5]))
    np.testing.assert_allclose(np.asarray(j_a[:, 0]), [0.0, 0.0, -0.3], atol=1e-7)
    # Speed clip: velocity' saturated at 0.07 whatever the velocity.
    j_s, _ = jac(jnp.array([-0.52, 0.069]), jnp.array([1.0]))
    assert float(j_s[1, 1]) == 0.0
    # Wall: moving left into it, velocity' is 0 whatever the state.
    j_s, j_a = jac(jnp.array([-1.19, -0.05]), jnp.array([-1.0]))
    assert float(j_s[1, 0]) == float(j_s[1, 1]) == float(j_a[1, 0]) == 0.0


def test_energy_loss():
    """The default loss: 0.1 a^2 alone at the flag's energy and beyond, a deficit that falls
    as energy rises, and a finite gradient for a car exactly at rest at the bottom."""
    task = diffcontrol.make(TASK)
    params = task.default_params()
    loss = task.step_loss("energy")
    a = jnp.array([0.5])

    def at(state):
        return loss(params, jnp.zeros(2), a, jnp.asarray(state, jnp.float32), jnp.zeros(()))

    on_flag_fast = at([0.45, 0.03])
    assert float(on_flag_fast) == pytest.approx(0.1 * 0.25)
    assert float(at([-0.52, 0.0])) > float(at([-0.7, 0.0])) > float(at([-0.9, 0.0])) > 0.025
    bottom = jnp.array([-math.pi / 6, 0.0])
    g = jax.grad(lambda s: at(s))(bottom)
    assert np.all(np.isfinite(np.asarray(g)))
    assert task.losses[0] == "energy" and "cost" in task.losses
    # The cancellation-free form is the energy above the floor, -gravity / 3.
    with jax.enable_x64(True):
        p64 = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)
        rng = np.random.default_rng(SEED + 2)
        for x, v in zip(rng.uniform(-1.2, 0.6, 16), rng.uniform(-0.07, 0.07, 16)):
            s = jnp.array([x, v])
            floor = float(mc.energy(p64, s)) + float(p64.gravity) / 3
            assert float(mc.energy_above_floor(p64, s)) == pytest.approx(floor, rel=1e-9, abs=1e-15)
        flag = jnp.array([0.45, 0.0])
        goal = float(mc.goal_energy_above_floor(p64))
        assert goal == pytest.approx(float(mc.energy_above_floor(p64, flag)), rel=1e-12)
    with pytest.raises(KeyError):
        task.step_loss("nope")


def test_frames_and_animation(tmp_path):
    """The task's drawing hook yields one figure per ``every`` states, and ``animate`` uses it."""
    from diffcontrol.animation import animate

    task = diffcontrol.make(TASK)
    t = np.arange(31)
    states = np.stack([-0.5 + 0.9 * np.sin(t / 10) ** 2, np.zeros_like(t, float)], axis=1)
    rec = Recording(
        env_id="MountainCarContinuous-v0",
        dt=0.02,
        states=states,
        actions=np.full((30, 1), 0.3),
        rewards=np.zeros(30),
    )
    figures = list(task.frames(rec, 10))
    assert len(figures) == 4  # states 0, 10, 20, 30
    path = animate(rec, task, tmp_path / "car.gif", max_frames=8)
    assert path.stat().st_size > 1000


@pytest.mark.slow
def test_learns_to_reach_the_flag():
    """A fifth of the default budget (100 updates, a few seconds) reaches the flag cheaply
    from every Gymnasium start tried; an untrained controller never does."""
    task = diffcontrol.make(TASK)
    cfg = resolve_config(task, updates=100, eval_every=50, eval_episodes=32)
    result = train(task, cfg)
    assert result.curve[0]["eval_return"] < 1.0
    policy = policies.NumpyPolicy(policies.controller_to_dict(result.controller, task))
    ev = evaluate(policy, task, episodes=20, seed=0)
    assert ev.returns.min() > 90.0, ev.returns
    assert ev.mean > 93.0
