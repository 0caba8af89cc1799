"""The trebuchet's three phases as scans, and the location of their events.

The integrator behind ``system`` (whose docstring has the physics and the event
semantics). Each phase is one ``lax.scan`` of explicit-Euler steps whose body computes only
that phase's rates and the sign test of its event at the step's end. Once the test fires, the
scan holds the state at the start of that step, and every later step recomputes the same step
(the same compiled operations on the same state give the same bits). After the scan the event
is located once, inside that step (``locate_liftoff``, ``locate_release``), by the root finding
and implicit-function derivative that a single scan over all phases would have to run on
every step. The landing is located in the flight scan itself, in closed form.

Each decision is taken once and carried: the scans carry their event tests' outcomes to the
location code, which does not test them again. The same expression can round differently in
different compiled contexts (vectorised or not, in a loop or unrolled, fused one way or
another), so a value near 0 could pass a test in one place and fail it in another. For the
same reason the root finder accepts a Newton step that leaves its bracket by rounding: once
converged, the sign of the test is noise, and bisecting on it, as the original does, would
move a converged root.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.ad_checkpoint import checkpoint_name

from ._eom import flight_rates, ground_rates, hang_rates, sling_velocity

NEWTON_ITERS = 4
"""Newton iterations from the regula-falsi point; the 5th (differentiable) one reaches
rounding."""

# Rematerialise each step in the backward pass, except for the event tests' outcomes:
# recomputing a step is cheaper than storing its many small intermediates, and memory stays
# O(carry). Saving the outcomes spares the backward pass the tests.
_REMAT = jax.checkpoint_policies.save_only_these_names("event")


def event_fraction(fn, args, f_lo, f_hi, active):
    """The ``s`` in ``(0, 1]`` where ``fn(s, args) = 0``, given ``fn(0+) = f_lo`` and
    ``fn(1) = f_hi`` of opposite signs (meaningful where ``active``).

    Safeguarded Newton from the regula-falsi point, without gradient; then one Newton step
    whose gradient is the implicit-function derivative ``ds/dp = -(dfn/dp) / (dfn/ds)``. The
    search is a ``fori_loop`` on ``args`` without gradient, so XLA compiles one iteration.
    """
    f_lo = jax.lax.stop_gradient(jnp.where(active, f_lo, 1.0))
    f_hi = jax.lax.stop_gradient(jnp.where(active, f_hi, -1.0))
    values = jax.tree.map(jax.lax.stop_gradient, args)

    # A Newton step may leave the bracket by rounding once converged; see the module docstring.
    slack = 16 * jnp.finfo(f_lo.dtype).eps

    def newton(_, search):
        s, lo, hi = search
        v, d = jax.jvp(lambda s: fn(s, values), (s,), (jnp.ones_like(s),))
        beyond = (v > 0) == (f_lo > 0)  # the root lies beyond s
        lo, hi = jnp.where(beyond, s, lo), jnp.where(beyond, hi, s)
        step = jnp.where(v == 0, s, s - v / jnp.where(d != 0, d, 1.0))
        inside = (d != 0) & (step >= lo - slack) & (step <= hi + slack)
        return jnp.where(inside, step, (lo + hi) / 2), lo, hi

    lo, hi = jnp.zeros_like(f_lo), jnp.ones_like(f_lo)
    s, _, _ = jax.lax.fori_loop(0, NEWTON_ITERS, newton, (f_lo / (f_lo - f_hi), lo, hi))
    s = jnp.where(active & jnp.isfinite(s), s, 1.0)
    # The last step, with gradient: fn's value carries it, its slope does not.
    value = fn(s, args)
    slope = jax.jvp(lambda s: fn(s, values), (s,), (jnp.ones_like(s),))[1]
    slope = jnp.where(active & (slope != 0), slope, 1.0)
    return jnp.clip(s - jnp.where(active, value, 0.0) / slope, 0.0, 1.0)


def liftoff_test(p, u, u1, vx0, s):
    """``(m_P g - T cos(q_A + q_S - pi), T, cos(q_A + q_S - pi))`` at ``u(s)`` of the step
    ``u -> u1``, with ``T`` from the finite difference of ``v_x`` since its start (``vx0``)."""
    us = u + s * (u1 - u)
    v = sling_velocity(p, us)
    sin_a, cos_a = -jnp.sin(us[0] + us[2]), -jnp.cos(us[0] + us[2])
    tension = -p.projectile_mass * (v[0] - vx0) / (jnp.where(s > 0, s, 1.0) * p.dt) / sin_a
    return p.projectile_mass * p.gravity - tension * cos_a, tension, cos_a


def aim(p, u, r):
    """The release test ``|v| sin(phi - r)``, ``v`` the sling end's velocity at angle ``phi``."""
    v = sling_velocity(p, u)
    return v[1] * jnp.cos(r) - v[0] * jnp.sin(r)


def _mechanism_scan(p, rates, event, n, t, u, running, length, record):
    """Explicit Euler of the mechanism for up to ``length`` steps (and ``p.max_steps`` in all)
    from the state ``u`` after ``n`` steps at time ``t`` (if ``running``), up to the step
    whose end ``event(u, u1)`` flags; ``event`` returns ``(fires, outcome)``.

    Returns ``(n, t, u, u1, hit, outcome, ys)``: the steps taken before that step, the time
    and state at its start (or after the last step), its end, whether the event came and its
    ``outcome``. With ``record``, ``ys`` has the time and state after each step (the first
    ``n`` are the phase's); else None.
    """

    def step(carry, _):
        n, t, u, _, running, hit, _ = carry
        u1 = u + p.dt * rates(u)
        fires, outcome = checkpoint_name(event(u, u1), "event")
        active = running & (n < p.max_steps)
        advance = active & ~fires
        t = jnp.where(advance, t + p.dt, t)
        u = jnp.where(advance, u1, u)  # held at the event step's start
        carry = (n + advance, t, u, u1, running & ~fires, hit | (active & fires), outcome)
        return carry, ((t, u) if record else None)

    init = (n, t, u, u, running, jnp.asarray(False), jnp.asarray(False))
    carry, ys = jax.lax.scan(jax.checkpoint(step, policy=_REMAT), init, None, length=length)
    n, t, u, u1, _, hit, outcome = carry
    return n, t, u, u1, hit, outcome, ys


def ground_scan(p, m_w, u, length, record):
    """The ground phase from the rest state ``u``, up to the step where the lift-off test or
    the slack-sling test (``T < 0``) fires; its ``outcome`` is whether the lift-off test did.
    See ``_mechanism_scan``."""

    def event(u, u1):
        test1, tension1, _ = liftoff_test(p, u, u1, sling_velocity(p, u)[0], 1.0)
        return (test1 <= 0) | (tension1 < 0), test1 <= 0

    n0, t0 = jnp.asarray(0, jnp.int32), jnp.zeros((), u.dtype)
    rates = lambda u: ground_rates(p, u, m_w)  # noqa: E731
    return _mechanism_scan(p, rates, event, n0, t0, u, jnp.asarray(True), length, record)


def hang_scan(p, m_w, r, n, t, u, running, length, record):
    """The hang phase from lift-off, up to the step over which ``sin(phi - r)`` changes sign
    (also at ``phi = r +- pi``, quirk 3). See ``_mechanism_scan``."""

    def event(u, u1):
        a0, a1 = aim(p, u, r), aim(p, u + (u1 - u), r)
        fires = (a0 != 0) & (a0 * a1 <= 0)
        return fires, fires

    rates = lambda u: hang_rates(p, u, m_w)  # noqa: E731
    return _mechanism_scan(p, rates, event, n, t, u, running, length, record)


def locate_liftoff(p, u, u1, hit, lifts):
    """Locate the ground event in the step ``u -> u1`` that ``ground_scan`` stopped at (``hit``;
    ``lifts`` is its outcome).

    Returns ``(s, lift, fail)``: the fraction of the step, whether the projectile lifted off,
    and whether the sling went slack (``T < 0``: the weight is too light), at lift-off or
    without it.
    """
    zero, one = jnp.zeros((), u.dtype), jnp.ones((), u.dtype)
    m_p, g, dt = p.projectile_mass, p.gravity, p.dt
    args = (p, u, u1, sling_velocity(p, u)[0])

    def test(s, args=args):
        return liftoff_test(*args, s)

    # The lift-off test's right limit at s = 0+: the tension from the slope of v_x (only
    # compared with 0, so without gradient).
    q, v, v1, _ = jax.tree.map(jax.lax.stop_gradient, args)
    dvx0 = jax.jvp(lambda s: sling_velocity(q, v + s * (v1 - v))[0], (zero,), (one,))[1]
    tn0 = m_p * dvx0 / dt / jnp.sin(v[0] + v[2])
    c0 = m_p * g + tn0 * jnp.cos(v[0] + v[2])
    lift = hit & lifts
    jump = lift & (c0 <= 0)  # the root is the jump at s = 0 (module docstring)
    smooth = lift & ~jump
    s = event_fraction(lambda s, args: test(s, args)[0], args, c0, test(one)[0], smooth)
    s = jnp.where(jump, 0.0, s)
    # At a lift-off root T cos(q_A + q_S - pi) = m_P g, so T < 0 iff that cosine is < 0.
    # Without lift-off the scan stopped because T < 0 at the step's end.
    cos_ev = test(jnp.where(smooth, s, one))[2]
    fail = hit & (~lift | jnp.where(jump, tn0 < 0, cos_ev < 0))
    return s, lift, fail


def locate_release(p, u, u1, r, hit):
    """The fraction of the step ``u -> u1`` where the projectile is released, for a step that
    ``hang_scan`` stopped at (``hit``)."""
    zero, one = jnp.zeros((), u.dtype), jnp.ones((), u.dtype)

    def test(s, args=(p, u, u1, r)):
        p, u, u1, r = args
        return aim(p, u + s * (u1 - u), r)

    return event_fraction(test, (p, u, u1, r), test(zero), test(one), hit)


def flight_scan(p, wind, n, t, f, running, length, record):
    """Explicit Euler of the released projectile ``f = (x, y, v_x, v_y)`` after ``n`` steps at
    time ``t`` (if ``running``) until it lands at ``y = -h``, located on the step's linear
    interpolant in closed form, or its budget (or ``p.max_steps`` in all) is spent.

    Returns ``(n, t, f, landed, ys)``; with ``record``, ``ys`` has the time, state and whether
    it had landed after each step; else None.
    """

    def step(carry, _):
        n, t, f, running, landed = carry
        f1 = f + p.dt * flight_rates(p, f, wind)
        y0, y1 = f[1] + p.pivot_height, f1[1] + p.pivot_height
        land = checkpoint_name((y0 != 0) & (y0 * y1 <= 0), "event")
        s = y0 / jnp.where(land, y0 - y1, 1.0)
        active = running & (n < p.max_steps)
        t = jnp.where(active, t + jnp.where(land, s, 1) * p.dt, t)
        f = jnp.where(active, jnp.where(land, f + s * (f1 - f), f1), f)
        landed = landed | (active & land)
        carry = (n + active, t, f, running & ~land, landed)
        return carry, ((t, f, landed) if record else None)

    init = (n, t, f, running, jnp.asarray(False))
    carry, ys = jax.lax.scan(jax.checkpoint(step, policy=_REMAT), init, None, length=length)
    n, t, f, _, landed = carry
    return n, t, f, landed, ys
