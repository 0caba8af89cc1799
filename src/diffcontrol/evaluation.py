"""Running a controller in Gymnasium's own environments (the ones users trust)."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from . import _gym, _jax_setup
from .envs import make_env
from .errors import ConfigError, DiffcontrolError
from .rollout import force_fn, solve_closed_loop
from .tasks import ContinuousTask, Task
from .tasks._hooks import task_hook


@dataclasses.dataclass
class EvalResult:
    """Returns of one controller over Gymnasium episodes with seeds ``seed ... seed+n-1``."""

    env_id: str
    seed: int
    returns: np.ndarray
    lengths: np.ndarray
    optimum: Any = None  # an ``optimal.OptimumResult`` on the same seeds, where asked for
    solves: str | None = None  # a planner's count of unconverged and non-finite solves

    key = "gym_eval"  # its entry in metrics.json

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))

    def to_json(self) -> dict[str, Any]:
        return {
            "env_id": self.env_id,
            "episodes": int(self.returns.size),
            "seeds": [self.seed, self.seed + int(self.returns.size) - 1],
            "mean_return": self.mean,
            "std_return": self.std,
            "min_return": float(np.min(self.returns)),
            "max_return": float(np.max(self.returns)),
            "mean_length": float(np.mean(self.lengths)),
            "returns": self.returns.tolist(),
            **({} if self.optimum is None else {"optimum": self.optimum.to_json()}),
            **({} if self.optimum is None else {"gap_to_optimum": self.optimum.gap(self.mean)}),
            **({} if self.solves is None else {"planner_solves": self.solves}),
        }

    def summary(self) -> str:
        """One line: the mean and spread of the return and the seeds it was measured on; then,
        where there are, a line with a planner's solves and one with the optimum on the same
        seeds and the gap to it."""
        n = int(self.returns.size)
        line = (
            f"{self.env_id}: return {self.mean:.2f} ± {self.std:.2f} over {n} episodes "
            f"(seeds {self.seed}-{self.seed + n - 1}; min {self.returns.min():.1f}, "
            f"max {self.returns.max():.1f})"
        )
        if self.solves is not None:
            line += f"\nplanner: {self.solves}"
        if self.optimum is None:
            return line
        gap = self.optimum.gap(self.mean)
        return f"{line}\n{self.optimum.summary()}; gap to it {100 * gap:.1f} %"

    def headline(self) -> str:
        """A few words for the end of ``diffcontrol train``'s last line."""
        return f"return {self.mean:.1f} ± {self.std:.1f} in {self.env_id}"


@dataclasses.dataclass
class Recording:
    """One episode recorded in Gymnasium: the true states (not just observations)."""

    env_id: str
    dt: float
    states: np.ndarray  # [T+1, state]
    actions: np.ndarray  # [T, act] the controller's continuous action
    rewards: np.ndarray  # [T]

    @property
    def total_return(self) -> float:
        return float(np.sum(self.rewards))


def evaluate(
    policy: Callable[[np.ndarray], Any],
    task: Task,
    episodes: int = 100,
    seed: int = 0,
    real: tuple[str, dict | None] | None = None,
) -> EvalResult:
    """Run ``policy`` (observation -> Gymnasium action) in ``task``'s Gymnasium environment.

    Episode ``i`` is reset with ``seed + i``; each runs until Gymnasium terminates or
    truncates it. This is the standard protocol, so the mean return compares with any
    other method evaluated on the same seeds. A policy with a ``reset()`` method (a planner,
    whose warm start is the last plan) is reset before every episode. A NumPy MLP
    (``batched``) runs up to ``LOCKSTEP_WIDTH`` episodes side by side in Gymnasium's and
    diffcontrol's Gymnasium-backed environments, each episode in an environment of its own,
    with the same returns; any other environment is made once (``_side_by_side``).

    Args:
        real: ``(env_id, env_kwargs)`` of another environment to run instead, e.g. the "real"
            system that a fitted model was learned from
            (``("diffcontrol/PendulumFriction-v0", {"g": 12.0, "friction": 0.1})``).
    """
    if episodes <= 0:
        raise ValueError(f"episodes must be positive, got {episodes}")
    env, label = eval_environment(task, real)
    try:
        with _system_errors(label, real):
            _check_fits(policy, env, label)
            if _side_by_side(policy, env):
                returns, lengths = _lockstep(policy, task, real, env, episodes, seed)
            else:
                returns, lengths = _one_by_one(policy, env, episodes, seed)
    finally:
        env.close()
    if not np.all(np.isfinite(returns)):  # a system whose rewards are not numbers: no verdict
        i = int(np.argmin(np.isfinite(returns)))
        raise ConfigError(
            f"{label} gave the return {returns[i]} in episode {i} (reset seed {seed + i}): its "
            "rewards are not finite numbers, so no return can be judged; fix the environment"
        )
    return EvalResult(label, seed, returns, lengths)


DEFAULT_EPISODES = 100
"""How many episodes (or situations) the final evaluation of ``diffcontrol train`` runs, unless
the task declares its own ``default_eval_episodes``."""


@task_hook
def evaluate_run(task: Any, run: Any, episodes: int | None = None, seed: int = 0) -> Any:
    """Judge a trained controller (a ``diffcontrol.runs.Run``): the final evaluation of
    ``diffcontrol train`` and what ``diffcontrol evaluate`` prints.

    Returns an object with ``key`` (its name in ``metrics.json``), ``to_json()`` and
    ``summary()`` (one line), or ``None`` where there is nothing to evaluate in. Default:
    Gymnasium episodes with reset seeds ``seed ... seed+episodes-1`` in ``gym_id`` (the task's
    own ``diffcontrol/<Name>-v0`` where it has no twin), or in the run's real system (e.g. the
    environment a fitted model's data came from); a continuous-time task has none unless it
    defines its own (the built-in swing-ups' reference solve). A task overrides it as
    ``tasks._hooks`` says.
    """
    n = episodes or getattr(task, "default_eval_episodes", DEFAULT_EPISODES)
    return evaluate(run.policy, task, episodes=n, seed=seed, real=run.real_env)


@evaluate_run.register(ContinuousTask)
def _closed_loop(task: Any, run: Any, episodes: int | None = None, seed: int = 0) -> Any:
    """A continuous-time task: float64 reference solves of the run's closed loop with the
    task's own vector field (``evaluate_closed_loop``), from ``episodes`` starts of its reset
    distribution (default ``EVAL_STARTS``; 1 where the task has the one initial state)."""
    if episodes is None:
        episodes = EVAL_STARTS if type(task).reset is not ContinuousTask.reset else 1
    return evaluate_closed_loop(
        task, run.feedback, run.params, config=run.config, starts=episodes, seed=seed
    )


def _one_by_one(policy: Any, env: Any, episodes: int, seed: int) -> tuple[np.ndarray, ...]:
    """The episodes one after another in ``env``: one policy call per step."""
    returns, lengths = [], []
    reset = getattr(policy, "reset", None)
    for i in range(episodes):
        if callable(reset):
            reset()
        obs, _ = env.reset(seed=seed + i)
        total, n, done = 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            n += 1
            done = terminated or truncated
        returns.append(total)
        lengths.append(n)
    return np.asarray(returns), np.asarray(lengths)


def _side_by_side(policy: Any, env: Any) -> bool:
    """Whether ``evaluate`` runs the episodes side by side in copies of ``env``.

    The policy must declare ``batched = True`` on its own class (a subclass that does not
    declare it is called one observation at a time) and have no state between steps (no
    ``reset``: a planner's warm start). The environment must be one of Gymnasium's or
    diffcontrol's Gymnasium-backed ones (its entry point in ``gymnasium`` or ``diffcontrol``),
    and not one of diffcontrol's JAX-backed task environments (``diffcontrol.envs``, which
    compile programs as they are made). A user's own environment is made once and run one
    episode at a time: it may stand for a system that cannot be opened many times.
    """
    declared = vars(type(policy)).get("batched", False) is True
    stateless = not callable(getattr(policy, "reset", None))
    entry = getattr(getattr(env, "spec", None), "entry_point", None)
    where = entry if isinstance(entry, str) else getattr(entry, "__module__", "") or ""
    ours = where.startswith(("gymnasium.", "diffcontrol."))
    jax_backed = type(getattr(env, "unwrapped", env)).__module__ == "diffcontrol.envs"
    return declared and stateless and ours and not jax_backed


LOCKSTEP_WIDTH = 128
"""How many episodes ``evaluate`` runs side by side for a batched policy."""


def _lockstep(
    policy: Any, task: Task, real: Any, env: Any, episodes: int, seed: int
) -> tuple[np.ndarray, ...]:
    """The episodes side by side in up to ``LOCKSTEP_WIDTH`` environments, one batched policy
    call per step for all of them (the NumPy MLP's cost is per call, not per row).

    Episode ``i`` is still reset with ``seed + i`` and runs alone in its environment, so the
    returns are the sequential ones (``tests/test_evaluation.py`` checks them equal). A slot
    whose episode ends takes the next seed. Gymnasium's ``SyncVectorEnv`` is not used: it steps
    every environment on every call and resets finished ones itself, where episodes of
    CartPole end at different steps and each must start from its own seed here.
    """
    envs = [env]
    returns, lengths = np.zeros(episodes), np.zeros(episodes, np.int64)
    episode_of: dict[int, int] = {}  # slot -> the episode it runs
    started = 0
    try:
        while len(envs) < min(LOCKSTEP_WIDTH, episodes):
            envs.append(eval_environment(task, real)[0])
        obs: list[Any] = [None] * len(envs)
        for slot in range(len(envs)):
            obs[slot], _ = envs[slot].reset(seed=seed + started)
            episode_of[slot] = started
            started += 1
        while episode_of:
            slots = list(episode_of)
            actions = policy(np.stack([obs[s] for s in slots]))
            for slot, action in zip(slots, actions):
                i = episode_of[slot]
                obs[slot], reward, terminated, truncated, _ = envs[slot].step(action)
                returns[i] += float(reward)
                lengths[i] += 1
                if not (terminated or truncated):
                    continue
                if started < episodes:
                    obs[slot], _ = envs[slot].reset(seed=seed + started)
                    episode_of[slot] = started
                    started += 1
                else:
                    del episode_of[slot]
    finally:  # the copies (``env`` is its caller's); one that fails to close stops none
        for other in envs[1:]:
            with contextlib.suppress(Exception):
                other.close()
    return returns, lengths


def _check_fits(policy: Any, env: Any, label: str) -> None:
    """A controller and an environment of different observation sizes (``--env`` of another
    system) are refused in one line before the first episode."""
    try:
        policy(env.observation_space.sample())
    except ValueError as e:  # the policy names the size it takes
        raise ConfigError(f"the controller cannot act in {label}: {e}") from None


@contextlib.contextmanager
def _system_errors(label: str, real: Any) -> Iterator[None]:
    """Another system's failure (``real``: the user's environment) as one line naming it, not
    a traceback from inside it; the task's own environment's errors pass through."""
    try:
        yield
    except (KeyboardInterrupt, SystemExit, DiffcontrolError):
        raise
    except Exception as e:
        if real is None:
            raise
        raise ConfigError(
            f"{label} raised {type(e).__name__}: {e} while the controller acted in it; check "
            "the environment and its arguments"
        ) from None


def eval_environment(task: Task, real: tuple[str, dict | None] | None) -> tuple[Any, str]:
    """The environment to evaluate in and its label: the task's own, or ``real``
    (``(env_id, env_kwargs)``, labelled ``env_id(k=v, ...)``)."""
    if real is None:
        return _gym.make_gym_env(task), _gym.gym_label(task)
    env_id, kwargs = real
    args = ", ".join(
        f"{k}={v!r}" if isinstance(v, str) else f"{k}={v}" for k, v in (kwargs or {}).items()
    )
    try:
        env = make_env(env_id, kwargs)
    except ImportError as e:  # the module before ':' of an id the user named
        raise ConfigError(
            f"cannot make the environment {env_id!r}: {type(e).__name__}: {e}; check the "
            "module path (run from the directory that holds it, or install its package)"
        ) from None
    return env, f"{env_id}({args})" if args else env_id


def record_episode(
    policy: Any, task: Task, seed: int = 0, real: tuple[str, dict | None] | None = None
) -> Recording:
    """Record one Gymnasium episode of ``policy`` (a ``NumpyPolicy``) with the true states
    (in ``real``'s environment where given, as for ``evaluate``)."""
    env, label = eval_environment(task, real)
    if callable(getattr(policy, "reset", None)):  # a planner: start from its initial plan
        policy.reset()
    with _system_errors(label, real), contextlib.closing(env):
        obs, _ = env.reset(seed=seed)
        states = [_gym.gym_state(task, env)]
        actions, rewards = [], []
        done = False
        while not done:
            actions.append(np.asarray(policy.action(obs), np.float64).reshape(-1))
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            states.append(_gym.gym_state(task, env))
            rewards.append(float(reward))
            done = terminated or truncated
        dt = float(getattr(env.unwrapped, "dt", getattr(env.unwrapped, "tau", 0.02)))
    return Recording(
        env_id=label,
        dt=dt,
        states=np.stack(states),
        actions=np.stack(actions),
        rewards=np.asarray(rewards),
    )


# ---------------------------------------------------------------------------------------------
# Continuous-time tasks (the swing-ups): a reference solve of the closed loop.

REFERENCE_RTOL = 1e-9
REFERENCE_ATOL = 1e-9
"""Tolerances of the reference solve (float64, 8th-order Dormand-Prince): far tighter than
training's, so the reported figures are the physical closed loop's, not the solver's."""


@dataclasses.dataclass
class ContinuousRecording:
    """A closed loop solved on a uniform grid: ``y[k] = (x, x_dot, theta, theta_dot, impulse,
    dissipated_energy)`` at ``t[k]`` and the controller's force ``force[k]`` (N)."""

    task: str
    t: np.ndarray
    y: np.ndarray
    force: np.ndarray
    loss: float

    def to_json(self) -> dict[str, Any]:
        """``data.json``: the time series, ``theta`` wrapped to ``[-pi, pi)`` (0 upright)."""
        wrapped = (self.y[:, 2] + np.pi) % (2 * np.pi) - np.pi
        return {
            "format": "diffcontrol-data",
            "version": 1,
            "task": self.task,
            "units": {
                "t": "s",
                "x": "m",
                "x_dot": "m/s",
                "theta": "rad (0 = up)",
                "theta_dot": "rad/s",
                "force": "N",
                "impulse": "N s",
                "dissipated_energy": "J",
            },
            "t": self.t.tolist(),
            "x": self.y[:, 0].tolist(),
            "x_dot": self.y[:, 1].tolist(),
            "theta": wrapped.tolist(),
            "theta_dot": self.y[:, 3].tolist(),
            "force": self.force.tolist(),
            "impulse": self.y[:, 4].tolist(),
            "dissipated_energy": self.y[:, 5].tolist(),
        }


EVAL_STARTS = 20
"""Starts of a continuous-time task's closed-loop evaluation where it has a reset distribution."""


@dataclasses.dataclass
class ClosedLoopResult:
    """A continuous-time controller judged by float64 reference solves of its closed loop
    (``evaluate_closed_loop``): the loss of each start's trajectory and its final state."""

    task: str
    loss_name: str
    seed: int
    horizon_s: float
    losses: np.ndarray
    final_states: np.ndarray
    state_names: tuple[str, ...]
    warnings: list[str] = dataclasses.field(default_factory=list)
    optimum: Any = None  # an ``mpc.ClosedLoopOptimum`` from the same starts, where asked for
    key = "closed_loop"

    def to_json(self) -> dict[str, Any]:
        return {
            "what": (
                "float64 dopri8 solves of the closed loop (rtol = atol = 1e-9) with the task's "
                "vector field over horizon_s, start i drawn from the task's reset distribution "
                "with PRNGKey(seed + i)"
            ),
            "task": self.task,
            "starts": int(self.losses.size),
            "seed": self.seed,
            "horizon_s": self.horizon_s,
            "loss": self.loss_name,
            "mean_loss": self.mean,
            "std_loss": float(np.std(self.losses)),
            "losses": self.losses.tolist(),
            "final_states": [dict(zip(self.state_names, s.tolist())) for s in self.final_states],
            "warnings": self.warnings,
            **({} if self.optimum is None else {"optimum": self.optimum.to_json()}),
            **({} if self.optimum is None else {"gap_to_optimum": self.optimum.gap(self.mean)}),
        }

    @property
    def mean(self) -> float:
        return float(np.mean(self.losses))

    def headline(self) -> str:
        """A few words for the end of ``diffcontrol train``'s last line."""
        return f"loss {self.mean:.4g} ± {np.std(self.losses):.2g} ({self.losses.size} starts)"

    def summary(self) -> str:
        mean = np.mean(self.final_states, axis=0)
        final = ", ".join(f"{n} {v:.3g}" for n, v in zip(self.state_names, mean))
        warned = "".join(f"\nwarning: {w}" for w in self.warnings)
        if self.optimum is not None:
            gap, diff = self.optimum.gap(self.mean), self.mean - self.optimum.mean
            side = "above" if diff >= 0 else "below"
            by = f"{abs(diff):.4g}" if gap is None else f"{100 * abs(gap):.1f} %"
            warned += f"\n{self.optimum.summary()}\nthe controller's loss is {by} {side} it"
        return (
            f"loss ({self.loss_name}) {self.mean:.4g} ± {np.std(self.losses):.2g} over "
            f"{self.losses.size} start(s) (seed {self.seed}; float64 reference solves of "
            f"{self.horizon_s:g} s); final state, mean over the starts: {final}{warned}"
        )


def evaluate_closed_loop(
    task: Any,
    controller: Any,
    params: Any = None,
    *,
    config: Any = None,
    starts: int = 1,
    seed: int = 0,
) -> ClosedLoopResult:
    """Judge a continuous-time controller by float64 reference solves of its closed loop.

    Start ``i`` is ``task.reset(PRNGKey(seed + i), params)`` (the one ``initial_state`` for a
    task without a reset distribution); each is solved with the task's ``vector_field`` over
    ``config.horizon_s`` (``dopri8`` at ``REFERENCE_RTOL``/``REFERENCE_ATOL``), and its
    trajectory on ``config.saves`` points is judged by ``config``'s loss (the task's first
    when empty), as in training. A state-feedback controller whose closed loop ends where one
    that does nothing ends (its last layer zero) gets a warning in the result: it may be
    untrained, or the task infeasible within its bounds.

    Args:
        controller: an ``MLPController`` (state feedback inside the ODE), or a sampled-data
            controller with ``closed_loop`` (``simulate_continuous``).
        config: an ``ODETrainConfig`` (default: the task's).

    Raises:
        ValueError: a solve failed (the closed loop explodes).
    """
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    config = config or task.default_config()
    params = task.default_params() if params is None else params
    loss_name = config.loss or task.losses[0]
    warnings: list[str] = []
    loss_fn = task.trajectory_loss(loss_name)
    # The starts drawn as training draws them (outside float64 mode, where a task's own
    # jax.random draws would give others), then widened.
    keys = jnp.stack([jax.random.PRNGKey(seed + i) for i in range(starts)])
    y0s = np.asarray(jax.jit(jax.vmap(task.reset, in_axes=(0, None)))(keys, params), np.float64)
    with _jax_setup.float64():
        p64 = jax.tree.map(lambda x: jax.device_put(np.asarray(x, np.float64)), params)
        ts = jnp.linspace(0.0, float(config.horizon_s), config.saves)
        y0s = jax.device_put(y0s)
        if hasattr(controller, "closed_loop"):  # sampled data: its own solve, start by start
            out = []
            for y0 in y0s:
                ys, us, ok = controller.closed_loop(task, p64, y0, np.asarray(ts))
                tr = task.trajectory(p64, controller, ts, ys)
                out.append((float(loss_fn(tr)), np.asarray(ys)[-1], bool(ok)))
            losses, finals, ok = (np.asarray(x) for x in zip(*out))
        else:

            @jax.jit
            def solve(ctrl, p, y0s):
                def one(y0):
                    sol = _reference(task, ctrl, p, y0, ts)
                    return loss_fn(task.trajectory(p, ctrl, ts, sol.ys)), sol.ys[-1], sol.ok

                return jax.vmap(one)(y0s)

            losses, finals, ok = (np.asarray(x) for x in solve(controller, p64, y0s))
            # the same starts under a controller that does nothing (its last layer zero: the
            # head's neutral action), through the same program
            neutral = eqx.tree_at(
                lambda c: (c.layers[-1].weight, c.layers[-1].bias),
                controller,
                replace_fn=jnp.zeros_like,
            )
            _, still, still_ok = solve(neutral, p64, y0s)
            observe = jax.vmap(task.observe)
            if np.all(still_ok) and _same_ends(observe(finals), observe(still)):
                warnings.append(
                    f"the controller ends where a controller that does nothing ends (from each "
                    f"of the {starts} start(s), its final observation within 5 % of the "
                    "neutral action's): it may be untrained (train longer, at another learning "
                    "rate, or with --population N), or the task infeasible within its action "
                    "bounds; `diffcontrol plan` from the same starts is a reference"
                )
    if not np.all(ok) or not np.all(np.isfinite(losses)):
        raise ValueError("the reference solve failed: the closed loop explodes")
    names = tuple(task.state_names)
    return ClosedLoopResult(
        task.name, loss_name, seed, float(config.horizon_s), losses, finals[:, : len(names)], names,
        warnings,
    )  # fmt: skip


def _reference(task: Any, ctrl: Any, p: Any, y0: Any, ts: Any) -> Any:
    """The reference solve of the closed loop from ``y0``, saved at ``ts``: ``dopri8`` at
    ``REFERENCE_RTOL``/``REFERENCE_ATOL`` (float64 inside ``jax.enable_x64``)."""
    return solve_closed_loop(
        task.vector_field,
        y0,
        ts,
        (p, force_fn(task, ctrl)),
        solver="dopri8",
        rtol=REFERENCE_RTOL,
        atol=REFERENCE_ATOL,
        max_steps=100_000,
    )


def _same_ends(a: Any, b: Any) -> bool:
    """Whether the observations ``a`` and ``b`` (``[starts, obs]``) are within 5 % of ``b``
    (at least 0.05) everywhere."""
    a, b = np.asarray(a), np.asarray(b)
    return bool(np.all(np.abs(a - b) <= 0.05 * np.maximum(1.0, np.abs(b))))


def simulate_continuous(
    task: Any,
    controller: Any,
    params: Any = None,
    *,
    config: Any = None,
    rate_hz: float = 100.0,
) -> ContinuousRecording:
    """Solve ``task``'s closed loop with ``controller`` for reporting.

    A float64 reference solve (``dopri8`` at ``REFERENCE_RTOL``/``REFERENCE_ATOL``) saved at
    ``rate_hz`` over the horizon of ``config`` (an ``ODETrainConfig``; default: the task's),
    plus that config's loss (by name; the task's default if empty) on its own save grid
    (``saves`` points, as in training).

    ``controller`` is an ``MLPController`` (state feedback inside the ODE), or a sampled-data
    controller: anything with ``closed_loop(task, params, y0, ts) -> (states, actions, ok)``
    that solves its own closed loop with ``task``'s vector field (a planner,
    ``mpc.SampledPlannerPolicy``: each action held for its period). The loss then sees the
    action held at each save.
    """
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    config = config or task.default_config()
    horizon = float(config.horizon_s)
    params = task.default_params() if params is None else params
    n = int(round(horizon * rate_hz)) + 1
    with _jax_setup.float64():
        # Widened by NumPy (exactly) and placed: no conversion program per array.
        def wide(x):
            return jax.device_put(np.asarray(x, np.float64))

        p64 = jax.tree.map(wide, params)

        ts = jnp.linspace(0.0, horizon, n)
        ts_loss = jnp.linspace(0.0, horizon, config.saves)
        loss_fn = task.trajectory_loss(config.loss or task.losses[0])

        @jax.jit
        def run(ctrl, p, ts, at_loss):
            """The solve, its forces and the loss on its saves ``at_loss`` (one program, not
            the loss op by op)."""
            sol = _reference(task, ctrl, p, task.initial_state(p), ts)
            force = jax.vmap(lambda y: ctrl(task.observe(y[:4]))[0])(sol.ys)
            loss = loss_fn(task.trajectory(p, ctrl, ts_loss, sol.ys[at_loss]))
            return sol.ys, force, loss, sol.ok

        if hasattr(controller, "closed_loop"):  # sampled data: one solve for both grids
            both = np.union1d(np.asarray(ts), np.asarray(ts_loss))
            ys_all, us, ok = controller.closed_loop(task, p64, task.initial_state(p64), both)
            at, at_loss = (np.searchsorted(both, np.asarray(t)) for t in (ts, ts_loss))
            ys, force, ys_loss, ok_loss = ys_all[at], us[at, 0], ys_all[at_loss], True
            # The trajectory's force is the action held at each save, not a state feedback.
            tr = task.trajectory(p64, lambda obs: jnp.zeros(1), ts_loss, ys_loss)
            tr = eqx.tree_at(lambda tr: tr.force, tr, us[at_loss, 0])
            loss = float(loss_fn(tr))
        else:  # one solve saved at both grids (the steps do not depend on the saves)
            ctrl = jax.tree.map(wide, controller)
            both = np.union1d(np.asarray(ts), np.asarray(ts_loss))
            at, at_loss = (np.searchsorted(both, np.asarray(t)) for t in (ts, ts_loss))
            args = (ctrl, p64, jax.device_put(both), at_loss)
            # Solved once per report: compiled with the older CPU emitters, which compile it
            # faster and move a trajectory by rounding only (2e-9 relative at most for the
            # friction swing-up; docs/benchmarks.md); level 1 would move its last bits too.
            program = _jax_setup.compile_with(run.lower(*args), "xla_cpu_use_fusion_emitters")
            ys_all, force_all, loss, ok = (np.asarray(x) for x in program(*args))
            ys, force, loss, ok_loss = ys_all[at], force_all[at], float(loss), True
        if not (bool(ok) and bool(ok_loss)):
            raise ValueError("the reference solve failed: the closed loop explodes")
    return ContinuousRecording(task.name, np.asarray(ts), np.asarray(ys), np.asarray(force), loss)
