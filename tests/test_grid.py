"""Exact stick-slip friction (`KarnoppFriction`) on the fixed grid with events located inside the step
(`pamjax._solve.grid`): against an independent event-driven SciPy reference, holding still, gradients through the event
times against finite differences, the stepping rules, and the steps' Hermite interpolant."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import NumpyPlant, host_signal, initial_state, np_stick_slip_run

import pamjax as pj
from pamjax import PamjaxInputError, presets
from pamjax._solve.simulate import solve

MODEL = presets.mas10_system("pwm", friction="karnopp")
TRIANGLE = pj.Triangle(0.05, 0.95, 0.5)  # up and down in 2 s: stick at both ends, slip between
TS = np.linspace(0.0, 2.0, 401)


def _plant(model):
    fl, vol = model.muscle.force_law, model.muscle.volume_law
    return NumpyPlant(a=np.asarray(fl.max_force_coefficients), k0=float(fl.k0), k1=float(fl.k1), k2=float(fl.k2),
                      v0=float(vol.v0), v1=float(vol.v1), x_min=float(model.muscle.min_position),
                      x_max=float(model.muscle.max_position), fc=float(model.friction.coulomb_force),
                      cf=float(model.friction.viscous_coefficient))


@pytest.fixture(scope="module")
def reference():
    duty = host_signal(TRIANGLE)
    duties = [duty(k * 0.02) for k in range(101)]
    return np_stick_slip_run(_plant(MODEL), duties, TS)


@pytest.mark.parametrize("substeps, x_tol, p_tol", [(8, 2e-7, 30.0), (16, 2e-8, 5.0)])
def test_matches_event_driven_reference(reference, substeps, x_tol, p_tol):
    # SciPy DOP853 at rtol 1e-11, piecewise between valve edges and friction events (tests/helpers.py); pamjax's
    # RK4 grid is O(h⁴): measured 3.0e-8 m / 7.1 Pa at K = 8, 2.5e-9 m / 1.2 Pa at K = 16 (2 s, max over 401 times).
    p_ref, x_ref = reference
    traj = pj.simulate(MODEL, TRIANGLE, TS, substeps=substeps)
    assert np.max(np.abs(np.asarray(traj.position) - x_ref)) < x_tol
    assert np.max(np.abs(np.asarray(traj.pressure) - p_ref)) < p_tol
    # the run does stick and slip: it moves (tens of mm) and it holds still at the end of the down ramp
    assert np.ptp(x_ref) > 0.03


# The tests that start at duty 5 % share one compiled solve: one horizon and output grid (the longest, 1 s, sampled
# every 10 ms) and an explicit initial state whose leaves are float64 arrays like `initial_state()`'s (a Python float
# or a weakly typed leaf would be a different program), made with NumPy (jnp.asarray of a Python float compiles).
HOLD_TS = np.linspace(0.0, 1.0, 101)


def _from_rest(y0):
    y0 = jax.tree_util.tree_map(lambda leaf: np.asarray(leaf, dtype=float), y0)
    return pj.simulate(MODEL, pj.Constant(0.05), HOLD_TS, y0=y0)


def test_holds_still_while_the_net_force_is_within_coulomb():
    # Duty 5 %: the valve never opens (10 % dead band at 50 Hz), the payload rests in equilibrium, stuck: its
    # position must not move at all (a smooth sign lets it creep).
    traj = _from_rest(initial_state(MODEL))  # simulate's default start, given explicitly
    x = np.asarray(traj.position)
    assert np.all(x == x[0]) and np.all(np.asarray(traj.velocity) == 0.0)
    # a pressure step that changes the muscle force by less than F_c does not move it either (for the whole second)
    x0 = float(initial_state(MODEL).position)
    # jitted: eagerly, each operation of the force law compiles a program of its own
    slope = float(eqx.filter_jit(MODEL.muscle.force_law.pressure_slope)(np.asarray(x0)))  # N/Pa
    dp = 0.5 * float(MODEL.friction.coulomb_force) / slope
    y0 = eqx.tree_at(lambda s: s.pressure, initial_state(MODEL), float(MODEL.air.atmospheric_pressure) + dp)
    held = _from_rest(y0)
    assert np.all(np.asarray(held.position)[1:] == x0)
    assert np.all(np.asarray(held.friction_force) != 0.0)  # static friction carries the difference


def test_a_start_outside_its_mode_switches_at_once():
    # Stuck, but the net force exceeds F_c: it slides from the first step (position[1]: t = 10 ms).
    x0 = float(initial_state(MODEL).position)
    y0 = eqx.tree_at(lambda s: s.position, initial_state(MODEL), x0 + 2e-3)  # weaker muscle force: it falls
    traj = _from_rest(y0)
    assert float(np.asarray(traj.position)[1]) < x0 + 2e-3 - 1e-5


def test_a_start_velocity_on_a_stuck_mode_slides_in_its_direction():
    # A velocity set on a stuck y0 (eqx.tree_at after initial_state(), or a sweep over "y0.velocity" with a base y0)
    # was thrown away at t0: the mode re-decided by the net force and the velocity zeroed, so 0.2 m/s ran exactly as
    # 0 (x 30 -> 29.63 mm at 10 ms instead of 31.23 mm, MAS-10 averaged). The mode follows the velocity instead.
    x0 = float(initial_state(MODEL).position)
    edited = eqx.tree_at(lambda s: s.velocity, initial_state(MODEL), np.asarray(0.2))
    moving = _from_rest(initial_state(MODEL, velocity=np.asarray(0.2)))  # sliding up from the start
    assert float(np.asarray(moving.position)[1]) > x0 + 1e-3
    np.testing.assert_allclose(np.asarray(_from_rest(edited).position), np.asarray(moving.position), rtol=0, atol=1e-12)


def _loss(params, duty):
    coulomb, viscous, v1, k0 = params
    model = eqx.tree_at(lambda s: (s.friction.coulomb_force, s.friction.viscous_coefficient,
                                   s.muscle.volume_law.v1, s.muscle.force_law.k0), MODEL, (coulomb, viscous, v1, k0))
    ts = jnp.linspace(0.0, 1.2, 61)
    traj = solve(model, pj.Constant(duty), ts, model.initial_state(), 0.0, stepping="pwm", substeps=8,
                 num_periods=60)
    return jnp.mean(traj.position) * 1e3 + jnp.mean(traj.pressure) * 1e-5


def test_gradients_through_event_times_match_finite_differences():
    # A duty step from rest: breakaway, slide, come to rest: every parameter moves the event times. Forward and
    # reverse mode against central differences (steps small enough not to change the event sequence).
    params = np.asarray([16.0, 250.0, 4.1558930e-04, 102.844885])
    duty = 0.35
    fwd = [np.asarray(g) for g in jax.jit(jax.jacfwd(_loss, argnums=(0, 1)))(params, duty)]
    # One compiled value-and-gradient gives the reverse-mode gradient and the ten loss values of the differences (no
    # separate loss compilation; an eager solve re-traces at every call). The differences' arguments are NumPy
    # arrays and Python floats like the first call's, so no call compiles anew.
    value_and_grad = jax.jit(jax.value_and_grad(_loss, argnums=(0, 1)))
    rev = [np.asarray(g) for g in value_and_grad(params, duty)[1]]

    def loss(p, d):
        return float(value_and_grad(p, d)[0])

    steps = np.asarray([1e-4, 1e-3, 1e-10, 1e-5])
    for i, h in enumerate(steps):
        up, down = params.copy(), params.copy()
        up[i] += h
        down[i] -= h
        fd = (loss(up, duty) - loss(down, duty)) / (2 * h)
        assert abs(float(fwd[0][i])) > 0
        np.testing.assert_allclose(float(fwd[0][i]), fd, rtol=1e-5)
        np.testing.assert_allclose(float(rev[0][i]), float(fwd[0][i]), rtol=1e-9)
    fd = (loss(params, duty + 1e-6) - loss(params, duty - 1e-6)) / 2e-6
    np.testing.assert_allclose(float(fwd[1]), fd, rtol=1e-5)


def _edge_on_node_loss(hi):
    """A triangle 0.05…`hi` at 0.5 Hz from rest for 0.4 s: at hi = 0.8 the period from 0.30 s has duty 0.275, whose
    off edge (0.275 × 20 ms + 2 ms = 7.5 ms) falls exactly on the grid's uniform node 3 × 2.5 ms."""
    ts = jnp.linspace(0.0, 0.4, 41)
    traj = solve(MODEL, pj.Triangle(0.05, hi, 0.5), ts, MODEL.initial_state(), 0.0, stepping="pwm", substeps=8,
                 num_periods=20)
    return jnp.mean(traj.position) * 1e3 + jnp.mean(traj.pressure) * 1e-5


def test_a_switching_edge_on_a_grid_node_keeps_its_derivative():
    # An edge that coincides with a uniform node leaves a zero-length interval between them, whose length moves with
    # the duty: its RK4 step of length 0 carries the state's derivative (the vector field times the length's), which
    # a step skipped for having zero length lost (10 % of d loss / d hi here). Against central and one-sided
    # differences (the discrete map is smooth there: both sides agree).
    value = jax.jit(_edge_on_node_loss)
    ad = float(jax.jit(jax.grad(_edge_on_node_loss))(0.8))
    h = 1e-7
    central = (float(value(0.8 + h)) - float(value(0.8 - h))) / (2 * h)
    forward = (float(value(0.8 + 1e-6)) - float(value(0.8))) / 1e-6
    np.testing.assert_allclose(forward, central, rtol=1e-5)
    np.testing.assert_allclose(ad, central, rtol=1e-6)


def _landing_loss(params, hi, landing):
    """`_loss` for `landing`, a plant whose payload starts on the lower stop, under a triangle 0.15…`hi` (every duty
    above the valve's threshold)."""
    coulomb, viscous, v1, k0 = params
    model = eqx.tree_at(lambda s: (s.friction.coulomb_force, s.friction.viscous_coefficient,
                                   s.muscle.volume_law.v1, s.muscle.force_law.k0), landing, (coulomb, viscous, v1, k0))
    ts = jnp.linspace(0.0, 2.0, 101)
    traj = solve(model, pj.Triangle(0.15, hi, 0.5), ts, model.initial_state(), 0.0, stepping="pwm", substeps=8,
                 num_periods=100)
    return jnp.mean(traj.position) * 1e3 + jnp.mean(traj.pressure) * 1e-5


def test_second_derivatives_through_event_times_match_finite_differences():
    # A design's gradient differentiates a Jacobian again (d/d duty of d loss/d parameters, forward over forward):
    # the located event times' own derivatives are differentiated. Against central differences in the duty of the
    # first derivatives (forward mode, checked above), on a payload that lifts off its lower stop and slides and
    # sticks. A Newton step from a gradient-stopped root carried the first derivatives only: its mixed second
    # derivatives missed g_θ g_sc / g_s² (here 0.1-31 % off; the wrong sign on a design's heavy payload).
    # eq. 7 at the lower stop and atmospheric pressure: 50 N, below the 94 N payload, which rests there at the start
    f_stop = float(eqx.filter_jit(MODEL.muscle.static_force)(MODEL.muscle.min_position, 101325.0, MODEL.air))
    a = MODEL.muscle.force_law.max_force_coefficients
    landing = eqx.tree_at(lambda m: m.muscle.force_law.max_force_coefficients, MODEL, a.at[0].add(50.0 - f_stop))
    params = np.asarray([16.0, 250.0, 4.1558930e-04, float(MODEL.muscle.force_law.k0)])
    hi = 0.8
    gradient = jax.jit(jax.jacfwd(_landing_loss))
    mixed = np.asarray(jax.jit(jax.jacfwd(jax.jacfwd(_landing_loss), argnums=1))(params, hi, landing))
    h = 1e-6
    fd = (np.asarray(gradient(params, hi + h, landing)) - np.asarray(gradient(params, hi - h, landing))) / (2 * h)
    assert np.all(np.abs(mixed) > 0)
    np.testing.assert_allclose(mixed, fd, rtol=1e-6)


def test_stepping_rules():
    ts = np.linspace(0.0, 0.1, 11)
    with pytest.raises(PamjaxInputError, match="hybrid.*stepping='auto'"):
        pj.simulate(MODEL, pj.Constant(0.5), ts, stepping="adaptive")
    averaged = presets.mas10_system("averaged", friction="karnopp")
    with pytest.raises(PamjaxInputError, match="switching valve"):
        pj.simulate(averaged, pj.Constant(0.5), ts, stepping="pwm")
    # a continuous valve runs on the uniform grid; halving the step changes the result by O(h⁴)
    coarse = pj.simulate(averaged, TRIANGLE, TS[:201], grid_step=2e-3)
    fine = pj.simulate(averaged, TRIANGLE, TS[:201], grid_step=5e-4)
    assert np.ptp(np.asarray(fine.position)) > 0.01
    assert np.max(np.abs(np.asarray(coarse.position) - np.asarray(fine.position))) < 1e-6


def test_vmap_over_parameters_equals_one_by_one():
    forces = np.asarray([12.0, 16.0, 22.0])
    ts = np.linspace(0.0, 1.0, 26)

    def run(fc):
        model = eqx.tree_at(lambda s: s.friction.coulomb_force, MODEL, fc)
        return solve(model, TRIANGLE, ts, model.initial_state(), 0.0, stepping="pwm", substeps=8,
                     num_periods=50).position

    batch = jax.jit(jax.vmap(run))(forces)
    for k in range(3):
        np.testing.assert_allclose(np.asarray(batch)[k], np.asarray(jax.jit(run)(forces[k])), rtol=0, atol=1e-12)


def test_step_interpolant_is_the_cubic_hermite():
    # The grid's dense output and event location use the cubic Hermite of each step (Horner form): against the
    # textbook basis-function form in NumPy, and its end values and end slopes (dz/ds = h f).
    from pamjax._solve.grid import _hermite

    rng = np.random.default_rng(7)
    za, zb, fa, fb = rng.normal(size=(4, 3))
    h = 1e-3
    s = np.linspace(0.0, 1.0, 11)[:, None]
    basis = ((2 * s**3 - 3 * s**2 + 1) * za + (s**3 - 2 * s**2 + s) * h * fa + (-2 * s**3 + 3 * s**2) * zb
             + (s**3 - s**2) * h * fb)
    interp = jax.jit(_hermite)
    np.testing.assert_allclose(np.asarray(interp(s, h, za, zb, fa, fb)), basis, rtol=1e-13, atol=1e-15)
    assert np.array_equal(np.asarray(interp(0.0, h, za, zb, fa, fb)), za)
    np.testing.assert_allclose(np.asarray(interp(1.0, h, za, zb, fa, fb)), zb, rtol=1e-14, atol=1e-15)
    # the end slopes by forward mode, jitted: one program for both ends (eagerly, one per operation)
    tangent = jax.jit(lambda q: jax.jvp(lambda r: _hermite(r, h, za, zb, fa, fb), (q,), (jnp.ones(()),)))
    for end, slope in ((0.0, fa), (1.0, fb)):
        _, ds = tangent(jnp.asarray(end))
        np.testing.assert_allclose(np.asarray(ds), h * slope, rtol=1e-12, atol=1e-15)


def test_event_location_is_the_root_and_its_derivative_the_implicit_functions():
    # `_locate` on a straight step z(s) = za + s (zb - za) (slopes zb - za over h = 1: the Hermite is the line) and
    # g = z - c: the crossing s* = (za - c)/(za - zb) to the bisection's 2^-41, dτ/d(za, zb, c) the implicit function
    # theorem's in closed form, and a start where g < 0 already: τ = the step's start, moving with it only.
    from pamjax._solve.grid import _locate

    def event(c, t, z):
        return z[0] - c

    def tau(za, zb, c, ta=0.0):
        za, zb = jnp.atleast_1d(za), jnp.atleast_1d(zb)
        return _locate(event, c, (ta, ta + 1.0, za, zb, zb - za, zb - za))[0]

    located = jax.jit(jax.value_and_grad(tau, argnums=(0, 1, 2, 3)))
    za, zb, c = 1.0, -0.6, 0.3
    value, grads = located(za, zb, c, 0.0)
    assert abs(float(value) - (za - c) / (za - zb)) < 1e-12
    d = za - zb  # s* = (za - c)/d: ∂/∂za = (c - zb)/d², ∂/∂zb = (za - c)/d², ∂/∂c = -1/d, ∂/∂ta = 1
    np.testing.assert_allclose([float(x) for x in grads], [(c - zb) / d**2, (za - c) / d**2, -1.0 / d, 1.0],
                               rtol=1e-10)
    value, grads = located(0.2, -0.6, 0.3, 0.5)  # g(0) = -0.1 < 0: no root inside the step
    assert float(value) == 0.5 and [float(x) for x in grads] == [0.0, 0.0, 0.0, 1.0]


def test_runs_in_one_loop_switch_their_start_modes_each_on_its_own():
    # A fit integrates experiments of one structure as runs of one loop; a start outside its mode is switched per
    # run before it (mapped over the runs). Two runs, stuck at the preset's rest and stuck 2 mm below it (the net
    # force exceeds F_c: it slides at once), each equal to its own single-run solve.
    from pamjax._solve import synchronous
    from pamjax._solve.scaled import scaled
    from pamjax._solve.simulate import _DEFAULT_SUBSTEPS, fixed_grid_size

    x0 = float(initial_state(MODEL).position)
    starts = [initial_state(MODEL), eqx.tree_at(lambda s: s.position, initial_state(MODEL), x0 + 2e-3)]
    starts = [jax.tree_util.tree_map(lambda leaf: np.asarray(leaf, dtype=float), y0) for y0 in starts]
    size = fixed_grid_size(MODEL, "pwm", 0.0, float(HOLD_TS[-1]))

    # jitted: eagerly, the set-up around the loop (grids, stacking, outputs) compiles ~140 one-operation programs
    @eqx.filter_jit
    def solve_runs(starts):
        flats = [scaled(MODEL, y0) for y0 in starts]
        return synchronous.solve_runs([MODEL, MODEL], [pj.Constant(0.05)] * 2, [HOLD_TS] * 2, [f[0] for f in flats],
                                      flats[0][1], [0.0, 0.0], stepping="pwm", substeps=_DEFAULT_SUBSTEPS,
                                      sizes=[size, size])

    runs = solve_runs(starts)
    held, slid = (np.asarray(states.position) for states, _, _ in runs)
    np.testing.assert_allclose(held, np.asarray(_from_rest(starts[0]).position), rtol=0, atol=1e-12)
    np.testing.assert_allclose(slid, np.asarray(_from_rest(starts[1]).position), rtol=0, atol=1e-12)
    assert np.ptp(held) < 1e-9 and slid[1] < x0 + 2e-3 - 1e-5  # one holds still, the other slides from the start


def test_a_duty_held_per_period_keeps_rk4s_fourth_order_on_the_grid():
    # A continuous valve with stick-slip friction runs on the uniform grid; a duty held per 20 ms period (a closed
    # loop's, a recorded column's) changes on a grid node, and the RK4 step's last stage read the NEXT period's duty
    # there: first order (the error halved with the step: 1,200, 591, 286 Pa). The stage now reads the interval's own.
    plant = presets.mas10_system("averaged", friction="karnopp")
    y0 = plant.initial_state(pressure=4e5)
    ts = jnp.linspace(0.0, 0.2, 11)
    held = pj.Sampled(0.02 * np.arange(10), np.where(np.arange(10) % 2 == 0, 0.3, 0.8), period=0.02)
    ref = pj.simulate(plant, held, ts, y0=y0, grid_step=1e-3 / 16)
    errors = [float(jnp.max(jnp.abs(pj.simulate(plant, held, ts, y0=y0, grid_step=h).pressure - ref.pressure)))
              for h in (1e-3, 5e-4)]
    assert errors[0] < 0.05 and errors[1] < errors[0] / 8, errors  # Pa; 4th order: /16 per halving
