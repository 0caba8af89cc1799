"""The trebuchet (``diffcontrol.builtin.trebuchet.system``): the post's gradient, gradients against
finite differences, ``vmap``, physics sanity checks and input validation.

Tolerances, and why:

- The post's gradient ``(4.02, -0.99, 0.051)`` at ``(-2 m/s, 45 deg, 200 lb)``: within 2 % per
  component (``RTOL_BLOG``). The post prints 2-3 digits. Its ForwardDiff pass went through
  Roots.jl's iterations where ours uses the implicit-function derivative, and ours comes out
  0.1 %, 0.6 % and 1.2 % off. Float32 must agree with float64 to ``RTOL_F32 = 1e-4``.
- Finite differences (float64): central, with step ``h_i = 1e-5 max(1, |x_i|)`` (smaller steps
  amplify the distance's ~1e-10 m of rounding noise). Over ``SPREAD`` they agree with the
  gradient to 1e-7 relative; ``RTOL_FD = 1e-5`` (plus ``ATOL_FD = 1e-6`` per unit) leaves a
  margin of 100. Dropping the sensitivity of the lift-off and release times changes the
  gradient by 25 % to 100x. The points avoid the non-smooth points of the module docstring,
  and for each one the test checks that no event moves to another step across the stencil.
- Forward mode (``jacfwd``) and reverse mode (``grad``) compute the same derivative:
  ``RTOL_MODES = 1e-9``.
- ``vmap`` against a Python loop of the same jitted scalar function: ``1e-12`` relative
  (float64; only the order of operations may differ).
- Energy: the equations of motion with high-accuracy SciPy ``solve_ivp`` (``rtol = 1e-11``)
  conserve ``T + V``, with the original's swapped inertias, to ``1e-9`` of the peak kinetic
  energy. Euler at ``dt = 1/60`` is part of the model, so it is not held to this.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from diffcontrol.builtin.trebuchet import system as tb
from diffcontrol.errors import ConfigError

BLOG_POINT = (-2.0, 45.0, 200.0)
BLOG_GRADIENT = np.array([4.02, -0.99, 0.051])
RTOL_BLOG = 0.02
RTOL_F32 = 1e-4
DISTANCE_AT_BLOG_POINT = 74.758  # ours (float64); the post gives no distance for this throw
RTOL_FD, ATOL_FD, REL_STEP_FD = 1e-5, 1e-6, 1e-5
RTOL_MODES = 1e-9
BATCH = 64  # every batched call is padded to this, so one compiled program serves them all

# (wind m/s, angle deg, weight lb): a spread of winds, angles and weights, all landing forward.
SPREAD = [
    (-2.0, 45.0, 200.0),
    (0.0, 30.0, 200.0),
    (5.0, 30.0, 150.0),
    (-5.0, 60.0, 300.0),
    (3.0, 20.0, 120.0),
    (-10.0, 35.0, 250.0),
    (8.0, 70.0, 180.0),
    (0.0, 5.0, 200.0),
    (12.0, 80.0, 400.0),
    (-15.0, 15.0, 60.0),
]

# Module-level jitted functions, shared by the tests (compilation dominates the run time).
# Scalars go in as Python floats (weakly typed), so that every call hits the same trace.
_shoot_jit = jax.jit(tb.shoot)
_grad_jit = jax.jit(jax.grad(tb.shoot, argnums=(0, 1, 2)))
_jacfwd_jit = jax.jit(jax.jacfwd(tb.shoot, argnums=(0, 1, 2)))
_shoot_batch = jax.jit(jax.vmap(tb.shoot, in_axes=(0, 0, 0, None)))
_simulate_jit = jax.jit(tb.simulate)
DEFAULT = tb.TrebuchetParams()


def _shoot(wind, angle, weight):
    return float(_shoot_jit(float(wind), float(angle), float(weight), DEFAULT))


def _grad(wind, angle, weight):
    return np.array(
        [float(g) for g in _grad_jit(float(wind), float(angle), float(weight), DEFAULT)]
    )


def _jacfwd(wind, angle, weight):
    return np.array(
        [float(g) for g in _jacfwd_jit(float(wind), float(angle), float(weight), DEFAULT)]
    )


def _simulate(wind, angle, weight, params=DEFAULT):
    return _simulate_jit(float(wind), float(angle), float(weight), params)


def _distances(wind, angle, weight, params=None):
    """``shoot`` over a batch (NumPy in, NumPy out), padded to ``BATCH`` for one compile."""
    w, a, m = (np.atleast_1d(np.asarray(v, float)) for v in (wind, angle, weight))
    w, a, m = np.broadcast_arrays(w, a, m)
    n = w.size
    assert n <= BATCH
    pad = [np.concatenate([v, np.full(BATCH - n, fill)]) for v, fill in zip((w, a, m), BLOG_POINT)]
    return np.asarray(_shoot_batch(*pad, params or DEFAULT))[:n]


@pytest.fixture
def x64():
    with jax.enable_x64(True):
        yield


# --- the post's gradient ------------------------------------------------------------------------


@pytest.mark.slow
def test_blog_gradient_float64(x64):
    distance, grad = _shoot(*BLOG_POINT), _grad(*BLOG_POINT)
    print(f"\n(-2, 45, 200) float64: distance {distance:.4f} m, gradient {grad}")
    np.testing.assert_allclose(grad, BLOG_GRADIENT, rtol=RTOL_BLOG)
    assert distance == pytest.approx(DISTANCE_AT_BLOG_POINT, abs=1e-3)


@pytest.mark.slow
def test_blog_gradient_float32_matches_float64():
    assert _shoot_jit(*BLOG_POINT, DEFAULT).dtype == jnp.float32
    distance, grad = _shoot(*BLOG_POINT), _grad(*BLOG_POINT)
    print(f"\n(-2, 45, 200) float32: distance {distance:.4f} m, gradient {grad}")
    np.testing.assert_allclose(grad, BLOG_GRADIENT, rtol=RTOL_BLOG)
    with jax.enable_x64(True):
        grad64 = _grad(*BLOG_POINT)
    np.testing.assert_allclose(grad, grad64, rtol=RTOL_F32)
    assert distance == pytest.approx(DISTANCE_AT_BLOG_POINT, rel=RTOL_F32)


@pytest.mark.slow
def test_tutorial_anchors(x64):
    """The JuliaAcademy notebook's figures for 200 lb without wind: 1 m/s of tail wind adds
    about 4 m at 45 degrees, and the best angle is about 30 degrees for about 90 m."""
    d0, d1 = _distances([0.0, 1.0], 45.0, 200.0)
    assert 3.5 < d1 - d0 < 4.5
    angles = np.arange(15.0, 46.0, 1.0)
    d = _distances(0.0, angles, 200.0)
    assert 25 <= angles[np.argmax(d)] <= 35
    assert 85 < d.max() < 95


# --- gradients ----------------------------------------------------------------------------------


def _phase_lengths(throw):
    return np.bincount(np.asarray(throw.phases), minlength=4)


@pytest.fixture(scope="module")
def spread():
    """Reverse- and forward-mode gradients and central differences over ``SPREAD`` (float64),
    and whether each point's events stay in the same steps across its FD stencil."""
    with jax.enable_x64(True):
        x = np.array(SPREAD)
        rev = np.array([_grad(*point) for point in x])
        fwd = np.array([_jacfwd(*point) for point in x])
        h = REL_STEP_FD * np.maximum(1.0, np.abs(x))
        plus = (x[:, None, :] + np.eye(3)[None] * h[:, None, :]).reshape(-1, 3)
        minus = (x[:, None, :] - np.eye(3)[None] * h[:, None, :]).reshape(-1, 3)
        values = _distances(*np.concatenate([plus, minus]).T)
        fd = (values[: plus.shape[0]] - values[plus.shape[0] :]).reshape(x.shape) / (2 * h)
        throws = [_simulate(*point) for point in x]
        same_steps = [
            all(
                np.array_equal(_phase_lengths(_simulate(*q)), _phase_lengths(throws[i]))
                for q in np.concatenate([plus[3 * i : 3 * i + 3], minus[3 * i : 3 * i + 3]])
            )
            for i in range(len(x))
        ]
    return dict(x=x, rev=rev, fwd=fwd, fd=fd, throws=throws, same_steps=same_steps)


@pytest.mark.slow
def test_gradients_match_finite_differences(spread):
    for i, point in enumerate(spread["x"]):
        throw = spread["throws"][i]
        assert bool(throw.landed) and float(throw.distance) > 0, point  # lands, forward
        assert spread["same_steps"][i], point  # smooth across the FD stencil
        np.testing.assert_allclose(
            spread["rev"][i], spread["fd"][i], rtol=RTOL_FD, atol=ATOL_FD, err_msg=str(point)
        )


@pytest.mark.slow
def test_forward_and_reverse_mode_agree(spread):
    np.testing.assert_allclose(spread["fwd"], spread["rev"], rtol=RTOL_MODES, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize(
    "point",
    [
        (0.0, 90.0, 200.0),  # the fold of asin(sin r)
        (0.0, 0.0, 200.0),  # release on either zero of sin(phi - r)
        (0.0, -30.0, 200.0),  # let go backwards (quirk 3)
        (0.0, 45.0, 1000.0),  # past what Euler can follow: let go backwards (quirk 5)
        (0.0, 45.0, 10.0),  # weight too light
        (0.0, 45.0, 0.0),  # no weight: the rest position
        (0.0, 45.0, -5.0),
        (25.0, 45.0, 200.0),  # strong tail wind
        (-25.0, 45.0, 200.0),  # strong head wind
    ],
)
def test_gradients_are_finite_everywhere(x64, point):
    grad = _grad(*point)
    assert np.all(np.isfinite(grad)), (point, grad)
    assert np.isfinite(_shoot(*point))


# --- vmap ---------------------------------------------------------------------------------------


@pytest.mark.slow
def test_vmap_matches_python_loop(x64):
    x = np.array(SPREAD)
    batched = _distances(*x.T)
    looped = np.array([_shoot(*point) for point in x])
    np.testing.assert_allclose(batched, looped, rtol=1e-12)


def test_shoot_broadcasts_and_simulate_vmaps():
    shape = jax.eval_shape(tb.shoot, jnp.zeros(5), 45.0, jnp.full((5,), 200.0)).shape
    assert shape == (5,)
    throws = jax.eval_shape(jax.vmap(tb.simulate), jnp.zeros(3), jnp.zeros(3), jnp.zeros(3))
    n = tb.TrebuchetParams().max_steps + 1
    assert throws.distance.shape == (3,) and throws.projectile.shape == (3, n, 2)


# --- physics ------------------------------------------------------------------------------------


@pytest.mark.slow  # three phases' solves in float64: about 2.3 s
def test_phases_and_start(x64):
    th = _simulate(*BLOG_POINT)
    phases = np.asarray(th.phases)
    assert np.all(np.diff(phases) >= 0) and set(np.unique(phases)) == {0, 1, 2, 3}
    assert bool(th.landed) and not bool(th.weight_too_light) and int(th.phase) == tb.END
    assert not bool(th.diverged)
    assert 0 < float(th.liftoff_time) < float(th.release_time) < float(th.landing_time)
    np.testing.assert_allclose(np.asarray(th.projectile[0]), [0.6816, -1.524], atol=1e-4)
    np.testing.assert_allclose(np.asarray(th.arm_tip[0, 1]), -1.524, atol=1e-12)  # on the ground
    # The projectile slides on the ground until lift-off, then lands at y = -h.
    on_ground = phases == tb.GROUND
    np.testing.assert_allclose(np.asarray(th.projectile[on_ground, 1]), -1.524, atol=0.05)
    assert float(th.projectile[-1, 1]) == pytest.approx(-1.524, abs=1e-9)
    assert float(th.projectile[-1, 0]) == pytest.approx(float(th.distance), abs=1e-12)
    # After END every per-step array repeats its final values.
    end = np.argmax(phases == tb.END)
    assert np.all(np.asarray(th.time[end:]) == float(th.landing_time))
    # Released at 45 degrees: the release velocity points along the release angle.
    v = np.asarray(th.release_velocity)
    assert np.degrees(np.arctan2(v[1], v[0])) == pytest.approx(45.0, abs=1e-9)


@pytest.mark.slow
def test_failure_flags(x64):
    """Too light to lift the projectile; not landed within ``max_steps``; Euler blown up."""
    light = _simulate(0.0, 45.0, 10.0)
    assert bool(light.weight_too_light) and not bool(light.landed)
    assert np.isnan(float(light.liftoff_time))
    assert float(light.distance) == pytest.approx(0.68, abs=0.02)
    short = _simulate(*BLOG_POINT, tb.TrebuchetParams(max_steps=60))
    assert not bool(short.landed) and int(short.phase) == tb.RELEASED
    assert np.isfinite(float(short.distance)) and np.isnan(float(short.landing_time))
    blown_up = _simulate(0.0, 45.0, 1200.0)  # quirk 5: beyond what Euler at 1/60 s can follow
    assert bool(blown_up.diverged) and not bool(_simulate(0.0, 45.0, 600.0).diverged)


def _energy(p, u, weight_lb):
    """``T + V`` from the positions alone (velocities by ``jvp``), with the model's inertias."""
    q, w = u[:3], u[3:]
    l_cg = (p.long_arm - p.short_arm) / 2
    bodies = [
        (p.arm_mass, lambda q: l_cg * jnp.stack([-jnp.sin(q[0]), jnp.cos(q[0])])),
        (weight_lb * tb.LB, lambda q: tb.counterweight(p, jnp.concatenate([q, w]))),
        (p.projectile_mass, lambda q: tb.sling_end(p, jnp.concatenate([q, w]))),
    ]
    i1, i2 = p.inertias
    kinetic = 0.5 * i1 * w[0] ** 2 + 0.5 * i2 * (w[0] + w[1]) ** 2
    potential = 0.0
    for mass, position in bodies:
        x, v = jax.jvp(position, (q,), (w,))
        kinetic = kinetic + 0.5 * mass * jnp.sum(v**2)
        potential = potential + mass * p.gravity * x[1]
    return kinetic + potential, kinetic


@pytest.mark.parametrize("phase", ["ground", "hang"])
def test_equations_of_motion_conserve_energy(x64, phase):
    """Frictionless ground and sling: ``T + V`` is conserved by both systems of equations
    (the ground phase up to lift-off at 0.25 s; the sling from rest for 0.6 s)."""
    p, weight = tb.TrebuchetParams(), 200.0
    rates, duration = (tb.ground_rates, 0.24) if phase == "ground" else (tb.hang_rates, 0.6)
    rhs = jax.jit(lambda u: rates(p, u, weight * tb.LB))
    energy = jax.jit(lambda u: _energy(p, u, weight))
    u0 = np.asarray(tb.initial_state(p))
    sol = solve_ivp(lambda t, u: np.asarray(rhs(u)), (0.0, duration), u0, rtol=1e-11, atol=1e-11)
    e, kinetic = np.array([[float(v) for v in energy(u)] for u in sol.y.T]).T
    assert kinetic.max() > 100.0  # it really moved (J)
    assert np.ptp(e) < 1e-9 * kinetic.max()
    if phase == "ground":  # the projectile stays on the ground
        y = np.array([float(tb.sling_end(p, u)[1]) for u in sol.y.T])
        np.testing.assert_allclose(y, -p.pivot_height, atol=1e-8)


@pytest.mark.slow  # a float64 throw and three more, each compiled: 4.4 s on one core
def test_flight_without_drag(x64):
    """With ``rho = 0``: ``v_x`` is constant, Euler's energy error is exactly ``g^2 dt^2 / 2``
    per step, and the wind has no effect."""
    p = tb.TrebuchetParams(air_density=0.0)
    th = _simulate(*BLOG_POINT, p)
    flying = np.flatnonzero(np.asarray(th.phases) == tb.RELEASED)
    xy = np.asarray(th.projectile)[flying]  # from release, full steps of dt apart
    vel = np.diff(xy, axis=0) / p.dt
    np.testing.assert_allclose(vel[:, 0], vel[0, 0], rtol=1e-10)
    e = 0.5 * (vel[:, 0] ** 2 + vel[:, 1] ** 2) + p.gravity * xy[:-1, 1]
    np.testing.assert_allclose(np.diff(e), 0.5 * p.gravity**2 * p.dt**2, rtol=1e-6)
    d = _distances([-5.0, 0.0, 5.0], 45.0, 200.0, p)
    np.testing.assert_allclose(d, d[1], rtol=1e-12)


def test_tail_wind_throws_farther(x64):
    d = _distances([-10.0, -5.0, 0.0, 5.0, 10.0], 45.0, 200.0)
    assert np.all(np.diff(d) > 0), d


def test_distance_increases_with_weight(x64):
    weights = np.arange(100.0, 301.0, 10.0)
    d = _distances(0.0, 45.0, weights)
    assert np.all(np.diff(d) > 0), d


# --- input validation ---------------------------------------------------------------------------


def test_check_inputs_accepts_and_broadcasts():
    w, a, m = tb.check_inputs(0.0, [30.0, 45.0, 90.0], 200)
    assert w.shape == a.shape == m.shape == (3,) and w.dtype == np.float64
    assert tb.check_inputs(-2, 45, 200)[0].shape == ()


@pytest.mark.parametrize(
    "args, match",
    [
        ((float("nan"), 45.0, 200.0), "wind_mps must be finite"),
        ((0.0, float("inf"), 200.0), "angle_deg must be finite"),
        ((0.0, 45.0, 0.0), r"weight_lb \(counterweight, pounds\) must be in \(0, 600\]"),
        ((0.0, 45.0, [200.0, -1.0]), r"weight_lb .* must be in \(0, 600\]"),
        ((0.0, 45.0, 650.0), r"weight_lb .* must be in \(0, 600\]"),
        ((0.0, 0.0, 200.0), r"angle_deg must be in \(0, 90\]"),
        ((0.0, -10.0, 200.0), r"angle_deg must be in \(0, 90\]"),
        ((0.0, 95.0, 200.0), r"angle_deg must be in \(0, 90\]"),
        ((np.zeros((2, 2)), 45.0, 200.0), "scalar or a 1-D batch"),
        ((np.zeros(3), np.full(2, 45.0), 200.0), "share one length"),
        (("windy", 45.0, 200.0), "wind_mps must be a number"),
    ],
)
def test_check_inputs_rejects(args, match):
    with pytest.raises(ConfigError, match=match):
        tb.check_inputs(*args)


# --- the phase scans: budgets, trajectory layout, root finding ----------------------------------

# (wind m/s, angle deg, weight lb): the corners of the step budgets' sweep (TrebuchetParams):
# the slowest throws in all (452 steps) and the longest flight, and the lightest weight that
# lifts off within the ground budget (44 of 45 steps), with its slowest release (47 of 50).
BUDGET_CORNERS = [
    (20.0, 67.0, 530.0),
    (20.0, 63.0, 590.0),
    (-20.0, 0.05, 25.0),
    (20.0, 90.0, 25.0),
]


@pytest.mark.slow
@pytest.mark.parametrize("point", BUDGET_CORNERS)
def test_step_budgets_cover_the_supported_range(point):
    p = DEFAULT
    th = _simulate(*point)
    assert bool(th.landed) and not bool(th.diverged), point
    ground, hang, flying, _ = _phase_lengths(th)
    assert ground <= p.ground_steps and hang <= p.hang_steps, (point, ground, hang)
    assert ground + hang + flying <= 460 < p.max_steps, (point, ground, hang, flying)


@pytest.mark.slow
def test_spent_budgets_report_not_landed():
    """A phase that runs out of its budget stops the throw there, reported as not landed."""
    on_ground = _simulate(*BLOG_POINT, tb.TrebuchetParams(ground_steps=10))
    assert not bool(on_ground.landed) and int(on_ground.phase) == tb.GROUND
    assert np.isnan(float(on_ground.liftoff_time)) and not bool(on_ground.weight_too_light)
    assert np.all(np.asarray(on_ground.phases) == tb.GROUND)
    np.testing.assert_allclose(float(on_ground.time[-1]), 10 * DEFAULT.dt, rtol=1e-6)
    assert float(on_ground.distance) == pytest.approx(float(on_ground.projectile[-1, 0]))
    on_sling = _simulate(*BLOG_POINT, tb.TrebuchetParams(hang_steps=5))
    assert not bool(on_sling.landed) and int(on_sling.phase) == tb.HANG
    assert np.isfinite(float(on_sling.liftoff_time)) and np.isnan(float(on_sling.release_time))
    assert np.isfinite(float(on_sling.distance))


@pytest.mark.parametrize("field", ["max_steps", "ground_steps", "hang_steps"])
def test_step_budgets_must_be_positive_ints(field):
    with pytest.raises(ConfigError, match=f"TrebuchetParams.{field} must be a positive int"):
        tb.TrebuchetParams(**{field: 0})


@pytest.mark.slow  # a saved throw's solve in float64: about 2 s
def test_trajectory_rows_are_steps(x64):
    """Row ``i`` is the state after ``i`` steps: full steps of ``dt``, except the three steps
    that end at lift-off, release and landing, where the phase changes (here lift-off is the
    jump at its step's start, so that step takes no time)."""
    th = _simulate(*BLOG_POINT)
    phases, time = np.asarray(th.phases), np.asarray(th.time)
    end = int(np.argmax(phases == tb.END))
    steps = np.diff(time[: end + 1])
    partial = np.flatnonzero(~np.isclose(steps, DEFAULT.dt, rtol=1e-9, atol=0)) + 1
    changes = np.flatnonzero(np.diff(phases[: end + 1])) + 1
    np.testing.assert_array_equal(partial, changes)
    assert np.all(steps >= 0) and len(changes) == 3
    assert float(th.liftoff_time) == time[changes[0]]
    assert float(th.release_time) == time[changes[1]]
    assert float(th.landing_time) == time[changes[2]]
    assert float(th.distance) == pytest.approx(_shoot(*BLOG_POINT), abs=1e-12)


def test_vmap_matches_python_loop_at_converged_roots(x64):
    """Throws whose release root finding converges with the test's sign at rounding level.
    Bisecting there, as the original's safeguard does, put the vmapped distance 1e-5 m off."""
    points = np.array([(-10.0, 35.0, 249.9975), (-15.0, 15.0, 60.0006)])
    looped = np.array([_shoot(*point) for point in points])
    np.testing.assert_allclose(_distances(*points.T), looped, rtol=1e-12)
