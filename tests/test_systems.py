"""Systems (`pamjax._systems`: `tank`, `muscle`): vector fields against a NumPy transcription of paper 000 eq. 7, 11,
13-16; physical bounds; mass balance."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import P_ATM, R_AIR, T_AIR, NumpyPlant, counted_compilations

import pamjax
from pamjax import presets


def numpy_plant(valve):
    return NumpyPlant(
        a=presets.MAS10_MAX_FORCE_COEFFICIENTS,
        k0=presets.MAS10_K0,
        k1=presets.MAS10_K1,
        k2=presets.MAS10_K2,
        v0=presets.MAS10_V0,
        v1=presets.MAS10_V1,
        x_min=presets.MAS10_MIN_POSITION,
        x_max=presets.MAS10_MAX_POSITION,
        valve=valve,
        m=presets.MAS10_AVERAGED_VALVE,
        volume=presets.TANK_VOLUME,
    )


STATES = [(P_ATM, 0.0, 0.0), (3e5, 0.02, 0.05), (5.5e5, 0.06, -0.1), (2e5, -0.021, 0.0), (6.4e5, 0.0752, 0.01)]


@pytest.mark.parametrize("valve", ["averaged", "pwm"])
def test_muscle_vector_field_matches_numpy_transcription(valve):
    system = presets.mas10_system(valve)
    plant = numpy_plant(valve)
    for t, u in ((0.0031, 0.5), (0.0123, 0.3), (0.019, 0.8)):
        for p, x, v in STATES:
            state = pamjax.MuscleState(jnp.asarray(p), jnp.asarray(x), jnp.asarray(v))
            got = system.vector_field(jnp.asarray(t), state, jnp.asarray(u))
            expected = plant.rhs(t, [p, x, v], lambda _: u)
            np.testing.assert_allclose([got.pressure, got.position, got.velocity], expected, rtol=1e-10, atol=1e-10)


def test_tank_vector_field_matches_numpy_transcription():
    system = presets.mas10_tank_system("pwm")
    plant = numpy_plant("pwm")
    for t, u, p in ((0.001, 0.5, P_ATM), (0.005, 0.5, 3e5), (0.015, 0.2, 6e5)):
        got = system.vector_field(t, pamjax.TankState(jnp.asarray(p)), jnp.asarray(u)).pressure
        assert float(got) == pytest.approx(plant.tank_rhs(t, [p], lambda _: u)[0], rel=1e-11, abs=1e-6)


@pytest.mark.parametrize(
    "valve",
    [
        "pwm",
        "averaged",  # the preset eq. 13 fit is pinned to zero flow at (0, p_atm) and (1, p_supply)
    ],
)
def test_tank_pressure_stays_between_atmosphere_and_supply(valve):
    system = presets.mas10_tank_system(valve)
    ts = jnp.linspace(0.0, 0.6, 301)
    up = np.asarray(pamjax.simulate(system, pamjax.Constant(0.95), ts).pressure)
    down = np.asarray(
        pamjax.simulate(system, pamjax.Constant(0.05), ts, y0=pamjax.TankState(jnp.asarray(6.5e5))).pressure
    )
    tol = 10.0 if valve == "pwm" else 0.02 * 6.5e5  # Pa: solver tolerance; the fitted eq. 13 is a 2 % approximation
    for p in (up, down):
        assert np.all(p >= P_ATM - tol) and np.all(p <= 6.5e5 + tol)
    assert up[-1] > 6e5 and down[-1] < 1.5e5  # and it does get near each end


def test_isothermal_tank_mass_balance():
    # n = 1: m = pV/(RT) must equal m(0) + ∫ ṁ dt. Averaged valve (smooth flow) so the trapezoid rule on 4001 points
    # is accurate to ~1e-8 of the mass change; tolerance 1e-6 relative.
    system = pamjax.TankSystem(presets.mas10_averaged_valve(), presets.TANK_VOLUME, polytropic_index=1.0)
    ts = np.linspace(0.0, 0.4, 4001)
    traj = pamjax.simulate(system, pamjax.Triangle(0.2, 0.9, 2.0), jnp.asarray(ts), rtol=1e-10, atol=1e-10)
    mass = np.asarray(traj.pressure) * presets.TANK_VOLUME / (R_AIR * T_AIR)
    flow = np.asarray(traj.mass_flow)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (flow[1:] + flow[:-1]) * np.diff(ts))])
    np.testing.assert_allclose(mass - mass[0], integral, rtol=0, atol=1e-6 * np.ptp(mass))
    assert np.ptp(mass) > 1e-4  # the check is not vacuous: about 0.3 g moves


def test_equilibrium_position_carries_the_payload():
    system = presets.mas10_system("averaged")
    x = system.equilibrium_position(jnp.asarray(4e5))
    assert presets.MAS10_MIN_POSITION < float(x) < presets.MAS10_MAX_POSITION
    assert float(system.muscle.force(x, 4e5, system.air)) == pytest.approx(9.6 * 9.81, rel=1e-10)


def test_eager_equilibria_compile_once_per_muscle_model():
    """`initial_state()` called at the top level (a user's script, a bench loader) compiles its equilibrium once per
    muscle model: another pressure, payload or valve reuses it (the bisection's loop compiled anew at every eager
    call before: ~65 ms each). Counted with JAX's own compilation events."""
    system = presets.mas10_system("averaged")
    x_first = float(system.initial_state().position)
    heavier = eqx.tree_at(lambda s: s.payload_mass, system, jnp.asarray(20.0))
    with counted_compilations() as compiled:
        xs = [float(presets.mas10_system("pwm").initial_state().position), float(heavier.equilibrium_position(4e5)),
              float(system.equilibrium_position(jnp.asarray(5e5)))]
    assert not any("equilibrium" in name or "scan" in name for name in compiled), compiled
    assert xs[0] == x_first  # the same muscle and payload behind another valve
    assert float(heavier.muscle.force(xs[1], 4e5, heavier.air)) == pytest.approx(20.0 * 9.81, rel=1e-10)
    assert float(system.muscle.force(xs[2], 5e5, system.air)) == pytest.approx(9.6 * 9.81, rel=1e-10)


def test_start_pressures_name_every_absolute_pressure_a_state_holds():
    """`AbstractSystem.start_pressures`, which `simulate` and `sweep` check in a y0: the top-level `pressure` by
    default, a regulator's where the state keeps it there (a regulated muscle, both muscles of a joint); another
    structure has none."""
    muscle, regulator = presets.dmsp40_muscle(), pamjax.ISO6358Regulator()
    tank = presets.mas10_tank_system("averaged")
    regulated = pamjax.RegulatedMuscleSystem(regulator, muscle)
    joint = pamjax.AntagonisticJoint(regulator, regulator, muscle, muscle)
    cases = [
        (tank, tank.initial_state(pressure=3e5), {"pressure": 3e5}),
        (pamjax.RegulatorSystem(regulator), pamjax.RegulatorSystem(regulator).initial_state(4e5), {"pressure": 4e5}),
        (regulated, regulated.initial_state(pressure=5e5, position=0.02), {"regulator.pressure": 5e5}),
        (joint, joint.initial_state(3e5, 2e5, angle=0.0), {"flexor.pressure": 3e5, "extensor.pressure": 2e5}),
        (regulated, tank.initial_state(pressure=3e5), {}),
    ]
    for system, state, expected in cases:
        got = system.start_pressures(state)
        assert {name: float(p) for name, p in got.items()} == expected, type(system).__name__


@pytest.mark.parametrize("field, value, match", [
    # each ended as an AttributeError inside simulate
    ("muscle", None, r"MuscleSystem\.muscle must be an AbstractMuscle .*got NoneType"),
    ("valve", None, r"MuscleSystem\.valve must be an AbstractValve .*got NoneType"),
    ("valve", pamjax.ISO6358Regulator(), r"MuscleSystem\.valve .*got ISO6358Regulator; a muscle fed by a pressure "
                                         r"regulator is a RegulatedMuscleSystem"),
    ("friction", 5.0, r"MuscleSystem\.friction must be an AbstractFriction .*got float"),
])
def test_a_muscle_system_given_a_part_of_the_wrong_kind_names_it(field, value, match):
    parts = dict(valve=presets.mas10_valve(), muscle=presets.mas10_muscle())
    parts[field] = value
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        pamjax.MuscleSystem(**parts)


def test_a_stick_slip_friction_is_refused_where_its_modes_or_stops_would_be_ignored():
    # The regulated system locates no events: a Karnopp friction stayed in its start mode (a 1-5 V sine ran as pure
    # viscous friction, 5.9 mm off the smooth Coulomb twin; from a moving start +200 N with the motion). Beside a
    # stick-slip friction the stroke limits are inelastic events: a soft bumper EndStops(1e4, 200, 1e-3) changed
    # nothing (an 80 kg drop bottomed out as with the default stops).
    with pytest.raises(pamjax.PamjaxInputError, match=r"RegulatedMuscleSystem\.friction: a stick-slip friction "
                                                      r"\(KarnoppFriction\) needs its modes switched at events"):
        pamjax.RegulatedMuscleSystem(pamjax.ISO6358Regulator(), presets.dmsp40_muscle(),
                                     friction=pamjax.KarnoppFriction(200.0, 3000.0))
    parts = dict(valve=presets.mas10_valve(), muscle=presets.mas10_muscle(), friction=pamjax.KarnoppFriction())
    with pytest.raises(pamjax.PamjaxInputError, match=r"MuscleSystem\.end_stops: with a stick-slip friction "
                                                      r"\(KarnoppFriction\) .* would be ignored"):
        pamjax.MuscleSystem(**parts, end_stops=pamjax.EndStops(1e4, 200.0, 1e-3))
    assert pamjax.MuscleSystem(**parts, end_stops=pamjax.EndStops()).hybrid  # the default stops: nothing ignored
    assert not pamjax.MuscleSystem(**{**parts, "friction": pamjax.CoulombViscousFriction()},
                                   end_stops=pamjax.EndStops(1e4, 200.0, 1e-3)).hybrid


def test_start_positions_name_every_displacement_a_state_holds_with_its_stroke():
    """`AbstractSystem.start_positions`, which `simulate` checks in a y0: a muscle system's `position` with its
    muscle's stroke; a tank's state holds none, and a joint's (an angle) none either."""
    muscle, regulator = presets.dmsp40_muscle(), pamjax.ISO6358Regulator()
    plant, tank = presets.mas10_system("averaged"), presets.mas10_tank_system("averaged")
    regulated = pamjax.RegulatedMuscleSystem(regulator, muscle)
    joint = pamjax.AntagonisticJoint(regulator, regulator, muscle, muscle)
    cases = [
        (plant, plant.initial_state(pressure=3e5, position=0.01),
         {"position": (0.01, (presets.MAS10_MIN_POSITION, presets.MAS10_MAX_POSITION))}),
        (regulated, regulated.initial_state(pressure=5e5, position=0.02),
         {"position": (0.02, (float(muscle.min_position), float(muscle.max_position)))}),
        (tank, tank.initial_state(pressure=3e5), {}),
        (joint, joint.initial_state(3e5, 2e5, angle=0.0), {}),
    ]
    for system, state, expected in cases:
        got = system.start_positions(state)
        got = {name: (float(x), None if s is None else tuple(float(b) for b in s)) for name, (x, s) in got.items()}
        assert got == expected, type(system).__name__
