"""Box-constrained iLQR (the method of trajax's ``ilqr`` and mpc.pytorch's box-DDP).

Each iteration linearises the dynamics and takes a second-order model of the costs along the
current plan (``jax.jacfwd`` and ``jax.hessian`` of the task's own step and loss, vectorised
over the horizon), runs the Riccati-like backward pass with the action bounds handled as a
box-constrained quadratic program per step (projected Newton: the bounds that are active and
pushed against are clamped and their rows of the feedback gain are zero; Tassa, Mansard and
Todorov, "Control-limited differential dynamic programming", ICRA 2014), and then a forward
pass that tries several step sizes at once (``vmap`` over a fixed list, as trajax does) and keeps
the best plan if it lowers the cost. The regularisation ``mu`` (added to ``Q_uu``) shrinks after
an accepted step and grows after a rejected one. The iteration count is fixed, so a solve is
one jitted program.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._problem import Problem, SolveInfo

_LINE_SEARCH = (1.0, 0.5, 0.25, 0.1, 0.03, 0.01)


def _solve_pd(a: Array, b: Array) -> Array:
    """``a^-1 b`` for a small positive definite ``a`` by Gaussian elimination unrolled over its
    size: no LAPACK call, which on a CPU costs more than the arithmetic at these sizes (a few
    per step of the backward pass, every iteration). Positive definite, so no pivoting."""
    m = a.shape[0]
    vector = b.ndim == 1
    aug = jnp.concatenate([a, b[:, None] if vector else b], axis=1)
    for i in range(m):
        aug = aug.at[i].divide(aug[i, i])
        aug = aug - jnp.outer(jnp.where(jnp.arange(m) == i, 0.0, aug[:, i]), aug[i])
    out = aug[:, m:]
    return out[:, 0] if vector else out


def _box_qp(quu: Array, qu: Array, lower: Array, upper: Array, sweeps: int):
    """``argmin_du 0.5 du' Quu du + qu' du`` with ``lower <= du <= upper`` by projected Newton
    (exact for one action); returns ``du`` and the mask of free (unclamped) actions."""
    m = qu.shape[0]
    du = jnp.clip(-_solve_pd(quu, qu), lower, upper)
    free = jnp.ones(m, bool)
    for _ in range(sweeps):
        grad = quu @ du + qu
        clamped = ((du <= lower) & (grad > 0)) | ((du >= upper) & (grad < 0))
        free = ~clamped
        both = free[:, None] & free[None, :]
        h = jnp.where(both, quu, jnp.eye(m))
        rhs = jnp.where(free, qu + quu @ jnp.where(free, 0.0, du), 0.0)
        du = jnp.where(free, jnp.clip(-_solve_pd(h, rhs), lower, upper), du)
    return du, free


class ILQR(eqx.Module):
    """Box-constrained iLQR with a fixed number of iterations (a value, like a diffrax solver).

    Attributes:
        iterations: backward + forward passes per solve.
        mu: the initial regularisation of ``Q_uu`` (grows x4 after a rejected step, shrinks
            /2 after an accepted one, within ``[1e-6, 1e6]``).
        tol: a solve counts as converged when its last iteration lowered the cost by less
            than ``tol`` times the cost.
        qp_sweeps: projected-Newton sweeps of the box QP per step (1 is exact for one action).
    """

    iterations: int = eqx.field(static=True, default=10)
    mu: float = 1e-3
    tol: float = 1e-4
    qp_sweeps: int = eqx.field(static=True, default=2)

    def solve(self, problem: Problem, x0: Array, actions: Float[Array, "H m"]):
        """Improve the plan ``actions`` from ``x0``; returns ``(plan, SolveInfo)``."""
        # An action exactly at a bound has a tie in the model's clip (half a derivative in JAX):
        # keep plans a hair inside.
        span = problem.high - problem.low
        low, high = problem.low + 1e-6 * span, problem.high - 1e-6 * span
        actions = jnp.clip(actions, low, high).astype(jnp.result_type(actions, x0))
        states, cost = problem.rollout(x0, actions)
        d = x0.shape[0]

        def joint_cost(z):
            return problem.running_cost(z[:d], z[d:])

        def iteration(carry, _):
            us, xs, cost, mu = carry
            a, b = jax.vmap(jax.jacfwd(problem.dynamics, (0, 1)))(xs[:-1], us)
            z = jnp.concatenate([xs[:-1], us], axis=1)
            g = jax.vmap(jax.grad(joint_cost))(z)
            h = jax.vmap(jax.hessian(joint_cost))(z)
            vx = jax.grad(problem.final_cost)(xs[-1])
            vxx = jax.hessian(problem.final_cost)(xs[-1])

            def backward(v, k):
                vx, vxx = v
                ak, bk, gk, hk, uk = a[k], b[k], g[k], h[k], us[k]
                qx = gk[:d] + ak.T @ vx
                qu = gk[d:] + bk.T @ vx
                qxx = hk[:d, :d] + ak.T @ vxx @ ak
                qux = hk[d:, :d] + bk.T @ vxx @ ak
                quu = hk[d:, d:] + bk.T @ vxx @ bk
                # Positive definite whatever the local model: shift by Gershgorin's lower bound
                # on the eigenvalues where it is not positive (exact for one action), add mu.
                quu = 0.5 * (quu + quu.T)
                eye = jnp.eye(quu.shape[0])
                radius = jnp.abs(quu).sum(1) - jnp.abs(jnp.diag(quu))
                lowest = jnp.min(jnp.diag(quu) - radius)
                quu = quu + (jnp.maximum(1e-8 - lowest, 0.0) + mu) * eye
                du, free = _box_qp(quu, qu, low - uk, high - uk, self.qp_sweeps)
                both = free[:, None] & free[None, :]
                hf = jnp.where(both, quu, eye)
                gain = jnp.where(free[:, None], -_solve_pd(hf, qux), 0.0)
                vx = qx + gain.T @ quu @ du + gain.T @ qu + qux.T @ du
                vxx = qxx + gain.T @ quu @ gain + gain.T @ qux + qux.T @ gain
                return (vx, 0.5 * (vxx + vxx.T)), (du, gain)

            steps = jnp.arange(us.shape[0])
            _, (ks, gains) = jax.lax.scan(backward, (vx, vxx), steps, reverse=True)

            def forward(alpha):
                def one(x, inputs):
                    xk, uk, kk, gk = inputs
                    u = jnp.clip(uk + alpha * kk + gk @ (x - xk), low, high)
                    nxt, reward, _ = problem.task.step(problem.params, x, u)
                    return nxt, (nxt, u, problem.step_loss(problem.params, x, u, nxt, reward))

                last, (new_xs, new_us, costs) = jax.lax.scan(one, x0, (xs[:-1], us, ks, gains))
                new_cost = costs.sum() + problem.final_cost(last)
                new_xs = jnp.concatenate([x0[None], new_xs])
                return new_us, new_xs, jnp.where(jnp.isfinite(new_cost), new_cost, jnp.inf)

            cand_us, cand_xs, cand_cost = jax.vmap(forward)(jnp.asarray(_LINE_SEARCH))
            best = jnp.argmin(cand_cost)
            accept = cand_cost[best] < cost
            new = jax.tree.map(
                lambda c, old: jnp.where(accept, c[best], old),
                (cand_us, cand_xs, cand_cost),
                (us, xs, cost),
            )
            mu = jnp.clip(jnp.where(accept, mu / 2, mu * 4), 1e-6, 1e6)
            return (*new, mu), cost - new[2]

        init = (actions, states, cost, jnp.asarray(self.mu, cost.dtype))
        (us, _, final, _), gains = jax.lax.scan(iteration, init, None, length=self.iterations)
        last = gains[-1]
        return us, SolveInfo.of(us, cost, final, last, self.tol)
