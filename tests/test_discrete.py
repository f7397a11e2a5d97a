"""Paper 000's discrete-time model (eq. 17-21): the update rule, and convergence to the continuous model as T_s → 0."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import P_ATM, R_AIR, T_AIR, np_eq7_force, np_friction

import pamjax
from pamjax import presets


def test_one_step_is_eq18_to_21():
    # Written out from paper 000 eq. 18-20 with the preset's components (averaged valve eq. 13, force eq. 7 with
    # gauge pressure, Coulomb + viscous friction); the state is far from slack and end stops, so their smoothing is
    # negligible (< 1e-12 relative).
    system = presets.mas10_system("averaged")
    p, x, v, u, ts = 4e5, 0.03, 0.02, 0.6, 1e-3
    m = np.asarray(presets.MAS10_AVERAGED_VALVE)
    pg = p - P_ATM
    mdot = sum(m[i, j] * u**i * pg**j for i in range(3) for j in range(3))
    v0, v1 = presets.MAS10_V0, presets.MAS10_V1
    p1 = 1.4 * ts / (v0 + v1 * x) * (R_AIR * T_AIR * mdot - p * v1 * v) + p  # eq. 18
    f = np_eq7_force(x, pg, presets.MAS10_MAX_FORCE_COEFFICIENTS, presets.MAS10_K0, presets.MAS10_K1, presets.MAS10_K2)
    v_next = ts / 9.6 * (f - np_friction(v, 16.0, 250.0, 1e-3) - 9.6 * 9.81) + v  # eq. 20
    x_next = ts * v_next + x  # eq. 19
    state = pamjax.MuscleState(jnp.asarray(p), jnp.asarray(x), jnp.asarray(v))
    new = pamjax.unchecked.discrete_step(system, 0.0, state, jnp.asarray(u), ts)
    np.testing.assert_allclose([new.pressure, new.position, new.velocity], [p1, x_next, v_next], rtol=1e-12)


def test_simulate_discrete_outputs():
    system = presets.mas10_system("averaged")
    d = pamjax.simulate_discrete(system, pamjax.Constant(0.6), 1e-3, 0.05, y0=system.initial_state(pressure=3e5))
    assert d.t.shape == (51,) and float(d.t[-1]) == pytest.approx(0.05)
    # eq. 21: acceleration is the velocity difference quotient.
    np.testing.assert_allclose(d.acceleration[1:], np.diff(d.velocity) / 1e-3, rtol=1e-12)
    assert d.force is not None and np.all(np.isfinite(d.pressure))
    g = jax.grad(lambda u: pamjax.simulate_discrete(system, pamjax.Constant(u), 1e-3, 0.05).position[-1])(0.6)
    assert np.isfinite(g)


@pytest.mark.parametrize("valve, t_end", [("averaged", 0.5), ("pwm", 0.1)])
def test_converges_to_continuous_model_first_order(valve, t_end):
    # Errors against the continuous model (rtol 1e-10) at the end time, halving T_s: explicit Euler is first order,
    # so each halving should roughly halve the error (measured ratios ≈ 2; accepted 1.6-2.4).
    system = presets.mas10_system(valve)
    signal = pamjax.Constant(0.6)
    y0 = system.initial_state(pressure=3e5)
    cont = pamjax.simulate(system, signal, jnp.asarray([0.0, t_end]), y0=y0, rtol=1e-10, atol=1e-10)
    steps = (4e-4, 2e-4, 1e-4) if valve == "averaged" else (2e-5, 1e-5, 5e-6)
    errors = []
    for ts in steps:
        d = pamjax.simulate_discrete(system, signal, ts, t_end, y0=y0)
        errors.append(abs(float(d.position[-1]) - float(cont.position[-1])) / 1e-2
                      + abs(float(d.pressure[-1]) - float(cont.pressure[-1])) / 1e5)
    print(valve, "scaled end-state errors for T_s =", steps, ":", errors)
    ratios = [a / b for a, b in zip(errors, errors[1:])]
    assert all(1.6 < r < 2.4 for r in ratios), (errors, ratios)
    assert errors[-1] < 1e-3


@pytest.mark.parametrize("signal", [pamjax.Constant(0.95), pamjax.Triangle(0.8, 0.95, 10.0)],
                         ids=["constant-0.95", "triangle-across-0.9"])
def test_switching_valve_above_90_percent_converges_first_order(signal):
    # Above 90 % duty the off-pulse (1 - u) T < 2 ms at 50 Hz is shorter than the valve's 2 ms switch-off delay
    # (paper 000: switching time ≈ 2 ms), so the valve stays open into the next period: it acts on (this period's
    # duty, the last one's), off before the run, as `simulate` reads it. A single duty held over both left the valve
    # open from t = 0 (error ~3e4 Pa whatever T_s).
    # Errors at 21 times over 0.1 s (5 PWM periods; the triangle crosses 0.9 at 1/30 and 2/30 s: the periods from
    # 0.02, 0.04, 0.06 s latch 0.86, 0.92, 0.92) against the continuous model (rtol 1e-10): first order, each halving
    # of T_s roughly halves them (measured ratios ≈ 2.0; accepted 1.6-2.4), for the state and the `mass_flow` output.
    system = presets.mas10_system("pwm")
    y0 = system.initial_state(pressure=3e5)
    t_end, times = 0.1, np.linspace(0.0, 0.1, 21)
    cont = pamjax.simulate(system, signal, jnp.asarray(times), y0=y0, rtol=1e-10, atol=1e-10)
    errors, flow_errors = [], []
    for ts in (4e-5, 2e-5, 1e-5):
        d = pamjax.simulate_discrete(system, signal, ts, t_end, y0=y0)
        k = np.round(times / ts).astype(int)
        np.testing.assert_allclose(np.asarray(d.t)[k], times, atol=1e-12)
        np.testing.assert_allclose(np.asarray(d.command)[k], cont.command, atol=1e-12)  # the latched duty
        errors.append(np.max(np.abs(np.asarray(d.pressure)[k] - np.asarray(cont.pressure))) / 1e5
                      + np.max(np.abs(np.asarray(d.position)[k] - np.asarray(cont.position))) / 1e-2)
        flow_errors.append(np.max(np.abs(np.asarray(d.mass_flow)[k] - np.asarray(cont.outputs["mass_flow"]))))
    print("scaled state errors", errors, "mass-flow errors [kg/s]", flow_errors)
    for e in (errors, flow_errors):
        ratios = [a / b for a, b in zip(e, e[1:])]
        assert all(1.6 < r < 2.4 for r in ratios), (e, ratios)
    assert errors[-1] < 2e-3  # 76 Pa and 1.4 µm at 10 µs (measured)


def test_hybrid_system_is_refused():
    # Euler steps cannot switch a stick-slip mode: the payload of a Karnopp plant, stuck at rest, stayed stuck for ever
    # (simulate moves it 55 mm in 0.5 s at duty 0.7). Refused before any solve, naming what to use instead.
    system = presets.mas10_system("averaged", friction="karnopp")
    with pytest.raises(pamjax.PamjaxInputError, match="hybrid.*CoulombViscousFriction.*simulate"):
        pamjax.simulate_discrete(system, pamjax.Constant(0.7), 1e-4, 0.01)


def test_a_diverging_run_or_a_sample_time_past_the_run_is_named():
    # Euler at T_s = 0.1 s (the paper's 0.1 ms typed as ms) returned NaN and negative absolute pressures silently;
    # T_s = 1 s for a 10 ms run made one step to 1 s (4.6 MPa)
    system = presets.mas10_system("averaged")
    y0 = system.initial_state(pressure=3e5)
    with pytest.raises(pamjax.PamjaxSolveError, match=r"simulate_discrete diverged at t = .* sample_time = 0.1 s is "
                                                      r"above its stability limit"):
        pamjax.simulate_discrete(system, pamjax.Constant(0.6), 0.1, 1.0, y0=y0)
    with pytest.raises(pamjax.PamjaxInputError, match=r"sample_time \(1.0 s\) must not exceed the run"):
        pamjax.simulate_discrete(system, pamjax.Constant(0.6), 1.0, 0.01, y0=y0)


def test_a_regulated_muscle_steps_its_position_with_the_new_velocity():
    # eq. 19 (semi-implicit Euler), as MuscleSystem steps it: paper 001's RegulatedMuscleSystem fell back on the
    # generic explicit step (x moved by the OLD velocity: 1.8e-8 m per step off eq. 19 at T_s = 0.1 ms)
    system = pamjax.RegulatedMuscleSystem(pamjax.ISO6358Regulator(), presets.dmsp40_muscle())
    d = pamjax.simulate_discrete(system, pamjax.Constant(3.0), 1e-4, 0.02)
    x, v = np.asarray(d.position), np.asarray(d.velocity)
    assert np.max(np.abs(v)) > 1e-3  # it moves
    np.testing.assert_allclose(np.diff(x), 1e-4 * v[1:], rtol=0, atol=1e-15)


def test_plain_float_start_states_and_a_listed_sample_time():
    """A y0 of Python floats (which `simulate` takes) failed with a raw TypeError in the scan, sample_time=[1e-4] with
    one from float(): the floats run as the arrays do, the list is refused by name."""
    system = presets.mas10_system("averaged")
    floats = pamjax.MuscleState(pressure=3e5, position=0.01, velocity=0.0)
    arrays = jax.tree_util.tree_map(jnp.asarray, floats)
    run = [pamjax.simulate_discrete(system, pamjax.Constant(0.6), 1e-3, 0.05, y0=y0) for y0 in (floats, arrays)]
    np.testing.assert_array_equal(np.asarray(run[0].pressure), np.asarray(run[1].pressure))
    for kwargs, match in ((dict(sample_time=[1e-4]), r"sample_time must be one number \[s\].*got \[0\.0001\]"),
                          (dict(t_end=np.array([0.05])), r"t_end must be one number")):
        args = dict(sample_time=1e-3, t_end=0.05) | kwargs
        with pytest.raises(pamjax.PamjaxInputError, match=match):
            pamjax.simulate_discrete(system, pamjax.Constant(0.6), **args)
