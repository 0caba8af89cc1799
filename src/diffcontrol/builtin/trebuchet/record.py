"""Recording the trebuchet's throws, and its parameters as plain numbers.

``record_throws`` plays the real trebuchet: it throws a ``TrebuchetParams`` (the "real" one,
e.g. ``drag_coefficient = 1.5`` and ``wind_factor = 1.5``) with random or given inputs, or
aimed by a trained controller, and adds Gaussian noise to the measured distances; the throws
come back as one-step episodes (``throws``). ``record_data`` is the task's
``record_data`` hook (``diffcontrol record trebuchet``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..._jax_setup import float64
from ...errors import ConfigError
from ...identify.data import TrajectoryData
from ...io import now_iso
from ...policies import read_model
from ...tasks import check_params, make
from . import system as tb
from .task import TARGET_RANGE_M
from .throws import Throws, throws_table

RANDOM_ANGLE_DEG = (20.0, 70.0)
"""``record_throws`` draws random release angles uniformly from here (degrees)."""
RANDOM_WEIGHT_LB = (50.0, 450.0)
"""``record_throws`` draws random counterweights uniformly from here (pounds)."""
RANDOM_WIND_STD_MPS = 5.0
"""``record_throws`` draws random winds ~ N(0, 5^2) m/s clipped to +-20, as the task does."""


def parameter_names() -> tuple[str, ...]:
    """The trebuchet's fittable parameters: the float fields of ``TrebuchetParams`` (the step
    budgets and ``swap_inertias`` are static and cannot be fitted)."""
    p = tb.TrebuchetParams()
    return tuple(
        f.name
        for f in dataclasses.fields(p)
        if not f.metadata.get("static", False) and isinstance(getattr(p, f.name), float)
    )


def trebuchet_params(env_args: list[tuple[str, float]]) -> tb.TrebuchetParams:
    """``TrebuchetParams`` with the ``--env-arg NAME=VALUE`` overrides (floats only).

    Raises:
        ConfigError: an unknown name (the message lists the trebuchet's parameters).
    """
    known = parameter_names()
    bad = [name for name, _ in env_args if name not in known]
    if bad:
        raise ConfigError(
            f"--env-arg {bad[0]}: the trebuchet has no parameter {bad[0]!r}; choose among "
            f"{', '.join(known)} (e.g. --env-arg drag_coefficient=1.5 --env-arg wind_factor=1.5)"
        )
    params = tb.TrebuchetParams(**{name: float(value) for name, value in env_args})
    check_params(make("trebuchet"), params)  # the task's ranges, as for --param
    return params


def params_dict(params: tb.TrebuchetParams) -> dict[str, float]:
    """The fittable parameters of ``params`` as plain floats (for metadata and JSON)."""
    return {n: float(np.asarray(getattr(params, n))) for n in parameter_names()}


def as64(params: tb.TrebuchetParams) -> tb.TrebuchetParams:
    """``params`` with every leaf a float64 array (under ``jax.enable_x64``)."""
    return jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params)


@jax.jit
def _shoot(wind, angle, weight, params):
    return tb.shoot(wind, angle, weight, params)


THROW_ROWS = 64
"""Throw data sets are padded to a multiple of this many rows (the last throw repeated) for
their compiled programs, so that a loop's growing data and its held-out set share them."""


def padded_rows(*columns: Any) -> tuple[int, tuple[np.ndarray, ...]]:
    """The columns broadcast against each other and flattened (``n`` rows), then padded to a
    multiple of ``THROW_ROWS`` rows by repeating their last row: ``(n, padded columns)``;
    take ``[:n]`` of what is computed from them."""
    flat = [c.reshape(-1) for c in np.broadcast_arrays(*map(np.asarray, columns))]
    n = flat[0].size
    size = -(-max(n, 1) // THROW_ROWS) * THROW_ROWS
    return n, tuple(np.concatenate([c, np.repeat(c[-1:], size - n)]) for c in flat)


def predict_distances(params: tb.TrebuchetParams | None, throws: Throws) -> np.ndarray:
    """The distances (m) the trebuchet ``params`` (default the nominal one) throws with the
    recorded inputs of ``throws`` (broadcast against each other), simulated in float64."""
    columns = (throws.wind, throws.release_angle, throws.counterweight)
    shape = np.broadcast_shapes(*(np.shape(c) for c in columns))
    n, inputs = padded_rows(*columns)
    with float64():
        p = as64(params or tb.TrebuchetParams())
        return np.asarray(_shoot(*inputs, p))[:n].reshape(shape)


def record_throws(
    n: int,
    params: tb.TrebuchetParams | None = None,
    *,
    seed: int = 0,
    noise_m: float = 0.0,
    inputs: tuple[Any, Any, Any] | None = None,
    policy: Any = None,
    source: str | None = None,
) -> TrajectoryData:
    """Throw the trebuchet ``params`` (default nominal) ``n`` times and record the throws.

    The inputs are, in this order of precedence: ``inputs`` ``(wind_mps, angle_deg,
    weight_lb)`` (arrays of length ``n``, or scalars); or ``policy`` (a trained aiming
    controller, e.g. ``diffcontrol.load(run)``, whose ``action`` maps ``(target, wind)`` to
    ``(angle, weight)``) aiming at random targets ~ U(20, 100) m; or random inputs (angles
    ~ U(``RANDOM_ANGLE_DEG``), counterweights ~ U(``RANDOM_WEIGHT_LB``)). Random winds are
    N(0, 5^2) m/s clipped to +-20 m/s. Everything random comes from
    ``numpy.random.default_rng(seed)``; the recorded distance is the simulated one (float64)
    plus Gaussian noise of standard deviation ``noise_m`` (m).

    Returns:
        The throws' ``TrajectoryData`` (one-step episodes), whose metadata records the
        system's parameters, the noise and the seed.

    Raises:
        ConfigError: ``n < 1``, a negative or non-finite ``noise_m``, or inputs out of the
            simulator's checked ranges (the message names the bad value).
    """
    if not isinstance(n, int | np.integer) or n < 1:
        raise ConfigError(f"the number of throws must be a positive integer, got {n!r}")
    if not (math.isfinite(noise_m) and noise_m >= 0):
        raise ConfigError(f"noise_m must be a standard deviation >= 0 (m), got {noise_m!r}")
    p = params or tb.TrebuchetParams()
    rng = np.random.default_rng(seed)
    wind = np.clip(RANDOM_WIND_STD_MPS * rng.standard_normal(n), -20.0, 20.0)
    if inputs is not None:
        wind, angle, weight = (np.broadcast_to(np.asarray(x, np.float64), (n,)) for x in inputs)
        how = "given inputs"
    elif policy is not None:
        target = rng.uniform(*TARGET_RANGE_M, size=n)
        actions = np.asarray(policy.action(np.stack([target, wind], axis=-1)), np.float64)
        angle, weight = actions[:, 0], actions[:, 1]
        how = f"a controller (task {getattr(policy, 'task', '?')!r}) aiming at random targets"
    else:
        angle = rng.uniform(*RANDOM_ANGLE_DEG, size=n)
        weight = rng.uniform(*RANDOM_WEIGHT_LB, size=n)
        how = "random inputs"
    wind, angle, weight = tb.check_inputs(wind, angle, weight)
    distance = predict_distances(p, Throws(wind, np.zeros(n), angle, weight))
    if not np.all(np.isfinite(distance)):
        i = int(np.flatnonzero(~np.isfinite(distance))[0])
        raise ConfigError(
            f"throw {i} (wind {wind[i]:g} m/s, {angle[i]:g} deg, {weight[i]:g} lb) diverged in "
            f"the simulator with these parameters; check them ({params_dict(p)})"
        )
    distance = distance + noise_m * rng.standard_normal(n)
    metadata = {
        "system": "trebuchet",
        "source": source or f"simulated trebuchet, {how}",
        "params": params_dict(p),
        "noise_m": float(noise_m),
        "seed": int(seed),
        "recorded": now_iso(),
    }
    return throws_table(Throws(wind, distance, angle, weight), metadata)


def record_data(task: Any, episodes: int, *, env_id=None, env_kwargs=None, controller=None,
                seed=0, max_steps=None, noise_m=None, progress=None) -> TrajectoryData:  # fmt: skip
    """The trebuchet task's ``record_data``: ``episodes`` throws with random inputs (or a
    trained ``controller`` aiming at random targets) of the trebuchet whose parameters
    ``env_kwargs`` change, with ``noise_m`` m of noise on the distances."""
    for flag, value in (("--max-steps", max_steps), ("an environment id", env_id)):
        if value is not None:
            raise ConfigError(
                f"{flag} does not apply to the trebuchet (one episode is one throw of the "
                "simulated trebuchet whose parameters --env-arg sets); drop it"
            )
    params = trebuchet_params(list((env_kwargs or {}).items()))
    policy = None
    if controller:
        policy = task.load_policy(read_model(controller))
        if policy.task != task.name:
            raise ConfigError(
                f"--controller {controller} was trained for task {policy.task!r}, not "
                f"{task.name}; give a {task.name} run, or omit --controller for random throws"
            )
    if progress:
        changed = ", ".join(f"{n}={v:g}" for n, v in (env_kwargs or {}).items())
        what = f"controller {controller}" if policy else "random inputs"
        progress(
            f"recording {episodes} throw(s) of the trebuchet "
            f"({changed or 'the nominal parameters'}) with {what}"
        )
    return record_throws(
        episodes,
        params,
        seed=seed,
        noise_m=noise_m or 0.0,
        policy=policy,
        source=f"controller {controller}" if policy else None,
    )
