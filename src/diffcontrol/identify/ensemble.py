"""``Ensemble``: K ``Correction`` networks fitted together, their mean as the model and their
spread as its uncertainty (Lakshminarayanan et al. 2017, "Simple and scalable predictive
uncertainty estimation using deep ensembles"; Chua et al. 2018, PETS).

The members are one ``Correction`` whose every array has a leading axis of length K, made and
called with ``eqx.filter_vmap`` (Equinox's ensembling idiom), so K networks are fitted in one
compiled program and evaluated in one call. Each member starts from its own PRNG key and, with
``bootstrap``, is fitted to its own resample (with replacement) of the recorded windows; all
share the data's input normalisation and output scale.

A hybrid or neural model whose ``correction`` is an ``Ensemble`` predicts with the members'
mean; the spread (``Ensemble.spread``) is the members' standard deviation of the predicted
state change, in units of the output scale (the typical size of what the network predicts),
as one number per input (the root mean square over the state's components). ``model_task``
adds ``penalty * spread`` to the training loss of every step, so a controller trained through
the model is kept away from where the members disagree (where there was no data).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..errors import ConfigError, ModelFileError
from .network import Correction, correction_from_dict, correction_to_dict
from .steps import task_actions

MAX_MEMBERS = 64
"""The most networks of an ensemble."""

DEFAULT_PENALTY = 1.0
"""The default weight of the spread in the training loss (loss units per output scale)."""


def check_members(members: Any, penalty: Any = DEFAULT_PENALTY) -> None:
    """Refuse a bad number of members or penalty weight (naming it and the fix).

    Raises:
        ConfigError: ``members`` not an integer in ``[1, MAX_MEMBERS]``, or ``penalty`` not a
            finite number >= 0.
    """
    if not isinstance(members, int) or isinstance(members, bool) or not 1 <= members <= MAX_MEMBERS:
        raise ConfigError(
            f"members must be a whole number of networks from 1 to {MAX_MEMBERS}, got "
            f"{members!r}; e.g. --members 5"
        )
    ok = isinstance(penalty, int | float) and not isinstance(penalty, bool)
    if not ok or not np.isfinite(penalty) or penalty < 0:
        raise ConfigError(
            f"uncertainty_penalty must be a finite number >= 0, got {penalty!r}; e.g. 1"
        )


class Ensemble(eqx.Module):
    """K networks with stacked weights: their mean is the correction, their spread its doubt.

    Attributes:
        members: a ``Correction`` whose arrays have a leading axis of length K.
        penalty: the weight of ``spread`` in the training loss through the model (``model_task``).
    """

    members: Correction
    penalty: float = eqx.field(static=True)

    def all(self, x: Float[Array, " in"]) -> Float[Array, "K out"]:
        """Every member's output at ``x``."""
        return eqx.filter_vmap(lambda c: c(x))(self.members)

    def __call__(self, x: Float[Array, " in"]) -> Float[Array, " out"]:
        """The members' mean."""
        return jnp.mean(self.all(x), axis=0)

    def spread(self, x: Float[Array, " in"]) -> Float[Array, ""]:
        """The members' standard deviation at ``x``, per component divided by the output scale,
        then the root mean square over the components (0 where the members agree)."""
        y = self.all(x) / jax.lax.stop_gradient(self.members.out_scale[0])
        variance = jnp.mean((y - jnp.mean(y, axis=0)) ** 2, axis=0)
        return jnp.sqrt(jnp.mean(variance) + 1e-12) - 1e-6  # 0, with a finite gradient, at 0

    @property
    def num_members(self) -> int:
        return int(self.members.out_scale.shape[0])

    @property
    def num_parameters(self) -> int:
        """Trainable weights and biases of all members."""
        return sum(l.weight.size + l.bias.size for l in self.members.net.layers)

    def member(self, k: int) -> Correction:
        """The ``k``-th network alone."""
        return jax.tree.map(lambda a: a[k] if eqx.is_array(a) else a, self.members)


def make_ensemble(
    key: PRNGKeyArray,
    members: int,
    in_size: int,
    out_size: int,
    hidden: Sequence[int],
    *,
    penalty: float = DEFAULT_PENALTY,
    **scalings: Any,
) -> Ensemble:
    """``members`` ``Correction`` networks, each from its own key (``jax.random.split``), made
    by one ``eqx.filter_vmap``; ``scalings`` (``in_offset``, ``in_scale``, ``out_scale``,
    ``zero_output``, ``activation``) are the same for all."""
    make = eqx.filter_vmap(lambda k: Correction(k, in_size, out_size, tuple(hidden), **scalings))
    return Ensemble(make(jax.random.split(key, members)), float(penalty))


def stack(corrections: Sequence[Correction], penalty: float = DEFAULT_PENALTY) -> Ensemble:
    """An ``Ensemble`` of networks of one shape (``ValueError`` for networks that differ)."""
    arrays = [eqx.filter(c, eqx.is_array) for c in corrections]
    shapes = {tuple(a.shape for a in jax.tree.leaves(x)) for x in arrays}
    statics = {jax.tree.structure(eqx.partition(c, eqx.is_array)[1]) for c in corrections}
    if len(shapes) != 1 or len(statics) != 1:
        raise ValueError("the members' networks differ in shape or activation")
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *arrays)
    rest = eqx.partition(corrections[0], eqx.is_array)[1]
    return Ensemble(eqx.combine(stacked, rest), float(penalty))


def bootstrap_counts(n: int, members: int, seed: int, resample: bool) -> np.ndarray:
    """[members, n]: how often each of ``n`` windows is drawn for each member (a resample with
    replacement of size ``n`` where ``resample``, otherwise 1 each)."""
    if not resample:
        return np.ones((members, n))
    rng = np.random.default_rng([seed, 1])
    return np.stack([np.bincount(rng.integers(0, n, n), minlength=n) for _ in range(members)])


def ensemble_to_dict(e: Ensemble) -> dict[str, Any]:
    """JSON-able: every member as ``correction_to_dict`` gives it, and the penalty weight."""
    return {
        "members": [correction_to_dict(e.member(k)) for k in range(e.num_members)],
        "uncertainty_penalty": e.penalty,
    }


def ensemble_from_dict(
    doc: Any, where: str = "the model file", sizes: tuple[int, int] | None = None
) -> Ensemble:
    """Rebuild an ``Ensemble`` from ``ensemble_to_dict``'s output.

    Raises:
        ModelFileError: the members are missing, malformed or of different shapes, or the
            penalty is not a finite number >= 0 (one line naming what and where).
    """
    members = doc.get("members") if isinstance(doc, dict) else None
    if not isinstance(members, list) or not 1 <= len(members) <= MAX_MEMBERS:
        raise ModelFileError(
            f"{where}: an ensemble needs 'members', a list of 1 to {MAX_MEMBERS} networks; "
            "refit the model"
        )
    penalty = doc.get("uncertainty_penalty", DEFAULT_PENALTY)
    try:
        check_members(len(members), penalty)
    except ConfigError:
        raise ModelFileError(
            f"{where}: 'uncertainty_penalty' must be a finite number >= 0, got {penalty!r}; "
            "refit the model"
        ) from None
    nets = [correction_from_dict(m, f"{where} (member {k})", sizes) for k, m in enumerate(members)]
    try:
        return stack(nets, penalty)
    except ValueError as e:
        raise ModelFileError(f"{where}: {e}; refit the model") from None


def mean_spread(task: Any, model: Any, data: Any) -> float | None:
    """The mean ``Ensemble.spread`` of a hybrid or neural ``model`` over the recorded
    transitions of ``data`` (at each recorded observation and action); ``None`` for a model
    that is not an ensemble."""
    if not isinstance(getattr(model, "correction", None), Ensemble):
        return None
    obs, actions, _ = data.transitions()
    x = np.concatenate([np.asarray(obs), np.asarray(task_actions(task, actions))], axis=1)
    return float(jnp.mean(jax.jit(jax.vmap(model.correction.spread))(jnp.asarray(x, jnp.float32))))
