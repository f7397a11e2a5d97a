"""`linearise`: autodiff Jacobians → state space, transfer functions, Bode data; paper 001 eq. 6-8 reproduced."""

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import counted_compilations
from scipy.optimize import brentq

import pamjax
from pamjax._physics.regulator import BAR, FLOW_UNIT, FeedbackRegulator, LinearRegulator
from pamjax._solve.linearise import StateSpace, equilibrium, linearise
from pamjax._systems.regulated import RegulatorSystem

TAU1, TAU2 = 0.041, 0.023  # eq. 6


def _eq6(f):
    s = 2j * np.pi * f
    return 1.01 / ((1 + TAU1 * s) * (1 + TAU2 * s))


@pytest.fixture(scope="module")
def regulator_model():
    system = RegulatorSystem(LinearRegulator(), volume=0.0)
    y = system.initial_state(pressure=system.air.atmospheric_pressure + 3 * 1.01 * BAR)
    return linearise(system, y, 3.0, inputs={"outlet_flow": lambda s: s.outlet_flow})


def test_eq6_bandwidth_and_eq7_static_gain(regulator_model):
    ss = regulator_model
    # Independent reference: the -3 dB point of eq. 6's formula, solved with SciPy. A drop of exactly 3 dB gives
    # 3.1404 Hz, the paper's 3.14 Hz; the half-power point 1/sqrt(2) (3.0103 dB) would give 3.1470 Hz.
    f3 = brentq(lambda f: abs(_eq6(f)) - 1.01 * 10 ** (-3 / 20), 0.1, 100.0, xtol=1e-12)
    assert f3 == pytest.approx(3.14, abs=0.001)
    assert ss.bandwidth("pressure", "command") == pytest.approx(f3, rel=1e-8)
    assert ss.dc_gain("pressure", "command") / BAR == pytest.approx(1.01, rel=1e-12)
    # eq. 7 in paper units: bar per l/min (ANR)
    assert ss.dc_gain("pressure", "outlet_flow") * FLOW_UNIT / BAR == pytest.approx(-0.922, rel=1e-12)
    f = np.logspace(-1, 2, 30)
    np.testing.assert_allclose(ss.frequency_response(f, 0, 0) / BAR, _eq6(f), rtol=1e-10)


@pytest.mark.parametrize("volts", [0.0, 10.0])
def test_the_voltage_gain_at_the_calibration_ends_is_eq6s(volts):
    # Was: 0.505 bar/V at exactly 0 V and 10 V (the calibration held its ends with jnp.clip, whose derivative at a
    # bound is 1/2), 1.01 everywhere else.
    system = RegulatorSystem(LinearRegulator(), volume=0.0)
    y = system.initial_state(pressure=system.air.atmospheric_pressure + volts * 1.01 * BAR)
    ss = linearise(system, y, volts, inputs={"outlet_flow": lambda s: s.outlet_flow})
    assert ss.dc_gain("pressure", "command") / BAR == pytest.approx(1.01, rel=1e-12)


def test_transfer_function_coefficients(regulator_model):
    num, den = regulator_model.transfer_function("pressure", "command")
    # eq. 6: 1.01/(τ1τ2 s² + (τ1+τ2) s + 1), normalised to a monic denominator
    scale = TAU1 * TAU2
    np.testing.assert_allclose(den, [1.0, (TAU1 + TAU2) / scale, 1.0 / scale], rtol=1e-10)
    np.testing.assert_allclose(num, [1.01 * BAR / scale], rtol=1e-10)


def test_eq8_feedback_form_matches_its_formula():
    # eq. 8 is linear: its model is the same at any operating point; at 0 V (not 2 V: with K1 = 0.7 the static gain
    # is -9.5 bar/V, and 2 V an outlet at -18 bar abs, which `linearise` refuses as `simulate` refuses it in y0)
    reg = FeedbackRegulator(k1=0.7, k2=0.3)
    system = RegulatorSystem(reg, volume=0.0)
    y = equilibrium(system, 0.0, system.initial_state())
    ss = linearise(system, y, 0.0, inputs={"outlet_flow": lambda s: s.outlet_flow})
    f = np.logspace(-2, 2, 25)
    s = 2j * np.pi * f
    gv = 1.01 / ((1 + TAU1 * s) * (1 + TAU2 * s))
    gq = -0.922 / ((1 + TAU1 * s) * (1 + TAU2 * s))
    tv = 0.7 * gv * gq / (1 + gv * gq)  # eq. 8, bar/V
    tq = 0.3 * gq / (1 + gv * gq)  # eq. 8, bar per l/min
    np.testing.assert_allclose(ss.frequency_response(f, 0, 0) / BAR, tv, rtol=1e-9)
    np.testing.assert_allclose(ss.frequency_response(f, 0, 1) * FLOW_UNIT / BAR, tq, rtol=1e-9)
    # default K1, K2 reproduce eq. 5's static gains
    d = RegulatorSystem(FeedbackRegulator(), volume=0.0)
    ssd = linearise(d, equilibrium(d, 3.0, d.initial_state()), 3.0, inputs={"outlet_flow": lambda s: s.outlet_flow})
    assert ssd.dc_gain(0, 0) / BAR == pytest.approx(1.01, rel=1e-9)
    assert ssd.dc_gain(0, 1) * FLOW_UNIT / BAR == pytest.approx(-0.922, rel=1e-9)


def test_muscle_system_jacobian_matches_finite_differences():
    system = pamjax.presets.mas10_system(valve="averaged")
    y = system.initial_state(pressure=3e5)
    u = 0.6
    ss = linearise(system, y, u, outputs=("pressure", "force"))
    scale = system.state_scale()
    names = ["pressure", "position", "velocity"]
    for j, name in enumerate(names):
        h = 1e-6 * float(getattr(scale, name))

        def f(delta):
            yy = type(y)(**{**{k: getattr(y, k) for k in names + ["friction"]}, name: getattr(y, name) + delta})
            d = system.vector_field(0.0, yy, jnp.asarray(u))
            return np.array([float(getattr(d, k)) for k in names])

        fd = (f(h) - f(-h)) / (2 * h)
        np.testing.assert_allclose(ss.A[:, j], fd, rtol=1e-5, atol=1e-8 * np.abs(ss.A).max())
    h = 1e-6
    fb = system.vector_field(0.0, y, jnp.asarray(u + h)).pressure
    fa = system.vector_field(0.0, y, jnp.asarray(u - h)).pressure
    assert ss.B[0, 0] == pytest.approx(float(fb - fa) / (2 * h), rel=1e-6)
    assert ss.output_names == ("pressure", "force")
    with pytest.raises(pamjax.PamjaxInputError, match="unknown output"):
        linearise(system, y, u, outputs=("torque",))


def test_a_second_linearisation_compiles_nothing_new():
    """`linearise` about another operating point, time or command of the same system reuses its one program (it
    compiled anew at every call before, ~0.25 s each), and gives what a first call there gives."""
    system = pamjax.presets.mas10_system(valve="averaged")
    linearise(system, system.initial_state(pressure=3e5), 0.6, outputs=("pressure", "force"))
    with counted_compilations() as compiled:
        again = linearise(system, system.initial_state(pressure=4e5), 0.4, t=0.5, outputs=("pressure", "force"))
    assert compiled == [], compiled
    fresh = linearise(pamjax.presets.mas10_system(valve="averaged"), system.initial_state(pressure=4e5), 0.4, t=0.5,
                      outputs=("pressure", "force"))
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))
    h = 1e-6
    fb = system.vector_field(0.5, system.initial_state(pressure=4e5), jnp.asarray(0.4 + h)).pressure
    fa = system.vector_field(0.5, system.initial_state(pressure=4e5), jnp.asarray(0.4 - h)).pressure
    assert again.B[0, 0] == pytest.approx(float(fb - fa) / (2 * h), rel=1e-6)


def test_python_control_cross_check(regulator_model):
    control = pytest.importorskip("control")
    sys = regulator_model.to_control()
    siso = control.ss(sys.A, sys.B[:, :1], sys.C, sys.D[:, :1])
    assert float(np.real(control.dcgain(siso))) / BAR == pytest.approx(1.01, rel=1e-9)
    bw_hz = control.bandwidth(siso) / (2 * np.pi)
    assert bw_hz == pytest.approx(regulator_model.bandwidth(0, 0), rel=1e-4)
    mag, phase, omega = control.frequency_response(siso, 2 * np.pi * np.array([0.5, 3.0, 20.0]))
    np.testing.assert_allclose(
        np.ravel(mag), np.abs(regulator_model.frequency_response([0.5, 3.0, 20.0], 0, 0)), rtol=1e-9
    )


@pytest.mark.parametrize("command", [-0.3, 1.5, float("nan")])
def test_a_command_outside_the_range_is_named_before_any_solve(command):
    """Eq. 13's parabola extrapolates: duty -0.3 gave a 2 MPa "equilibrium", NaN a NaN B. Refused, as `simulate`
    refuses such a signal; and a regulator's 0-10 V."""
    system = pamjax.presets.mas10_system(valve="averaged")
    guess = system.initial_state(pressure=4e5)
    with pytest.raises(pamjax.PamjaxInputError, match="command"):
        equilibrium(system, command, guess)
    with pytest.raises(pamjax.PamjaxInputError, match="command"):
        linearise(system, guess, command)
    regulated = RegulatorSystem(LinearRegulator(), volume=0.0)
    with pytest.raises(pamjax.PamjaxInputError, match=r"command.*\[0\.0, 10\.0\]"):
        equilibrium(regulated, 12.0, regulated.initial_state())


@pytest.fixture(scope="module")
def bouc_wen_settled():
    """The MAS-10 with Bouc–Wen friction (a memory state) at duty 0.6, and its state after a 10 s `simulate`."""
    system = pamjax.presets.mas10_system(valve="averaged", friction="bouc_wen")
    traj = pamjax.simulate(system, pamjax.Constant(0.6), np.linspace(0.0, 10.0, 3))
    return system, jax.tree_util.tree_map(lambda a: a[-1], traj.state)


def test_equilibrium_with_a_memory_state_is_the_settled_state(bouc_wen_settled):
    """The friction state's rate vanishes at rest whatever its value: a continuum of equilibria, a singular Jacobian
    (Newton's solve went to NaN). The least-squares steps converge to the equilibrium nearest the guess: from the
    settled state of a long simulate, with its pressure off by 5 kPa, back to that state."""
    system, settled = bouc_wen_settled
    guess = eqx.tree_at(lambda s: s.pressure, settled, settled.pressure + 5e3)
    eq = equilibrium(system, 0.6, guess)
    # measured: pressure 6e-8 Pa, position 7e-10 m, friction state 4e-10 m apart (the simulate settled to 1e-13 m/s)
    assert float(eq.pressure) == pytest.approx(float(settled.pressure), abs=1.0)
    assert float(eq.position) == pytest.approx(float(settled.position), abs=1e-7)
    assert float(eq.friction) == pytest.approx(float(settled.friction), abs=1e-7)
    rate = system.vector_field(0.0, eq, jnp.asarray(0.6))
    assert abs(float(rate.pressure)) < 1e-3 and abs(float(rate.velocity)) < 1e-9 and abs(float(eq.velocity)) < 1e-12


def test_a_failed_equilibrium_prints_values_and_names_the_singular_state(bouc_wen_settled):
    system, _ = bouc_wen_settled
    with pytest.raises(pamjax.PamjaxSolveError) as failed:
        equilibrium(system, 0.6, system.initial_state(pressure=5.4e5), max_steps=1)
    message = str(failed.value)
    assert "f64[" not in message and re.search(r"pressure=5\d{5}", message), message  # values, not shapes
    assert "singular" in message and "friction" in message and "simulate" in message, message


def test_a_system_simulate_refuses_is_refused_before_anything_is_computed():
    """`linearise` and `equilibrium` ran none of `simulate`'s parameter checks: with payload_mass = -1 set by
    `eqx.tree_at`, equilibrium returned a state and linearise an A with a positive pole; with k2 = 0 linearise gave a
    NaN row. Both now refuse them by name, as `simulate` does, compiling nothing."""
    system = pamjax.presets.mas10_system(valve="averaged")
    guess = system.initial_state(pressure=4e5)
    for where, value, match in ((lambda s: s.payload_mass, -1.0, r"payload_mass must be > 0 and finite, got -1"),
                                (lambda s: s.muscle.force_law.k2, 0.0, r"PolynomialForce\.k2 must be > 0")):
        bad = eqx.tree_at(where, system, value)
        with counted_compilations() as compiled:
            with pytest.raises(pamjax.PamjaxInputError, match=match):
                equilibrium(bad, 0.5, guess)
            with pytest.raises(pamjax.PamjaxInputError, match=match):
                linearise(bad, guess, 0.5)
        assert compiled == [], compiled


def test_a_state_or_time_that_is_not_finite_is_named_before_anything_is_computed():
    """A NaN pressure in the operating point gave NaN rows of A (and a NaN guess a 'did not converge' without the
    cause): the leaf is named."""
    system = pamjax.presets.mas10_system(valve="averaged")
    state = system.initial_state(pressure=4e5)
    nan_pressure = eqx.tree_at(lambda s: s.pressure, state, jnp.asarray(np.nan))
    with counted_compilations() as compiled:
        with pytest.raises(pamjax.PamjaxInputError, match=r"state\.pressure must be finite \(no NaN or inf\), got nan"):
            linearise(system, nan_pressure, 0.5)
        with pytest.raises(pamjax.PamjaxInputError, match=r"guess\.pressure must be finite"):
            equilibrium(system, 0.5, nan_pressure)
        with pytest.raises(pamjax.PamjaxInputError, match=r"\bt must be finite"):
            linearise(system, state, 0.5, t=np.inf)
    assert compiled == [], compiled


def test_derivatives_that_are_not_finite_are_refused_naming_where():
    """A finite operating point far outside the model's domain (the payload moving at 1e308 m/s: a position 1e200 m up
    is now refused as a start state, in mm) has non-finite derivatives: refused with a `PamjaxSolveError` naming the
    rows and columns, never returned as a model (the program is the one the tests above compiled for this system);
    `equilibrium` from there says its state left the model's domain."""
    system = pamjax.presets.mas10_system(valve="averaged")
    far = eqx.tree_at(lambda s: s.velocity, system.initial_state(pressure=4e5), jnp.asarray(1e308))
    with pytest.raises(pamjax.PamjaxSolveError, match=r"not finite.*A: ∂\(state\.pressure, state\.velocity\)/∂"):
        linearise(system, far, 0.5, outputs=("pressure", "force"))
    with pytest.raises(pamjax.PamjaxSolveError, match=r"left the model's domain: its state turned non-finite"):
        equilibrium(system, 0.5, far)  # (was: "did not converge ... or a larger max_steps")


def test_a_command_that_is_not_one_number_is_refused():
    """An array command broadcast into the state: `equilibrium` returned a "state" whose pressure was a pair and whose
    rates were not zero, `linearise` an A of shape (4, 3). Refused by name, before anything is computed."""
    system = pamjax.presets.mas10_system(valve="averaged")
    guess = system.initial_state(pressure=4e5)
    with counted_compilations() as compiled:
        for command in (np.array([0.5, 0.6]), [0.5], np.array([[0.5]])):
            with pytest.raises(pamjax.PamjaxInputError, match=r"command must be one number .*got shape"):
                equilibrium(system, command, guess)
            with pytest.raises(pamjax.PamjaxInputError, match=r"command must be one number"):
                linearise(system, guess, command)
    assert compiled == [], compiled


def test_an_operating_point_or_guess_simulate_refuses_as_a_start_is_refused():
    """A pressure in bar (5.4) gave the poles of a model at a vacuum, a position in mm (30) a model 30 m up: refused
    as `simulate` refuses them in `y0`, naming the leaf, before anything is computed."""
    system = pamjax.presets.mas10_system(valve="averaged")
    bar = system.initial_state(pressure=5.4, position=0.03)
    mm = system.initial_state(pressure=5.4e5, position=30.0)
    with counted_compilations() as compiled:
        with pytest.raises(pamjax.PamjaxInputError, match=r"state\.pressure is 5\.4 Pa at most: that looks like bar"):
            linearise(system, bar, 0.6)
        with pytest.raises(pamjax.PamjaxInputError, match=r"guess\.pressure .*bar"):
            equilibrium(system, 0.6, bar)
        with pytest.raises(pamjax.PamjaxInputError, match=r"state\.position.*mm"):
            linearise(system, mm, 0.6)
    assert compiled == [], compiled


def test_a_pole_at_zero_gives_the_limit_where_it_cancels_and_is_named_where_it_does_not(bouc_wen_settled):
    """A memory state (Bouc-Wen friction here; bristle friction, a regulator's hysteresis) puts a pole at 0 in A:
    dc_gain and bandwidth raised numpy's raw LinAlgError at `equilibrium`'s state, and at a settled state's (a pole
    at 1e-12 of the largest) gave G at exactly 0, not the limit the response tends to. The pole cancels in the
    command-to-position channel (the command does not drive the memory state): dc_gain is the limit G(0⁺), equal to
    the response at a low frequency. An integrator a channel keeps (ẋ = u) is a `PamjaxInputError` naming the pole
    at 0 and the state, not a LinAlgError."""
    system, settled = bouc_wen_settled
    for point in (settled, equilibrium(system, 0.6, settled)):
        ss = linearise(system, point, 0.6, outputs=("position",))
        assert np.min(np.abs(ss.poles())) < 1e-9 * np.max(np.abs(ss.poles()))
        low = ss.frequency_response(1e-8, "position")[0]
        assert ss.dc_gain("position") == pytest.approx(low.real, rel=1e-6) and ss.dc_gain("position") > 0
        assert 0.1 < ss.bandwidth("position") < 100.0
    integrator = pamjax.StateSpace(A=np.array([[-1.0, 0.0], [0.0, 0.0]]), B=np.ones((2, 1)), C=np.ones((1, 2)),
                                   D=np.zeros((1, 1)), state_names=("lag", "ramp"), input_names=("u",),
                                   output_names=("y",))
    for method in (integrator.dc_gain, integrator.bandwidth):
        with pytest.raises(pamjax.PamjaxInputError, match=r"G\(0\) of y / u .* infinite: .*\(in the rates of ramp"):
            method()
    assert np.isfinite(integrator.frequency_response(0.1)[0])


def test_bad_channel_frequency_drop_and_newton_settings_are_named(regulator_model):
    """An output index past the last gave a raw IndexError; a negative frequency and a drop_db <= 0 silently gave
    numbers (the bandwidth was the search grid's first point, 1e-4 Hz); equilibrium's max_steps=-1 and rtol=NaN
    ran to a "did not converge". Each refused, naming the argument."""
    ss = regulator_model
    with pytest.raises(pamjax.PamjaxInputError, match=r"output index 5 is out of range: this model has 1 outputs"):
        ss.frequency_response(1.0, output=5)
    with pytest.raises(pamjax.PamjaxInputError, match=r"input index -1 is out of range"):
        ss.dc_gain(0, -1)
    with pytest.raises(pamjax.PamjaxInputError, match=r"frequency must be finite and >= 0"):
        ss.frequency_response([1.0, -1.0])
    for drop in (0.0, -3.0, np.nan):
        with pytest.raises(pamjax.PamjaxInputError, match=r"drop_db must be a finite number > 0"):
            ss.bandwidth(drop_db=drop)
    system = pamjax.presets.mas10_system(valve="averaged")
    guess = system.initial_state(pressure=4e5)
    with counted_compilations() as compiled:
        for kwargs, match in ((dict(max_steps=-1), "max_steps must be an int >= 1"),
                              (dict(max_steps=2.5), "max_steps must be an int >= 1"),
                              (dict(rtol=np.nan), "rtol must be a finite number > 0"),
                              (dict(atol=0.0), "atol must be a finite number > 0")):
            with pytest.raises(pamjax.PamjaxInputError, match=match):
                equilibrium(system, 0.6, guess, **kwargs)
    assert compiled == [], compiled


def test_a_joint_is_linearised_about_its_command_vector():
    """`linearise` and `equilibrium` refused the `AntagonisticJoint` (docs: "works on any pamjax system") with its
    (V_f, V_e) command ("command must be one number") and with one voltage. A vector is taken where the system's rates
    keep the state's shapes: B and D get a column per voltage, and the static angle gain per volt matches the
    equilibria's finite difference. One voltage, or three, are refused by the joint's own message."""
    m = pamjax.presets.dmsp40_muscle()
    joint = pamjax.AntagonisticJoint(pamjax.ISO6358Regulator(), pamjax.ISO6358Regulator(), m, m)
    command = jnp.array([3.0, 2.0])
    y = equilibrium(joint, command, joint.initial_state(101325.0 + 3.03e5, 101325.0 + 2.02e5))
    ss = linearise(joint, y, command, outputs=("angle",))
    assert ss.B.shape == (8, 2) and ss.input_names == ("command[0]", "command[1]")
    assert np.all(np.real(ss.poles()) < 0)
    h = 0.01
    moved = equilibrium(joint, command + jnp.array([h, 0.0]), y)
    fd = (float(moved.angle) - float(y.angle)) / h
    assert ss.dc_gain("angle", "command[0]") == pytest.approx(fd, rel=5e-3)
    assert ss.dc_gain("angle", "command[1]") < 0 < ss.dc_gain("angle", "command[0]")
    for bad in (3.0, jnp.array([3.0, 2.0, 1.0])):
        with pytest.raises(pamjax.PamjaxInputError, match=r"must be \(flexor, extensor\) voltages, shape \(2,\)"):
            linearise(joint, y, bad)


def test_equilibrium_is_reverse_differentiable_with_the_implicit_derivative():
    """jax.grad through `equilibrium` raised JAX's while-loop error; its derivative is the implicit function's,
    equal to jax.jacfwd's and to finite differences."""
    system = pamjax.presets.mas10_system("averaged")
    guess = system.initial_state(pressure=3e5)

    def position(m):
        return equilibrium(eqx.tree_at(lambda s: s.payload_mass, system, m), 0.5, guess).position

    grad = float(jax.grad(position)(9.6))
    fd = float((position(9.6 + 1e-4) - position(9.6 - 1e-4)) / 2e-4)
    np.testing.assert_allclose(grad, float(jax.jacfwd(position)(9.6)), rtol=1e-8)
    np.testing.assert_allclose(grad, fd, rtol=1e-5)


def test_a_root_the_system_cannot_reach_is_refused():
    """Eq. 13's polynomial in p has a second root far above the supply: from a guess at 6e5 Pa, duty 0.1 converged
    to p = 2.52 MPa abs (4x the MAS-10's 0.65 MPa supply, x = 75.2 mm) with no error, where `simulate` settles at
    0.131 MPa. Refused, naming the pressure and the bound; from a guess near the state it is found."""
    system = pamjax.presets.mas10_system("averaged")
    with pytest.raises(pamjax.PamjaxSolveError, match=r"cannot reach.*pressure = 2\.51\d+e\+06 Pa abs lies outside "
                                                      r"\[\d+, 6\d{5}\] Pa abs.*guess nearer.*simulate to rest"):
        equilibrium(system, 0.1, system.initial_state(pressure=6e5))
    near = equilibrium(system, 0.1, system.initial_state(pressure=1.5e5))
    assert float(near.pressure) == pytest.approx(131295.0, rel=1e-4)



def test_a_stick_slip_equilibrium_holds_its_stuck_mode_and_has_no_linear_model():
    """KarnoppFriction: the stuck mode's position and velocity rates are 0 at every position, so Newton's method kept
    the guess's position: from guesses at 4e5 and 2.5e5 Pa, duty 0.5 "converged" at 26.96 and 16.85 mm where the net
    force on the payload is 45.7 and 96.7 N, beyond F_c = 16 N (simulated from there, it moved to 35.2 mm), and
    `linearise` there gave three poles at 0. Refused, naming the force and the friction-free rest position; a guess
    that holds gives an equilibrium within ±F_c; a sliding or moving guess, and linearising a stuck state, are refused
    before anything is computed, naming the smooth twin."""
    system = pamjax.presets.mas10_system("averaged", friction="karnopp")
    with pytest.raises(pamjax.PamjaxSolveError, match=r"position = 26\.95\d* mm.*net force on it is 45\.\d+ N, "
                                                      r"beyond F_c = 16 N.*rest position 39\.90\d* mm"):
        equilibrium(system, 0.5, system.initial_state(pressure=4e5))
    rest = equilibrium(system, 0.5, system.initial_state(pressure=4.6e5))
    assert float(rest.friction) == 0.0 and float(rest.velocity) == 0.0
    assert abs(float(system.outputs(0.0, rest, 0.5)["friction_force"])) <= 16.0
    with pytest.raises(pamjax.PamjaxInputError, match=r"stuck.*no small-signal model.*CoulombViscousFriction"
                                                      r"\(coulomb_force=16, viscous_coefficient=250\)"):
        linearise(system, rest, 0.5)
    moving = eqx.tree_at(lambda s: s.velocity, rest, jnp.asarray(0.2))
    with counted_compilations() as compiled:
        for guess, kind in ((system.initial_state(pressure=4.6e5, velocity=0.01), "sliding"), (moving, "stuck")):
            with pytest.raises(pamjax.PamjaxInputError, match=rf"guess is {kind}.* at velocity 0\.\d+ m/s"):
                equilibrium(system, 0.5, guess)
    assert compiled == [], compiled

def test_a_switching_valve_is_refused_naming_the_averaged_one():
    """A PWM valve was frozen at the PWM phase of `t`: "equilibria" at 101325 Pa (t = 0) and -1.09e9 Pa (t = 5 ms),
    and a static gain of 0. Refused before anything is computed, naming the averaged valve."""
    system = pamjax.presets.mas10_system("pwm")
    guess = system.initial_state()
    with counted_compilations() as compiled:
        with pytest.raises(pamjax.PamjaxInputError, match=r"system\.valve \(OnOffValve\) switches.*AveragedValve"):
            equilibrium(system, 0.5, guess, t=0.005)
        with pytest.raises(pamjax.PamjaxInputError, match=r"switches.*mas10_system\(\"averaged\"\)"):
            linearise(system, guess, 0.5)
    assert compiled == [], compiled


def test_a_bandwidth_below_the_search_grid_is_found():
    """With τ₁ = 4000 s the -3 dB point, 3.97e-5 Hz, lies below the search grid's 1e-4 Hz, which came back."""
    # G(s) = 1/((1 + 4000 s)(1 + s)) as a state space (a regulator with τ₁ = 4000 s is refused: time constants
    # above 10 s look like ms), x1' = (u − x1)/4000, x2' = x1 − x2, y = x2
    ss = StateSpace(np.array([[-1 / 4000, 0.0], [1.0, -1.0]]), np.array([[1 / 4000], [0.0]]), np.array([[0.0, 1.0]]),
                    np.zeros((1, 1)), ("x1", "x2"), ("u",), ("y",))
    exact = brentq(lambda f: abs(1 / ((1 + 4000j * 2 * np.pi * f) * (1 + 2j * np.pi * f))) - 10 ** (-3 / 20),
                   1e-9, 1.0, xtol=1e-16)
    assert ss.bandwidth() == pytest.approx(exact, rel=1e-6)


def test_bad_frequencies_inputs_and_hand_built_models_are_named(regulator_model):
    """A 2-D frequency array, an input selecting a sub-module or given as a list, an input named "command" (its
    column read as the command's), and a hand-built model whose matrices disagree in shape each raised a raw
    ValueError or TypeError, or were accepted."""
    with pytest.raises(pamjax.PamjaxInputError, match=r"frequency must be one number or a 1-D array"):
        regulator_model.bode(np.array([[0.1, 1.0], [2.0, 3.0]]))
    system = RegulatorSystem(LinearRegulator(), volume=0.0)
    y = system.initial_state(pressure=system.air.atmospheric_pressure + 3 * 1.01 * BAR)
    with counted_compilations() as compiled:
        for inputs, match in (({"air": lambda s: s.air}, r"inputs\['air'\] must select an array leaf .*'Air'"),
                              ([lambda s: s.outlet_flow], r"inputs must be a dict name → function"),
                              ({"command": lambda s: s.outlet_flow}, r"names must differ from the command's")):
            with pytest.raises(pamjax.PamjaxInputError, match=match):
                linearise(system, y, 3.0, inputs=inputs)
    assert compiled == [], compiled
    with pytest.raises(pamjax.PamjaxInputError, match=r"StateSpace: .*B has shape \(2, 1\), expected \(1, 1\)"):
        pamjax.StateSpace(A=-np.eye(1), B=np.ones((2, 1)), C=np.ones((1, 1)), D=np.zeros((1, 1)), state_names=("x",),
                          input_names=("u",), output_names=("y",))


def test_linearising_a_hysteretic_regulator_warns_that_its_gain_at_rest_averages_the_branches():
    """The VPPM at rest after a rise to 3 V: dc_gain 0.510 bar/V where a +0.1 V step moves the outlet 1.010 bar/V and
    a -0.1 V step 0.509 bar/V (the smoothed |dp_set/dt| has zero slope at rest). Said, where it was silent."""
    system = RegulatorSystem(pamjax.vppm_regulator(), volume=5e-5)
    y = system.initial_state(pressure=system.air.atmospheric_pressure + 3 * 1.01 * BAR)
    with pytest.warns(UserWarning, match=r"averages the rising and falling branches"):
        linearise(system, y, 3.0)
