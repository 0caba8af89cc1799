"""MuJoCo tasks through MJX against Gymnasium's own MuJoCo environments, and their gradients.

Skipped without the ``mujoco`` extra; ``.ci/run`` installs it and runs these.

Each task (``InvertedDoublePendulum-v5``, ``Reacher-v5``, ``Swimmer-v5``, and the user's file
``examples/mujoco_task.py`` on ``InvertedPendulum-v5``) against ``gymnasium.make(<id>)``, steps
where a joint limit engages left out (counted: fewer than half of the cases):

- float64 (``jax.enable_x64(True)``), one step (2-5 RK4 physics steps) from states of the
  reset distribution and beyond it: ``ATOL_F64 = 1e-12`` on the observation, the reward and
  the state. Both sides run MuJoCo's algorithms in IEEE double (MJX's one constraint-solver
  iteration against the C engine's 100 solves no constraint here: none is active); measured
  8e-15.
- float32, the default: ``ATOL_F32 = 1e-5`` on the observation and the reward (measured 2e-6:
  float32 rounding through 20 RK4 stages at speeds of a few rad/s).
- At the double pendulum's slider limit the two differ by design (one solver iteration against
  100): one step from x = 0.98 m at 2 m/s moved the velocities 0.06 apart;
  ``test_the_limit_is_where_they_part`` checks that the difference is there and bounded.
- Gradients (reverse mode, what training uses; the unconstrained step's, ``systems.mjx``) of
  the double pendulum's 3-action loss against central finite differences of the step itself
  in float64, ``h = 1e-6``: truncation and rounding are both ~1e-10 relative; measured 1e-9,
  ``RTOL_GRAD = 1e-6``.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("mujoco.mjx")
gymnasium = pytest.importorskip("gymnasium")

from diffcontrol import _jax_setup  # noqa: E402
from diffcontrol.builtin.mujoco.tasks import InvertedDoublePendulum, Reacher, Swimmer  # noqa: E402
from diffcontrol.errors import ConfigError  # noqa: E402
from diffcontrol.systems import mjx as mjx_system  # noqa: E402

pytestmark = pytest.mark.mujoco

ATOL_F64 = 1e-12
ATOL_F32 = 1e-5
RTOL_GRAD = 1e-6
N_STATES = 100


def _example_task():
    """``examples/mujoco_task.py``'s task: a user's file on Gymnasium's ``InvertedPendulum-v5``."""
    path = Path(__file__).resolve().parents[1] / "examples" / "mujoco_task.py"
    spec = importlib.util.spec_from_file_location("mujoco_task", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Balance


TASKS = {
    "InvertedDoublePendulum-v5": InvertedDoublePendulum,
    "Reacher-v5": Reacher,
    "Swimmer-v5": Swimmer,
    "InvertedPendulum-v5": _example_task(),
}


def _cases(task, n, seed=0):
    """States from the reset distribution, every other one pushed further (0.3 rad, m, /s),
    and a random action for each."""
    rng = np.random.default_rng(seed)
    params = task.default_params()
    states = np.array(
        jax.vmap(lambda k: task.reset(k, params))(jax.random.split(jax.random.PRNGKey(seed), n))
    )
    size = task.system.nq + task.system.nv
    states[::2, :size] += rng.normal(0.0, 0.3, (len(states[::2]), size))
    return states.astype(np.float64), rng.uniform(-1.0, 1.0, (n, task.action_size))


def _against_gymnasium(task, states, actions, dtype, limits=False):
    env = gymnasium.make(task.gym_id).unwrapped
    env.reset(seed=0)
    step = jax.jit(jax.vmap(task.step, in_axes=(None, 0, 0)))
    ns, rewards, terms = step(
        task.default_params(), jnp.asarray(states, dtype), jnp.asarray(actions, dtype)
    )
    obs = np.asarray(jax.vmap(task.observe)(ns))
    size = task.system.nq + task.system.nv
    worst = dict(obs=0.0, reward=0.0, state=0.0)
    for i, (state, action) in enumerate(zip(states, actions)):
        task.set_gym_state(env, state)
        o, r, term, truncated, _ = env.step(action)
        assert not truncated and bool(terms[i]) == term, i
        if env.data.nefc:  # a joint limit engaged: compared only with limits=True
            worst["limited"] = worst.get("limited", 0) + 1
            if not limits:
                continue
        worst["obs"] = max(worst["obs"], float(np.abs(obs[i] - o).max()))
        worst["reward"] = max(worst["reward"], abs(float(rewards[i]) - r))
        qs = np.concatenate([env.data.qpos, env.data.qvel])
        worst["state"] = max(worst["state"], float(np.abs(np.asarray(ns[i, :size]) - qs).max()))
    env.close()
    return worst, np.asarray(terms)


@pytest.mark.parametrize("gym_id", TASKS)
def test_steps_as_gymnasium_in_float64(gym_id):
    task = TASKS[gym_id]()
    task.system  # noqa: B018  (loaded in float32: a state in float64 steps a float64 copy)
    with jax.enable_x64(True):
        states, actions = _cases(task, N_STATES)
        worst, terms = _against_gymnasium(task, states, actions, jnp.float64)
    # Most steps are off the limits (Reacher's target, pushed past its range, is not always).
    assert worst.get("limited", 0) < len(states) // 2, worst
    assert max(worst["obs"], worst["reward"], worst["state"]) < ATOL_F64, worst
    if gym_id == "InvertedDoublePendulum-v5":  # both outcomes of the termination test occur
        assert 0 < terms.sum() < len(terms)


@pytest.mark.parametrize("gym_id", TASKS)
def test_steps_as_gymnasium_in_float32(gym_id):
    task = TASKS[gym_id]()
    states, actions = _cases(task, N_STATES, seed=1)
    worst, _ = _against_gymnasium(task, states, actions, jnp.float32)
    assert worst.get("limited", 0) < len(states) // 2, worst
    assert worst["obs"] < ATOL_F32 and worst["reward"] < ATOL_F32, worst


@pytest.mark.parametrize("gym_id", TASKS)
def test_a_reset_observes_what_gymnasiums_reset_does(gym_id):
    """The first observation: the reset state's forward pass (Reacher's fingertip to target)."""
    with jax.enable_x64(True):
        task = TASKS[gym_id]()
        state = np.asarray(task.reset(jax.random.PRNGKey(0), task.default_params()))
        env = gymnasium.make(gym_id).unwrapped
        env.reset(seed=0)
        task.set_gym_state(env, state)
        np.testing.assert_allclose(task.observe(state), env._get_obs(), atol=ATOL_F64)


def test_the_limit_is_where_they_part():
    """Against the slider's limit, MJX's one solver iteration is not the C engine's converged
    solve: the step differs, by a bounded amount, and both see the constraint force."""
    with jax.enable_x64(True):
        task = InvertedDoublePendulum()
        state = np.zeros(7)
        state[0], state[3] = 0.98, 2.0  # running into the limit at x = 1 m
        worst, _ = _against_gymnasium(
            task, state[None], np.array([[1.0]]), jnp.float64, limits=True
        )
    assert worst["limited"] == 1 and 1e-3 < worst["obs"] < 0.5, worst


def _three_step_loss(task):
    params = task.default_params()

    def loss(state, actions):
        def body(s, u):
            ns, reward, _ = task.step(params, s, u)
            return ns, -reward

        return jax.lax.scan(body, state, actions)[1].sum()

    return loss


@pytest.mark.parametrize("gym_id", ["InvertedDoublePendulum-v5", "Reacher-v5", "Swimmer-v5"])
def test_gradients_through_three_actions_match_finite_differences(gym_id):
    """The loss of three steps from a reset state (off the joint limits) against central
    differences, in float64, by the actions and by every position and speed."""
    with jax.enable_x64(True):
        task = TASKS[gym_id]()
        size = task.system.nq + task.system.nv
        loss = _three_step_loss(task)
        state = task.reset(jax.random.PRNGKey(3), task.default_params())
        actions = jnp.asarray(np.random.default_rng(3).uniform(-0.5, 0.5, (3, task.action_size)))
        g_state, g_actions = jax.jit(jax.grad(loss, argnums=(0, 1)))(state, actions)
        f = jax.jit(loss)
        h = 1e-6

        def fd(x, i, by_state):
            e = jnp.zeros_like(x).at[i].set(h)
            args = (lambda y: (y, actions)) if by_state else (lambda y: (state, y))
            return (f(*args(x + e)) - f(*args(x - e))) / (2 * h)

        fd_actions = np.array(
            [[fd(actions, (t, j), False) for j in range(task.action_size)] for t in range(3)]
        )
        fd_state = np.array([fd(state, i, True) for i in range(size)])
    np.testing.assert_allclose(g_actions, fd_actions, rtol=RTOL_GRAD, atol=1e-9)
    np.testing.assert_allclose(g_state[:size], fd_state, rtol=RTOL_GRAD, atol=1e-9)
    assert np.abs(fd_actions[0]).min() > 1e-6  # every first action reaches the loss


def test_a_missing_model_file_is_one_line(tmp_path):
    with pytest.raises(ConfigError, match="does not exist; give the path of an MJCF"):
        mjx_system.MjxSystem(tmp_path / "robot.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body><joint type='nonsense'/></body></worldbody></mujoco>")
    with pytest.raises(ConfigError, match="MuJoCo cannot load") as info:
        mjx_system.MjxSystem(bad)
    assert "\n" not in str(info.value)


def test_without_the_extra_a_mujoco_task_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    with pytest.raises(ConfigError, match=r"pip install 'diffcontrol\[mujoco\]'"):
        InvertedDoublePendulum().system  # noqa: B018


@pytest.mark.parametrize("gym_id", ["InvertedDoublePendulum-v5", "Reacher-v5", "Swimmer-v5"])
def test_the_state_comes_back_from_the_observation(gym_id):
    """``state_from_observation`` (what ``plan`` and ``loop`` act and fit from) inverts
    ``observe`` on states of the reset distribution: exactly, but for what the observation
    leaves out and the steps do not read (Swimmer's position in the plane, 0)."""
    task = TASKS[gym_id]()
    keys = jax.random.split(jax.random.PRNGKey(3), 16)
    states = jax.vmap(lambda k: task.reset(k, task.default_params()))(keys)
    back = jax.vmap(lambda s: task.state_from_observation(task.observe(s)))(states)
    if gym_id == "Swimmer-v5":
        assert np.all(np.asarray(back[:, :2]) == 0)
        back, states = back[:, 2:], states[:, 2:]
    np.testing.assert_allclose(np.asarray(back), np.asarray(states), atol=1e-6)


def _toppling_episode():
    """The double pendulum's episode under a steady push (it topples in a few dozen steps)."""
    from diffcontrol.evaluation import record_episode

    class Push:
        def action(self, obs):
            return np.array([0.3])

        def __call__(self, obs):
            return np.array([0.3], np.float32)

    return record_episode(Push(), InvertedDoublePendulum(), seed=0)


def test_a_step_traced_in_float64_leaves_the_float32_step_working():
    """A model fit traces the task's step in float64 (``_jax_setup.float64``); the training
    after it traces the same step in float32. JAX's caches keep MJX's float64 NumPy tables
    from the first trace, and the second then fails to lower unless ``float64()`` clears them
    on leaving (as it does once an MJX step has run in float64)."""
    task = Reacher()
    params = task.default_params()
    state = task.reset(jax.random.PRNGKey(0), params)
    action = jnp.zeros(task.action_size)

    def step(s, a):
        return task.step(params, s, a)[0]

    with _jax_setup.float64():
        wide = jax.jit(step).lower(state.astype(jnp.float64), action.astype(jnp.float64))
    narrow = jax.jit(step).lower(state, action)
    assert wide.out_info.dtype == jnp.float64 and narrow.out_info.dtype == jnp.float32


def test_an_episode_is_recorded_with_the_tasks_states():
    """``evaluation.record_episode`` (the run's plots) reads the states of Gymnasium's MuJoCo
    environment through the task (``gym_state``): ``qpos``, ``qvel`` and the extras."""
    rec = _toppling_episode()
    assert rec.states.shape == (len(rec.actions) + 1, 7)
    assert 0 < len(rec.actions) < 1000  # a steady push topples the poles
    env = gymnasium.make("InvertedDoublePendulum-v5")
    obs, _ = env.reset(seed=0)
    np.testing.assert_allclose(rec.states[0, :3], [obs[0], *np.arctan2(obs[1:3], obs[3:5])])


def test_animate_renders_with_mujoco_and_draws_without_opengl(tmp_path, monkeypatch):
    """``animate`` of a MuJoCo task: MuJoCo's own renderer where an OpenGL context can be
    made (EGL here, headless), one picture per frame, the poles moving between them; with no
    OpenGL backend (``MUJOCO_GL`` naming none), matplotlib drawings of the bodies instead."""
    from PIL import Image

    from diffcontrol.animation import animate
    from diffcontrol.tasks import _mujoco_frames

    task, rec = InvertedDoublePendulum(), _toppling_episode()
    steps = rec.states.shape[0]  # every state a frame (max_frames below)
    with monkeypatch.context() as env:
        env.setenv("MUJOCO_GL", "no-such-backend")
        drawn = animate(rec, task, tmp_path / "drawn.gif", max_frames=steps)
    with Image.open(drawn) as im:
        assert im.n_frames == steps and im.size != _mujoco_frames.SIZE[::-1]
    try:
        pictures = list(_mujoco_frames.rendered(task, rec.states[::4]))
    except Exception as exc:  # noqa: BLE001  (what making the context raised)
        pytest.skip(f"no OpenGL context on this machine: {exc}")
    assert len(pictures) == len(rec.states[::4])
    assert pictures[0].shape == (*_mujoco_frames.SIZE, 3) and pictures[0].dtype == np.uint8
    assert pictures[0].std() > 5  # a scene, not a blank
    assert np.abs(pictures[0].astype(int) - pictures[-1]).mean() > 0.5  # the poles fell
    gif = animate(rec, task, tmp_path / "mj.gif", max_frames=steps)
    with Image.open(gif) as im:
        assert im.n_frames == steps and im.size == _mujoco_frames.SIZE[::-1]


def test_the_rl_baselines_normalise_as_the_zoo_and_are_judged_on_what_they_saw():
    """Each MuJoCo task has PPO and SAC; the zoo's PPO normalises observations (with the
    algorithm's gamma for the rewards), and the evaluation feeds the policy its training's
    normalised observations, not the raw ones."""
    pytest.importorskip("stable_baselines3")
    import diffcontrol
    from diffcontrol.compare.baselines import build_model, rl_setup
    from diffcontrol.compare.run import make_eval_env, sb3_act

    for name in ("inverted-double-pendulum", "reacher", "swimmer"):
        assert set(rl_setup(diffcontrol.make(name)).baselines) == {"ppo", "sac"}, name
    task = diffcontrol.make("reacher")
    baseline = rl_setup(task).baselines["ppo"]
    model = build_model(baseline, lambda: make_eval_env(task), seed=0)
    model.learn(600)
    norm = model.get_vec_normalize_env()
    assert norm is not None and norm.gamma == baseline.kwargs["gamma"] == 0.9
    obs = np.stack([make_eval_env(task).reset(seed=i)[0] for i in range(4)])
    expected, _ = model.predict(norm.normalize_obs(obs), deterministic=True)
    np.testing.assert_array_equal(sb3_act(model)(obs), expected)
    raw, _ = model.predict(obs, deterministic=True)
    assert not np.allclose(raw, expected)


def test_the_exact_gradient_sees_a_joint_limit_the_smooth_one_does_not():
    """Swimmer's first joint pressed into its limit (100 degrees): the forward-mode derivative
    (``gradient="exact"``) matches central differences; the smooth one (the step without its
    constraint solver) is off, as docs/own-system.md says."""

    class Exact(Swimmer):
        gradient = "exact"

    with jax.enable_x64(True):
        exact, smooth = Exact(), Swimmer()
        state = exact.reset(jax.random.PRNGKey(1), exact.default_params())
        state = state.at[3].set(1.70).at[8].set(3.0)  # the joint's angle and speed
        actions = jnp.asarray(np.random.default_rng(0).uniform(-1, 1, (3, 2)))
        f = jax.jit(_three_step_loss(exact))
        h = 1e-6
        fd = np.array(
            [
                [
                    (f(state, actions.at[t, j].add(h)) - f(state, actions.at[t, j].add(-h)))
                    / (2 * h)
                    for j in range(2)
                ]
                for t in range(3)
            ]
        )
        g_exact = jax.jit(jax.grad(_three_step_loss(exact), argnums=1))(state, actions)
        g_smooth = jax.jit(jax.grad(_three_step_loss(smooth), argnums=1))(state, actions)
    np.testing.assert_allclose(g_exact, fd, rtol=RTOL_GRAD, atol=1e-9)
    assert np.abs(np.asarray(g_smooth) - fd).max() > 1e-3 * np.abs(fd).max()


def test_the_exact_gradient_is_finite_in_float32_at_many_states():
    """MJX's own reverse-mode derivative of its solver turned NaN at random float32 states;
    the forward-mode one never does (64 states, half pushed to or past the limits)."""

    class Exact(Swimmer):
        gradient = "exact"

    task = Exact()
    states, actions = _cases(task, 64, seed=5)
    states[::2, 3:5] = np.sign(states[::2, 3:5]) * 1.75
    grad = jax.jit(jax.vmap(jax.grad(_three_step_loss(task), argnums=(0, 1))))
    acts = np.repeat(actions[:, None, :], 3, axis=1)
    g_state, g_actions = grad(jnp.asarray(states, jnp.float32), jnp.asarray(acts, jnp.float32))
    assert np.isfinite(np.asarray(g_state)).all() and np.isfinite(np.asarray(g_actions)).all()


def test_swimmers_stroke_swims_in_gymnasium_open_loop():
    """The stroke Swimmer's training starts from (``Swimmer.stroke``, the search of
    ``benchmarks/swimmer_gaits.py``) earns what the search measured, 286 +- 2.3 open loop, in
    Gymnasium's own environment: the declared numbers are the search's, rounded."""
    drive = Swimmer().stroke()
    low, high = -np.ones(2), np.ones(2)
    env = gymnasium.make("Swimmer-v5")
    for seed in (1000, 1001):
        env.reset(seed=seed)
        actions = [np.asarray(drive.actions(t, low, high)) for t in range(1000)]
        total = sum(env.step(a)[1] for a in actions)
        assert 280 < total < 292, seed
