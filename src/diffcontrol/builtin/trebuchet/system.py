"""The trebuchet of Trebuchet.jl (the 2019 FluxML post) as a pure, differentiable JAX program.

A counterweight trebuchet with a sling, with virtualtrebuchet.com's equations of motion as
Trebuchet.jl writes them (``shared/reference/seed-systems.md`` section 2). SI units inside; the
user-facing API takes the wind in m/s (``+`` is a tail wind, toward ``+x``), the release angle
in degrees and the counterweight in pounds, and returns the distance in metres.

Origin at the pivot, ``+x`` the throw direction, ``+y`` up, the ground at ``y = -h``. The
mechanism's state is ``u = (q_A, q_W, q_S, w_A, w_W, w_S)``: the arm angle, the counterweight's
angle relative to the arm, the sling's angle relative to the arm, and their rates. At rest the
long-arm tip touches the ground and the sling lies flat along ``+x``; the projectile is at
``x = L_S - L_l cos(asin(h / L_l)) = 0.6816 m``.

Phases ``GROUND -> HANG -> RELEASED -> END``, each integrated with explicit Euler at
``dt = 1/60 s``:

- ``GROUND``: the projectile slides on the frictionless ground (2 DOF; ``q_S`` is slaved at the
  acceleration level). Lift-off when ``m_P g - T cos(q_A + q_S - pi)`` reaches 0, where the sling
  tension ``T = -m_P a_x / sin(q_A + q_S - pi)`` comes from a finite difference of the sling
  end's horizontal velocity since the step's start. If ``T < 0`` at a step end, the weight is
  too light: the throw ends there, and its distance is the projectile's current ``x``.
- ``HANG``: the projectile swings on the sling (3 DOF). Release when ``sin(phi - r) = 0``, where
  ``phi`` is the direction of the sling end's velocity and ``r = asin(sin(angle))``.
- ``RELEASED``: a point mass with quadratic drag relative to the wind,
  ``a = -g e_y - k |v - w e_x| (v - w e_x)``, ``k = rho C_d pi z^2 / (2 m_P)``, until it lands at
  ``y = -h``; ``w`` is ``wind_factor`` times the wind input (1 by default). The distance is
  ``x`` at landing, measured from the pivot.

Events are located as the original's ``ContinuousCallback`` does on a fixed-step ``Euler()``
integrator: inside the step, on the linear interpolant ``u(s) = u_n + s (u_{n+1} - u_n)`` with
``s`` in ``(0, 1]``. For the lift-off test, the tension's finite difference runs from ``u_n`` to
``u(s)`` over ``s dt``. The original evaluates that test as ``m_P g`` at ``s = 0`` itself. When
its right limit at ``0+`` is already ``<= 0``, the root is that jump: lift-off at the step's
start, with no sensitivity to the inputs (the original's root finder converges there too).
Otherwise the root is found by safeguarded Newton without gradient, and then one more Newton
step carries the implicit-function derivative. So event times and states depend on the
inputs as in the original's ForwardDiff pass (discretise-then-differentiate). The next phase
starts from the event time and state with full ``dt`` steps.

The throw runs as three ``lax.scan``s, one a phase (``_trebuchet_phases``), with static
budgets of steps (``TrebuchetParams.ground_steps``, ``hang_steps`` and ``max_steps``). A step
computes only its phase's rates and the sign test of its event at the step's end. Once the
test fires, the scan holds the state at that step's start, and the event is located once,
after the scan, inside that step. So the root finding runs twice a throw, not on every step.
The throw ``jit``s, ``vmap``s and differentiates in both modes.

Where the derivative is non-smooth. The distance is continuous in the inputs except on the
failure branches below, but its derivative jumps:

- when an event moves to another step, and when lift-off switches between the jump case and
  the smooth case above;
- on the weight-too-light branch (``T < 0``), and for a throw that has not landed within its
  step budgets (``landed`` is ``False``). The distance jumps there, and its gradient is that of
  the current ``x``;
- at the fold ``r = asin(sin(angle))``, at +-90 degrees;
- at ``weight_lb <= 0``, which returns the rest ``x`` with zero gradient, as the original does.

Quirks of the original, kept on purpose:

1. The two inertias are swapped inside both equations of motion. The arm's slot gets the
   counterweight's ``1 lb ft^2``; the counterweight's slots get the arm's
   ``m_A (L_l + L_s)^2 / 12`` (``TrebuchetParams.swap_inertias``). The blog's gradient needs it:
   without the swap it comes out as ``(3.86, -0.968, 0.0490)``, 2-4 % off.
2. ``rho = 1.0`` (not 1.225) and the coarse Euler step are part of the "environment".
3. The release test fires on every zero of ``sin(phi - r)``, so also when the velocity points
   along ``r +- pi``. For ``r`` below about -1 to -2 degrees the projectile is then let go
   backwards.
4. The release angle is normalised with ``asin(sin r)``, so 100 degrees throws as 80 degrees.
5. Euler at ``dt = 1/60`` cannot follow the sling's whip above about 640 lb (a quarter of the
   step makes the same throws sane). The hang phase then gains energy, often releases
   backwards, and at some angles blows up (release speeds up to 1e48 m/s, or NaN).
   ``Throw.diverged`` flags such gross failures. ``check_inputs`` caps the counterweight at
   ``MAX_WEIGHT_LB = 600``.

Departures from the original:

- Events are only sought at the step ends. The original also probes 8 interpolated points
  inside each step, which only matters if a test crosses zero twice within one step.
- A phase whose event never comes stops at its budget of steps (``ground_steps``,
  ``hang_steps``, or ``max_steps`` in all), and the throw reports ``landed=False``. The
  original restarts the phase in windows of 1 s (ground, hang) or 5 s (flight) until it ends.
  With the default budgets every throw with ``|wind| <= 20`` m/s and 25-600 lb lands, as in
  the original (``TrebuchetParams``). Lift-off takes longer than the ground budget (0.75 s)
  only below about 25 lb; below about 15.5 lb the sling goes slack on the ground.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ...errors import ConfigError
from ._eom import (
    FT,
    LB,
    TrebuchetParams,
    arm_tip,
    counterweight,
    flight_rates,
    ground_rates,
    hang_rates,
    initial_state,
    lengths,
    sling_end,
    sling_velocity,
)
from ._phases import flight_scan, ground_scan, hang_scan, locate_liftoff, locate_release

__all__ = [
    "END",
    "FT",
    "GROUND",
    "HANG",
    "LB",
    "MAX_ANGLE_DEG",
    "MAX_WEIGHT_LB",
    "MIN_ANGLE_DEG",
    "RELEASED",
    "Throw",
    "TrebuchetParams",
    "arm_tip",
    "check_inputs",
    "counterweight",
    "flight_rates",
    "ground_rates",
    "hang_rates",
    "initial_state",
    "shoot",
    "simulate",
    "sling_end",
    "sling_velocity",
]

GROUND, HANG, RELEASED, END = 0, 1, 2, 3
"""The phases, in the order a throw passes through them."""

MIN_ANGLE_DEG, MAX_ANGLE_DEG = 0.0, 90.0
"""``check_inputs`` accepts release angles in ``(0, 90]`` degrees."""
MAX_WEIGHT_LB = 600.0
"""``check_inputs`` accepts counterweights in ``(0, 600]`` lb (see the module docstring)."""


class Throw(eqx.Module):
    """One simulated throw: scalars, then per-step arrays of length ``max_steps + 1`` (row
    ``i`` is the state after ``i`` steps, row 0 the rest state; after the last step, at
    ``END`` or where a budget ran out, they repeat the final values)."""

    distance: Float[Array, ""]
    """Projectile ``x`` at the end (m, from the pivot): where it landed if ``landed``."""
    landed: Bool[Array, ""]
    """Whether the projectile reached the ground within the step budgets."""
    weight_too_light: Bool[Array, ""]
    """Whether the sling went slack on the ground (``T < 0``), or ``weight_lb <= 0``."""
    diverged: Bool[Array, ""]
    """Whether the Euler integration blew up (quirk 5): a non-finite state, or a release speed
    beyond what all the counterweight's and arm's potential energy could give the projectile.
    A detector of gross failures, not an accuracy check."""
    phase: Int[Array, ""]
    """The last phase reached (``GROUND``, ``HANG``, ``RELEASED`` or ``END``)."""
    liftoff_time: Float[Array, ""]
    """Time (s) the projectile left the ground; NaN if it never did."""
    release_time: Float[Array, ""]
    """Time (s) of release; NaN if never released."""
    landing_time: Float[Array, ""]
    """Time (s) of landing; NaN if it did not land."""
    release_velocity: Float[Array, 2]
    """Projectile velocity (m/s) at release; NaN if never released."""
    time: Float[Array, " n"]
    """Time (s) of each recorded state."""
    arm_tip: Float[Array, "n 2"]
    """Long-arm tip (m); the arm stays at its release pose after release, as in the original."""
    counterweight: Float[Array, "n 2"]
    """Counterweight centre of gravity (m)."""
    projectile: Float[Array, "n 2"]
    """Projectile (m)."""
    phases: Int[Array, " n"]
    """Phase of each recorded state."""

    @property
    def flight_time(self):
        """Time (s) from release to landing."""
        return self.landing_time - self.release_time


def _release_angle(angle_deg):
    """``asin(sin r)``, ``r`` in radians, as a triangle wave (slope +-1, finite everywhere)."""
    m = jnp.mod(jnp.deg2rad(angle_deg) + jnp.pi / 2, 2 * jnp.pi)
    return jnp.where(m < jnp.pi, m - jnp.pi / 2, 1.5 * jnp.pi - m)


def _run(wind, angle_deg, weight_lb, p: TrebuchetParams, record: bool):
    dtype = jnp.result_type(float)
    wind, angle_deg, weight_lb = (jnp.asarray(v, dtype) for v in (wind, angle_deg, weight_lb))
    r = _release_angle(angle_deg)
    m_w = jnp.maximum(weight_lb, 0.0) * LB  # <= 0 returns the rest x below, as the original
    u_rest = initial_state(p).astype(dtype)
    f_dummy = jnp.array([0.0, 0.0, 1.0, 1.0], dtype)  # a finite stand-in where no flight is
    budgets = [
        min(p.ground_steps, p.max_steps),
        min(p.hang_steps, p.max_steps),
        max(p.max_steps - 2, 1),
    ]

    def sling_state(u):
        return jnp.concatenate([sling_end(p, u), sling_velocity(p, u)])

    # GROUND up to the step where lift-off or a slack sling is detected; then locate it.
    n_g, t_g, u_g, u1_g, hit_g, lifts, ys_g = ground_scan(p, m_w, u_rest, budgets[0], record)
    s_g, lift, fail = locate_liftoff(p, u_g, u1_g, hit_g, lifts)
    u_g = jnp.where(lift, u_g + s_g * (u1_g - u_g), jnp.where(hit_g, u1_g, u_g))
    t_g = jnp.where(hit_g, t_g + jnp.where(lift, s_g, 1) * p.dt, t_g)
    n_g = n_g + hit_g
    hanging = lift & ~fail

    # HANG from lift-off up to the step where the release test changes sign; then locate it.
    n_h, t_h, u_h, u1_h, release, _, ys_h = hang_scan(
        p, m_w, r, n_g, t_g, u_g, hanging, budgets[1], record
    )
    s_h = locate_release(p, u_h, u1_h, r, release)
    u_h = jnp.where(release, u_h + s_h * (u1_h - u_h), u_h)  # the arm stays in this pose
    t_h = jnp.where(release, t_h + s_h * p.dt, t_h)
    n_h = n_h + release

    # RELEASED until landing.
    f_h = jnp.where(release, sling_state(u_h), f_dummy)
    n_r, t_r, f_r, landed, ys_r = flight_scan(p, wind, n_h, t_h, f_h, release, budgets[2], record)

    x_end = jnp.where(release, f_r[0], sling_end(p, u_h)[0])
    distance = jnp.where(weight_lb > 0, x_end, sling_end(p, u_rest)[0])
    if not record:
        return distance

    phase = jnp.where(release, RELEASED, jnp.where(hanging, HANG, GROUND))
    phase = jnp.where(fail | landed, END, phase).astype(jnp.int32)
    f_end = jnp.where(release, f_r, sling_state(u_h))
    finite = jnp.all(jnp.isfinite(u_h)) & jnp.all(jnp.isfinite(f_end)) & jnp.isfinite(t_r)
    nan = jnp.asarray(jnp.nan, dtype)
    release_velocity = jnp.where(release, sling_velocity(p, u_h), nan)
    release_speed2 = jnp.sum(jnp.where(release, release_velocity, 0.0) ** 2)
    _, l_s, l_w, _, l_cg = lengths(p)
    drop = m_w * 2 * (l_s + l_w) + p.arm_mass * 2 * l_cg  # most potential energy / g to spend
    max_speed2 = 2 * p.gravity * drop / p.projectile_mass

    # The per-step arrays, gathered from a table of (time, mechanism state, projectile state,
    # phase) rows: the rest state, the ground steps, lift-off (or the slack sling), the hang
    # steps, release, the flight steps and the final state.
    def rows(t, u, f, phase):
        t = jnp.atleast_1d(t)
        u, f = jnp.broadcast_to(u, t.shape + (6,)), jnp.broadcast_to(f, t.shape + (4,))
        return t, u, f, jnp.broadcast_to(jnp.asarray(phase, jnp.int32), t.shape)

    table = [
        rows(jnp.zeros((), dtype), u_rest, f_dummy, GROUND),
        rows(ys_g[0], ys_g[1], f_dummy, GROUND),
        rows(t_g, u_g, sling_state(u_g), jnp.where(fail, END, HANG)),
        rows(ys_h[0], ys_h[1], f_dummy, HANG),
        rows(t_h, u_h, f_h, RELEASED),
        rows(ys_r[0], u_h, ys_r[1], jnp.where(ys_r[2], END, RELEASED)),
        rows(t_r, u_h, f_end, phase),
    ]
    start = np.cumsum([0] + [len(part[0]) for part in table])
    i = jnp.arange(p.max_steps + 1)
    row = jnp.where(
        i <= n_h,
        jnp.where(
            i <= n_g,
            jnp.where((i == n_g) & hit_g, start[2], start[1] + i - 1),
            jnp.where((i == n_h) & release, start[4], start[3] + i - n_g - 1),
        ),
        jnp.where(i <= n_r, start[5] + i - n_h - 1, start[6]),
    )
    t, u, f, phases = (jnp.concatenate(column)[jnp.where(i == 0, 0, row)] for column in zip(*table))
    attached = (phases == GROUND) | (phases == HANG)
    projectile = jnp.where(attached[:, None], jax.vmap(sling_end, (None, 0))(p, u), f[:, :2])
    return Throw(
        distance=distance,
        landed=landed & (weight_lb > 0),
        weight_too_light=fail | (weight_lb <= 0),
        diverged=~(finite & ~(release_speed2 > max_speed2)),
        phase=phase,
        liftoff_time=jnp.where(hanging, t_g, nan),
        release_time=jnp.where(release, t_h, nan),
        landing_time=jnp.where(landed, t_r, nan),
        release_velocity=release_velocity,
        time=t,
        arm_tip=jax.vmap(arm_tip, (None, 0))(p, u),
        counterweight=jax.vmap(counterweight, (None, 0))(p, u),
        projectile=projectile,
        phases=phases,
    )


def simulate(
    wind_mps: ArrayLike,
    angle_deg: ArrayLike,
    weight_lb: ArrayLike,
    params: TrebuchetParams | None = None,
) -> Throw:
    """Simulate one throw and record its trajectory (for plots and animations).

    Arguments are scalars: wind (m/s, ``+`` is a tail wind), release angle (degrees) and
    counterweight (pounds); ``jax.vmap`` it for batches. Pure and jittable; it does not
    validate its inputs (call ``check_inputs`` at the boundary).
    """
    return _run(wind_mps, angle_deg, weight_lb, params or TrebuchetParams(), record=True)


def shoot(
    wind_mps: ArrayLike,
    angle_deg: ArrayLike,
    weight_lb: ArrayLike,
    params: TrebuchetParams | None = None,
) -> Float[Array, "*batch"]:
    """Distance (m, from the pivot) of a throw: the blog's ``Trebuchet.shoot``.

    Args:
        wind_mps: wind speed (m/s); ``+`` blows toward the target.
        angle_deg: release angle (degrees above the horizontal), folded with ``asin(sin r)``.
        weight_lb: counterweight (pounds).
        params: the trebuchet's constants (default ``TrebuchetParams()``).

    The three inputs broadcast against each other, and the result has their broadcast shape.
    The distance is differentiable in all of them (and in ``params``) with ``jax.grad`` or
    ``jax.jacfwd``, and ``vmap``pable. The function is pure and jittable and does not validate
    its inputs: call ``check_inputs`` at the boundary. A weight too light to lift the
    projectile gives the projectile's ``x`` when the sling went slack (about 0.68 m), and
    ``weight_lb <= 0`` gives the rest position, as in the original. A throw that runs out of
    its step budgets (``TrebuchetParams``: below about 25 lb, or far outside the checked
    winds) gives the projectile's ``x`` where it stopped. Above about 640 lb the result can
    be wrong, absurd or NaN (quirk 5; ``simulate`` reports ``diverged``). At
    ``(-2, 45, 200)`` the distance is 74.76 m and the gradient is ``(4.025, -0.9964, 0.05037)``;
    the post reports ``(4.02, -0.99, 0.051)``. With three inputs, forward mode (``jax.jacfwd``,
    as the original's ForwardDiff) is the cheaper one on a CPU.
    """
    p = params or TrebuchetParams()
    run = jnp.vectorize(lambda w, a, m: _run(w, a, m, p, record=False))
    return run(wind_mps, angle_deg, weight_lb)


def check_inputs(wind_mps, angle_deg, weight_lb) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate user inputs on the host. Returns them as float64 NumPy arrays, broadcast.

    Each argument is a finite number or a 1-D array; the 1-D ones must share one length.
    ``weight_lb`` must be in ``(0, 600]``: heavier counterweights can make the Euler steps
    diverge (quirk 5). ``angle_deg`` must be in ``(0, 90]``: at ``<= 0`` the projectile can be
    let go backwards (quirk 3), and above 90 the angle folds back.

    Raises:
        ConfigError: naming the bad argument and what is accepted.
    """
    named = {"wind_mps": wind_mps, "angle_deg": angle_deg, "weight_lb": weight_lb}
    arrays = {}
    for name, value in named.items():
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as e:
            msg = f"{name} must be a number or a 1-D array of numbers, got {value!r}"
            raise ConfigError(msg) from e
        if arr.ndim > 1:
            raise ConfigError(f"{name} must be a scalar or a 1-D batch, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ConfigError(f"{name} must be finite, got {value!r}")
        arrays[name] = arr
    if len({a.shape for a in arrays.values() if a.ndim == 1}) > 1:
        shapes = {k: a.shape for k, a in arrays.items()}
        raise ConfigError(f"batched inputs must share one length, got shapes {shapes}")
    weight = arrays["weight_lb"]
    if np.any((weight <= 0) | (weight > MAX_WEIGHT_LB)):
        hi = MAX_WEIGHT_LB
        raise ConfigError(
            f"weight_lb (counterweight, pounds) must be in (0, {hi:g}], got {weight_lb!r}"
        )
    angle = arrays["angle_deg"]
    if np.any((angle <= MIN_ANGLE_DEG) | (angle > MAX_ANGLE_DEG)):
        lo, hi = MIN_ANGLE_DEG, MAX_ANGLE_DEG
        raise ConfigError(f"angle_deg must be in ({lo:g}, {hi:g}] degrees, got {angle_deg!r}")
    w, a, m = np.broadcast_arrays(*arrays.values())
    return w, a, m
