"""Trebuchet aiming: a network maps (target, wind) to (release angle, counterweight).

The seed post's first demo. One "episode" is one throw: the reset distribution samples a
situation (target distance and wind, as in the original's training data), the controller
answers with a release angle and a counterweight through bounded heads, and the
differentiable trebuchet (``builtin.trebuchet.system``) throws. The reward is minus the
miss, so the generic trainer with ``window = horizon = 1`` is minibatch gradient descent
through the simulator over random situations, the original's recipe with a batch under
``vmap`` instead of one sample at a time.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import diffcontrol.builtin.trebuchet.system as tb

from ..._jax_setup import FastJit
from ...config import TrainConfig
from ...errors import ConfigError, ModelFileError
from ...policies import AimingPolicy
from ...systems import draws
from ...tasks import StepLoss, Task, task_params

TARGET_RANGE_M = (20.0, 100.0)
"""Targets are drawn uniformly from this range (m), as in the original."""
WIND_STD_MPS = 5.0
"""Wind ~ N(0, 5^2) m/s, as in the original."""
WIND_LIMIT_MPS = 20.0
"""Sampled winds are clipped to +-20 m/s (4 sigma; the simulator's step budget is checked
for this range). The original's Gaussian is unbounded."""
ANGLE_RANGE_DEG = (5.0, 85.0)
"""The angle head's bounds (degrees); the original's ``90 sigmoid(o)`` spans (0, 90)."""
WEIGHT_RANGE_LB = (30.0, 450.0)
"""The counterweight head's bounds (lb). The distance grows with the weight up to about
500 lb at every angle; beyond that the sling releases early and the throw shortens."""
THROW_COLUMNS = (
    ("state.wind [m/s]", "state.distance [m]"),
    ("action.release_angle [deg]", "action.counterweight [lb]"),
)
"""The columns of recorded throws (``data_columns()``): the wind and distance of the task's
state ``(target, wind, distance)``, and the aim."""
REFINEMENT = {"method": "gauss-newton", "iterations": 2}
"""How a trained network's aim is refined at act time (``model.json``'s ``refine``): two
Gauss-Newton steps of ``aim_directly`` from the network's angle and weight, through the
trebuchet the network was trained on. One step leaves a few millimetres on average, two a
fraction of one (``docs/benchmarks.md``, "Trebuchet aiming")."""
MAX_REFINE_ITERATIONS = 50


class TrebuchetAiming(Task):
    """Aim the trebuchet of the seed post at any target in 20-100 m for any wind.

    State ``(target_m, wind_mps, distance_m)`` (the distance is 0 before the throw);
    observation ``(target_m, wind_mps)``; action ``(angle_deg, weight_lb)`` through sigmoid
    heads bounded by ``ANGLE_RANGE_DEG`` and ``WEIGHT_RANGE_LB``. One step is one throw and
    ends the episode. Reward: ``-|distance - target|`` (m).

    Training losses:

    - ``squared_miss``: ``(distance - target)^2``, the original's loss.
    - ``abs_miss``: ``|distance - target|``, less dominated by unreachable targets.
    - ``huber_miss``: squared below 1 m, linear above: precise near the target, and the
      unreachable targets' pull is bounded.
    """

    name = "trebuchet"
    # The evaluation's returns move by float32 rounding with both options, but whole runs
    # return the same update with the same weights: the returned controller and every figure
    # of it are the defaults'. The chunk keeps XLA's defaults (either option moves the trained
    # weights and the mean miss).
    fast_compile = {"evaluate": ("xla_backend_optimization_level", "xla_cpu_use_fusion_emitters")}
    summary = "aim the 2019 post's differentiable trebuchet: (target, wind) -> (angle, weight)"
    gym_id = None
    default_eval_episodes = 1000  # random targets
    episode_length = 1
    observation_size = 2
    action_size = 2
    action_head = "sigmoid"
    action_low = (ANGLE_RANGE_DEG[0], WEIGHT_RANGE_LB[0])
    action_high = (ANGLE_RANGE_DEG[1], WEIGHT_RANGE_LB[1])
    obs_offset = (60.0, 0.0)
    obs_scale = (1.0 / 40.0, 1.0 / WIND_STD_MPS)
    reward_threshold = None
    act_refinement = REFINEMENT
    losses = ("squared_miss", "abs_miss", "huber_miss")
    state_labels = ("target (m)", "wind (m/s)", "distance (m)")
    action_labels = ("release angle (deg)", "counterweight (lb)")

    positive_params = (
        "pivot_height", "long_arm", "short_arm", "weight_arm", "sling_length",
        "projectile_radius", "projectile_mass", "arm_mass", "counterweight_inertia", "dt",
    )  # fmt: skip
    nonnegative_params = ("air_density", "drag_coefficient")
    fit_parameter_names = ("drag_coefficient", "wind_factor")
    """What the nominal trebuchet does not know: fitted from recorded throws by default."""

    def default_params(self) -> tb.TrebuchetParams:
        return tb.TrebuchetParams()

    # --- learning its physics from recorded throws (``builtin.trebuchet``) -----------------

    def data_columns(self):
        """A throw is a one-step episode: the wind and distance 0, the aim, then the wind and
        the measured distance (``builtin.trebuchet.throws``)."""
        return THROW_COLUMNS

    def data_file_name(self, env_id=None) -> str:
        return "trebuchet-throws.csv"

    def reset(self, key, params):
        k_target, k_wind = jax.random.split(key)
        target = draws.uniform(k_target, (), minval=TARGET_RANGE_M[0], maxval=TARGET_RANGE_M[1])
        wind = jnp.clip(WIND_STD_MPS * draws.normal(k_wind, ()), -WIND_LIMIT_MPS, WIND_LIMIT_MPS)
        return jnp.stack([target, wind, jnp.zeros_like(target)])

    def step(self, params, state, action):
        target, wind = state[0], state[1]
        distance = tb.shoot(wind, action[0], action[1], params)
        next_state = jnp.stack([target, wind, distance])
        return next_state, -jnp.abs(distance - target), jnp.asarray(True)

    def observe(self, state):
        return state[:2]

    def step_loss(self, name: str) -> StepLoss:
        if name == "squared_miss":
            return lambda params, state, action, next_state, reward: reward**2
        if name == "abs_miss":
            return lambda params, state, action, next_state, reward: -reward
        if name == "huber_miss":

            def huber(params, state, action, next_state, reward):
                miss = -reward
                return jnp.where(miss < 1.0, 0.5 * miss**2, miss - 0.5)

            return huber
        raise KeyError(name)

    def default_config(self) -> TrainConfig:
        # abs_miss, not the original's squared miss: the unreachable targets' pull on the
        # shared weights is bounded.
        return TrainConfig(
            updates=2000,
            batch=64,
            window=1,
            horizon=1,
            learning_rate=1e-2,
            lr_schedule="warmup_cosine",
            lr_final_fraction=0.01,
            grad_clip=0.0,
            hidden=(32, 32),
            activation="tanh",
            loss="abs_miss",
            eval_every=100,
            eval_episodes=512,
        )

    # --- hooks of a run: aimed, judged and drawn as throws ------------------------------------

    EXAMPLE_THROW = (80.0, -3.0)
    """The target (m) and wind (m/s) of the throw drawn in ``rollout.png``/``rollout.gif``."""

    def step_seconds(self, params) -> None:
        return None  # one step is one throw

    def load_policy(self, doc: dict):
        """An ``AimingPolicy``: ``policy(target_m, wind_mps) -> (angle_deg, weight_lb)``; a
        ``RefinedAimingPolicy`` (JAX at act time) where ``model.json`` holds ``refine``."""
        return RefinedAimingPolicy(doc) if "refine" in doc else AimingPolicy(doc)

    def throw(self, run, target_m: float, wind_mps: float):
        """Simulate the throw that the run's controller aims at one target."""
        check_target(target_m, wind_mps)
        angle, weight = run.policy(target_m, wind_mps)
        return _SIMULATE(wind_mps, angle, weight, run.params if run.real else None)

    def aim(self, run, target_m: float, wind_mps: float, direct: bool = False):
        """Aim the run's controller at one target (``diffcontrol aim``): the network's angle
        and weight, the throw's distance and miss, and with ``direct`` the same found by
        gradient steps on the simulator alone (``aim_directly``). Returns ``(result dict,
        printable lines)``."""
        import time

        check_target(target_m, wind_mps)
        obs = np.array([target_m, wind_mps], np.float64)
        network = getattr(run.policy, "network_action", None)  # a refined policy's network
        t0 = time.perf_counter()
        angle, weight = (float(x) for x in (network or run.policy.action)(obs))
        net_seconds = time.perf_counter() - t0
        distance = float(shoot_in_chunks(wind_mps, angle, weight))
        lines = [
            f"network: angle {angle:.2f} deg, weight {weight:.1f} lb -> {distance:.2f} m "
            f"(miss {distance - target_m:+.3f} m; {net_seconds * 1e6:.0f} us)"
        ]
        result = {"target_m": target_m, "wind_mps": wind_mps, "network_seconds": net_seconds}
        if network:  # the controller: the network's aim refined through the simulator
            result["network"] = {"angle_deg": angle, "weight_lb": weight, "distance_m": distance}
            run.policy.action(obs)  # compile first
            t0 = time.perf_counter()
            angle, weight = (float(x) for x in run.policy.action(obs))
            seconds = time.perf_counter() - t0
            distance = float(shoot_in_chunks(wind_mps, angle, weight))
            result["refine_seconds"] = seconds
            lines.append(
                f"refined ({run.policy.iterations} Gauss-Newton steps through the simulator): "
                f"angle {angle:.2f} deg, weight {weight:.1f} lb -> {distance:.2f} m "
                f"(miss {distance - target_m:+.4f} m; {seconds * 1e3:.0f} ms)"
            )
        result.update(
            angle_deg=angle, weight_lb=weight, distance_m=distance, miss_m=distance - target_m
        )
        if direct:
            solve = jax.jit(aim_directly)
            jax.block_until_ready(solve(target_m, wind_mps))  # compile first
            t0 = time.perf_counter()
            a, w, miss = jax.block_until_ready(solve(target_m, wind_mps))
            seconds = time.perf_counter() - t0
            result["direct"] = {
                "angle_deg": float(a),
                "weight_lb": float(w),
                "miss_m": float(miss),
                "seconds": seconds,
            }
            lines.append(
                f"direct:  angle {float(a):.2f} deg, weight {float(w):.1f} lb -> "
                f"{target_m + float(miss):.2f} m (miss {float(miss):+.3f} m; "
                f"{seconds * 1e3:.1f} ms)"
            )
        return result, lines

    def recipes(self) -> dict[str, dict[str, Any]]:
        return {
            # trebuchet/DiffRL.jl@10bd26c: Dense(2,16,s)-Dense(16,64,s)-Dense(64,16,s)-Dense(16,2)
            # with sigmoid s, ADAM 1e-3, squared miss, batch 1, 100,000 fresh samples.
            "original": dict(
                updates=100_000,
                batch=1,
                window=1,
                horizon=1,
                learning_rate=1e-3,
                lr_schedule="constant",
                grad_clip=0.0,
                hidden=(16, 64, 16),
                activation="sigmoid",
                loss="squared_miss",
                eval_every=5_000,
                eval_episodes=100,
                keep_best=False,
            )
        }


# ---------------------------------------------------------------------------------------------
# Reachability and direct aiming: the simulator alone, no network.


SHOOT_CHUNK = 1000
"""Throws per call of ``shoot_in_chunks``'s one compiled program: ``evaluate_aiming``'s 1,000
targets are one call, and the reachability searches and ``diffcontrol aim`` run through the same
program, so an evaluation compiles the throw once rather than once per caller."""

_SHOOT = jax.jit(tb.shoot)
_SIMULATE = FastJit(tb.simulate, "xla_cpu_use_fusion_emitters")
"""``TrebuchetTask.throw``'s program. The throw is only drawn (the run's figure and GIF), so
it is compiled with the older CPU emitters, quicker to compile and the same throw to float32
rounding."""
_PADDING = (0.0, 45.0, 200.0)
"""The wind, angle and weight of the padding throws: an ordinary throw, quick to land."""


def shoot_in_chunks(wind_mps, angle_deg, weight_lb, params: tb.TrebuchetParams | None = None):
    """``system.shoot`` elementwise over NumPy inputs (broadcast against each
    other), in calls of ``SHOOT_CHUNK`` throws (the last padded) to one compiled program.

    Returns a float64 NumPy array of the inputs' broadcast shape. ``params=None`` (the nominal
    trebuchet) and a ``TrebuchetParams`` compile one program each.
    """
    inputs = np.broadcast_arrays(
        *(np.asarray(v, np.float64) for v in (wind_mps, angle_deg, weight_lb))
    )
    flat = [v.reshape(-1) for v in inputs]
    shoot = lambda *chunk: _SHOOT(*chunk, params)  # noqa: E731
    return _in_chunks(shoot, flat, _PADDING, SHOOT_CHUNK, np.float64).reshape(inputs[0].shape)


def _in_chunks(fn, columns, padding, chunk: int, dtype) -> np.ndarray:
    """``fn`` over the rows of equal-length 1-D NumPy ``columns`` (cast to ``dtype``), in calls
    of ``chunk`` rows, the last padded with the values ``padding``: one compiled program for
    any number of rows. Returns ``fn``'s rows as float64, the padding's dropped."""
    n = columns[0].size
    size = -(-max(n, 1) // chunk) * chunk
    flat = [
        np.concatenate([c, np.full(size - n, pad)]).astype(dtype)
        for c, pad in zip(columns, padding)
    ]
    parts = [
        np.asarray(fn(*(c[i : i + chunk] for c in flat)), np.float64) for i in range(0, size, chunk)
    ]
    return np.concatenate(parts)[:n]


GOLDEN_ITERATIONS = 14
"""Golden-section steps of the longest throw's angle: the coarse grid's bracket (two grid
steps, 10 degrees) shrinks to about 0.01 degree."""


def reachable_range(wind_mps, params: tb.TrebuchetParams | None = None):
    """The shortest and longest distances (m) the bounded heads can reach in this wind.

    The distance grows with the counterweight inside ``WEIGHT_RANGE_LB`` and is unimodal in
    the angle, so the longest throw is the heaviest weight at the best angle (a coarse grid,
    then golden-section search to about 0.01 degree). The shortest is the least of the
    lightest and heaviest weights over the coarse angle grid: approximate (to a few metres),
    and below 20 m unless the tail wind exceeds about 17 m/s, so it rarely decides whether
    a target of the task is reachable.
    Elementwise over a batch of winds (NumPy arrays of the winds' shape). Every throw goes
    through ``shoot_in_chunks``: the search runs in NumPy, a batch of throws per step.
    """
    wind = np.asarray(wind_mps, np.float64)
    flat = wind.reshape(-1)[:, None]
    (a_lo, a_hi), (w_lo, w_hi) = ANGLE_RANGE_DEG, WEIGHT_RANGE_LB
    grid = np.linspace(a_lo, a_hi, 17)
    coarse = shoot_in_chunks(flat, grid, w_hi, params)
    light = shoot_in_chunks(flat, grid, w_lo, params)
    best = np.max(coarse, axis=-1)
    i = np.argmax(coarse, axis=-1)
    step = grid[1] - grid[0]
    lo, hi = np.clip(grid[i] - step, a_lo, a_hi), np.clip(grid[i] + step, a_lo, a_hi)
    inv = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(GOLDEN_ITERATIONS):  # both probes of a step in one call
        a, b = hi - inv * (hi - lo), lo + inv * (hi - lo)
        f = shoot_in_chunks(flat, np.stack([a, b], axis=-1), w_hi, params)
        left = f[:, 0] >= f[:, 1]
        lo, hi = np.where(left, lo, a), np.where(left, b, hi)
    longest = np.maximum(shoot_in_chunks(flat[:, 0], (lo + hi) / 2, w_hi, params), best)
    shortest = np.minimum(np.min(coarse, axis=-1), np.min(light, axis=-1))
    return shortest.reshape(wind.shape), longest.reshape(wind.shape)


def check_target(target_m, wind_mps) -> None:
    """Raise ``ConfigError`` if the target cannot be hit within the heads' bounds."""
    target_m, wind_mps = float(target_m), float(wind_mps)
    for name, value in (("target", target_m), ("wind", wind_mps)):
        if not math.isfinite(value):
            raise ConfigError(f"{name} must be a finite number, got {value!r}")
    if target_m <= 0:
        raise ConfigError(f"target must be a positive distance in metres, got {target_m:g}")
    shortest, longest = (float(x) for x in reachable_range(wind_mps))
    if not shortest <= target_m <= longest:
        raise ConfigError(
            f"a target at {target_m:g} m is out of reach in a {wind_mps:+g} m/s wind: this "
            f"trebuchet reaches {shortest:.1f}-{longest:.1f} m with angles "
            f"{ANGLE_RANGE_DEG[0]:g}-{ANGLE_RANGE_DEG[1]:g} deg and weights "
            f"{WEIGHT_RANGE_LB[0]:g}-{WEIGHT_RANGE_LB[1]:g} lb"
        )


MAX_STEP = 0.25
"""Largest Gauss-Newton step of ``aim_directly`` in scaled units (10 degrees or 50 lb)."""


def aim_directly(
    target_m, wind_mps, angle_deg=35.0, weight_lb=200.0, iterations: int = 20, params=None
):
    """Aim one throw by gradient steps on the simulator alone (no network).

    Gauss-Newton on the miss ``r = shoot(wind, angle, weight) - target`` in scaled
    coordinates ``z = (angle / 40 deg, weight / 200 lb)``: the minimum-norm step
    ``dz = -r J / |J|^2`` with the gradient ``J`` of the miss, projected onto the
    heads' bounds, with a trust region and the coordinates held at a bound frozen.
    Elementwise over batches; jit it. Near the longest throw of a wind the angle's derivative
    vanishes and the iteration can stall short of the target (check ``miss_m``).

    It returns ``(angle_deg, weight_lb, miss_m)`` after ``iterations`` steps.
    """
    p = params or tb.TrebuchetParams()
    dtype = jnp.result_type(float)
    target, wind = jnp.asarray(target_m, dtype), jnp.asarray(wind_mps, dtype)
    scale = jnp.array([40.0, 200.0], dtype)
    low = jnp.array([ANGLE_RANGE_DEG[0], WEIGHT_RANGE_LB[0]], dtype) / scale
    high = jnp.array([ANGLE_RANGE_DEG[1], WEIGHT_RANGE_LB[1]], dtype) / scale

    def miss(z, target, wind):
        return tb.shoot(wind, z[0] * scale[0], z[1] * scale[1], p) - target

    def one(target, wind, z0):
        def body(_, z):
            r, jac = jax.value_and_grad(miss)(z, target, wind)
            dz = -r * jac / jnp.maximum(jnp.sum(jac**2), 1e-12)
            # At a bound, move only the coordinates that are free to go the wanted way
            # (at the heaviest weight a longer throw must come from the angle).
            stuck = ((z <= low) & (dz < 0)) | ((z >= high) & (dz > 0))
            jac = jnp.where(stuck, 0.0, jac)
            dz = -r * jac / jnp.maximum(jnp.sum(jac**2), 1e-12)
            # A trust region: far from the target the linearisation overshoots into the
            # bounds, where the gradient of the angle vanishes and the iteration stalls.
            dz = dz * jnp.minimum(1.0, MAX_STEP / jnp.maximum(jnp.linalg.norm(dz), 1e-12))
            return jnp.clip(z + dz, low, high)

        z = jax.lax.fori_loop(0, iterations, body, z0)
        return z * scale, miss(z, target, wind)

    z0 = jnp.stack(
        jnp.broadcast_arrays(jnp.asarray(angle_deg, dtype), jnp.asarray(weight_lb, dtype)), -1
    )
    z0 = z0 / scale
    target, wind, z0 = jnp.broadcast_arrays(target[..., None], wind[..., None], z0)
    shape = z0.shape[:-1]
    out, r = jax.vmap(one)(target[..., 0].reshape(-1), wind[..., 0].reshape(-1), z0.reshape(-1, 2))
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape), r.reshape(shape)


_REFINE = FastJit(aim_directly, "xla_cpu_use_fusion_emitters", static_argnames=("iterations",))
"""``RefinedAimingPolicy``'s program, ``REFINE_CHUNK`` aims a call. It is compiled once a run,
so with the older CPU emitters (about half the time to compile; the aims move by float32
rounding)."""
REFINE_CHUNK = 16
"""Aims per call of ``_REFINE``: a single aim takes about 4 ms (with 1,000 a call, 100 ms), and
1,000 aims 0.25 s (0.1 s)."""
_AIM_PADDING = (60.0, 0.0, 45.0, 200.0)
"""The target, wind, angle and weight of the padding aims."""


class RefinedAimingPolicy(AimingPolicy):
    """An ``AimingPolicy`` whose network's aim is refined through the simulator at act time:
    ``model.json``'s ``refine`` (``REFINEMENT``) Gauss-Newton steps of ``aim_directly`` from the
    network's angle and weight, on the trebuchet the network was trained on (the run's
    ``params`` overrides included). It needs JAX; ``network_action`` is the network alone, the
    controller's NumPy-only form (what NumPy readers of ``model.json`` and the ONNX export run).
    """

    needs_jax = True

    def __init__(self, doc: dict):
        super().__init__(doc)
        refine = doc["refine"]
        steps = refine.get("iterations") if isinstance(refine, dict) else None
        if (
            not isinstance(refine, dict)
            or refine.get("method") != REFINEMENT["method"]
            or not isinstance(steps, int)
            or isinstance(steps, bool)
            or not 0 <= steps <= MAX_REFINE_ITERATIONS
        ):
            raise ModelFileError(
                f"refine {refine!r} is not Gauss-Newton with 0-{MAX_REFINE_ITERATIONS} "
                "iterations; re-create the model with `diffcontrol train`"
            )
        self.iterations = steps
        pairs = None
        try:  # the params the network was trained with (its run's config)
            pairs = ((doc.get("metadata") or {}).get("config") or {}).get("params") or ()
            overrides = tuple((str(n), float(v)) for n, v in pairs)
        except (AttributeError, TypeError, ValueError):
            raise ModelFileError(
                f"the training params {pairs!r} are not (name, number) pairs; re-create the "
                "model with `diffcontrol train`"
            ) from None
        self.params = task_params(TrebuchetAiming(), overrides) if overrides else None

    def network_action(self, obs: np.ndarray) -> np.ndarray:
        """The network's aim alone (``AimingPolicy.action``)."""
        return super().action(obs)

    def action(self, obs: np.ndarray) -> np.ndarray:
        """The network's aim at observations ``(target_m, wind_mps)`` refined by the
        simulator, in calls of ``REFINE_CHUNK`` aims to one compiled program."""
        obs = np.asarray(obs, np.float64)
        first = super().action(obs)
        if not self.iterations:
            return first
        columns = [
            *np.moveaxis(obs.reshape(-1, 2), -1, 0),
            *np.moveaxis(first.reshape(-1, 2), -1, 0),
        ]

        def refine(*chunk):
            aims = _REFINE(*chunk, iterations=self.iterations, params=self.params)
            return np.stack(aims[:2], -1)

        return _in_chunks(refine, columns, _AIM_PADDING, REFINE_CHUNK, np.float32).reshape(
            first.shape
        )


def miss_statistics(misses: np.ndarray, reachable: np.ndarray) -> dict[str, Any]:
    """Mean, median, 95th percentile and worst |miss| (m) over the reachable targets."""
    m = np.abs(np.asarray(misses, np.float64))[np.asarray(reachable, bool)]
    n_all = int(np.asarray(reachable).size)
    out: dict[str, Any] = {
        "targets": n_all,
        "reachable": int(m.size),
        "unreachable": n_all - int(m.size),
    }
    if m.size:
        out.update(
            mean_miss_m=float(np.mean(m)),
            median_miss_m=float(np.median(m)),
            p95_miss_m=float(np.percentile(m, 95)),
            worst_miss_m=float(np.max(m)),
        )
    return out
