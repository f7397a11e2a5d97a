"""simulate/solve: the whole ODE against scipy DOP853 on a NumPy vector field, gradients of a trajectory loss against
central finite differences for every parameter leaf, forward = reverse mode, jit/vmap equivalence."""

import functools

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import P_ATM, NumpyPlant, central_difference, flat_parameters, host_signal, parameter_names
from scipy.integrate import solve_ivp

import pamjax
from pamjax import presets
from pamjax._solve.simulate import solve


def _plant(valve):
    return NumpyPlant(
        a=presets.MAS10_MAX_FORCE_COEFFICIENTS, k0=presets.MAS10_K0, k1=presets.MAS10_K1, k2=presets.MAS10_K2,
        v0=presets.MAS10_V0, v1=presets.MAS10_V1, x_min=presets.MAS10_MIN_POSITION, x_max=presets.MAS10_MAX_POSITION,
        valve=valve, m=presets.MAS10_AVERAGED_VALVE, volume=presets.TANK_VOLUME,
    )


@pytest.mark.parametrize("valve, t_end", [("averaged", 0.3), ("pwm", 0.05)])
def test_muscle_ode_matches_scipy_dop853(valve, t_end):
    # Both solved at rtol 1e-10. Tolerance: 1e-5 relative in pressure (≈ 3 Pa), 1e-7 m in position, 1e-5 m/s in
    # velocity: the solutions agree to ~1e-8; the margin absorbs the PWM edges (width 0.1 ms) that both resolve.
    system = presets.mas10_system(valve)
    u = pamjax.Triangle(0.3, 0.8, 4.0)
    y0 = system.initial_state(pressure=3e5)
    ts = np.linspace(0.0, t_end, 11)
    traj = pamjax.simulate(system, u, jnp.asarray(ts), y0=y0, rtol=1e-10, atol=1e-10)
    plant = _plant(valve)
    ref = solve_ivp(plant.rhs, (0.0, t_end), [3e5, float(y0.position), 0.0], method="DOP853", t_eval=ts, rtol=1e-10,
                    atol=[1e-4, 1e-12, 1e-10], args=(host_signal(u),))
    assert ref.success
    np.testing.assert_allclose(traj.pressure, ref.y[0], rtol=1e-5)
    np.testing.assert_allclose(traj.position, ref.y[1], atol=1e-7)
    np.testing.assert_allclose(traj.velocity, ref.y[2], atol=1e-5)
    assert np.ptp(ref.y[1]) > 2e-4  # the payload actually moves (0.6 mm in 50 ms)


def test_tank_ode_matches_scipy_dop853():
    system = presets.mas10_tank_system("pwm")
    ts = np.linspace(0.0, 0.06, 13)
    traj = pamjax.simulate(system, pamjax.Constant(0.4), jnp.asarray(ts), rtol=1e-10, atol=1e-10)
    ref = solve_ivp(_plant("pwm").tank_rhs, (0.0, 0.06), [P_ATM], method="DOP853", t_eval=ts, rtol=1e-10, atol=1e-4,
                    args=(lambda t: 0.4,))
    np.testing.assert_allclose(traj.pressure, ref.y[0], rtol=1e-6)


# --- gradients of a trajectory loss w.r.t. every parameter leaf ------------------------------------------------
CASES = {
    "tank-pwm": (lambda: presets.mas10_tank_system("pwm"), pamjax.Constant(0.6), 0.03, None),
    "tank-averaged": (lambda: presets.mas10_tank_system("averaged"), pamjax.Constant(0.6), 0.05, None),
    "muscle-pwm": (lambda: presets.mas10_system("pwm"), pamjax.Constant(0.6), 0.03, 3e5),
    "muscle-averaged": (lambda: presets.mas10_system("averaged"), pamjax.Triangle(0.3, 0.8, 4.0), 0.1, 3e5),
    "muscle-bristle": (lambda: presets.mas10_system("averaged", friction="bristle"), pamjax.Constant(0.7), 0.05, 3e5),
}


def _loss_factory(case):
    make, signal, t_end, p0 = CASES[case]
    system = make()
    ts = jnp.linspace(0.0, t_end, 6)
    flat, rebuild = flat_parameters(system)

    def loss(v, adjoint=None):
        s = rebuild(v)
        y0 = s.initial_state() if p0 is None else s.initial_state(pressure=p0)
        traj = solve(s, signal, ts, y0, ts[0], rtol=1e-12, atol=1e-12, adjoint=adjoint)
        out = jnp.sum((traj.pressure / 1e5) ** 2)
        if traj.position is not None:
            out = out + jnp.sum((traj.position / 1e-2) ** 2) + jnp.sum((traj.velocity / 1e-2) ** 2)
        return out

    return system, flat, loss


@functools.cache
def _value_and_grad(case):
    """(system, flat parameters, loss, jitted value-and-gradient of the loss) of a case, built and compiled once per
    module: the finite-difference test and the forward-mode test share the reverse-mode gradient of "muscle-averaged"
    (one compilation instead of two)."""
    system, flat, loss = _loss_factory(case)
    return system, flat, loss, jax.jit(jax.value_and_grad(loss))


@pytest.mark.parametrize("case", list(CASES))
def test_gradient_every_parameter_matches_finite_differences(case):
    # Compared as sensitivities θ ∂L/∂θ (the change for a relative change of each parameter), so leaves of very
    # different units share one tolerance: 2e-4 of the largest sensitivity plus 1e-4 relative. Central differences
    # with relative step 1e-5 at solver rtol 1e-12 are accurate to ~1e-7 relative.
    # one compiled value-and-gradient serves the gradient and the differences' values (no separate loss compile)
    system, flat, _, value_and_grad = _value_and_grad(case)
    grad = np.asarray(value_and_grad(jnp.asarray(flat))[1])
    fd = central_difference(lambda v: value_and_grad(v)[0], flat)
    names = parameter_names(system)
    s_ad, s_fd = flat * grad, flat * fd
    scale = np.max(np.abs(s_fd))
    bad = [(n, a, f) for n, a, f in zip(names, s_ad, s_fd) if not abs(a - f) <= 2e-4 * scale + 1e-4 * abs(f)]
    assert not bad, bad
    assert np.all(np.isfinite(grad)) and scale > 0


@pytest.mark.slow  # ~60 s on 2 cores: jacfwd through the solve over ~40 parameters, mostly compile time
def test_forward_mode_jacobian_equals_reverse_mode_gradient():
    # jitted: eager transforms of the solve trace and compile it piecewise (~1.7x slower); the reverse-mode gradient
    # is the finite-difference test's compiled value-and-gradient of the same loss
    _, flat, loss, value_and_grad = _value_and_grad("muscle-averaged")
    rev = value_and_grad(jnp.asarray(flat))[1]
    fwd = jax.jit(jax.jacfwd(lambda v: loss(v, adjoint="forward")))(jnp.asarray(flat))
    np.testing.assert_allclose(fwd, rev, rtol=1e-8, atol=1e-12 * float(jnp.max(jnp.abs(rev))))


def test_vmap_over_duties_equals_loop():
    system = presets.mas10_system("pwm")
    ts = jnp.linspace(0.0, 0.04, 5)
    y0 = system.initial_state(pressure=3e5)
    duties = jnp.asarray([0.2, 0.5, 0.8])
    periods = 2  # 0.04 s at 50 Hz: simulate clips steps at the smoothed edges (EdgeClipController)

    def run(u):
        return solve(system, pamjax.Constant(u), ts, y0, ts[0], rtol=1e-8, atol=1e-8, num_periods=periods).position

    batched = eqx.filter_jit(jax.vmap(run))(duties)
    looped = [eqx.filter_jit(run)(u) for u in duties]
    np.testing.assert_allclose(batched, np.stack(looped), rtol=1e-10, atol=1e-12)
    jitted = pamjax.simulate(system, pamjax.Constant(0.5), ts, y0=y0, rtol=1e-8, atol=1e-8).position
    np.testing.assert_allclose(jitted, looped[1], rtol=1e-12, atol=1e-14)


def test_trajectory_channels_and_failed_solve():
    system = presets.mas10_system("averaged")
    ts = jnp.linspace(0.0, 0.1, 5)
    traj = pamjax.simulate(system, pamjax.Constant(0.5), ts)
    assert set(traj.channels()) >= {"pressure", "position", "velocity", "force", "mass_flow"}
    assert np.all(traj.succeeded)
    with pytest.raises(pamjax.PamjaxSolveError, match="max_steps"):
        pamjax.simulate(system, pamjax.Constant(0.5), ts, max_steps=3)
    partial = pamjax.simulate(system, pamjax.Constant(0.5), ts, max_steps=3, throw=False)
    assert int(partial.result) != 0 and np.all(np.isnan(partial.pressure))
    assert dfx  # diffrax is the solver underneath


def test_another_horizon_tolerance_or_first_step_does_not_compile_again():
    # Issue 14: what changes between runs of one system is an argument of the compiled solve, not a constant in it:
    # the horizon (its PWM period count, the smoothed-edge valve's step clipping), rtol, atol, dt0 (a given dt0 is
    # another program than the automatic first step, once). Bad values are refused naming the argument.
    system = presets.mas10_tank_system()  # smoothed PWM edges, adaptive Tsit5 with the edge clipping

    def run(t_end=0.2, rtol=1e-6, atol=1e-6, dt0=None, **kwargs):
        ts = np.linspace(0.0, t_end, 11)
        return pamjax.simulate(system, pamjax.Constant(0.5), ts, rtol=rtol, atol=atol, dt0=dt0, **kwargs).pressure

    first, first_dt0 = run(), run(dt0=1e-4)
    with pamjax.runtime.CompileStats() as stats:
        longer, tighter, other_dt0 = run(t_end=0.3), run(rtol=1e-8, atol=1e-7), run(dt0=3e-4)
        # a concrete call's result cannot be differentiated: its default program is the forward-mode loop (the
        # lighter trace), the one an explicit adjoint="forward" asks for; under grad the default stays reverse mode
        forward = run(adjoint="forward")
    assert stats.count["compile"] == 0 and stats.count["trace"] == 0, stats.summary()
    np.testing.assert_array_equal(forward, first)
    assert np.all(np.isfinite(np.stack([first, first_dt0, longer, tighter, other_dt0])))
    for same_run in (tighter, first_dt0, other_dt0):  # other tolerances or first steps: the same solution
        np.testing.assert_allclose(same_run, first, rtol=1e-4)
    assert longer[-1] > first[-1]  # the tank fills further over the longer horizon
    for name, bad in (("rtol", 0.0), ("atol", -1e-6), ("dt0", float("nan")), ("rtol", "1e-6"), ("atol", True)):
        with pytest.raises(pamjax.PamjaxInputError, match=f"{name} must be a finite number > 0"):
            pamjax.simulate(system, pamjax.Constant(0.5), np.linspace(0.0, 0.2, 11), **{name: bad})


def test_a_step_command_is_solved_to_the_tolerance_across_its_jump():
    # The adaptive solve stepped over a Step's jump unseen by its error estimate: the averaged MAS-10 from duty 0.97
    # to 0.2 ended 349 Pa / 22 um off a tight solve at the default tolerances (2 Pa at a constant duty). The jump is
    # now a step boundary.
    system = presets.mas10_system("averaged")
    ts = jnp.linspace(0.0, 0.3, 61)
    y0 = system.initial_state(pressure=3e5)
    signal = pamjax.Step(0.97, 0.2, 0.1)
    ref = pamjax.simulate(system, signal, ts, y0=y0, rtol=1e-12, atol=1e-12)
    traj = pamjax.simulate(system, signal, ts, y0=y0)
    assert float(jnp.max(jnp.abs(traj.pressure - ref.pressure))) < 20.0
    assert float(jnp.max(jnp.abs(traj.position - ref.position))) < 1e-6


@pytest.mark.parametrize("t0", [-np.inf, np.nan, np.inf])
@pytest.mark.parametrize("valve", ["averaged", "pwm"])
def test_a_start_time_that_is_not_finite_is_named_before_the_solve(valve, t0):
    # t0 = -inf passed the check "t0 <= ts[0]" and surfaced as a bare OverflowError from the step budget
    with pytest.raises(pamjax.PamjaxInputError, match=r"t0 must be finite \(no NaN or inf\)"):
        pamjax.simulate(presets.mas10_system(valve), pamjax.Constant(0.5), np.linspace(0.0, 0.1, 3), t0=t0)


def _nested_start(kind, pressure):
    """A regulated muscle's or an antagonistic joint's start state whose pressure (kept in a regulator's state) is
    `pressure`, built without solving anything."""
    muscle, regulator = presets.dmsp40_muscle(), pamjax.ISO6358Regulator()
    if kind == "regulated":
        system = pamjax.RegulatedMuscleSystem(regulator, muscle)
        return system, pamjax.Constant(3.0), system.initial_state(pressure=pressure, position=0.02)
    system = pamjax.AntagonisticJoint(regulator, regulator, muscle, muscle)
    y0 = system.initial_state(3e5, 3e5, angle=0.0)
    y0 = eqx.tree_at(lambda s: s.extensor.pressure, y0, jnp.asarray(pressure))
    return system, pamjax.VoltagePair(pamjax.Constant(3.0), pamjax.Constant(3.0)), y0


@pytest.mark.parametrize("kind, pressure, match", [
    ("regulated", 3.0, r"y0.regulator.pressure is 3 Pa at most: that looks like bar"),
    ("regulated", 0.0, r"y0.regulator.pressure must be an ABSOLUTE pressure > 0 \[Pa\], got 0.0"),
    ("regulated", 2e4, r"y0.regulator.pressure is 20000 Pa at most: .*GAUGE"),
    ("joint", 3.0, r"y0.extensor.pressure is 3 Pa at most: that looks like bar"),
    ("joint", -1e5, r"y0.extensor.pressure must be an ABSOLUTE pressure > 0"),
])
def test_a_start_pressure_kept_in_a_regulators_state_is_checked_like_y0_pressure(kind, pressure, match):
    # simulate read only a top-level y0.pressure: a regulated muscle or a joint started in bar or gauge ran silently
    # (from 3 Pa). Its pressures are now read through the system's `start_pressures`; refused before any solve.
    system, signal, y0 = _nested_start(kind, pressure)
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.simulate(system, signal, np.linspace(0.0, 0.1, 3), y0=y0)


@pytest.mark.parametrize("kind, position, match", [
    # 30 (mm as m) failed at t = 0 with "minimum step size reached"; 0.5 m, outside the 95 mm stroke, too
    ("mas10", 30.0, r"y0\.position = 30 m: more than 1 m; that looks like mm"),
    ("mas10", 0.5, r"y0\.position = 0\.5 m lies outside the stroke its system allows, \[-0\.02, 0\.075\] m"),
    ("mas10", -0.1, r"y0\.position = -0\.1 m lies outside the stroke"),
    ("regulated", 0.4, r"y0\.position = 0\.4 m lies outside the stroke its system allows, \[-0\.02, 0\.1\] m"),
])
def test_a_start_position_in_mm_or_outside_the_stroke_is_named_before_the_solve(kind, position, match):
    # checked as y0's pressures are, through the system's contract (`start_positions`), before anything compiles
    system = (presets.mas10_system("averaged") if kind == "mas10" else
              pamjax.RegulatedMuscleSystem(pamjax.ISO6358Regulator(), presets.dmsp40_muscle()))
    signal = pamjax.Constant(0.5 if kind == "mas10" else 3.0)  # a duty; a regulator's reference voltage [V]
    y0 = system.initial_state(pressure=3e5, position=position)
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.simulate(system, signal, np.linspace(0.0, 0.1, 3), y0=y0)


def test_unchecked_solve_with_its_defaults_gives_simulates_answer():
    # pamjax.unchecked.solve clipped its steps at the smoothed PWM edges only when num_periods was passed (simulate
    # always does: up to 1.5 kPa apart at the default tolerances), and never built the exact valve's switching
    # schedule that simulate builds. Now: the same answer with the defaults; an exact valve traced under jit (no
    # concrete edge times) is refused by name.
    ts = jnp.linspace(0.0, 0.1, 6)
    signal = pamjax.Constant(0.25)
    for mode in ("smooth", "exact"):
        system = presets.mas10_tank_system(presets.mas10_valve(mode))
        reference = pamjax.simulate(system, signal, ts).pressure
        np.testing.assert_allclose(pamjax.unchecked.solve(system, signal, ts, None, 0.0).pressure, reference,
                                   rtol=0, atol=1e-6)
    with pytest.raises(pamjax.PamjaxInputError, match=r"OnOffValve\(mode='exact'\) needs a concrete signal"):
        eqx.filter_jit(lambda s: pamjax.unchecked.solve(s, signal, ts, None, 0.0))(system)


def test_unchecked_solve_picks_simulates_solver():
    # unchecked.solve with solver=None ran the core's Tsit5 (the closed loops keep it) while simulate picks
    # default_solver, Rodas5 for a continuous valve: on the averaged MAS-10's 25 s triangle 3,170 steps against 809,
    # and here 321 against 235, ~5 Pa and 0.06 µm apart. Now the same solver: the same steps, the same answer.
    system, signal, ts = presets.mas10_system("averaged"), pamjax.Triangle(0.05, 0.95, 0.5), np.linspace(0.0, 2.0, 11)
    reference = pamjax.simulate(system, signal, ts)
    traj = pamjax.unchecked.solve(system, signal, ts, None, 0.0)
    assert abs(int(traj.num_steps) - int(reference.num_steps)) <= max(2, int(reference.num_steps) // 50)
    np.testing.assert_allclose(traj.pressure, reference.pressure, rtol=1e-6, atol=0)
    np.testing.assert_allclose(traj.position, reference.position, rtol=0, atol=1e-9)


@pytest.mark.parametrize("value", [[0.5], [0.2, 0.5]])
def test_a_constant_holding_an_array_is_refused_by_name(value):
    # Constant([0.5]) from a data slice constructed (a sweep builds batched Constants on purpose) and simulate then
    # failed with diffrax's raw broadcasting ValueError: a simulated command is one number, several are a sweep.
    with pytest.raises(pamjax.PamjaxInputError, match=r"Constant holds commands of shape \(.*\): simulate takes one"):
        pamjax.simulate(presets.mas10_tank_system(), pamjax.Constant(value), np.linspace(0.0, 0.2, 3))


@pytest.mark.parametrize("valve", ["exact", "pwm"])
def test_grid_stepping_of_a_switching_valve_is_refused_by_name(valve):
    # The uniform grid read the command as one duty at each RK4 stage: not latched per PWM period, the valve's state
    # from the period before lost, 27-30 kPa off the exact-edge solve over a 2 s triangle, not converging as the step
    # shrank. Refused before any solve, pointing to the PWM-synchronous grid; an unchecked solve refuses it too.
    system, signal, ts = presets.mas10_system(valve), pamjax.Triangle(0.05, 0.95, 1.0), np.linspace(0.0, 0.1, 3)
    with pytest.raises(pamjax.PamjaxInputError, match=r"stepping='grid' is for continuous valves.* use stepping='pwm'"):
        pamjax.simulate(system, signal, ts, stepping="grid")
    with pytest.raises(pamjax.PamjaxInputError, match=r"stepping='grid' is for continuous valves"):
        solve(system, signal, jnp.asarray(ts), None, 0.0, stepping="grid", num_periods=100)
    hybrid = presets.mas10_system(valve, friction="karnopp")  # its adaptive solve is refused: 'auto' is advised
    with pytest.raises(pamjax.PamjaxInputError, match=r"use stepping='pwm' .* or stepping='auto'"):
        pamjax.simulate(hybrid, signal, ts, stepping="grid")


@pytest.mark.parametrize("kind", ["muscle", "tank"])
def test_a_start_state_holding_several_values_is_refused_by_name(kind):
    # a y0 holding two pressures failed in a muscle's solve with JAX's raw carry-type TypeError, and a tank returned
    # pressures of shape (n, 2) without a word: one start state is simulated, several are a sweep.
    pressures = jnp.array([2e5, 3e5])
    if kind == "muscle":
        system = presets.mas10_system("averaged")
        with pytest.raises(pamjax.PamjaxInputError, match=r"initial_state: pressure must be one number, got shape "
                                                          r"\(2,\).*jax\.vmap"):
            system.initial_state(pressure=pressures)  # raw carry-type TypeError in the equilibrium's bisection
        y0 = eqx.tree_at(lambda s: s.pressure, system.initial_state(position=0.01), pressures)
    else:
        system = presets.mas10_tank_system("exact")
        y0 = system.initial_state(pressure=pressures)
    with pytest.raises(pamjax.PamjaxInputError, match=r"y0\.pressure has shape \(2,\) where the system's state .* "
                                                      r"holds one number: .*pamjax\.sweep.* jax\.vmap"):
        pamjax.simulate(system, pamjax.Constant(0.5), np.linspace(0.0, 0.1, 3), y0=y0)


def test_forward_mode_autodiff_of_the_default_adjoint_names_adjoint_forward():
    """jax.jacfwd through simulate with its default (reverse-mode) adjoint raised JAX's raw custom_vjp TypeError."""
    system = presets.mas10_system("averaged")

    def loss(m):
        traj = pamjax.simulate(eqx.tree_at(lambda s: s.payload_mass, system, m), pamjax.Constant(0.5),
                               jnp.linspace(0.0, 0.02, 3))
        return jnp.mean(traj.position**2)

    with pytest.raises(pamjax.PamjaxInputError, match='adjoint="forward"'):
        jax.jacfwd(loss)(9.6)
