"""The plan's derivatives by implicit differentiation at the optimum (as mpc.pytorch does).

A solved plan ``u*`` minimises ``J(u; x0, theta)`` within the action box, so on its free
actions (those strictly inside the bounds) the gradient vanishes: ``g_F(u*; x0, theta) = 0``.
The implicit function theorem then gives ``du*_F = -H_FF^-1 dg_F`` for any change of the
start ``x0`` or of the problem's arrays ``theta`` (the model's parameters, the bounds' and the
terminal cost's weight), with ``H`` the Hessian of ``J`` in ``u``; an action held at a bound
stays there (``du* = 0``). ``implicit_plan`` returns ``u*`` unchanged in value and with exactly
these derivatives, in forward and reverse mode, by adding the correction
``-H_FF^-1 (g - stop_gradient(g))``, which is zero in value. The solver's own iterations are
not differentiated (its cost is one Hessian of the plan, ``H m`` reverse passes, and one linear
solve of size ``H m``), and the result does not depend on the warm start or on how many
iterations the solver took, only on the plan being a (local) optimum: where the solver stopped
short, the derivative is that of the optimum it was heading for, approximately.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float

from ._problem import Problem, stop_gradient

FREE = 1e-4
"""An action within ``FREE`` times the bounds' span of a bound counts as held there."""


def implicit_plan(problem: Problem, x0: Array, plan: Float[Array, "H m"]) -> Array:
    """``plan`` (a solved optimum of ``problem`` from ``x0``) with the derivatives of the
    implicit function theorem in ``x0`` and ``problem``'s arrays (see the module doc)."""
    plan = lax.stop_gradient(plan)
    shape, n = plan.shape, plan.size
    span = problem.high - problem.low
    free = ((plan > problem.low + FREE * span) & (plan < problem.high - FREE * span)).ravel()

    def gradient(p: Problem, x: Array) -> Array:
        return jax.grad(lambda u: p.cost(x, u.reshape(shape)))(plan.ravel())

    g = gradient(problem, x0)  # carries the derivatives in x0 and the problem
    fixed_problem, fixed_x0 = stop_gradient((problem, x0))
    hessian = jax.hessian(lambda u: fixed_problem.cost(fixed_x0, u.reshape(shape)))(plan.ravel())
    both = free[:, None] & free[None, :]
    reduced = jnp.where(both, hessian, jnp.eye(n, dtype=hessian.dtype))
    change = jnp.where(free, g - lax.stop_gradient(g), 0.0)
    return plan - jnp.linalg.solve(reduced, change).reshape(shape)
