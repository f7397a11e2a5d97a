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
