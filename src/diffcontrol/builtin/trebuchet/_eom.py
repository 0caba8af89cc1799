"""The trebuchet's constants, geometry and equations of motion (``system``'s physics).

The rates of the three phases as Trebuchet.jl writes them (``shared/reference/seed-systems.md``
section 2), in SI units: the state ``u = (q_A, q_W, q_S, w_A, w_W, w_S)`` of the mechanism and
``(x, y, v_x, v_y)`` of the released projectile. The throw itself (phases, events, the scans)
lives in ``systems/trebuchet.py``, which re-exports everything public here.
"""

from __future__ import annotations

import math
import numbers

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ...errors import ConfigError

FT = 0.3048
"""Metres per foot (the original's ``ft2m``)."""
LB = 0.45359237
"""Kilograms per pound (the original's ``lb2kg``)."""


class TrebuchetParams(eqx.Module):
    """Constants of Trebuchet.jl's trebuchet, in SI units (converted from its imperial values).

    The counterweight, the wind and the release angle are inputs of ``shoot``, not parameters.
    Every float field is a PyTree leaf (``vmap``pable, differentiable); the step budgets are
    static (they set the scans' lengths).

    The throw runs as three scans, one a phase: at most ``ground_steps`` steps of ``dt`` on
    the ground, ``hang_steps`` on the sling, and ``max_steps`` in all. A throw that runs out
    of a budget reports ``landed=False``. The defaults cover sweeps in float32 over winds of
    -20 to 20 m/s, angles of 0.05-90 degrees and 21-600 lb: from 25 lb up, lift-off takes at
    most 44 steps, release at most 47 more, and the slowest throw 452 in all. So every throw
    with ``|wind| <= 20`` m/s and 25-600 lb lands within the default budgets, as in the
    original.
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
    wind_factor: float = 1.0
    """How strongly the wind acts on the flight: the air moves at ``wind_factor * wind``
    (the drag is relative to it). 1 is the original; a "real" trebuchet whose site has
    gustier or stronger wind than the anemometer reads has more (``fit_throws``)."""
    dt: float = 1.0 / 60.0
    """Explicit-Euler step (s): the original's ``rate = 60``."""
    max_steps: int = eqx.field(static=True, default=600)
    """Most steps of ``dt`` in a whole throw (10 s at the default ``dt``), and ``simulate``'s
    per-step arrays have ``max_steps + 1`` rows. The flight's scan has ``max_steps - 2``
    steps (a throw spends at least one on the ground and one on the sling), so that the flight
    gets every step the earlier phases leave, as in the original."""
    ground_steps: int = eqx.field(static=True, default=45)
    """Most steps on the ground, lift-off (or the slack sling) included (0.75 s)."""
    hang_steps: int = eqx.field(static=True, default=50)
    """Most steps on the sling after lift-off, release included (0.83 s)."""
    swap_inertias: bool = eqx.field(static=True, default=True)
    """Keep the original's swap of the arm and counterweight inertias (quirk 1)."""

    def __check_init__(self):
        budgets = {
            "max_steps": self.max_steps,
            "ground_steps": self.ground_steps,
            "hang_steps": self.hang_steps,
        }
        for name, value in budgets.items():
            if not isinstance(value, numbers.Integral) or value < 1:
                raise ConfigError(f"TrebuchetParams.{name} must be a positive int, got {value!r}")

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


def lengths(p: TrebuchetParams):
    """``(L_l, L_s, L_w, L_S, L_cg)`` (m), ``L_cg = (L_l - L_s) / 2`` the arm's CG offset."""
    return (
        p.long_arm,
        p.short_arm,
        p.weight_arm,
        p.sling_length,
        (p.long_arm - p.short_arm) / 2,
    )


def ground_rates(
    p: TrebuchetParams, u: Float[Array, 6], m_w: ArrayLike, valid: ArrayLike = True
) -> Float[Array, 6]:
    """``du/dt`` while the projectile slides on the ground; ``m_w`` is the counterweight (kg).

    Singular where ``sin(q_A + q_S) = 0`` (a vertical sling), which the ground phase never
    reaches. Where ``valid`` is false that sine is replaced by 1: finite garbage with finite
    gradients, for a branch that a ``jnp.where`` discards (the "double where").
    """
    q_a, q_w, q_s, w_a, w_w, w_s = u
    (i1, i2), (l_l, l_s, l_w, l_sl, l_cg) = p.inertias, lengths(p)
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
    (i1, i2), (l_l, l_s, l_w, l_sl, l_cg) = p.inertias, lengths(p)
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
    rel_x, v_y = f[2] - p.wind_factor * wind, f[3]
    speed2 = rel_x**2 + v_y**2
    # Double where: sqrt has an infinite slope at 0 (the projectile moving with the air).
    speed = jnp.where(speed2 > 0, jnp.sqrt(jnp.where(speed2 > 0, speed2, 1.0)), 0.0)
    k = p.drag_constant
    return jnp.stack([f[2], v_y, -k * rel_x * speed, -p.gravity - k * v_y * speed])
