"""Cart-pole swing-up as a neural ODE: the second seed post (Paul Shen, 2020), and variants.

The controller ``F = NN(cos theta, sin theta, theta_dot)`` sits inside the right-hand side of
the cart-pole ODE (``builtin.swingup.system``); the closed loop is solved from
the pole hanging down with an adaptive solver, saved at ``saves`` equally spaced times, and a
loss on that saved trajectory is differentiated through the solve
(``../shared/reference/seed-systems.md`` §7).

Built-in losses (``theta`` wrapped to ``[-pi, pi)``, sums over the ``N`` saves, ``_N`` the last):

- ``swingup``: ``sum(theta^2)/N + 4 theta_N^2 + x_dot_N^2``, the post's (no force penalty).
- ``limited``: the above ``+ 0.1 sum(x^2)/N + 0.001 max(F^2)``, the post's "motor can't give
  60 N" variant over 10 s, where the controller should pump energy like a child on a swing.
- ``limited_hold``: ``limited + theta_dot_N^2``: also arrive at rest. The post's ``limited``
  does not ask for ``theta_dot = 0`` at the end, and its low-force (pumping) solutions can
  reach the top just at t = 10 s still turning.
- ``energy``: the swing-up loss ``+ ENERGY_WEIGHT * E_N``, with ``E`` the energy dissipated
  by friction, integrated as a state of the ODE (the post's "add a friction term and tag on a
  frictional power integral").

A loss is any function of a ``SwingUpTrajectory``; pass your own to
``diffcontrol.train(task, config, trajectory_loss=...)``.

The force ``F`` the losses see is the controller's output at each save (exact). The post read
it back from the impulse state, ``(I_k - I_{k-1}) / dt``, the mean force over the interval;
``SwingUpTrajectory.impulse_force`` gives that (with the right spacing; the post's code divided
by ``1/N`` instead of ``1/(N-1)``, 2 % off).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

import diffcontrol.builtin.swingup.system as cp

from ...config import ODETrainConfig
from ...errors import ConfigError
from ...settings import PlanConfig
from ...tasks import ContinuousTask, TrajectoryLoss

POST_NETWORK = dict(hidden=(8,), grad_clip=0.0, population=1, window_s=0.0)
"""The post's training (a 3-8-1 network, unclipped Adam, the whole horizon differentiated in
each update), which the swing-ups' defaults and figures are: not ``ODETrainConfig``'s own
defaults, which are for a task of the user's."""

ENERGY_WEIGHT = 0.1
"""Weight of the dissipated energy (per joule) in the ``energy`` loss."""


class SwingUpTrajectory(eqx.Module):
    """A saved closed-loop trajectory of the swing-up, what every swing-up loss sees.

    All fields have one value per save (shape ``[N]``): time (s), cart position (m) and
    velocity (m/s), pole angle wrapped to ``[-pi, pi)`` with 0 upright (rad) and its rate
    (rad/s), the controller's force (N), the impulse ``integral F dt`` (N s), and the energy
    dissipated by friction so far (J).
    """

    t: Float[Array, " N"]
    x: Float[Array, " N"]
    x_dot: Float[Array, " N"]
    theta: Float[Array, " N"]
    theta_dot: Float[Array, " N"]
    force: Float[Array, " N"]
    impulse: Float[Array, " N"]
    dissipated_energy: Float[Array, " N"]

    @property
    def impulse_force(self) -> Float[Array, " N"]:
        """The post's read-back: ``(I_k - I_{k-1}) / (t_k - t_{k-1})``, the first copied."""
        f = jnp.diff(self.impulse) / jnp.diff(self.t)
        return jnp.concatenate([f[:1], f])


def swingup_loss(tr: SwingUpTrajectory) -> Array:
    """The post's loss: ``sum(theta^2)/N + 4 theta_N^2 + x_dot_N^2``."""
    n = tr.theta.shape[0]
    return jnp.sum(tr.theta**2) / n + 4 * tr.theta[-1] ** 2 + tr.x_dot[-1] ** 2


def limited_loss(tr: SwingUpTrajectory) -> Array:
    """The post's actuator-limited loss: ``swingup + 0.1 sum(x^2)/N + 0.001 max(F^2)``."""
    n = tr.x.shape[0]
    return swingup_loss(tr) + 0.1 * jnp.sum(tr.x**2) / n + 0.001 * jnp.max(tr.force**2)


def limited_hold_loss(tr: SwingUpTrajectory) -> Array:
    """The actuator-limited loss plus ``theta_dot_N^2``: end upright *and* at rest."""
    return limited_loss(tr) + tr.theta_dot[-1] ** 2


def energy_loss(tr: SwingUpTrajectory) -> Array:
    """The swing-up loss plus ``ENERGY_WEIGHT`` times the energy lost to friction (J)."""
    return swingup_loss(tr) + ENERGY_WEIGHT * tr.dissipated_energy[-1]


# --- planning (``mpc.discretise``): the limited_hold loss as a running and an end cost ------

PLAN_ANGLE_WEIGHT = 1.0
"""Weight of ``2 (1 - cos theta)`` per second in the planning cost."""
PLAN_POSITION_WEIGHT = 0.1
"""Weight of ``x^2`` per second (the loss's ``0.1 sum(x^2)/N``)."""
PLAN_FORCE_WEIGHT = 0.01
"""Weight of ``F^2`` (N^2) per second (the loss's peak-force term; the bound caps the peak)."""
PLAN_ENERGY_WEIGHT = 10.0
"""Weight of the end cost's squared energy gap, relative to the upright energy."""
PLAN_END_WEIGHT = 0.1
"""Weight of the loss's own end terms in the end cost of a plan (see ``limited_hold_end``)."""


def limited_hold_rate(params: cp.SwingUpParams, y: Array, force: Array) -> Array:
    """The cost per second of the planning ``limited_hold`` loss.

    ``2 (1 - cos theta)`` is the smooth counterpart of the wrapped ``theta^2`` (equal to
    within ``theta^4 / 12``, and with no kink at the hanging position where the wrap flips
    sign, which the planner's second-order model would see); plus ``0.1 x^2`` and a small
    ``F^2`` standing in for the peak-force penalty (a maximum is not additive over time; the
    planner's action bounds cap the peak instead).
    """
    del params
    f = jnp.reshape(force, ())
    return (
        PLAN_ANGLE_WEIGHT * 2 * (1 - jnp.cos(y[2]))
        + PLAN_POSITION_WEIGHT * y[0] ** 2
        + PLAN_FORCE_WEIGHT * f**2
    )


def limited_hold_end(params: cp.SwingUpParams, y: Array) -> Array:
    """The end cost of a plan: the pole's energy gap, and the loss's end terms, weakly.

    ``PLAN_ENERGY_WEIGHT ((E_p - E_up) / E_up)^2`` with the pole's energy about its pivot
    ``E_p = m L^2 theta_dot^2 / 2 + m g L (1 + cos theta)`` and ``E_up = 2 m g L`` (upright at
    rest): energy shaping, which tells a plan much shorter than the pump (2 s of a 7 s pump)
    that more energy is the way up, and is zero upright at rest. Plus ``PLAN_END_WEIGHT``
    times the loss's end terms ``4 * 2 (1 - cos theta) + x_dot^2 + theta_dot^2`` (the angle
    smoothed). Those have a small weight because a plan ends at any phase of the pump: at
    full weight, ``theta_dot^2`` at the bottom of a swing (``4 g / L`` with the upright
    energy) outweighs the energy gap, and the planner stops pumping.
    """
    p = params
    mgl = p.pole_mass * p.g * p.length
    e_pole = 0.5 * p.pole_mass * p.length**2 * y[3] ** 2 + mgl * (1 + jnp.cos(y[2]))
    gap = (e_pole - 2 * mgl) / (2 * mgl)
    end_terms = 8 * (1 - jnp.cos(y[2])) + y[1] ** 2 + y[3] ** 2
    return PLAN_ENERGY_WEIGHT * gap**2 + PLAN_END_WEIGHT * end_terms


def energy_rate(params: cp.SwingUpParams, y: Array, force: Array) -> Array:
    """The cost per second of the planning ``energy`` loss: ``PLAN_ANGLE_WEIGHT`` times
    ``2 (1 - cos theta)``, the smooth wrapped ``theta^2`` (as in ``limited_hold_rate``). The
    loss has no force term and neither has its plan: the action bound caps the force.

    The weight per second is 1, three times the loss's own ``sum(theta^2) / N`` over the
    friction swing-up's 3 s: a plan sees 2 s ahead and meets its end terms at its own end, not
    the task's, and the heavier weight swings up sooner (docs/planning.md).
    """
    del params, force
    return PLAN_ANGLE_WEIGHT * 2 * (1 - jnp.cos(y[2]))


def energy_end(params: cp.SwingUpParams, y: Array) -> Array:
    """The end cost of a plan for ``energy``: the loss's own end terms ``4 theta^2 +
    x_dot^2`` (the angle smoothed) and ``ENERGY_WEIGHT`` times the energy dissipated so far
    (the ODE's last state: within a plan only its increase counts, the friction's work)."""
    del params
    return 8 * (1 - jnp.cos(y[2])) + y[1] ** 2 + ENERGY_WEIGHT * y[5]


PLANNING_COSTS = {
    "limited_hold": (limited_hold_rate, limited_hold_end),
    "energy": (energy_rate, energy_end),
}
"""The planning losses of the swing-ups by name: (cost per second, end cost of a plan)."""

LOSSES: dict[str, TrajectoryLoss] = {
    "swingup": swingup_loss,
    "limited": limited_loss,
    "limited_hold": limited_hold_loss,
    "energy": energy_loss,
}


STATE_COLUMNS = ("state.x [m]", "state.x_dot [m/s]", "state.theta [rad]", "state.theta_dot [rad/s]")
"""The recorded state of the swing-up cart-pole (theta = 0 upright, not wrapped)."""
ACTION_COLUMNS = ("action.force [N]",)
"""The recorded force on the cart, held over each interval."""


class CartPoleSwingUp(ContinuousTask):
    """Swing the post's cart-pole up from hanging down in 1 s, and stop (the post's loss)."""

    name = "cartpole-swingup"
    # Not for the chunk: either option changes its bits; level 1 also changes the limited and
    # friction swing-ups' evaluations (each class declares its own).
    fast_compile = {"evaluate": ("xla_cpu_use_fusion_emitters",)}
    # its one controller unbatched: the same weights to the bit in its defaults and the
    # original recipe, not in the limited swing-up's original recipe (each class its own)
    one_member_unbatched = True
    env_name = "CartPoleSwingUp"
    summary = "neural-ODE cart-pole swing-up of the 2020 post: 1 s, unbounded force"
    observation_size = 3
    action_size = 1
    action_head = "linear"
    losses: tuple[str, ...] = ("swingup", "limited", "limited_hold", "energy")
    state_names = cp.STATE_NAMES
    feature_names = ("cos(theta)", "sin(theta)", "theta_dot")
    state_labels = (
        "cart position x (m)",
        "cart velocity ẋ (m/s)",
        "pole angle θ (rad, 0 = up)",
        "pole rate θ̇ (rad/s)",
    )
    action_labels = ("force (N)",)
    positive_params = ("pole_mass", "cart_mass", "length", "coulomb_speed", "coulomb_rate")
    nonnegative_params = ("cart_viscous", "cart_coulomb", "pole_viscous", "pole_coulomb")

    def default_params(self) -> cp.SwingUpParams:
        return cp.SwingUpParams()

    def initial_state(self, params):
        return cp.initial_state(params)

    def vector_field(self, t, y, args):
        return cp.vector_field(t, y, args)

    def observe(self, state):
        return jnp.stack([jnp.cos(state[2]), jnp.sin(state[2]), state[3]])

    def trajectory(self, params, controller, ts, ys) -> SwingUpTrajectory:
        force = jax.vmap(lambda y: controller(self.observe(y[:4]))[0])(ys)
        return SwingUpTrajectory(
            t=ts,
            x=ys[:, 0],
            x_dot=ys[:, 1],
            theta=cp.wrap_angle(ys[:, 2]),
            theta_dot=ys[:, 3],
            force=force,
            impulse=ys[:, 4],
            dissipated_energy=ys[:, 5],
        )

    def trajectory_loss(self, name: str) -> TrajectoryLoss:
        return LOSSES[name]

    planning_losses: tuple[str, ...] = ("limited_hold", "energy")

    def running_cost(self, name: str):
        """``limited_hold_rate`` and ``energy_rate`` (the planning forms of those losses)."""
        if name not in PLANNING_COSTS:
            raise ConfigError(f"task {self.name!r} has no planning loss {name!r} (running_cost)")
        return PLANNING_COSTS[name][0]

    def terminal_cost(self, name: str):
        """``limited_hold_end`` (the pole's energy gap and the loss's end terms) and
        ``energy_end`` (the loss's end terms and the dissipated energy)."""
        return PLANNING_COSTS[name][1] if name in PLANNING_COSTS else None

    def default_plan_config(self):
        """The planner of the actuator-limited swing-up (docs/planning.md): the force held for
        0.05 s, 40 of them planned (2 s), 5 box-iLQR iterations from the warm start and both
        bounds. No force bound: this 1 s task's force is not limited (pass ``action_bound``)."""
        return PlanConfig(horizon=40, iterations=5, dt=0.05)

    def default_config(self) -> ODETrainConfig:
        # The post's recipe (Tsit5 at reltol 1e-3 / abstol 1e-6, 50 saves, 3-8-1 tanh net with
        # Glorot init, Adam 0.05) with 1000 updates, as in the post's text (the repository ran
        # 1500: the ``original`` recipe).
        return ODETrainConfig(
            horizon_s=1.0, saves=50, updates=1000, learning_rate=0.05, **POST_NETWORK
        )

    # --- a run is judged by a reference solve and drawn as a cart-pole (builtin.swingup) ---

    default_eval_episodes = 1  # one reference solve
    final_eval_skippable = False  # the reference solve is what a run reports and draws

    # --- learning a model from data (``diffcontrol.identify``; ``builtin.swingup``) ----------

    fit_parameter_names = ("cart_viscous", "cart_coulomb", "pole_viscous", "pole_coulomb")
    """The grey box fits the friction coefficients (the nominal model is frictionless)."""

    def data_columns(self):
        return STATE_COLUMNS, ACTION_COLUMNS

    def data_file_name(self, env_id=None):
        return f"{self.name}-state.csv"

    def recipes(self) -> dict[str, dict[str, Any]]:
        # The repository's sciml_train(loss, p0, ADAM(0.05), maxiters = 1500); last weights kept.
        return {"original": dict(updates=1500, population=1, keep_best=False)}


class CartPoleSwingUpLimited(CartPoleSwingUp):
    """The post's actuator-limited variant: 10 s, with a penalty on the peak force.

    The default loss is ``limited_hold`` (the post's ``limited`` plus ``theta_dot_N^2``); the
    post's own is ``--loss limited``. Eight controllers train side by side (``population``)
    and the best by loss is kept: from a single start the cart often never moves (the post's
    caveat) or the pumping ends off the top. 3000 updates with a cosine-decayed rate settle
    the end state that the constant rate leaves swinging.
    """

    name = "cartpole-swingup-limited"
    fast_compile = {"evaluate": ("xla_cpu_use_fusion_emitters",)}
    env_name = "CartPoleSwingUpLimited"
    summary = "the post's 'motor can't give 60 N' swing-up: 10 s, x and peak-force penalties"
    losses = ("limited_hold", "limited", "swingup", "energy")

    def default_config(self) -> ODETrainConfig:
        return ODETrainConfig(
            **{**POST_NETWORK, "population": 8},
            horizon_s=10.0,
            saves=50,
            updates=3000,
            learning_rate=0.05,
            lr_schedule="cosine",
        )

    def default_plan_config(self):
        """The swing-up's planner with the force within 5 N, below the trained controller's
        peak force (docs/planning.md)."""
        return super().default_plan_config().replace(action_bound=5.0)

    def recipes(self) -> dict[str, dict[str, Any]]:
        # The post's loss, one controller, constant Adam(0.05), the last weights.
        return {
            "original": dict(
                loss="limited", updates=1000, population=1, lr_schedule="constant", keep_best=False
            )
        }


class CartPoleSwingUpFriction(CartPoleSwingUp):
    """Swing-up with friction on the cart and the pole, paying for the energy it dissipates.

    Friction: viscous 1 N s/m and Coulomb 0.5 N on the cart, viscous 0.1 N m s/rad in the
    joint. The horizon is 3 s: within the post's 1 s there is no slower, cheaper way up, so
    an energy term has nothing to trade.
    """

    name = "cartpole-swingup-friction"
    fast_compile = {"evaluate": ("xla_cpu_use_fusion_emitters",)}
    env_name = "CartPoleSwingUpFriction"
    summary = "3 s swing-up with cart and joint friction; the loss adds the dissipated energy"
    losses = ("energy", "swingup", "limited", "limited_hold")

    def default_params(self) -> cp.SwingUpParams:
        return cp.SwingUpParams(cart_viscous=1.0, cart_coulomb=0.5, pole_viscous=0.1)

    def default_plan_config(self):
        """The planner of the task's own loss, ``energy`` (named, so that a saved planner
        without a loss name still reads as ``limited_hold``): the force within 40 N and 10
        box-iLQR iterations per step, the swing-ups' 0.05 s and 2 s otherwise."""
        return (
            super().default_plan_config().replace(loss="energy", action_bound=40.0, iterations=10)
        )

    def default_config(self) -> ODETrainConfig:
        return ODETrainConfig(
            **{**POST_NETWORK, "population": 4},
            horizon_s=3.0,
            saves=50,
            updates=1000,
            learning_rate=0.05,
        )
