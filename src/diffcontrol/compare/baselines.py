"""Reinforcement-learning baselines from Stable-Baselines3, with rl-baselines3-zoo's settings.

The hyperparameters below are the ones published by DLR-RM/rl-baselines3-zoo for each
environment, copied value by value from its ``hyperparams/<algo>.yml`` (the file and entry are
named next to each). Settings the zoo leaves out are Stable-Baselines3's defaults, as in the
zoo. ``lin_X`` in the zoo is a learning rate (or clip range) that decays linearly from ``X``
to 0 over the budget; ``noise_std`` is the standard deviation of Gaussian action noise in
Stable-Baselines3's normalised ``[-1, 1]`` action space; ``normalize: true`` wraps the training
environments in ``VecNormalize`` (observations and rewards, with the algorithm's ``gamma``, as
the zoo does), whose observation statistics the evaluation then applies.

Stable-Baselines3 and PyTorch are imported only when a baseline is built, so the rest of
diffcontrol works without them; ``require_rl()`` raises a ``DiffcontrolError`` naming the
install command when they are missing. Models are never saved or loaded here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from ..errors import DiffcontrolError
from ..tasks._hooks import task_hook

INSTALL_HINT = "install the rl extra: pip install 'diffcontrol[rl]'"


@dataclasses.dataclass(frozen=True)
class Baseline:
    """One RL algorithm with its published settings for one task.

    Attributes:
        algo: the Stable-Baselines3 class name (``"PPO"``, ``"DQN"``, ``"SAC"``, ``"TD3"``).
        n_timesteps: the zoo's training budget in environment steps.
        n_envs: environments stepped side by side (PPO's ``n_envs``).
        kwargs: constructor arguments; ``"lin_X"`` strings become linear schedules,
            ``noise_std`` becomes ``NormalActionNoise``.
        source: where the values were published.
        normalize: the zoo's ``normalize: true``: running normalisation of observations and
            rewards (``VecNormalize``).
    """

    algo: str
    n_timesteps: int
    n_envs: int = 1
    kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    source: str = ""
    normalize: bool = False


ZOO = "DLR-RM/rl-baselines3-zoo"
"""Where the published settings come from (named in each ``Baseline.source``)."""


@dataclasses.dataclass(frozen=True)
class RLSetup:
    """What ``diffcontrol compare`` runs against a task.

    Attributes:
        baselines: method name (``"ppo"``, ``"sac"``, ...) -> its ``Baseline``.
        thresholds: returns at which the task counts as solved (the "first reached" columns).
        eval_every: the RL methods' evaluation interval in environment steps.
    """

    baselines: dict[str, Baseline]
    thresholds: tuple[float, ...] = ()
    eval_every: int = 1000


@task_hook
def rl_setup(task: Any) -> RLSetup | None:
    """The RL comparison of ``task``, or ``None`` (the default): no baselines. A task gives
    its own as ``tasks._hooks`` says (the built-in ones: ``diffcontrol.builtin.zoo``, the
    rl-baselines3-zoo's settings of Gymnasium's CartPole and Pendulum, and the trebuchet's)."""
    return None


def require_rl() -> None:
    """Raise a ``DiffcontrolError`` with the install command if SB3 or PyTorch is missing."""
    try:
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as e:
        raise DiffcontrolError(
            f"the RL baselines need Stable-Baselines3 and PyTorch ({e}); {INSTALL_HINT}"
        ) from None


def _linear(initial: float) -> Callable[[float], float]:
    """The zoo's ``lin_X``: ``X`` times the remaining fraction of the budget (1 -> 0)."""

    def schedule(progress_remaining: float) -> float:
        return progress_remaining * initial

    return schedule


def build_model(
    baseline: Baseline, make_env: Callable[[], Any], seed: int, torch_threads: int | None = 1
) -> Any:
    """Construct the Stable-Baselines3 model of ``baseline`` on fresh environments.

    Args:
        baseline: the algorithm and its settings.
        make_env: returns one new Gymnasium environment (called ``n_envs`` times).
        seed: seeds the model, its environments and PyTorch.
        torch_threads: PyTorch's intra-op threads (``None`` leaves PyTorch's default).

    Returns:
        The untrained model (``model.learn(...)`` trains it).

    Raises:
        DiffcontrolError: Stable-Baselines3 is not installed.
    """
    require_rl()
    import numpy as np
    import stable_baselines3 as sb3
    import torch
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import VecNormalize

    if torch_threads:
        torch.set_num_threads(int(torch_threads))
    env = make_vec_env(make_env, n_envs=baseline.n_envs, seed=seed)
    if baseline.normalize:
        env = VecNormalize(env, gamma=baseline.kwargs.get("gamma", 0.99))
    kwargs = dict(baseline.kwargs)
    for name in ("learning_rate", "clip_range"):
        value = kwargs.get(name)
        if isinstance(value, str) and value.startswith("lin_"):
            kwargs[name] = _linear(float(value[4:]))
    if "noise_std" in kwargs:
        n = env.action_space.shape[-1]
        std = kwargs.pop("noise_std")
        kwargs["action_noise"] = NormalActionNoise(mean=np.zeros(n), sigma=std * np.ones(n))
    from stable_baselines3.common.logger import Logger

    cls = getattr(sb3, baseline.algo)
    model = cls("MlpPolicy", env, seed=seed, device="cpu", verbose=0, **kwargs)
    # A logger that writes nowhere: SB3's default makes an empty SB3-<date> folder in the
    # temporary directory on every learn().
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model
