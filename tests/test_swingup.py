"""Continuous-time control: the swing-up cart-pole as a neural ODE.

References and tolerances:

- The vector field against SciPy's ``solve_ivp`` (DOP853, rtol = atol = 1e-11) of independent
  NumPy formulations: the post's closed-form equations without friction, and the Lagrangian
  mass-matrix form ``M(q) q'' = rhs`` (solved numerically) with friction. Both in float64; the
  Diffrax solve (dopri8, 1e-11) agrees to 1e-7, four orders above both solvers' errors, so a
  wrong sign or a dropped term (O(1) differences within a second) cannot pass.
- Gradients in float64 at rtol = atol = 1e-10 against central finite differences
  (eps = 1e-6) along random weight directions: the discretised solve is smooth in the
  weights except where the adaptive controller changes its step sequence, which perturbs the
  loss by about the tolerance (1e-10) and FD by 1e-10 / 1e-6 = 1e-4 relative at worst; we ask
  for 1e-4 (checkpoint, forward) and 1e-3 (backsolve, whose gradient is approximate). The two
  discretise-then-optimise methods differentiate the same program: they agree to 1e-9.
"""

from __future__ import annotations

import json
import re

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import diffcontrol
from diffcontrol import rollout
from diffcontrol.builtin.swingup import system as cp
from diffcontrol.builtin.swingup.judge import swingup_result
from diffcontrol.builtin.swingup.task import POST_NETWORK, SwingUpTrajectory
from diffcontrol.cli import main
from diffcontrol.config import ODETrainConfig
from diffcontrol.errors import ConfigError, SolverFailed
from diffcontrol.evaluation import simulate_continuous
from diffcontrol.training import make_ode_trainer, train

from .conftest import TINY_SWINGUP

SWINGUP = diffcontrol.make("cartpole-swingup")


class OpenLoop(eqx.Module):
    """A smooth open-loop force ``F(t) = a sin(w t) + b`` (N), as a PyTree."""

    a: float = 8.0
    w: float = 3.0
    b: float = 1.5

    def __call__(self, t, state):
        return self.a * jnp.sin(self.w * t) + self.b


def _force(t):
    f = OpenLoop()
    return f.a * np.sin(f.w * t) + f.b


def _post_rhs(t, u, force=None):
    """The post's closed-form equations (no friction), NumPy; the force ``force(t, u)``
    (default: the open-loop ``_force(t)``)."""
    m, M, L, g = 1.0, 2.0, 1.0, 9.8
    x, dx, th, dth = u
    F = _force(t) if force is None else force(t, u)
    D = M + m * np.sin(th) ** 2
    ddx = (F + m * np.sin(th) * (L * dth**2 - g * np.cos(th))) / D
    ddth = (
        -F * np.cos(th) - m * L * dth**2 * np.sin(th) * np.cos(th) + (M + m) * g * np.sin(th)
    ) / (L * D)
    return [dx, ddx, dth, ddth]


def _lagrange_rhs(p):
    """Mass-matrix form of the same system with friction, solved numerically (NumPy)."""

    def rhs(t, u):
        x, dx, th, dth, _, _ = u
        F = _force(t)
        Fc = -p.cart_viscous * dx - p.cart_coulomb * np.tanh(dx / p.coulomb_speed)
        tau = -p.pole_viscous * dth - p.pole_coulomb * np.tanh(dth / p.coulomb_rate)
        m, M, L, g = p.pole_mass, p.cart_mass, p.length, p.g
        mass = np.array([[M + m, m * L * np.cos(th)], [m * L * np.cos(th), m * L**2]])
        force = np.array([F + Fc + m * L * dth**2 * np.sin(th), m * g * L * np.sin(th) + tau])
        ddx, ddth = np.linalg.solve(mass, force)
        return [dx, ddx, dth, ddth, F, -(Fc * dx + tau * dth)]

    return rhs


def _diffrax_solve(params, y0, ts, force_fn=None):
    with jax.enable_x64(True):
        sol = rollout.solve_closed_loop(
            cp.vector_field,
            jnp.asarray(y0, jnp.float64),
            jnp.asarray(ts, jnp.float64),
            (jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), params), force_fn or OpenLoop()),
            solver="dopri8",
            rtol=1e-11,
            atol=1e-11,
            max_steps=100_000,
        )
        assert bool(sol.ok)
        return np.asarray(sol.ys)


def test_vector_field_matches_the_posts_equations_against_scipy():
    ts = np.linspace(0.0, 2.0, 41)
    y0 = [0.1, -0.3, 2.5, 0.7]
    ref = solve_ivp(_post_rhs, (0, 2), y0, method="DOP853", t_eval=ts, rtol=1e-11, atol=1e-11)
    ys = _diffrax_solve(cp.SwingUpParams(), [*y0, 0.0, 0.0], ts)
    np.testing.assert_allclose(ys[:, :4], ref.y.T, atol=1e-7)
    assert np.max(np.abs(ys[:, :4] - ys[0, :4])) > 1.0  # it really moved
    np.testing.assert_array_equal(ys[:, 5], 0.0)  # no friction, nothing dissipated


def test_friction_matches_the_mass_matrix_form_against_scipy():
    params = cp.SwingUpParams(
        cart_viscous=1.3, cart_coulomb=0.7, pole_viscous=0.2, pole_coulomb=0.1
    )
    ts = np.linspace(0.0, 2.0, 41)
    y0 = [0.0, 0.5, 2.0, -1.0, 0.0, 0.0]
    ref = solve_ivp(
        _lagrange_rhs(params), (0, 2), y0, method="DOP853", t_eval=ts, rtol=1e-11, atol=1e-11
    )
    ys = _diffrax_solve(params, y0, ts)
    np.testing.assert_allclose(ys, ref.y.T, atol=1e-7)
    assert ys[-1, 5] > 0.1  # friction dissipated energy


@pytest.mark.parametrize("friction", [False, True])
def test_energy_balance(friction):
    """Without force: energy is conserved, or lost exactly as the dissipated-energy integral."""
    params = (
        cp.SwingUpParams(cart_viscous=1.0, pole_viscous=0.3) if friction else cp.SwingUpParams()
    )
    ts = np.linspace(0.0, 3.0, 31)
    ys = _diffrax_solve(params, [0.0, 1.0, 1.0, 0.0, 0.0, 0.0], ts, OpenLoop(a=0.0, b=0.0))
    with jax.enable_x64(True):
        e = np.asarray(cp.energy(params, jnp.asarray(ys)))
    np.testing.assert_allclose(e + ys[:, 5], e[0], atol=1e-8)
    assert (ys[-1, 5] > 1.0) == friction


# --- gradients ---------------------------------------------------------------------------------


def _loss_and_weights(gradient: str):
    """A float64 closed-loop loss of a 3-8-1 controller's layers, at tight tolerances."""
    cfg = ODETrainConfig(
        horizon_s=0.6, saves=13, rtol=1e-10, atol=1e-10, gradient=gradient, **POST_NETWORK
    )
    trainer = make_ode_trainer(SWINGUP, cfg)
    params = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), SWINGUP.default_params())
    ctrl = jax.tree.map(
        lambda x: jnp.asarray(x, jnp.float64), trainer.new_controller(jax.random.PRNGKey(3))
    )
    spec = jax.tree.map(lambda _: False, ctrl)
    spec = eqx.tree_at(lambda c: c.layers, spec, replace=jax.tree.map(lambda _: True, ctrl.layers))
    diff, static = eqx.partition(ctrl, spec)

    def loss(diff):
        value, (ok, _, _) = trainer.member_loss(eqx.combine(diff, static), params, jnp.asarray(0.6))
        return value, ok

    return loss, diff


@pytest.fixture(scope="module")
def reference_gradient():
    with jax.enable_x64(True):
        loss, diff = _loss_and_weights("checkpoint")
        (value, ok), grad = eqx.filter_jit(rollout.value_and_grad(loss, "checkpoint"))(diff)
        assert bool(ok)
        flat, unravel = jax.flatten_util.ravel_pytree(grad)
        # Central finite differences along 3 random unit directions of the 41 weights.
        rng = np.random.default_rng(0)
        f = jax.jit(lambda d: loss(d)[0])
        x0, unravel_x = jax.flatten_util.ravel_pytree(diff)
        dirs = rng.normal(size=(3, x0.size))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        fd = []
        for d in dirs:
            plus = f(unravel_x(x0 + 1e-6 * d))
            minus = f(unravel_x(x0 - 1e-6 * d))
            fd.append(float(plus - minus) / 2e-6)
        return np.asarray(flat), dirs, np.asarray(fd), float(value)


@pytest.mark.parametrize(
    ("gradient", "rtol_fd"), [("checkpoint", 1e-4), ("forward", 1e-4), ("backsolve", 1e-3)]
)
@pytest.mark.slow
def test_gradient_methods_against_finite_differences(gradient, rtol_fd, reference_gradient):
    ref_flat, dirs, fd, ref_value = reference_gradient
    with jax.enable_x64(True):
        loss, diff = _loss_and_weights(gradient)
        (value, ok), grad = eqx.filter_jit(rollout.value_and_grad(loss, gradient))(diff)
        flat = np.asarray(jax.flatten_util.ravel_pytree(grad)[0])
    assert bool(ok) and abs(float(value) - ref_value) < 1e-12
    directional = dirs @ flat
    scale = np.linalg.norm(flat)
    assert scale > 1.0  # the loss really depends on the weights
    np.testing.assert_allclose(directional, fd, rtol=0, atol=rtol_fd * scale)
    if gradient == "forward":  # the same discretised program as checkpoint
        np.testing.assert_allclose(flat, ref_flat, rtol=0, atol=1e-9 * scale)
    if gradient == "backsolve":  # approximate, but close
        np.testing.assert_allclose(flat, ref_flat, rtol=0, atol=1e-3 * scale)


# --- losses, trajectories and the policy file -------------------------------------------------


@pytest.mark.slow
def test_force_read_back_matches_the_controller(swingup_run):
    """The impulse state's read-back is the mean force over each interval (the trapezoid of
    the controller's own output, to O(dt^2)), and the saved force is the NumPy policy's."""
    policy = diffcontrol.load(swingup_run)
    data = json.loads((swingup_run / "data.json").read_text())
    force = np.asarray(data["force"])
    state = np.stack([data["x"], data["x_dot"], data["theta"], data["theta_dot"]], axis=-1)
    np.testing.assert_allclose(policy(state), force, rtol=1e-5, atol=1e-4)
    names = ("t", "x", "x_dot", "theta", "theta_dot", "force", "impulse", "dissipated_energy")
    with jax.enable_x64(True):
        tr = SwingUpTrajectory(*(jnp.asarray(data[k], jnp.float64) for k in names))
        read_back = np.asarray(tr.impulse_force)[1:]
    trapezoid = (force[1:] + force[:-1]) / 2
    peak = np.max(np.abs(force))
    assert peak > 1.0
    # The trapezoid's error is dt^2 |F''| / 12 per interval; F'' dt^2 ~ the second difference.
    bound = np.max(np.abs(np.diff(force, 2))) / 12
    np.testing.assert_allclose(read_back, trapezoid, atol=2 * bound + 1e-6 * peak)
    assert np.max(np.abs(read_back - trapezoid)) > 0  # a read-back, not a copy of the force
    assert isinstance(policy(state[0]), float)


@pytest.mark.slow
def test_state_policy_resimulated_by_scipy_matches(swingup_run):
    """Anyone can re-simulate model.json with their own integrator: SciPy + the NumPy policy
    + the post's equations reproduce the reference solve."""
    policy = diffcontrol.load(swingup_run)
    data = json.loads((swingup_run / "data.json").read_text())
    t = np.asarray(data["t"])

    def rhs(t_, u):
        return _post_rhs(t_, u, lambda _, state: policy(np.asarray(state)))

    ref = solve_ivp(
        rhs, (0, t[-1]), [0, 0, np.pi, 0], method="DOP853", t_eval=t, rtol=1e-10, atol=1e-10
    )
    theta = (ref.y[2] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(ref.y[0], data["x"], atol=1e-4)
    np.testing.assert_allclose(np.cos(theta), np.cos(data["theta"]), atol=1e-4)


@pytest.mark.slow
def test_custom_loss_from_python_changes_what_is_learned():
    """A user's trajectory loss replaces the task's: here, drive the cart to x = 1 m."""
    cfg = SWINGUP.default_config().replace(updates=100)
    result = train(
        SWINGUP,
        cfg,
        trajectory_loss=lambda tr: (tr.x[-1] - 1.0) ** 2 + 1e-3 * jnp.mean(tr.force**2),
    )
    rec = simulate_continuous(SWINGUP, result.controller, result.params)
    assert abs(rec.y[-1, 0] - 1.0) < 0.2


def test_loss_that_is_not_a_scalar_is_refused():
    with pytest.raises(ConfigError, match="scalar"):
        make_ode_trainer(SWINGUP, SWINGUP.default_config(), lambda tr: tr.theta**2)


@pytest.mark.slow
def test_loss_that_is_nan_is_refused_before_training():
    cfg = SWINGUP.default_config().replace(updates=10, eval_every=10)
    with pytest.raises(ConfigError, match="finite number"):
        train(SWINGUP, cfg, trajectory_loss=lambda tr: jnp.sum(tr.theta) * jnp.nan)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (dict(horizon_s=0.0), "horizon_s"),
        (dict(horizon_s=-1.0), "horizon_s"),
        (dict(rtol=0.0), "rtol"),
        (dict(atol=-1e-6), "atol"),
        (dict(rtol=float("nan")), "rtol"),
        (dict(saves=1), "saves"),
        (dict(max_steps=0), "max_steps"),
        (dict(population=0), "population"),
        (dict(solver="euler"), "solver"),
        (dict(gradient="adjoint"), "gradient"),
        (dict(curriculum_start=0.0), "curriculum_start"),
        (dict(curriculum_fraction=1.5), "curriculum_fraction"),
    ],
)
def test_bad_settings_name_the_value(change, match):
    with pytest.raises(ConfigError, match=match):
        SWINGUP.default_config().replace(**change)


@pytest.mark.slow
def test_solver_step_limit_is_a_clear_error_not_a_nan():
    """A budget the untrained loop fits in (6 steps) but the trained one does not (about 11):
    the member is frozen when its solve fails, and the run stops with the fix named."""
    cfg = SWINGUP.default_config().replace(max_steps=8, updates=400)
    with pytest.raises(SolverFailed, match="max_steps=8") as exc:
        train(SWINGUP, cfg)
    message = str(exc.value)
    assert "raise --max-steps" in message
    failed_at = int(re.search(r"update (\d+):", message).group(1))
    assert failed_at > 1  # it trained for a while before the loop outgrew the budget


@pytest.mark.slow
def test_step_limit_on_the_untrained_controller_is_refused_at_once():
    with pytest.raises(ConfigError, match="max-steps"):
        train(SWINGUP, SWINGUP.default_config().replace(max_steps=2, updates=10))


# --- learning ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_swingup_defaults_meet_the_bar():
    """The post's recipe: upright (|wrap theta| < 0.1 rad) and |x_dot| < 0.5 m/s at t = 1 s, in
    the float64 reference solve, after the default 1000 updates."""
    result = train(SWINGUP, SWINGUP.default_config())
    report = swingup_result(simulate_continuous(SWINGUP, result.controller, result.params))
    assert abs(report.final_theta) < 0.1, report.summary()
    assert abs(report.final_x_dot) < 0.5, report.summary()
    assert report.peak_force > 20  # it needs a hard push to swing up in 1 s
    assert result.metrics["num_parameters"] == 41
    assert result.metrics["simulated_episodes"] == 1000


@pytest.mark.slow
def test_population_and_curriculum():
    """Three members from different weights under vmap, with a horizon growing from 0.5 s: the
    curve shows the horizon grow, and the returned controller is the best member's."""
    cfg = SWINGUP.default_config().replace(population=3, curriculum_start=0.5, updates=200)
    result = train(SWINGUP, cfg)
    horizons = [p["horizon_s"] for p in result.curve]
    assert horizons[0] == pytest.approx(0.5) and horizons[-1] == pytest.approx(1.0)
    assert all(b >= a for a, b in zip(horizons, horizons[1:]))
    assert result.metrics["simulated_episodes"] == 600
    chosen = result.curve[
        [p["update"] for p in result.curve].index(result.metrics["returned_update"])
    ]
    rec = simulate_continuous(SWINGUP, result.controller, result.params)
    # The reference solve is more accurate than training's (rtol 1e-3): close, not equal.
    assert rec.loss == pytest.approx(chosen["eval_loss"], rel=0.05)
    assert chosen["eval_loss"] == min(p["eval_loss"] for p in result.curve)


@pytest.mark.slow
def test_resume_continues_exactly(tmp_path):
    cfg = SWINGUP.default_config().replace(updates=150)
    whole = train(SWINGUP, cfg)
    calls = []

    def interrupt(line):
        calls.append(line)
        if len(calls) == 3:  # points at 0, 50, 100: the checkpoint at 50 exists
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(SWINGUP, cfg, out_dir=tmp_path / "run", progress=interrupt)
    resumed = train(SWINGUP, cfg, out_dir=tmp_path / "run", resume=True)
    for a, b in zip(
        jax.tree.leaves(whole.controller), jax.tree.leaves(resumed.controller), strict=True
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert [p["update"] for p in resumed.curve] == [0, 50, 100, 150]


# --- the command line ----------------------------------------------------------------------------


@pytest.mark.slow
def test_cli_writes_the_posts_outputs(swingup_run):
    for name in (
        "model.json",
        "data.json",
        "metrics.json",
        "swingup.png",
        "learning_curve.png",
        "rollout.gif",
    ):
        assert (swingup_run / name).stat().st_size > 0, name
    model = json.loads((swingup_run / "model.json").read_text())
    assert model["observation"]["state"] == ["x", "x_dot", "theta", "theta_dot"]
    assert model["observation"]["features"] == ["cos(theta)", "sin(theta)", "theta_dot"]
    data = json.loads((swingup_run / "data.json").read_text())
    assert len(data["t"]) == 101 and data["t"][-1] == pytest.approx(1.0)
    assert all(len(data[k]) == 101 for k in ("x", "x_dot", "theta", "theta_dot", "force"))
    metrics = json.loads((swingup_run / "metrics.json").read_text())
    assert metrics["swingup"]["peak_force"] == pytest.approx(max(abs(f) for f in data["force"]))
    assert isinstance(diffcontrol.load(swingup_run), diffcontrol.policies.StatePolicy)


@pytest.mark.slow
def test_cli_evaluate_and_animate(swingup_run, tmp_path, capsys):
    assert main(["evaluate", str(swingup_run), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    metrics = json.loads((swingup_run / "metrics.json").read_text())
    assert report["final_theta"] == pytest.approx(metrics["swingup"]["final_theta"], abs=1e-9)
    assert main(["animate", str(swingup_run), "--out", str(tmp_path / "a.gif")]) == 0
    assert (tmp_path / "a.gif").stat().st_size > 1000


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--horizon-s", "0"], "> 0"),
        (["--rtol=-1e-3"], "tolerance"),
        (["--atol", "nan"], "tolerance"),
        (["--solver", "euler"], "solver"),
        (["--gradient", "adjoint"], "gradient"),
        (["--window", "5"], "does not apply"),
        (["--loss", "nope"], "unknown loss"),
        (["--max-steps", "2"], "max-steps"),
    ],
)
@pytest.mark.slow
def test_cli_bad_input_is_one_line_and_exit_2(args, match, tmp_path, capsys):
    out = tmp_path / "run"
    try:
        code = main(
            ["train", "cartpole-swingup", "--out", str(out), "--quiet", *TINY_SWINGUP, *args]
        )
    except SystemExit as e:  # argparse's own type checks exit from inside
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert match in err and len(err.splitlines()) == 1, err


# --- the Gymnasium environments ------------------------------------------------------------------


@pytest.mark.parametrize(
    "name", ["CartPoleSwingUp", "CartPoleSwingUpLimited", "CartPoleSwingUpFriction"]
)
def test_swingup_environments_pass_check_env(name):
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(f"diffcontrol/{name}-v0")
    check_env(env.unwrapped, skip_render_check=True)
    task = env.unwrapped.task
    assert env.spec.max_episode_steps == task.default_config().saves - 1


@pytest.mark.slow
def test_swingup_environment_equals_the_differentiable_closed_loop():
    """With a constant force the held action and the controller inside the ODE are the same
    input, so the environment's episode must reproduce the differentiable solve: the same
    final state (to the solvers' tolerances) and a return of exactly minus the same loss."""
    force = 7.5
    cfg = SWINGUP.default_config().replace(rtol=1e-7, atol=1e-9)
    trainer = make_ode_trainer(SWINGUP, cfg)
    ctrl = trainer.new_controller(jax.random.PRNGKey(0))
    zeroed = [
        eqx.tree_at(lambda l: (l.weight, l.bias), l, (l.weight * 0, l.bias * 0))
        for l in ctrl.layers
    ]
    zeroed[-1] = eqx.tree_at(lambda l: l.bias, zeroed[-1], jnp.full((1,), force))
    ctrl = eqx.tree_at(lambda c: c.layers, ctrl, tuple(zeroed))
    params = SWINGUP.default_params()
    loss, _ = jax.jit(trainer.member_loss)(ctrl, params, jnp.asarray(cfg.horizon_s))
    sol = trainer.solve(ctrl, params, jnp.asarray(cfg.horizon_s), "checkpoint")

    env = gymnasium.make("diffcontrol/CartPoleSwingUp-v0")
    env.reset(seed=0)
    total, steps, done = 0.0, 0, False
    while not done:
        _, reward, terminated, truncated, info = env.step(np.array([force], np.float32))
        total, steps, done = total + reward, steps + 1, terminated or truncated
    assert steps == cfg.saves - 1
    np.testing.assert_allclose(info["state"], np.asarray(sol.ys[-1, :4]), rtol=1e-4, atol=1e-4)
    assert total == pytest.approx(-float(loss), rel=1e-4)
    assert abs(info["state"][0]) > 1.0  # the push really moved the cart


@pytest.mark.slow
@pytest.mark.parametrize("gradient", ["backsolve", "forward"])
def test_cli_trains_with_each_gradient_method(gradient, tmp_path, capsys):
    """The trainer runs every gradient method end to end (under vmap and scan), and the
    continuous adjoint's approximation is said out loud."""
    out = tmp_path / gradient
    args = ["--updates", "20", "--eval-every", "10", "--gradient", gradient, "--no-animation"]
    assert main(["train", "cartpole-swingup", "--out", str(out), "--quiet", *args]) == 0
    err = capsys.readouterr().err
    assert ("approximate" in err) == (gradient == "backsolve")
    curve = json.loads((out / "metrics.json").read_text())["curve"]
    assert curve[-1]["eval_loss"] < curve[0]["eval_loss"]  # 20 updates already help


@pytest.mark.slow
def test_one_member_unbatched_trains_the_same_weights():
    """The swing-up differentiates its one controller outside ``vmap``
    (``one_member_unbatched``): faster to compile, and the weights of the batched programs to
    rounding, which a subclass keeps unless it declares its own (the limited swing-up's
    original recipe rounds differently unbatched, so it does not). On the newest releases the
    pins allow the two agree to the bit (docs/benchmarks.md); JAX 0.8's unbatched program
    rounds differently (3e-6 after three updates), and 50 updates of a swing-up grow that to
    1e-2, so three updates are compared, to 5e-5."""
    from diffcontrol.builtin.swingup.fitted import FittedSwingUp, nominal_model
    from diffcontrol.training._ode import unbatched_member

    task = diffcontrol.make("cartpole-swingup")

    class Batched(type(task)):
        one_member_unbatched = False

    assert unbatched_member(task) and not unbatched_member(Batched())
    for name in ("cartpole-swingup-limited", "cartpole-swingup-friction"):
        assert not unbatched_member(diffcontrol.make(name))
    assert not unbatched_member(FittedSwingUp(task, nominal_model(task.default_params())))
    config = task.default_config().replace(updates=3)
    batched, unbatched = (train(t, config).controller for t in (Batched(), task))
    for x, y in zip(jax.tree.leaves(batched), jax.tree.leaves(unbatched), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=0, atol=5e-5)
