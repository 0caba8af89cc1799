"""What every fit shares: the one result type, Adam under one ``lax.scan`` with divergence
kept out of the result, the Gauss-Newton standard errors and the fitting constants.

Divergence is reported, not hidden: the best parameters (or weights) seen so far are kept, a
non-finite loss stops the fit with ``diverged=True`` and a message, and no NaN is returned.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..errors import ConfigError
from ._progress import due, reporter

MIN_TRANSITIONS_PER_PARAMETER = 50
"""The fewest recorded transitions ``(y_t, u_t, y_{t+1})`` per fitted parameter."""

HORIZONS = (1, 10, 50)
"""The prediction horizons (steps) of the held-out errors."""


@dataclasses.dataclass(frozen=True)
class FitResult:
    """The outcome of ``identify.fit`` (any model type, any task).

    Attributes:
        model: what was fitted: the task's parameter PyTree (``params``), a ``HybridModel`` /
            ``NeuralModel`` of a discrete-time task, or a continuous-time task's own model.
        model_type: ``params``, ``hybrid`` or ``neural``.
        params: the physical parameters of the model (for ``params``, ``model`` itself).
        names, values, nominal, standard_errors: the fitted physical parameters by name, in
            their units (the standard error is ``inf`` where the data cannot determine one);
            empty for the network models.
        loss: the fit's loss at the returned model (in the data's units squared);
            ``nominal_loss``: the nominal model's on the same data.
        loss_history: the loss before each Adam step taken, then (with Levenberg-Marquardt)
            one entry after it where the route records one.
        diverged: a step gave a non-finite loss; the model is then the best seen before it.
        message: one line on how the fit ended.
        window, windows, transitions: the window length (steps; 1 for one-step episodes),
            how many windows and how many recorded transitions the fit used.
        num_parameters: how many numbers were fitted (weights, or parameters).
        dt_s, substeps: a continuous-time fit's recorded interval (s) and RK4 steps per
            interval (``None`` otherwise).
    """

    model: Any
    model_type: str
    params: Any
    loss: float
    nominal_loss: float
    loss_history: np.ndarray
    diverged: bool
    message: str
    window: int
    windows: int
    transitions: int
    num_parameters: int
    names: tuple[str, ...] = ()
    values: dict[str, float] = dataclasses.field(default_factory=dict)
    nominal: dict[str, float] = dataclasses.field(default_factory=dict)
    standard_errors: dict[str, float] = dataclasses.field(default_factory=dict)
    dt_s: float | None = None
    substeps: int | None = None


def check_settings(window: int = 1, steps: int = 0, learning_rate: float = 1.0, lm_steps: int = 0):
    """Refuse a bad ``window``/``steps``/``lm_steps``/``learning_rate`` (naming it).

    Raises:
        ConfigError: the first bad setting.
    """
    if not isinstance(window, int) or isinstance(window, bool) or window < 1:
        raise ConfigError(f"window must be a positive number of steps, got {window!r}")
    if not isinstance(steps, int) or steps < 0 or not isinstance(lm_steps, int) or lm_steps < 0:
        raise ConfigError(f"steps and lm_steps must be integers >= 0, got {steps!r}, {lm_steps!r}")
    if not (isinstance(learning_rate, int | float) and math.isfinite(learning_rate)):
        raise ConfigError(f"learning_rate must be a positive number, got {learning_rate!r}")
    if learning_rate <= 0:
        raise ConfigError(f"learning_rate must be a positive number, got {learning_rate!r}")


def set_params(params: Any, names: Sequence[str], values: jax.Array) -> Any:
    """``params`` with the fields ``names`` replaced by ``values`` [len(names)]."""
    return eqx.tree_at(
        lambda p: tuple(getattr(p, n) for n in names),
        params,
        tuple(values[i] for i in range(len(names))),
    )


CHUNK_STEPS = 50
"""The most Adam steps one compiled program runs: a fit of many steps runs as chunks of a
divisor of its steps (one program), so that a long one can say how far it is between them."""


def adam_fit(loss: Any, z: Any, optimiser: Any, steps: int, batch: Any, what: str = "parameters"):
    """``adam_scan``, and what every fit does with it: the best ``z`` (the last one if its loss
    is lower still, unless the run diverged), its loss, the loss history of the steps taken,
    whether it diverged, and a message if it did (naming ``what`` was kept).

    It returns ``(best_z, best_loss, history, diverged, message)``; ``message`` is ``""``
    unless the run diverged.
    """
    (last, best, best_loss, alive), (values, was_alive) = adam_scan(
        loss, z, optimiser, steps, batch
    )
    taken = int(np.sum(np.asarray(was_alive)))  # the steps run, the diverging one included
    history = [float(v) for v in np.asarray(values)[:taken]]
    best_loss, diverged, message = float(best_loss), not bool(alive), ""
    if diverged:
        message = f"Adam step {taken} gave a non-finite loss; kept the best {what} so far"
    else:
        final = float(jax.jit(loss)(last, batch))
        if math.isfinite(final) and final < best_loss:
            best, best_loss = last, final
    if not math.isfinite(best_loss):  # no step at all, or the very first diverged
        best_loss = float(jax.jit(loss)(best, batch))
    return best, best_loss, history, diverged, message


def chunk_steps(steps: int) -> int:
    """The steps of one compiled chunk: ``steps`` itself up to ``CHUNK_STEPS``, else its
    largest divisor up to ``CHUNK_STEPS``, so that every chunk is the same program."""
    if steps <= CHUNK_STEPS:
        return max(steps, 1)
    return max(d for d in range(1, CHUNK_STEPS + 1) if steps % d == 0)


def adam_scan(loss: Any, z: Any, optimiser: Any, steps: int, batch: Any):
    """``steps`` optimiser steps on ``loss(z, batch)`` under jitted ``lax.scan`` chunks.

    ``z`` is any PyTree of arrays (parameters, or a network filtered with ``eqx.filter``). A
    step whose loss or new ``z`` is non-finite freezes the run there (``alive`` turns false);
    the best ``z`` is the one with the lowest loss seen before it. The steps run in chunks of
    ``chunk_steps(steps)``, one compiled program, with the state carried between them; a fit
    inside ``_progress.reporting`` says how far it is between chunks once it has run
    ``_progress.SECONDS``.

    It returns ``(z, best_z, best_loss, alive), (losses, was_alive)``: the last and best ``z``,
    the best loss (``inf`` if no step ran), whether no step diverged, and per step the loss
    before it and whether the run was still alive then.
    """

    def finite(tree):
        return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(tree)]))

    def where(c, a, b):
        return jax.tree.map(lambda x, y: jnp.where(c, x, y), a, b)

    length = chunk_steps(steps)

    @jax.jit
    def run(carry, batch):
        def body(carry, _):
            z, opt_state, best_z, best_loss, alive = carry
            value, grad = jax.value_and_grad(loss)(z, batch)  # the loss at z, before the step
            updates, new_opt = optimiser.update(grad, opt_state, z)
            new_z = optax.apply_updates(z, updates)
            step = alive & jnp.isfinite(value) & finite(new_z)
            better = step & (value < best_loss)
            carry = (
                where(step, new_z, z),
                where(step, new_opt, opt_state),
                where(better, z, best_z),
                jnp.where(better, value, best_loss),
                step,
            )
            return carry, (value, alive)

        return jax.lax.scan(body, carry, None, length=length)

    inf = jnp.asarray(jnp.inf, jnp.result_type(float))
    carry = (z, optimiser.init(z), z, inf, jnp.asarray(True))
    progress, t0 = reporter(), time.perf_counter()
    said, values, was_alive = t0, [], []
    for done in range(length, steps + 1, length):
        carry, (value, alive) = run(carry, batch)
        values.append(value)
        was_alive.append(alive)
        if progress:  # the chunk done, not only dispatched, before the time is read
            jax.block_until_ready(carry)
        if progress and done < steps and due(said):
            said = now = time.perf_counter()
            left = (now - t0) / done * (steps - done)
            progress(
                f"Adam step {done}/{steps}: best loss {float(carry[3]):.4g} "
                f"({now - t0:.0f} s, about {left:.0f} s left)"
            )
    z, _, best_z, best_loss, alive = carry
    # the chunks' histories joined by NumPy: no program compiled for each number of chunks
    history = [
        np.concatenate([np.asarray(h) for h in hs] or [np.zeros(0)]) for hs in (values, was_alive)
    ]
    return (z, best_z, best_loss, alive), (history[0], history[1].astype(bool))


def standard_errors(residual_fn, values: jax.Array, *args: Any, size: int | None = None):
    """``sqrt(diag(sigma^2 (J^T J)^-1))`` at ``values`` (a float64 NumPy array); ``inf`` where
    ``J^T J`` is singular.

    ``residual_fn(values, *args)`` gives the residuals; with ``args`` (a fit's data) they and
    their Jacobian are computed by one compiled program that takes the data as an argument, so
    that it is shared by every data set of the same shape. ``size``: the number of residuals
    that count (default: all; fewer where the data is padded with zero residuals)."""
    if args:
        r, jac = _residuals_and_jacobian(residual_fn)(values, *args)
    else:
        r, jac = residual_fn(values), jax.jacfwd(residual_fn)(values)  # [R], [R, p]
    # The rest in NumPy (float64): a few small matrices, where JAX would compile a program
    # for each operation.
    r, jac = np.asarray(r, np.float64), np.asarray(jac, np.float64)
    dof = max((r.size if size is None else size) - values.size, 1)
    sigma2 = np.sum(r**2) / dof
    jtj = jac.T @ jac
    if not np.all(np.isfinite(jtj)):
        return np.full(values.shape, np.inf)
    eig = np.linalg.eigvalsh(jtj)
    if eig[0] <= 1e-12 * eig[-1]:
        return np.full(values.shape, np.inf)
    cov = sigma2 * np.linalg.inv(jtj)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _residuals_and_jacobian(residual_fn):
    @jax.jit
    def run(values, *args):
        return residual_fn(values, *args), jax.jacfwd(residual_fn)(values, *args)

    return run


def lm_refine(residuals: Any, loss: Any, best: Any, best_loss: float, batch: Any, steps: int):
    """Refine an Adam fit by ``steps`` Levenberg-Marquardt iterations on ``residuals`` (an
    ``optimistix`` least-squares solve, no exception on failure). Returns ``(best, best_loss,
    lm_loss)``: the refined point where it lowers ``loss``, else the Adam one; ``lm_loss`` is the
    refinement's loss (NaN or inf where it diverged)."""
    import optimistix as optx

    solution = optx.least_squares(
        residuals,
        optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12),
        best,
        args=batch,
        max_steps=steps,
        throw=False,
    )
    lm_loss = float(jax.jit(loss)(solution.value, batch))
    if math.isfinite(lm_loss) and lm_loss < best_loss:
        return solution.value, lm_loss, lm_loss
    return best, best_loss, lm_loss
