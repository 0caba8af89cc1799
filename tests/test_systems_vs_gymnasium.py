"""The JAX systems against Gymnasium's own ``Pendulum-v1`` and ``CartPole-v1``.

Every comparison sets ``env.unwrapped.state``, calls ``env.step`` and compares the next state,
the reward and (CartPole) the terminated flag with the JAX task. Tolerances:

- float64 (``jax.enable_x64(True)``), one step: ``ATOL_F64 = 1e-12`` absolute. Both sides run
  the same formulas in IEEE double; XLA's ``sin``/``cos``/``%`` may differ from NumPy's libm by
  an ulp (~2e-15 at the magnitudes used here), so 1e-12 leaves room for rounding and nothing
  else: a wrong constant or a swapped term shows up at 1e-4 or more.
- float32 (JAX's default), one step: ``RTOL_F32 = ATOL_F32 = 1e-5``. Gymnasium computes in
  float64 from the float32-rounded inputs, JAX in float32 (eps 1.2e-7). The quantities reach
  ~20 in magnitude (cost up to pi^2 + 0.1 * 10^2 + 0.001 * 4^2, speeds up to ~10, angles
  up to 3 pi) through a handful of operations, so rounding stays below ~20 ulp of 20 = 5e-6.
- Whole episodes: rounding differences of one step are amplified by the dynamics (a spinning
  pendulum is sensitive to its initial state), so the tolerances are wider and stated there.
"""

from __future__ import annotations

import math

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.envs.classic_control import pendulum as gym_pendulum

import diffcontrol.tasks
from diffcontrol.systems import cartpole as cp
from diffcontrol.systems import pendulum as pend

ATOL_F64 = 1e-12
RTOL_F32 = 1e-5
ATOL_F32 = 1e-5
# Gymnasium's observations are float32: one float32 ulp (relative 2^-23 ~ 1.2e-7) of rounding.
RTOL_OBS = 2.4e-7
ATOL_OBS = 1e-7

N_STATES = 300
SEED = 20240611

PENDULUM_TASKS = ("pendulum", "pendulum-unclipped")


def _pendulum_env(task_name: str):
    env = gymnasium.make("Pendulum-v1").unwrapped
    if task_name == "pendulum-unclipped":
        # The 2019 original's variant: Gymnasium's own dynamics with the torque clip removed.
        env.max_torque = np.inf
    env.reset(seed=0)
    return env


def _cartpole_env():
    env = gymnasium.make("CartPole-v1").unwrapped
    env.reset(seed=0)
    return env


def _batched_step(task):
    """``task.step`` over a batch of states and actions, jitted (compiled once per dtype)."""
    return jax.jit(jax.vmap(task.step, in_axes=(None, 0, 0)))


def _pendulum_cases(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """States and torques spanning the clips: angles to +-3 pi, speeds past +-8, torques past +-2."""
    theta = rng.uniform(-3 * np.pi, 3 * np.pi, n)
    theta_dot = rng.uniform(-10.0, 10.0, n)
    # A third of the speeds sit just inside the clip, so that one step crosses it or not.
    near = rng.random(n) < 1 / 3
    theta_dot[near] = rng.choice([-1.0, 1.0], near.sum()) * rng.uniform(7.5, 8.0, near.sum())
    torque = rng.uniform(-4.0, 4.0, n)
    # Exact edges: the wrap point, upright, the torque bounds, zero torque.
    theta[:6] = [np.pi, -np.pi, 0.0, np.pi, -np.pi, 2 * np.pi]
    torque[:6] = [2.0, -2.0, 0.0, 0.0, 4.0, -4.0]
    return np.stack([theta, theta_dot], axis=1), torque[:, None]


def _cartpole_cases(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """States inside and just outside the termination bounds; Gymnasium actions 0/1."""
    high = np.array([2.6, 3.0, 0.3, 3.5])
    states = rng.uniform(-high, high, (n, 4))
    actions = rng.integers(0, 2, n)
    return states, actions


def _cartpole_edges() -> np.ndarray:
    """States whose next state lies exactly on, or one ulp past, a termination bound."""
    x_thr = 2.4
    th_thr = 12 * 2 * math.pi / 360
    rows = []
    for sign in (1.0, -1.0):
        # With zero speeds the next position/angle equals the current one exactly.
        rows += [
            [sign * x_thr, 0.0, 0.0, 0.0],
            [sign * np.nextafter(x_thr, np.inf), 0.0, 0.0, 0.0],
            [0.0, 0.0, sign * th_thr, 0.0],
            [0.0, 0.0, sign * np.nextafter(th_thr, np.inf), 0.0],
        ]
    return np.array(rows)


def _gym_pendulum_steps(env, states, torques):
    next_states, rewards, observations = [], [], []
    for state, torque in zip(states, torques):
        env.state = np.array(state, dtype=np.float64)
        obs, reward, terminated, truncated, _ = env.step(np.array(torque, dtype=np.float64))
        assert not terminated and not truncated
        next_states.append(env.state.copy())
        rewards.append(reward)
        observations.append(obs)
    return np.array(next_states), np.array(rewards), np.array(observations)


def _gym_cartpole_steps(env, states, actions):
    next_states, rewards, terms = [], [], []
    for state, action in zip(states, actions):
        env.state = np.array(state, dtype=np.float64)
        # Each comparison is a fresh first step, so the failing step's reward is 1.
        env.steps_beyond_terminated = None
        _, reward, terminated, _, _ = env.step(int(action))
        next_states.append(env.state.copy())
        rewards.append(reward)
        terms.append(terminated)
    return np.array(next_states), np.array(rewards), np.array(terms)


def test_default_params_are_gymnasiums():
    p = pend.PendulumParams()
    env = gymnasium.make("Pendulum-v1").unwrapped
    assert (p.g, p.m, p.l, p.dt, p.max_speed, p.max_torque) == (
        env.g,
        env.m,
        env.l,
        env.dt,
        env.max_speed,
        env.max_torque,
    )
    c = cp.CartPoleParams()
    env = gymnasium.make("CartPole-v1").unwrapped
    assert (c.gravity, c.masscart, c.masspole, c.length, c.force_mag, c.tau) == (
        env.gravity,
        env.masscart,
        env.masspole,
        env.length,
        env.force_mag,
        env.tau,
    )
    assert (c.theta_threshold, c.x_threshold) == (env.theta_threshold_radians, env.x_threshold)
    assert env.kinematics_integrator == "euler"  # the JAX step is explicit Euler
    assert pend.EPISODE_LENGTH == gymnasium.spec("Pendulum-v1").max_episode_steps
    assert cp.EPISODE_LENGTH == gymnasium.spec("CartPole-v1").max_episode_steps


@pytest.mark.parametrize("x64", [True, False], ids=["float64", "float32"])
@pytest.mark.parametrize("task_name", PENDULUM_TASKS)
def test_pendulum_one_step(task_name, x64):
    rng = np.random.default_rng(SEED)
    states, torques = _pendulum_cases(rng, N_STATES)
    if task_name == "pendulum-unclipped":
        torques = torques * 3.0  # up to +-12 N m: the unclipped variant must not clip
    # The coverage the docstring promises: clipped torques and clipped speeds both occur.
    assert np.mean(np.abs(torques) > 2.0) > 0.25
    if not x64:
        # Gymnasium steps the float32-rounded inputs, so only JAX's float32 arithmetic differs.
        states = states.astype(np.float32).astype(np.float64)
        torques = torques.astype(np.float32).astype(np.float64)
    env = _pendulum_env(task_name)
    gym_next, gym_reward, gym_obs = _gym_pendulum_steps(env, states, torques)
    assert np.mean(np.abs(gym_next[:, 1]) == env.max_speed) > 0.1

    task = diffcontrol.tasks.make(task_name)
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        params = task.default_params()
        next_state, reward, terminated = _batched_step(task)(
            params, jnp.asarray(states, dtype), jnp.asarray(torques, dtype)
        )
        obs = jax.jit(jax.vmap(task.observe))(next_state)
        assert next_state.dtype == dtype and reward.dtype == dtype
    next_state, reward = np.asarray(next_state), np.asarray(reward)
    assert not np.any(np.asarray(terminated))
    if x64:
        np.testing.assert_allclose(next_state, gym_next, rtol=0, atol=ATOL_F64)
        np.testing.assert_allclose(reward, gym_reward, rtol=0, atol=ATOL_F64)
        np.testing.assert_allclose(np.asarray(obs), gym_obs, rtol=RTOL_OBS, atol=ATOL_OBS)
    else:
        np.testing.assert_allclose(next_state, gym_next, rtol=RTOL_F32, atol=ATOL_F32)
        np.testing.assert_allclose(reward, gym_reward, rtol=RTOL_F32, atol=ATOL_F32)


@pytest.mark.parametrize("x64", [True, False], ids=["float64", "float32"])
def test_cartpole_one_step(x64):
    rng = np.random.default_rng(SEED + 1)
    states, actions = _cartpole_cases(rng, N_STATES)
    if x64:
        edges = _cartpole_edges()
        states = np.concatenate([edges, states])
        actions = np.concatenate([np.zeros(len(edges), int), actions])
    else:
        states = states.astype(np.float32).astype(np.float64)
    env = _cartpole_env()
    gym_next, gym_reward, gym_term = _gym_cartpole_steps(env, states, actions)
    # Both outcomes occur often enough for the flag comparison to mean something.
    assert 0.2 < gym_term.mean() < 0.8

    task = diffcontrol.tasks.make("cartpole")
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        push = 2.0 * actions[:, None] - 1.0  # Gymnasium's action 1 is +1, action 0 is -1
        next_state, reward, terminated = _batched_step(task)(
            task.default_params(), jnp.asarray(states, dtype), jnp.asarray(push, dtype)
        )
        assert next_state.dtype == dtype and reward.dtype == dtype
        assert terminated.dtype == jnp.bool_
    next_state, reward, terminated = map(np.asarray, (next_state, reward, terminated))
    np.testing.assert_array_equal(reward, gym_reward)
    if x64:
        np.testing.assert_allclose(next_state, gym_next, rtol=0, atol=ATOL_F64)
        np.testing.assert_array_equal(terminated, gym_term)
        # The exact-edge states: on the bound is alive, one ulp past it terminates.
        np.testing.assert_array_equal(terminated[:8], [False, True] * 4)
    else:
        np.testing.assert_allclose(next_state, gym_next, rtol=RTOL_F32, atol=ATOL_F32)
        # A float32 state within rounding of a bound may legitimately fall either side.
        margin = np.minimum(
            np.abs(np.abs(gym_next[:, 0]) - env.x_threshold),
            np.abs(np.abs(gym_next[:, 2]) - env.theta_threshold_radians),
        )
        clear = margin > 1e-5
        assert clear.mean() > 0.95
        np.testing.assert_array_equal(terminated[clear], gym_term[clear])


def _pendulum_episode():
    task = diffcontrol.tasks.make("pendulum")

    @jax.jit
    def run(state0, torques):
        def body(state, torque):
            next_state, reward, _ = task.step(task.default_params(), state, torque)
            return next_state, (next_state, reward)

        return jax.lax.scan(body, state0, torques)[1]

    return run


# Whole-episode tolerances. float64: one-step differences are ~1e-15 (an ulp of XLA's sin
# against libm's); over 200 steps a pendulum that spins through the bottom amplifies them by up
# to ~1e5 (measured: 4e-10 worst over these seeds), so 1e-8. float32: the same amplification
# of float32 rounding (1e-7) reaches ~1e-2 on the spinning episodes (measured 8e-3), so 5e-2;
# any error in the dynamics themselves grows to O(1) over 200 steps and still fails.
EPISODE_ATOL = {True: 1e-8, False: 5e-2}


@pytest.mark.parametrize("x64", [True, False], ids=["float64", "float32"])
def test_pendulum_episodes(x64):
    rng = np.random.default_rng(SEED + 2)
    env = _pendulum_env("pendulum")
    task = diffcontrol.tasks.make("pendulum")
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        run = _pendulum_episode()
        for episode in range(4):
            _, _ = env.reset(seed=episode)
            state0 = env.state.copy()
            # Torques beyond the clip, as a random agent would send them.
            torques = rng.uniform(-3.0, 3.0, (task.episode_length, 1))
            if not x64:
                state0 = state0.astype(np.float32).astype(np.float64)
                torques = torques.astype(np.float32).astype(np.float64)
                env.state = state0.copy()
            gym_states, gym_rewards = [], []
            for torque in torques:
                _, reward, _, _, _ = env.step(torque)
                gym_states.append(env.state.copy())
                gym_rewards.append(reward)
            states, rewards = run(jnp.asarray(state0, dtype), jnp.asarray(torques, dtype))
            tol = EPISODE_ATOL[x64]
            np.testing.assert_allclose(np.asarray(states), np.array(gym_states), rtol=0, atol=tol)
            np.testing.assert_allclose(np.asarray(rewards), np.array(gym_rewards), rtol=0, atol=tol)


def _cartpole_episode():
    task = diffcontrol.tasks.make("cartpole")

    @jax.jit
    def run(state0, pushes):
        def body(state, push):
            out = task.step(task.default_params(), state, push)
            return out[0], out

        return jax.lax.scan(body, state0, pushes)[1]

    return run


@pytest.mark.parametrize("x64", [True, False], ids=["float64", "float32"])
def test_cartpole_episodes(x64):
    """Random pushes until Gymnasium terminates; JAX must terminate on the same step."""
    rng = np.random.default_rng(SEED + 3)
    env = _cartpole_env()
    task = diffcontrol.tasks.make("cartpole")
    # Episodes of random pushes last ~10-40 steps: float64 agrees to ~1e-15, float32 to ~3e-7.
    tol = ATOL_F64 if x64 else ATOL_F32
    lengths = []
    with jax.enable_x64(x64):
        dtype = jnp.float64 if x64 else jnp.float32
        run = _cartpole_episode()
        for episode in range(6):
            env.reset(seed=100 + episode)
            state0 = env.state.copy()
            if not x64:
                state0 = state0.astype(np.float32).astype(np.float64)
                env.state = state0.copy()
            # One fixed-length sequence (one compiled scan); Gymnasium uses its prefix.
            actions = rng.integers(0, 2, task.episode_length)
            gym_states = []
            for action in actions:
                _, reward, terminated, truncated, _ = env.step(int(action))
                assert reward == 1.0 and not truncated
                gym_states.append(env.state.copy())
                if terminated:
                    break
            n = len(gym_states)
            lengths.append(n)
            push = jnp.asarray(2.0 * actions[:, None] - 1.0, dtype)
            states, rewards, terms = run(jnp.asarray(state0, dtype), push)
            np.testing.assert_allclose(
                np.asarray(states)[:n], np.array(gym_states), atol=tol, rtol=0
            )
            np.testing.assert_array_equal(np.asarray(rewards)[:n], 1.0)
            terms = np.asarray(terms)[:n]
            assert terms[-1] and not terms[:-1].any(), f"episode {episode}: {terms}"
    assert min(lengths) > 5 and max(lengths) < task.episode_length


N_RESETS = 4096


@pytest.mark.parametrize(
    "task_name, high",
    [
        ("pendulum", (gym_pendulum.DEFAULT_X, gym_pendulum.DEFAULT_Y)),  # (pi, 1)
        ("pendulum-unclipped", (gym_pendulum.DEFAULT_X, gym_pendulum.DEFAULT_Y)),
        # CartPoleEnv.reset: every component ~ U(-0.05, 0.05).
        ("cartpole", (0.05, 0.05, 0.05, 0.05)),
    ],
)
def test_reset_distribution(task_name, high):
    """Inside Gymnasium's box, and filling it: min/max near the bounds, quartiles at +-high/2."""
    task = diffcontrol.tasks.make(task_name)
    keys = jax.random.split(jax.random.key(7), N_RESETS)
    samples = np.asarray(
        jax.jit(jax.vmap(task.reset, in_axes=(0, None)))(keys, task.default_params())
    )
    high = np.asarray(high)
    assert samples.shape == (N_RESETS, len(high))
    assert np.all(samples >= -high) and np.all(samples <= high)
    # With 4096 uniform samples the gap to a bound exceeds 1% of the range with
    # probability 0.99^4096 ~ 1e-18.
    np.testing.assert_array_less(samples.max(axis=0), high)
    assert np.all(samples.min(axis=0) < -high + 0.02 * high)
    assert np.all(samples.max(axis=0) > high - 0.02 * high)
    # Uniform, not just bounded: the quartiles of U(-h, h) are -h/2, 0, h/2 (sd ~0.03 h here).
    quartiles = np.quantile(samples, [0.25, 0.5, 0.75], axis=0)
    assert np.all(np.abs(quartiles - np.outer([-0.5, 0.0, 0.5], high)) < 0.06 * high)
    # Distinct keys give distinct states (no key reuse inside reset). Whole rows: single float32
    # components of 4096 draws collide by the birthday paradox.
    assert len(np.unique(samples, axis=0)) == N_RESETS


@pytest.mark.parametrize("task_name", ["pendulum", "cartpole"])
def test_observation_matches_gymnasium(task_name):
    """``observe`` of Gymnasium's state equals the observation Gymnasium returns (float32)."""
    task = diffcontrol.tasks.make(task_name)
    env = _pendulum_env(task_name) if task_name == "pendulum" else _cartpole_env()
    states, observations = [], []
    for seed in range(64):
        obs, _ = env.reset(seed=seed)
        states.append(env.state.copy())
        observations.append(obs)
    with jax.enable_x64(True):
        ours = np.asarray(jax.jit(jax.vmap(task.observe))(jnp.asarray(np.array(states))))
    assert ours.shape == (64, task.observation_size)
    np.testing.assert_allclose(ours, np.array(observations), rtol=RTOL_OBS, atol=ATOL_OBS)
    if task_name == "pendulum":
        # (cos theta, sin theta, theta_dot) in that order.
        theta, theta_dot = np.array(states).T
        np.testing.assert_allclose(ours, np.stack([np.cos(theta), np.sin(theta), theta_dot], 1))
