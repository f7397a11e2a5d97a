"""Paper 001: tabulated ISO 6358 flow (Tables 1-2), the VPPM regulator models and the muscle-side eq. 9-11."""

import equinox as eqx
import jax
import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator

import pamjax
from pamjax._physics.calibration import PreparedVoltageCalibration
from pamjax._physics.regulator import (
    PAPER001_AIR,
    ISO6358Regulator,
    LinearRegulator,
    VoltageCalibration,
)
from pamjax._physics.signals import SquareWave
from pamjax._physics.tabulated import (
    PreparedTabulatedRestriction,
    TabulatedISO6358Restriction,
    paper001_charging_restriction,
    pchip,
    prepared_tables,
)
from pamjax._systems.regulated import RegulatedMuscleSystem, RegulatorSystem, muscle_stiffness, stiffness_rate
from pamjax.presets import PAPER001_CHARGING_TABLE, PAPER001_DISCHARGING_TABLE, dmsp40_muscle

P_ATM = 101325.0

# The library functions the tests evaluate point by point, jitted once each (per shape), the numbers as array
# arguments: called eagerly, every operation of every evaluation would compile a program of its own.
_pchip = jax.jit(pchip)
_pchip_many = jax.jit(jax.vmap(pchip, in_axes=(None, None, 0)))
_mass_flow = eqx.filter_jit(lambda restriction, p1, p2: restriction.mass_flow(p1, p2, PAPER001_AIR))
_volume = eqx.filter_jit(lambda muscle, x: muscle.volume(x))
_volume_slope = eqx.filter_jit(lambda muscle, x: muscle.volume_slope(x))
_force = eqx.filter_jit(lambda muscle, x, p: muscle.force(x, p, PAPER001_AIR))
_muscle_stiffness = eqx.filter_jit(muscle_stiffness)
_stiffness_rate = eqx.filter_jit(stiffness_rate)


@pytest.mark.parametrize("table", [PAPER001_CHARGING_TABLE, PAPER001_DISCHARGING_TABLE])
@pytest.mark.parametrize("column", ["critical_ratio", "sonic_conductance_m3_per_s_bar"])
def test_pchip_matches_scipy_and_stays_within_each_interval(table, column):
    x = np.asarray(table.get("upstream_pressure_bar", table.get("tank_pressure_bar")))
    y = np.asarray(table[column])
    xq = np.linspace(x[0], x[-1], 301)
    ours = np.asarray(_pchip_many(x, y, xq))
    # Independent reference: SciPy's PCHIP. Same algorithm, float64: agreement to round-off.
    np.testing.assert_allclose(ours, PchipInterpolator(x, y)(xq), rtol=1e-12, atol=1e-15 * np.abs(y).max())
    i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, len(x) - 2)
    lo, hi = np.minimum(y[i], y[i + 1]), np.maximum(y[i], y[i + 1])
    assert np.all(ours >= lo - 1e-15) and np.all(ours <= hi + 1e-15)  # monotone-safe: no overshoot
    # end values held outside the table
    assert float(_pchip(x, y, np.asarray(x[0] - 1.0))) == pytest.approx(y[0])
    assert float(_pchip(x, y, np.asarray(x[-1] + 1.0))) == pytest.approx(y[-1])


def test_pchip_slope_at_the_table_ends_is_the_interior_one():
    # Was: `jnp.clip` held the end values, and JAX's derivative of clip AT a bound is 1/2: the calibration's gain at
    # exactly 0 V and 10 V was 0.505 bar/V instead of 1.01 (pj.linearise of LinearRegulator halved its static gain).
    x = np.asarray(PAPER001_CHARGING_TABLE["upstream_pressure_bar"]) * 1e5
    y = np.asarray(PAPER001_CHARGING_TABLE["sonic_conductance_m3_per_s_bar"])
    slope = jax.jit(jax.vmap(jax.grad(pchip, argnums=2), in_axes=(None, None, 0)))
    h = 1e-4 * (x[1] - x[0])
    for end, inward in ((x[0], h), (x[-1], -h)):
        one_sided = (float(_pchip(x, y, np.asarray(end + inward))) - float(_pchip(x, y, np.asarray(end)))) / inward
        assert float(slope(x, y, np.asarray([end]))[0]) == pytest.approx(one_sided, rel=1e-3)
    assert np.all(np.asarray(slope(x, y, np.asarray([x[0] - 1.0, x[-1] + 1.0]))) == 0.0)  # held beyond the ends
    calibration = VoltageCalibration()
    for part in (calibration, calibration.prepared()):
        gains = jax.jit(jax.vmap(jax.grad(part)))(np.asarray([0.0, 5.0, 10.0]))
        np.testing.assert_allclose(np.asarray(gains) / 1e5, 1.01, rtol=1e-12)


def _eq13_reference(c_si, b, p_in, p_out, temperature):
    """Paper 001 eq. 13-14 (ratio form), NumPy: mass flow = ρ0 C p_in sqrt(T0/T) φ."""
    r = p_out / p_in
    phi = 1.0 if r <= b else np.sqrt(1.0 - ((r - b) / (1.0 - b)) ** 2)
    return 1.185 * c_si * p_in * np.sqrt(293.15 / temperature) * phi


def test_tabulated_flow_at_table_rows_matches_eq13():
    t = PAPER001_CHARGING_TABLE
    restriction = paper001_charging_restriction()
    for p_bar, b, c in zip(t["upstream_pressure_bar"], t["critical_ratio"], t["sonic_conductance_m3_per_s_bar"]):
        p_in = p_bar * 1e5
        for ratio in (0.2, b + 0.5 * (1 - b), 0.95):
            ours = float(_mass_flow(restriction, np.asarray(p_in), np.asarray(ratio * p_in)))
            ref = _eq13_reference(c / 1e5, b, p_in, ratio * p_in, 298.0)
            assert ours == pytest.approx(ref, rel=1e-12)


def test_prepared_tables_give_the_same_flows_calibration_and_gradients():
    # A solve computes each interpolant's table once, ahead of its loop (`prepared_tables`): the same numbers as the
    # model's own PCHIPs, the same derivatives with respect to the table entries (which a fit may free), and only
    # inside the solve (the model itself keeps its plain parts).
    system = RegulatorSystem(pamjax.vppm_regulator(), volume=1e-6)
    prepared = prepared_tables(system)
    regulator, ready = system.regulator, prepared.regulator
    assert isinstance(ready.charging, PreparedTabulatedRestriction) and isinstance(
        ready.calibration, PreparedVoltageCalibration)
    assert not isinstance(regulator.charging, PreparedTabulatedRestriction)
    assert prepared_tables(prepared).regulator.charging is ready.charging  # prepared once
    pressures = np.linspace(1.0e5, 9.0e5, 41)
    for plain, fast in ((regulator.charging, ready.charging), (regulator.discharging, ready.discharging)):
        for method in ("conductance", "ratio"):
            np.testing.assert_allclose(_calls(plain, method, pressures), _calls(fast, method, pressures), rtol=1e-14)
    volts = np.linspace(-1.0, 11.0, 25)  # beyond the table: held end values
    np.testing.assert_allclose(_calls(regulator.calibration, "__call__", volts),
                               _calls(ready.calibration, "__call__", volts), rtol=1e-14, atol=1e-9)
    gauge = np.asarray(_calls(regulator.calibration, "__call__", volts))
    np.testing.assert_allclose(_calls(ready.calibration, "inverse", gauge), np.clip(volts, 0.0, 10.0), atol=1e-12)
    state = system.initial_state()
    for volt in (0.5, 3.0, 9.0):
        np.testing.assert_allclose(jax.tree.leaves(_field(system, state, volt)),
                                   jax.tree.leaves(_field(prepared, state, volt)), rtol=1e-13)
    grads = [_table_gradient(wrap, regulator.charging) for wrap in (lambda r: r, lambda r: r.prepared())]
    assert np.all(np.isfinite(grads[0])) and np.any(grads[0] != 0)
    np.testing.assert_allclose(grads[1], grads[0], rtol=1e-12)


_calls = eqx.filter_jit(lambda part, method, x: jax.vmap(getattr(part, method))(x))
_field = eqx.filter_jit(lambda system, state, volt: system.vector_field(0.0, state, volt))


def _table_gradient(wrap, restriction):
    """d(flow at 4.5 bar into 2 bar)/d(the C table), through `wrap(restriction)` with the table traced."""

    def flow(c):
        part = wrap(eqx.tree_at(lambda r: r.sonic_conductance, restriction, c))
        return part.mass_flow(4.5e5, 2.0e5, PAPER001_AIR)

    return np.asarray(jax.jit(jax.grad(flow))(restriction.sonic_conductance))


def test_bad_tables_and_voltages_are_named():
    p = np.array([2e5, 3e5, 4e5])
    with pytest.raises(pamjax.PamjaxInputError, match="pressure.*strictly increasing"):
        TabulatedISO6358Restriction(np.array([2e5, 4e5, 3e5]), np.full(3, 1e-9), np.full(3, 0.5))
    with pytest.raises(pamjax.PamjaxInputError, match="sonic_conductance"):
        TabulatedISO6358Restriction(p, np.array([1e-9, -1e-9, 1e-9]), np.full(3, 0.5))
    with pytest.raises(pamjax.PamjaxInputError, match="critical_ratio"):
        TabulatedISO6358Restriction(p, np.full(3, 1e-9), np.array([0.5, 1.2, 0.5]))
    with pytest.raises(pamjax.PamjaxInputError, match="VoltageCalibration.voltage"):
        VoltageCalibration(voltage=(0.0, 12.0), gauge_pressure=(0.0, 1e6))
    # a calibration table in bar (0-10.1) set 3.03 Pa at 3 V without a word
    with pytest.raises(pamjax.PamjaxInputError, match=r"gauge_pressure reaches 10.1 Pa at most: that looks like bar"):
        VoltageCalibration(gauge_pressure=(0.0, 10.1))
    with pytest.raises(pamjax.PamjaxInputError, match=r"\[0.0, 10.0\]"):
        pamjax.simulate(RegulatorSystem(LinearRegulator(), volume=0.0), SquareWave(0.0, 12.0), np.linspace(0, 0.1, 3))
    # a tank fed by a regulator: a TankSystem took one and crashed in its solve (AttributeError: no `mass_flow`);
    # `TankFromModel` (a config's `tank_volume`) of a regulator-fed model built that TankSystem
    with pytest.raises(pamjax.PamjaxInputError, match=r"TankSystem.valve must be a valve .* got ISO6358Regulator: a "
                                                      r"tank fed by a pressure regulator is a RegulatorSystem"):
        pamjax.TankSystem(valve=ISO6358Regulator(), volume=5e-5)
    tank = pamjax.TankFromModel(5e-5)(RegulatedMuscleSystem(ISO6358Regulator(), dmsp40_muscle()))
    assert isinstance(tank, RegulatorSystem) and float(tank.volume) == 5e-5


def test_linear_regulator_step_matches_eq6_analytically():
    system = RegulatorSystem(LinearRegulator(), volume=0.0)  # closed port: Q_in = 0
    ts = np.linspace(0.0, 0.4, 81)
    traj = pamjax.simulate(system, pamjax.Constant(3.0), ts, rtol=1e-10, atol=1e-10)
    t1, t2 = 0.041, 0.023
    t = np.asarray(ts)
    # Inverse Laplace of 1.01·3/(s (1 + t1 s)(1 + t2 s)) [bar], eq. 6
    step = 1.01 * 3.0 * (1.0 - (t1 * np.exp(-t / t1) - t2 * np.exp(-t / t2)) / (t1 - t2))
    np.testing.assert_allclose(np.asarray(traj.pressure), P_ATM + 1e5 * step, rtol=0, atol=1e-3 * 1e5)


def test_physical_regulator_follows_eq6_at_closed_port_and_is_flow_limited_on_a_tank():
    ts = np.linspace(0.0, 0.3, 31)
    closed = pamjax.simulate(RegulatorSystem(ISO6358Regulator(), volume=1e-6), pamjax.Constant(3.0), ts)
    linear = pamjax.simulate(RegulatorSystem(LinearRegulator(), volume=0.0), pamjax.Constant(3.0), ts)
    # A 1 cm³ outlet fills in ~1 ms at choked flow: the outlet tracks eq. 6 within 0.03 bar.
    np.testing.assert_allclose(np.asarray(closed.pressure), np.asarray(linear.pressure), atol=3e3)
    tank = pamjax.simulate(RegulatorSystem(ISO6358Regulator(), volume=0.04), pamjax.Constant(3.0), ts)
    # Choked flow limit from Table 1's last row (6.943 bar) interpolated at 7 bar: C held at 7.0564e-4 m³/(s bar).
    limit = 1.185 * 7.0564e-4 / 1e5 * 7e5 * np.sqrt(293.15 / 298.0)
    assert np.max(np.asarray(tank.mass_flow)) <= limit * (1 + 1e-9)
    assert np.max(np.asarray(tank.mass_flow)) >= 0.99 * limit  # it does saturate
    # pressure rise bounded by R T ṁ_max / V: far slower than eq. 6 (0.3 s after the step, well below 4 bar)
    assert float(np.asarray(tank.pressure)[-1]) <= P_ATM + 286.9 * 298.0 * limit * 0.3 / 0.04 + 1.0
    assert float(np.asarray(tank.pressure)[-1]) < P_ATM + 0.5e5


@pytest.fixture(scope="module")
def muscle_run():
    system = RegulatedMuscleSystem(ISO6358Regulator(), dmsp40_muscle())
    ts = np.linspace(0.0, 1.0, 401)
    traj = pamjax.simulate(system, SquareWave(0.0, 3.0, 1.5), ts, rtol=1e-8, atol=1e-8)
    return system, traj


def test_eq11_flow_equals_delivered_flow_along_a_run(muscle_run):
    """Mass conservation: eq. 11 from (p, ṗ, x, ẋ) equals the ISO 6358 flow the regulator delivers."""
    system, traj = muscle_run
    eq11 = eqx.filter_jit(lambda system, traj: jax.vmap(system.eq11_flow)(traj.t, traj.state, traj.command))(
        system, traj)  # one program (eagerly: one per operation)
    np.testing.assert_allclose(np.asarray(eq11), np.asarray(traj.mass_flow), rtol=1e-9, atol=1e-12)


def test_eq10_is_the_rate_of_p_dVdx_and_tracks_eq11(muscle_run):
    """Fig. 12: eq. 10 along the run equals d/dt (p V'(x)) (central differences of the saved trajectory), and it
    rises and falls with the valve flow of eq. 11 (strong positive correlation)."""
    system, traj = muscle_run

    @eqx.filter_jit  # one program for the four quantities along the run (eagerly: one per operation)
    def along_the_run(system, traj):
        return (jax.vmap(system.stiffness_rate)(traj.t, traj.state, traj.command),
                jax.vmap(system.muscle.volume_slope)(traj.position),
                jax.vmap(system.vector_field)(traj.t, traj.state, traj.command),
                jax.vmap(system.muscle.volume)(traj.position))

    eq10, slope, rates, volume = along_the_run(system, traj)
    eq10 = np.asarray(eq10)
    pv = np.asarray(traj.pressure) * np.asarray(slope)
    t = np.asarray(traj.t)
    fd = (pv[2:] - pv[:-2]) / (t[2:] - t[:-2])
    mid = eq10[1:-1]
    # Away from the regulator's switching instants (where ṗ jumps within a sample), FD error is O(dt²).
    smooth = np.abs(np.diff(eq10)[1:] - np.diff(eq10)[:-1]) < 0.05 * np.abs(eq10).max()
    assert smooth.mean() > 0.8
    np.testing.assert_allclose(fd[smooth], mid[smooth], atol=2e-2 * np.abs(eq10).max())
    q = np.asarray(traj.mass_flow)
    # Eq. 10 = V' ṗ + V'' ẋ p and eq. 11 ∝ V ṗ + V' ẋ p share the ṗ term's shape, but their volume-rate terms have
    # opposite signs (V'' < 0 for the DMSP-40 cubic): the paper's "equivalence" is a resemblance, measured here as a
    # correlation of 0.59 for the full terms (0.95 for the ṗ terms alone). A sign error in either would make it < 0.
    assert np.corrcoef(eq10, q)[0, 1] > 0.5
    pdot = np.asarray(rates.regulator.pressure)
    assert np.corrcoef(np.asarray(slope) * pdot, np.asarray(volume) * pdot)[0, 1] > 0.9


def test_eq9_stiffness_matches_closed_chamber_finite_difference():
    muscle = dmsp40_muscle()
    for x, p in [(0.01, 3e5), (0.03, 5e5), (0.05, 6e5)]:
        v0 = float(_volume(muscle, np.asarray(x)))
        h = 1e-6

        def force(xx):
            pp = p * v0 / float(_volume(muscle, np.asarray(xx)))  # closed isothermal chamber: p V = const
            return float(_force(muscle, np.asarray(xx), np.asarray(pp)))

        fd = -(force(x + h) - force(x - h)) / (2 * h)
        ours = float(_muscle_stiffness(muscle, np.asarray(x), np.asarray(p), PAPER001_AIR))
        assert ours == pytest.approx(fd, rel=1e-6)
        # isobaric term only (eq. 9's second term)
        iso = -(float(_force(muscle, np.asarray(x + h), np.asarray(p)))
                - float(_force(muscle, np.asarray(x - h), np.asarray(p)))) / (2 * h)
        isobaric = _muscle_stiffness(muscle, np.asarray(x), np.asarray(p), PAPER001_AIR, pressure_slope=0.0)
        assert float(isobaric) == pytest.approx(iso, rel=1e-6)


def test_stiffness_rate_formula():
    muscle = dmsp40_muscle()
    x, v, p, pdot = 0.02, 0.1, 4e5, 2e5
    h = 1e-6

    # d/dt (p V'(x)) with x(t) = x + v t, p(t) = p + pdot t, by central differences in t
    def pv(s):
        return (p + pdot * s) * float(_volume_slope(muscle, np.asarray(x + v * s)))

    fd = (pv(h) - pv(-h)) / (2 * h)
    assert float(_stiffness_rate(muscle, *map(np.asarray, (x, v, p, pdot)))) == pytest.approx(fd, rel=1e-6)


def test_a_table_of_upstream_pressures_in_bar_is_named():
    # Tables 1-2 print the upstream pressures in bar (1.946, 2.954, ...): given as such they were taken as Pa, so every
    # flow read the tables' first row. The axis is ABSOLUTE pressure in Pa: refused naming the likely unit.
    conductance, ratio = np.array([1.6e-9, 2.1e-9, 6.4e-9]), np.array([0.66, 0.6, 0.57])
    with pytest.raises(pamjax.PamjaxInputError, match=r"TabulatedISO6358Restriction.pressure is 3.9 Pa at most: that "
                                                      r"looks like bar"):
        TabulatedISO6358Restriction(np.array([1.9, 2.9, 3.9]), conductance, ratio)
    with pytest.raises(pamjax.PamjaxInputError, match=r"TabulatedISO6358Restriction.pressure drops to 20000 Pa.*GAUGE"):
        TabulatedISO6358Restriction(np.array([2e4, 1e5, 2e5]), conductance, ratio)  # gauge
    TabulatedISO6358Restriction(np.array([1.9e5, 2.9e5, 3.9e5]), conductance, ratio)


@pytest.mark.parametrize("build, match", [
    (lambda: ISO6358Regulator(internal_volume=206.0),
     r"ISO6358Regulator\.internal_volume = 206 m³: more than 0\.001 m³ .*looks like cm³ or litres"),
    (lambda: pamjax.vppm_regulator(internal_volume=0.206), r"internal_volume = 0\.206 m³.*cm³ or litres"),
    (lambda: RegulatorSystem(ISO6358Regulator(), outlet_flow=float("nan")),
     r"RegulatorSystem\.outlet_flow must be finite"),
    (lambda: RegulatorSystem(None), r"RegulatorSystem\.regulator must be a pressure regulator .*got NoneType"),
    (lambda: RegulatedMuscleSystem(ISO6358Regulator(), None),
     r"RegulatedMuscleSystem\.muscle must be a Muscle .*got NoneType"),
    (lambda: RegulatedMuscleSystem(dmsp40_muscle(), ISO6358Regulator()),
     r"RegulatedMuscleSystem\.regulator must be a pressure regulator .*got Muscle"),
])
def test_a_regulator_volume_in_litres_a_nan_outlet_flow_or_a_missing_part_is_named(build, match):
    """An internal volume of 0.206 (litres) or 206 (cm³) was taken as m³: the outlet reached 0.024 bar of a 3 bar
    set point after 1 s (the VPPM's 2.06e-4 m³: 3.005 bar); outlet_flow = NaN and a missing muscle or regulator
    failed only at the solve. Refused by name when built; the VPPM's own volume is accepted."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        build()
    assert float(pamjax.vppm_regulator().internal_volume) == pytest.approx(2.06e-4, rel=0.01)


@pytest.mark.parametrize("kwargs, match", [
    (dict(charging=7e-9), r"ISO6358Regulator\.charging must be an AbstractRestriction .*got float"),
    (dict(discharging=None), r"ISO6358Regulator\.discharging must be an AbstractRestriction .*got NoneType"),
])
def test_iso6358_regulator_refuses_a_path_that_is_no_restriction(kwargs, match):
    # a sonic conductance where the charging restriction belongs: accepted, then a raw AttributeError in the solve
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.ISO6358Regulator(**kwargs)


def test_feedback_regulator_initial_state_is_at_rest():
    """`initial_state(p)` is at rest, as its docstring says: with its three stages at 0 (as they were) ṗ was
    −1.3e7 Pa/s and the outlet fell from 3.03 to 0.55 bar gauge in 0.1 s at a constant 3 V. The rest state holds
    under `rest_voltage` (3 V at 3.03 bar gauge with the default gains: eq. 5's 1.01 bar/V), also with other gains,
    in a tank, in a muscle system and with another atmosphere (the systems pass their air)."""
    p = P_ATM + 3.03e5
    default = pamjax.FeedbackRegulator()
    assert float(default.rest_voltage(p)) == pytest.approx(3.0, rel=1e-12)
    thin = pamjax.Air(atmospheric_pressure=9.5e4)
    for system in (RegulatorSystem(default, volume=0.0), RegulatorSystem(default, volume=0.04),
                   RegulatorSystem(pamjax.FeedbackRegulator(k1=0.7, k2=0.3), volume=0.0),
                   RegulatorSystem(default, air=thin), RegulatedMuscleSystem(default, dmsp40_muscle())):
        state = system.initial_state(p)
        regulator = state.regulator if isinstance(system, RegulatedMuscleSystem) else state
        assert float(regulator.pressure) == p
        volt = system.regulator.rest_voltage(p, system.air)
        rates = _field(system, state, volt)
        rates = rates.regulator if isinstance(system, RegulatedMuscleSystem) else rates
        # the stages' rates are ~1e5 Pa/s per bar of imbalance; at rest only round-off is left
        assert np.max(np.abs(jax.tree.leaves(rates))) < 1e-3, (type(system).__name__, rates)


@pytest.mark.parametrize("call, match", [
    (lambda m: muscle_stiffness(m, 0.03, 4.01, PAPER001_AIR), r"pressure is 4.01 Pa at most: that looks like bar"),
    (lambda m: muscle_stiffness(m, 30.0, P_ATM + 3e5, PAPER001_AIR),
     r"x = 30 m lies outside the muscle's stroke \[-0.02, 0.1\] m .*looks like mm"),
    (lambda m: muscle_stiffness(m, -0.5, P_ATM + 3e5, PAPER001_AIR), r"x = -0.5 m lies outside the muscle's stroke"),
    (lambda m: muscle_stiffness(m, 0.03, float("nan"), PAPER001_AIR), r"pressure must be finite"),
    (lambda m: stiffness_rate(m, 30.0, 0.01, P_ATM + 3e5, 1e5), r"x = 30 m lies outside .*looks like mm"),
    (lambda m: stiffness_rate(m, 0.03, 0.01, 3e4, 1e5), r"pressure is 30000 Pa at most: .*GAUGE"),
    (lambda m: stiffness_rate(m, 0.03, float("nan"), P_ATM + 3e5, 1e5), r"velocity must be finite"),
])
def test_stiffness_of_a_point_in_other_units_is_named(call, match):
    """Eq. 9-10 at pressures in bar (4.01: K = −0.0), positions in mm (30: K = −1.4e13 N/m) or outside the stroke
    (−0.5 m: 9.3e7), or NaN were computed silently; refused naming the argument, as `linearise` refuses such a state.
    Traced values (the jitted calls of the tests above) are not checked."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        call(dmsp40_muscle())


def test_a_shorter_calibration_table_is_the_command_range():
    """A 0-5 V calibration commanded 7 V held its 5 V pressure: simulate settled there, equilibrium gave 606325 Pa
    and linearise a dc gain of 0, while `static_outlet_pressure` refused 7 V. The regulator's command range is now
    its calibration's table, which simulate and linearise check by name (the default stays 0-10 V)."""
    cal5 = VoltageCalibration(voltage=[0.0, 5.0], gauge_pressure=[0.0, 5.05e5])
    system = RegulatorSystem(LinearRegulator(calibration=cal5), volume=0.0)
    assert system.command_range == (0.0, 5.0)
    assert RegulatorSystem(LinearRegulator(), volume=0.0).command_range == (0.0, 10.0)
    assert pamjax.FeedbackRegulator().command_range == (0.0, 10.0)
    with pytest.raises(pamjax.PamjaxInputError, match=r"signal .*must stay within \[0\.0, 5\.0\]"):
        pamjax.simulate(system, pamjax.Constant(7.0), np.linspace(0.0, 1.0, 3))
    with pytest.raises(pamjax.PamjaxInputError, match=r"command_range \[0\.0, 5\.0\], got 7"):
        pamjax.linearise(system, system.initial_state(P_ATM + 5.05e5), 7.0)


@pytest.mark.parametrize("gauge, match", [
    ([0.0, 1010.0], r"reaches 1010 Pa at most .*looks like kPa or mbar"),
    ([0.0, 10100.0], r"reaches 10100 Pa at most .*looks like kPa or mbar"),
    ([P_ATM, P_ATM + 1.01e6], r"= 101325 Pa at 0 V: that looks like an ABSOLUTE pressure"),
    ([-5e5, 1.01e6], r"reaches -500000 Pa: below vacuum"),
])
def test_a_calibration_in_kpa_mbar_absolute_or_below_vacuum_is_named(gauge, match):
    """Each was taken as gauge Pa: the set pressure at 3 V was 303 Pa (kPa), 3030 Pa (mbar), 404325 (absolute)."""
    with pytest.raises(pamjax.PamjaxInputError, match=r"VoltageCalibration\.gauge_pressure " + match):
        VoltageCalibration(voltage=[0.0, 10.0], gauge_pressure=gauge)


@pytest.mark.parametrize("build, match", [
    (lambda: LinearRegulator(flow_gain=-0.922),
     r"LinearRegulator\.flow_gain = 0\.922 Pa/\(kg/s\).*looks like bar/\(l/min\).*-4\.668e\+09 Pa/\(kg/s\)"),
    (lambda: pamjax.FeedbackRegulator(flow_gain=-4.67e9),
     r"FeedbackRegulator\.flow_gain = 4\.67e\+09 bar/\(l/min\).*looks like SI.*bar per l/min ANR \(eq\. 7: -0\.922"),
    (lambda: LinearRegulator(time_constants=(41.0, 23.0)),
     r"LinearRegulator\.time_constants = \[41\. 23\.\] s: more than 10 s; .*milliseconds.*\(0\.041, 0\.023\) s"),
    (lambda: pamjax.FeedbackRegulator(time_constants=(41.0, 23.0)), r"FeedbackRegulator\.time_constants.*millisec"),
    (lambda: ISO6358Regulator(time_constants=(41.0, 23.0)), r"ISO6358Regulator\.time_constants.*milliseconds"),
    (lambda: RegulatorSystem(ISO6358Regulator(), volume=1e-3, outlet_flow=-2.79),
     r"RegulatorSystem\.outlet_flow = 2\.79 kg/s: more than 0\.1 kg/s; that looks like l/min \(1 l/min ANR"),
    # eq. 6's 1.01 bar/V typed as 1.01e5 Pa/V ran to 4.6e61 Pa, returned as a trajectory
    (lambda: pamjax.FeedbackRegulator(voltage_gain=1.01e5),
     r"FeedbackRegulator\.voltage_gain = 101000 bar/V in magnitude: more than 100; that looks like Pa/V"),
    # 0.05 (bar) for the 5 kPa full-opening error shifted the outlet by ~2.6 kPa, accepted
    (lambda: ISO6358Regulator(full_opening_error=0.05),
     r"ISO6358Regulator\.full_opening_error = 0\.05 Pa is below 1 Pa.*looks like bar"),
    # a 1.3 kg foot typed in grams
    (lambda: _joint(foot_mass=1300.0), r"AntagonisticJoint\.foot_mass .*1300.*g"),
])
def test_flow_gains_time_constants_and_outlet_flows_in_other_units_are_named(build, match):
    """Eq. 7's printed -0.922 bar/(l/min) in LinearRegulator's SI argument made its droop vanish; the SI -4.67e9 in
    FeedbackRegulator's bar/(l/min) one failed as "maximum step size"; eq. 6's (41, 23) ms left a 3 V step at
    0.0016 bar after 1 s; an outlet flow of 2.79 (l/min) as kg/s ran to 1713 bar. Refused as built; the defaults
    and eq. 7's SI value are taken."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        build()
    LinearRegulator(flow_gain=-4.67e9, time_constants=(0.082, 0.046))
    RegulatorSystem(ISO6358Regulator(), volume=1e-3, outlet_flow=5e-3)


@pytest.mark.parametrize("system", [lambda: RegulatorSystem(LinearRegulator(), volume=0.0),
                                    lambda: RegulatedMuscleSystem(ISO6358Regulator(), dmsp40_muscle())])
def test_a_voltage_pair_for_one_regulator_is_named(system):
    """A joint's `VoltagePair` given to a one-regulator system was JAX's raw TypeError on shapes."""
    pair = pamjax.VoltagePair(pamjax.Constant(3.0), pamjax.Constant(1.0))
    with pytest.raises(pamjax.PamjaxInputError, match=r"command must be one reference voltage .*shape \(2,\).*"
                                                      r"VoltagePair"):
        pamjax.simulate(system(), pair, np.linspace(0.0, 1.0, 3))


def _joint(**kwargs):
    return pamjax.AntagonisticJoint(ISO6358Regulator(), ISO6358Regulator(), dmsp40_muscle(), dmsp40_muscle(), **kwargs)


@pytest.mark.parametrize("call, match", [
    (lambda m: muscle_stiffness(m, np.linspace(0.0, 0.05, 3), 4e5, PAPER001_AIR),
     r"x must be one number \(one operating point\), got shape \(3,\): .*jax\.vmap"),
    (lambda m: stiffness_rate(m, np.linspace(0.0, 0.05, 3), 0.01, 4e5, 1e5), r"x must be one number .*jax\.vmap"),
    (lambda m: pamjax.regulated_stiffness(_joint(), np.array([0.0, 0.1]), 4e5, 3e5),
     r"angle must be one number .*shape \(2,\).*jax\.vmap"),
    (lambda m: muscle_stiffness(m, 0.01, 4e5, None), r"air must be an Air .*got NoneType"),
    (lambda m: pamjax.regulated_stiffness(m, 0.1, 4e5, 3e5), r"joint must be an AntagonisticJoint .*got Muscle"),
    (lambda m: muscle_stiffness(m, 0.01, 4e5, PAPER001_AIR, polytropic_index=float("nan")),
     r"polytropic_index must be finite"),
    (lambda m: muscle_stiffness(m, 0.01, 4e5, PAPER001_AIR, polytropic_index=0.0),
     r"polytropic_index must be in the open interval \(0\.99, 1\.41\)"),
    (lambda m: muscle_stiffness(m, 0.01, 4e5, PAPER001_AIR, polytropic_index=14.0), r"polytropic_index .*\(0\.99"),
    (lambda m: muscle_stiffness(m, 0.01, 4e5, PAPER001_AIR, pressure_slope=float("nan")),
     r"pressure_slope must be finite"),
])
def test_stiffness_of_several_points_a_wrong_object_or_a_bad_index_is_named(call, match):
    """Arrays of positions or angles were JAX's "Gradient only defined for scalar-output functions", air=None and a
    muscle for the joint raw AttributeErrors, and n = NaN, 0, 14 or a NaN pressure slope silent (NaN) stiffnesses."""
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        call(dmsp40_muscle())
