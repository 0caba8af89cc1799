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
  ``y = -h``. The distance is ``x`` at landing, measured from the pivot.

Events are located as the original's ``ContinuousCallback`` does on a fixed-step ``Euler()``
integrator: inside the step, on the linear interpolant ``u(s) = u_n + s (u_{n+1} - u_n)`` with
``s`` in ``(0, 1]``. For the lift-off test, the tension's finite difference runs from ``u_n`` to
``u(s)`` over ``s dt``. The original evaluates that test as ``m_P g`` at ``s = 0`` itself. When
its right limit at ``0+`` is already ``<= 0``, the root is that jump: lift-off at the step's
start, with no sensitivity to the inputs (the original's root finder converges there too).
Otherwise the root is found by safeguarded Newton without gradient, and then one more Newton
step carries the implicit-function derivative. So event times and states depend on the
inputs as in the original's ForwardDiff pass (discretise-then-differentiate). The next phase
starts from the event time and state with full ``dt`` steps. The whole throw is one
``lax.scan`` of ``params.max_steps`` steps, with the phase in the carry and ``jnp.where``
selection. It ``jit``s, ``vmap``s and differentiates in both modes.

Where the derivative is non-smooth. The distance is continuous in the inputs except on the
failure branches below, but its derivative jumps:

- when an event moves to another step, and when lift-off switches between the jump case and
  the smooth case above;
- on the weight-too-light branch (``T < 0``), and for a throw that has not landed within
  ``max_steps`` (``landed`` is ``False``). The distance jumps there, and its gradient is that of
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
- A phase whose event never comes continues until ``max_steps``. The original restarts it in
  windows of 1 s (ground, hang) or 5 s (flight). Lift-off takes longer than 1 s only below
  about 20.5 lb; below about 15.5 lb the sling goes slack on the ground.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ..errors import ConfigError

FT = 0.3048
"""Metres per foot (the original's ``ft2m``)."""
LB = 0.45359237
"""Kilograms per pound (the original's ``lb2kg``)."""

GROUND, HANG, RELEASED, END = 0, 1, 2, 3
"""The phases, in the order a throw passes through them."""

MIN_ANGLE_DEG, MAX_ANGLE_DEG = 0.0, 90.0
"""``check_inputs`` accepts release angles in ``(0, 90]`` degrees."""
MAX_WEIGHT_LB = 600.0
"""``check_inputs`` accepts counterweights in ``(0, 600]`` lb (see the module docstring)."""

_NEWTON_ITERS = 4  # from the regula-falsi point; the 5th (differentiable) one reaches rounding


class TrebuchetParams(eqx.Module):
    """Constants of Trebuchet.jl's trebuchet, in SI units (converted from its imperial values).

    The counterweight, the wind and the release angle are inputs of ``shoot``, not parameters.
    Every float field is a PyTree leaf (``vmap``pable, differentiable).
    """

    pivot_height: float = 5.0 * FT
    """``h``: pivot height above the ground (m)."""
    long_arm: float = 6.792 * FT
    """``L_l``: pivot to sling attachment (m)."""
    short_arm: float = 1.75 * FT
    """``L_s``: pivot to counterweight hinge (m)."""
    weight_arm: float = 2.0 * FT
    """``L_w``: hinge to the counterweight's centre of gravity (m)."""
    sling_length: float = 6.833 * FT
    """``L_S``: sling length (m)."""
    projectile_radius: float = 0.1245 * FT
    """``z``: projectile radius (m); the drag area is ``pi z^2``."""
    projectile_mass: float = 0.328 * LB
    """``m_P`` (kg)."""
    arm_mass: float = 10.65 * LB
    """``m_A`` (kg)."""
    counterweight_inertia: float = 1.0 * LB * FT**2
    """``I_cw`` (kg m^2): the original's ``1 lb ft^2``, which overrides its disk formula."""
    gravity: float = 9.80665
    """``g`` (m/s^2)."""
    air_density: float = 1.0
    """``rho`` (kg/m^3): the original's 1.0, not sea level's 1.225. 0 turns drag off."""
    drag_coefficient: float = 1.0
    """``C_d`` of the projectile."""
    dt: float = 1.0 / 60.0
    """Explicit-Euler step (s): the original's ``rate = 60``."""
    max_steps: int = eqx.field(static=True, default=600)
    """Length of the scan, in steps of ``dt`` (10 s at the default ``dt``). The slowest throw
    in ``check_inputs``' range with ``|wind| <= 20 m/s`` and 21-600 lb lands after 7.4 s
    (446 steps: 20 m/s, 65 degrees, 600 lb). A throw that has not landed by then reports
    ``landed=False``."""
    swap_inertias: bool = eqx.field(static=True, default=True)
    """Keep the original's swap of the arm and counterweight inertias (quirk 1)."""

    @property
    def arm_inertia(self):
        """``I_arm = m_A (L_l + L_s)^2 / 12`` (kg m^2): a uniform rod about its centre."""
        return self.arm_mass * (self.long_arm + self.short_arm) ** 2 / 12

    @property
    def inertias(self):
        """``(I1, I2)`` as the equations use them: I1 enters M11 only (the arm's slot), I2 enters
        M11, M12 and M22 (the counterweight's slot). Swapped as in the original by default."""
        if self.swap_inertias:
            return self.counterweight_inertia, self.arm_inertia
        return self.arm_inertia, self.counterweight_inertia

    @property
    def drag_constant(self):
        """``k = rho C_d pi z^2 / (2 m_P)`` (1/m)."""
        area = math.pi * self.projectile_radius**2
        return self.air_density * self.drag_coefficient * area / (2 * self.projectile_mass)


def initial_state(p: TrebuchetParams) -> Float[Array, 6]:
    """The rest state: arm tip on the ground, counterweight hanging, sling along ``+x``."""
    theta0 = jnp.arcsin(p.pivot_height / p.long_arm)
    q_a = jnp.pi / 2 + theta0
    zero = jnp.zeros_like(q_a)
    return jnp.stack([q_a, -q_a, jnp.pi - theta0, zero, zero, zero])


def arm_tip(p: TrebuchetParams, u: Float[Array, 6]) -> Float[Array, 2]:
    """Position (m) of the long arm's tip, where the sling is attached."""
    return p.long_arm * jnp.stack([-jnp.sin(u[0]), jnp.cos(u[0])])


def counterweight(p: TrebuchetParams, u: Float[Array, 6]) -> Float[Array, 2]:
    """Position (m) of the counterweight's centre of gravity."""
    hinge = p.short_arm * jnp.stack([jnp.sin(u[0]), -jnp.cos(u[0])])
    return hinge + p.weight_arm * jnp.stack([jnp.sin(u[0] + u[1]), -jnp.cos(u[0] + u[1])])


def sling_end(p: TrebuchetParams, u: Float[Array, 6]) -> Float[Array, 2]:
    """Position (m) of the sling's end: the projectile until release."""
    a = u[0] + u[2]
    return arm_tip(p, u) + p.sling_length * jnp.stack([-jnp.sin(a), jnp.cos(a)])


def sling_velocity(p: TrebuchetParams, u: Float[Array, 6]) -> Float[Array, 2]:
    """Velocity (m/s) of the sling's end."""
    a, w = u[0] + u[2], u[3] + u[5]
    tip = p.long_arm * u[3] * jnp.stack([jnp.cos(u[0]), jnp.sin(u[0])])
    return -tip - p.sling_length * w * jnp.stack([jnp.cos(a), jnp.sin(a)])


def _lengths(p: TrebuchetParams):
    return p.long_arm, p.short_arm, p.weight_arm, p.sling_length, (p.long_arm - p.short_arm) / 2


def ground_rates(
    p: TrebuchetParams, u: Float[Array, 6], m_w: ArrayLike, valid: ArrayLike = True
) -> Float[Array, 6]:
    """``du/dt`` while the projectile slides on the ground; ``m_w`` is the counterweight (kg).

    Singular where ``sin(q_A + q_S) = 0`` (a vertical sling), which the ground phase never
    reaches. Where ``valid`` is false that sine is replaced by 1: finite garbage with finite
    gradients, for a branch that ``jnp.where`` discards (the "double where").
    """
    q_a, q_w, q_s, w_a, w_w, w_s = u
    (i1, i2), (l_l, l_s, l_w, l_sl, l_cg) = p.inertias, _lengths(p)
    m_p, m_a, g = p.projectile_mass, p.arm_mass, p.gravity
    s, c = jnp.where(valid, jnp.sin(q_a + q_s), 1.0), jnp.cos(q_a + q_s)
    k = c / s * w_s * (w_s + 2 * w_a) + (c / s + l_l * jnp.cos(q_a) / (l_sl * s)) * w_a**2
    sling = 1 - 2 * jnp.sin(q_a) * jnp.cos(q_s) / s + jnp.sin(q_a) ** 2 / s**2
    m11 = m_p * l_l**2 * sling + i1 + i2 + m_a * l_cg**2
    m11 = m11 + m_w * (l_s**2 + l_w**2 + 2 * l_s * l_w * jnp.cos(q_w))
    m12 = i2 + l_w * m_w * (l_w + l_s * jnp.cos(q_w))
    m22 = i2 + m_w * l_w**2
    r1 = (
        g * l_cg * m_a * jnp.sin(q_a)
        + l_l * l_sl * m_p * (jnp.sin(q_s) * (w_a + w_s) ** 2 + jnp.cos(q_s) * k)
        + l_l * m_p * jnp.sin(q_a) * (l_l * jnp.sin(q_s) * w_a**2 - l_sl * k) / s
        - g * m_w * (l_s * jnp.sin(q_a) + l_w * jnp.sin(q_a + q_w))
        - l_s * l_w * m_w * jnp.sin(q_w) * (w_a**2 - (w_a + w_w) ** 2)
    )
    r2 = -l_w * m_w * (g * jnp.sin(q_a + q_w) + l_s * jnp.sin(q_w) * w_a**2)
    det = m11 * m22 - m12**2
    acc_a, acc_w = (r1 * m22 - r2 * m12) / det, (r2 * m11 - r1 * m12) / det
    acc_s = -k - (l_l * jnp.sin(q_a) + l_sl * s) * acc_a / (l_sl * s)
    return jnp.stack([w_a, w_w, w_s, acc_a, acc_w, acc_s])


def hang_rates(p: TrebuchetParams, u: Float[Array, 6], m_w: ArrayLike) -> Float[Array, 6]:
    """``du/dt`` while the projectile swings on the sling (``M alpha = r``, 3 DOF)."""
    q_a, q_w, q_s, w_a, w_w, w_s = u
    (i1, i2), (l_l, l_s, l_w, l_sl, l_cg) = p.inertias, _lengths(p)
    m_p, m_a, g = p.projectile_mass, p.arm_mass, p.gravity
    m11 = i1 + i2 + m_a * l_cg**2 + m_p * (l_l**2 + l_sl**2 + 2 * l_l * l_sl * jnp.cos(q_s))
    m11 = m11 + m_w * (l_s**2 + l_w**2 + 2 * l_s * l_w * jnp.cos(q_w))
    m12 = i2 + l_w * m_w * (l_w + l_s * jnp.cos(q_w))
    m13 = l_sl * m_p * (l_sl + l_l * jnp.cos(q_s))
    m22, m33 = i2 + m_w * l_w**2, m_p * l_sl**2
    r1 = (
        g * l_cg * m_a * jnp.sin(q_a)
        + g * m_p * (l_l * jnp.sin(q_a) + l_sl * jnp.sin(q_a + q_s))
        - g * m_w * (l_s * jnp.sin(q_a) + l_w * jnp.sin(q_a + q_w))
        - l_l * l_sl * m_p * jnp.sin(q_s) * (w_a**2 - (w_a + w_s) ** 2)
        - l_s * l_w * m_w * jnp.sin(q_w) * (w_a**2 - (w_a + w_w) ** 2)
    )
    r2 = -l_w * m_w * (g * jnp.sin(q_a + q_w) + l_s * jnp.sin(q_w) * w_a**2)
    r3 = l_sl * m_p * (g * jnp.sin(q_a + q_s) - l_l * jnp.sin(q_s) * w_a**2)
    # Cramer's rule with M23 = 0, as the original writes it out.
    den = m13 * m22 * m13 - m33 * (m11 * m22 - m12**2)
    acc_a = -(r1 * m22 * m33 - r2 * m12 * m33 - r3 * m13 * m22) / den
    acc_w = (r1 * m12 * m33 - r2 * (m11 * m33 - m13**2) - r3 * m13 * m12) / den
    acc_s = (r1 * m22 * m13 - r2 * m12 * m13 - r3 * (m11 * m22 - m12**2)) / den
    return jnp.stack([w_a, w_w, w_s, acc_a, acc_w, acc_s])


def flight_rates(p: TrebuchetParams, f: Float[Array, 4], wind: ArrayLike) -> Float[Array, 4]:
    """``d(x, y, v_x, v_y)/dt`` of the released projectile, with drag relative to the wind."""
    rel_x, v_y = f[2] - wind, f[3]
    speed2 = rel_x**2 + v_y**2
    # Double where: sqrt has an infinite slope at 0 (the projectile moving with the air).
    speed = jnp.where(speed2 > 0, jnp.sqrt(jnp.where(speed2 > 0, speed2, 1.0)), 0.0)
    k = p.drag_constant
    return jnp.stack([f[2], v_y, -k * rel_x * speed, -p.gravity - k * v_y * speed])


def _event_fraction(fn, f_lo, f_hi, active):
    """The ``s`` in ``(0, 1]`` where ``fn(s) = 0``, given ``fn(0+) = f_lo`` and ``fn(1) = f_hi``
    of opposite signs (meaningful where ``active``).

    Safeguarded Newton from the regula-falsi point, without gradient; then one Newton step
    whose gradient is the implicit-function derivative ``ds/dp = -(dfn/dp) / (dfn/ds)``.
    """
    f_lo = jax.lax.stop_gradient(jnp.where(active, f_lo, 1.0))
    f_hi = jax.lax.stop_gradient(jnp.where(active, f_hi, -1.0))
    lo, hi = jnp.zeros_like(f_lo), jnp.ones_like(f_lo)
    s = f_lo / (f_lo - f_hi)
    for _ in range(_NEWTON_ITERS):
        v, d = jax.lax.stop_gradient(jax.jvp(fn, (s,), (jnp.ones_like(s),)))
        beyond = (v > 0) == (f_lo > 0)  # the root lies beyond s
        lo, hi = jnp.where(beyond, s, lo), jnp.where(beyond, hi, s)
        newton = jnp.where(v == 0, s, s - v / jnp.where(d != 0, d, 1.0))
        s = jnp.where((d != 0) & (newton >= lo) & (newton <= hi), newton, (lo + hi) / 2)
    s = jnp.where(active & jnp.isfinite(s), s, 1.0)
    value, slope = jax.jvp(fn, (s,), (jnp.ones_like(s),))
    slope = jax.lax.stop_gradient(jnp.where(active & (slope != 0), slope, 1.0))
    return jnp.clip(s - jnp.where(active, value, 0.0) / slope, 0.0, 1.0)


class Throw(eqx.Module):
    """One simulated throw: scalars, then per-step arrays of length ``max_steps + 1`` (index 0
    is the rest state; after ``END`` they repeat the final values)."""

    distance: Float[Array, ""]
    """Projectile ``x`` at the end (m, from the pivot): where it landed if ``landed``."""
    landed: Bool[Array, ""]
    """Whether the projectile reached the ground within ``max_steps``."""
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


def _snapshot(p, phase, t, u, f):
    attached = (phase == GROUND) | (phase == HANG)
    projectile = jnp.where(attached, sling_end(p, u), f[:2])
    return t, arm_tip(p, u), counterweight(p, u), projectile, phase


def _run(wind, angle_deg, weight_lb, p: TrebuchetParams, record: bool):
    dtype = jnp.result_type(float)
    wind, angle_deg, weight_lb = (jnp.asarray(v, dtype) for v in (wind, angle_deg, weight_lb))
    r = _release_angle(angle_deg)
    m_w = jnp.maximum(weight_lb, 0.0) * LB  # <= 0 returns the rest x below, as the original
    dt, m_p, g = p.dt, p.projectile_mass, p.gravity
    u_rest = initial_state(p).astype(dtype)
    f_safe = jnp.array([0.0, 0.0, 1.0, 1.0], dtype)
    zero, one, nan = (jnp.asarray(v, dtype) for v in (0.0, 1.0, jnp.nan))

    def sling_state(u):
        return jnp.concatenate([sling_end(p, u), sling_velocity(p, u)])

    def step(carry, _):
        phase, t, u, f, t_lift, t_rel, t_land, failed = carry
        in_g, in_h, in_r = phase == GROUND, phase == HANG, phase == RELEASED

        # Ground and Hang share one Euler step of the mechanism (and its trigonometry).
        rates = jnp.where(in_g, ground_rates(p, u, m_w, valid=in_g), hang_rates(p, u, m_w))
        u1 = u + dt * rates
        vx0 = sling_velocity(p, u)[0]

        def test(s):
            """Lift-off test (Ground) or release test (Hang) on the step's interpolant."""
            us = u + s * (u1 - u)
            v = sling_velocity(p, us)
            # sin and cos of q_A + q_S - pi; the sine is only used (and nonzero) in Ground.
            sin_a = jnp.where(in_g, -jnp.sin(us[0] + us[2]), 1.0)
            cos_a = -jnp.cos(us[0] + us[2])
            tension = -m_p * (v[0] - vx0) / (jnp.where(s > 0, s, 1.0) * dt) / sin_a
            aim = v[1] * jnp.cos(r) - v[0] * jnp.sin(r)  # = |v| sin(phi - r)
            return jnp.where(in_g, m_p * g - tension * cos_a, aim), tension, cos_a

        # The lift-off test's right limit at s = 0+: the tension from the slope of v_x.
        dvx0 = jax.jvp(lambda s: sling_velocity(p, u + s * (u1 - u))[0], (zero,), (one,))[1]
        tn0 = m_p * dvx0 / dt / jnp.where(in_g, jnp.sin(u[0] + u[2]), 1.0)
        c0 = m_p * g + tn0 * jnp.cos(u[0] + u[2])
        test1, tn1, _ = test(one)
        a0 = test(zero)[0]
        lift = in_g & (test1 <= 0)
        jump = lift & (c0 <= 0)  # the root is the jump at s = 0 (module docstring)
        release = in_h & (a0 != 0) & (a0 * test1 <= 0)  # also at phi = r +- pi (quirk 3)
        smooth = (lift & ~jump) | release
        s_m = _event_fraction(lambda s: test(s)[0], jnp.where(in_g, c0, a0), test1, smooth)
        s_m = jnp.where(jump, 0.0, s_m)
        # At a lift-off root T cos(q_A + q_S - pi) = m_P g, so T < 0 iff that cosine is < 0.
        cos_ev = test(jnp.where(smooth, s_m, one))[2]
        fail = in_g & jnp.where(lift, jnp.where(jump, tn0 < 0, cos_ev < 0), tn1 < 0)
        u_ev = u + s_m * (u1 - u)
        u_new = jnp.where(lift | release, u_ev, jnp.where(in_g | in_h, u1, u))

        # Released: landing at y = -h on the (linear) Euler interpolant, in closed form.
        fr = jnp.where(in_r, f, f_safe)
        fr1 = fr + dt * flight_rates(p, fr, wind)
        y0, y1 = fr[1] + p.pivot_height, fr1[1] + p.pivot_height
        land = in_r & (y0 != 0) & (y0 * y1 <= 0)
        s_r = y0 / jnp.where(land, y0 - y1, 1.0)
        fr_new = jnp.where(land, fr + s_r * (fr1 - fr), fr1)

        event = lift | release | land
        t_new = jnp.where(phase == END, t, t + jnp.where(event, jnp.where(in_r, s_r, s_m), 1) * dt)
        f_new = jnp.where(in_r, fr_new, jnp.where(fail | release, sling_state(u_new), f))
        phase_new = jnp.where(fail | land, END, jnp.where(lift, HANG, phase + release))
        carry = (
            phase_new.astype(phase.dtype),
            t_new,
            u_new,
            f_new,
            jnp.where(lift & ~fail, t_new, t_lift),
            jnp.where(release, t_new, t_rel),
            jnp.where(land, t_new, t_land),
            failed | fail,
        )
        return carry, (_snapshot(p, carry[0], t_new, u_new, f_new) if record else None)

    phase0, t0, f0 = jnp.asarray(GROUND, jnp.int32), zero, sling_state(u_rest)
    init = (phase0, t0, u_rest, f0, nan, nan, nan, jnp.asarray(False))
    # Rematerialise each step in the backward pass: recomputing it is cheaper than storing
    # its many small intermediates (reverse mode about 25 % faster on CPU, and O(carry) memory).
    final, ys = jax.lax.scan(jax.checkpoint(step), init, None, length=p.max_steps)
    phase, t, u, f, t_lift, t_rel, t_land, failed = final
    attached = (phase == GROUND) | (phase == HANG)
    distance = jnp.where(weight_lb > 0, jnp.where(attached, sling_end(p, u)[0], f[0]), f0[0])
    if not record:
        return distance
    finite = jnp.all(jnp.isfinite(u)) & jnp.all(jnp.isfinite(f)) & jnp.isfinite(t)
    release_velocity = jnp.where(jnp.isnan(t_rel), nan, sling_velocity(p, u))
    release_speed2 = jnp.sum(jnp.where(jnp.isnan(t_rel), 0.0, release_velocity) ** 2)
    _, l_s, l_w, _, l_cg = _lengths(p)
    drop = m_w * 2 * (l_s + l_w) + p.arm_mass * 2 * l_cg  # most potential energy / g to spend
    max_speed2 = 2 * g * drop / m_p
    traj = jax.tree.map(
        lambda a, b: jnp.concatenate([a[None], b]), _snapshot(p, phase0, t0, u_rest, f0), ys
    )
    return Throw(
        distance=distance,
        landed=(phase == END) & ~failed & (weight_lb > 0),
        weight_too_light=failed | (weight_lb <= 0),
        diverged=~(finite & ~(release_speed2 > max_speed2)),
        phase=phase,
        liftoff_time=t_lift,
        release_time=t_rel,
        landing_time=t_land,
        release_velocity=release_velocity,
        time=traj[0],
        arm_tip=traj[1],
        counterweight=traj[2],
        projectile=traj[3],
        phases=traj[4],
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
    ``weight_lb <= 0`` gives the rest position, as in the original. Above about 640 lb the
    result can be wrong, absurd or NaN (quirk 5; ``simulate`` reports ``diverged``). At
    ``(-2, 45, 200)`` the distance is 74.76 m and the gradient is ``(4.025, -0.9964, 0.05037)``;
    the post reports ``(4.02, -0.99, 0.051)``. With three inputs, forward mode (``jax.jacfwd``,
    as the original's ForwardDiff) costs about a third of ``jax.grad`` on a CPU.
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
