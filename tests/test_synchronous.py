"""PWM-synchronous stepping (`pamjax._solve.synchronous`, `simulate(..., stepping="pwm")`) against the reference
adaptive solve, and its gradients against central finite differences.

Reference: the exact-edge valve (`mode="exact"`, the same sharp-edge model with the duty latched per period) solved by
diffrax Tsit5 with its switching times as jump times at rtol = atol = 1e-9. Horizons are short (0.5-1 s) to keep
the tests fast.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._solve.simulate import solve

TS = jnp.linspace(0.0, 0.5, 51)


def _reference(system, signal, ts):
    return pamjax.simulate(system, signal, ts, rtol=1e-9, atol=1e-9, max_steps=10**6)


@pytest.mark.parametrize("signal", [pamjax.Triangle(0.05, 0.95, 0.5), pamjax.Constant(0.37)])
def test_muscle_matches_exact_edge_reference(signal):
    # K = 16 (step ≤ 1.25 ms): RK4 error ~ h⁴; measured 4e-3 mm / 12 Pa over the 25 s benchmark. Stated bounds:
    # 0.01 mm (a tenth of the 0.1 mm measurement noise) and 50 Pa (1/40 of the 2 kPa pressure noise).
    ref = _reference(presets.mas10_system("exact"), signal, TS)
    fast = pamjax.simulate(presets.mas10_system("pwm"), signal, TS, stepping="pwm")
    assert np.max(np.abs(np.asarray(fast.position - ref.position))) < 1e-5
    assert np.max(np.abs(np.asarray(fast.pressure - ref.pressure))) < 50.0
    assert np.max(np.abs(np.asarray(fast.velocity - ref.velocity))) < 1e-3
    np.testing.assert_allclose(fast.command, ref.command, rtol=0, atol=1e-12)
    assert int(fast.num_rejected_steps) == 0 and bool(fast.succeeded)


def test_tank_matches_exact_edge_reference_and_converges():
    signal = pamjax.Constant(0.25)  # the duty that an adaptive solve once stepped over (40 kPa off)
    ts = jnp.linspace(0.0, 0.5, 51)
    ref = _reference(presets.mas10_tank_system("exact"), signal, ts)
    errors = []
    for k in (8, 16, 32):
        fast = pamjax.simulate(presets.mas10_tank_system("pwm"), signal, ts, stepping="pwm", substeps=k)
        errors.append(np.max(np.abs(np.asarray(fast.pressure - ref.pressure))))
    # The tank alone is not stiff: K = 16 is already at the reference's own accuracy (~0.01 Pa here).
    assert errors[1] < 50.0 and errors[2] < 1.0  # Pa
    assert errors[2] <= errors[0] + 0.05


def test_output_times_off_the_grid_and_late_start():
    # Output times that are not nodes (Hermite interpolation) and a start inside a PWM period.
    ts = jnp.asarray([0.0133, 0.0291, 0.2, 0.31415, 0.5])
    signal = pamjax.Constant(0.6)
    ref = _reference(presets.mas10_system("exact"), signal, ts)
    fast = pamjax.simulate(presets.mas10_system("pwm"), signal, ts, stepping="pwm")
    assert np.max(np.abs(np.asarray(fast.position - ref.position))) < 1e-5
    assert np.max(np.abs(np.asarray(fast.pressure - ref.pressure))) < 50.0
    np.testing.assert_allclose(fast.pressure[0], 101325.0)


def _loss(duty, on_delay, frequency, *, substeps=16):
    system = presets.mas10_system("pwm")
    system = eqx.tree_at(lambda s: (s.valve.switch_on_delay, s.valve.pwm_frequency), system, (on_delay, frequency))
    ts = jnp.linspace(0.0, 0.4, 41)
    traj = solve(system, pamjax.Constant(duty), ts, None, 0.0, stepping="pwm", substeps=substeps, num_periods=21)
    return jnp.mean(traj.position) * 1e3 + jnp.mean(traj.pressure) * 1e-5


# compiled once for both duties and the finite differences (an eager solve re-traces at every call); the reverse-mode
# value-and-gradient also gives the differences' loss values, so no separate loss program is compiled
_value_and_grad_jit = jax.jit(jax.value_and_grad(_loss, argnums=(0, 1, 2)))
_jacfwd_jit = jax.jit(jax.jacfwd(_loss, argnums=(0, 1, 2)))


def _loss_value(*args):
    return _value_and_grad_jit(*args)[0]


@pytest.mark.parametrize("duty", [0.3, 0.72])
def test_gradients_through_edge_times_match_finite_differences(duty):
    # The edges move the step boundaries, so d/d(duty), d/d(switch delay), d/d(frequency) are the sharp model's
    # derivatives. Central differences with steps small enough not to move an edge across a node; agreement 1e-6.
    args = (duty, 2e-3, 50.0)
    rev = _value_and_grad_jit(*args)[1]
    fwd = _jacfwd_jit(*args)
    for i, h in enumerate((1e-6, 1e-8, 1e-5)):
        up, down = list(args), list(args)
        up[i] += h
        down[i] -= h
        fd = (_loss_value(*up) - _loss_value(*down)) / (2 * h)
        assert np.isfinite(float(rev[i])) and abs(float(rev[i])) > 0
        np.testing.assert_allclose(float(rev[i]), float(fd), rtol=1e-6)
        np.testing.assert_allclose(float(fwd[i]), float(rev[i]), rtol=1e-10)


def test_gradient_wrt_physical_parameter_matches_finite_differences():
    def loss(area):
        system = presets.mas10_system("pwm")
        system = eqx.tree_at(lambda s: s.valve.inflate.area, system, area)
        traj = pamjax.simulate(system, pamjax.Triangle(0.05, 0.95, 0.5), TS[:21], stepping="pwm")
        return jnp.mean(traj.position) * 1e3

    # The gradient and both differences from one eager value-and-gradient, the area an array: the solve's compiled
    # pieces under grad are reused by the two further calls, where loss(area ± h) with a Python float compiled the
    # solve anew for each (a float leaf of the system is a constant of the program): 12 compilations instead of 16.
    # (Not jitted as a whole: simulate sizes its PWM grid from concrete values, which jit would trace.)
    value_and_grad = jax.value_and_grad(loss)
    g = value_and_grad(jnp.asarray(3.14e-6))[1]
    h = 1e-10
    fd = (value_and_grad(jnp.asarray(3.14e-6 + h))[0] - value_and_grad(jnp.asarray(3.14e-6 - h))[0]) / (2 * h)
    np.testing.assert_allclose(float(g), float(fd), rtol=1e-5)


def test_bad_input_is_rejected_before_solving():
    with pytest.raises(pamjax.PamjaxInputError, match="stepping='pwm' needs a switching valve.*AveragedValve"):
        pamjax.simulate(presets.mas10_system("averaged"), pamjax.Constant(0.5), TS, stepping="pwm")
    with pytest.raises(pamjax.PamjaxInputError, match="substeps"):
        pamjax.simulate(presets.mas10_system("pwm"), pamjax.Constant(0.5), TS, stepping="pwm", substeps=1)
    with pytest.raises(pamjax.PamjaxInputError, match="stepping"):
        pamjax.simulate(presets.mas10_system("pwm"), pamjax.Constant(0.5), TS, stepping="fast")
    with pytest.raises(pamjax.PamjaxInputError, match="num_periods"):
        jax.jit(lambda ts: solve(presets.mas10_system("pwm"), pamjax.Constant(0.5), ts, None, 0.0, stepping="pwm"))(TS)


def test_unstable_grid_reports_failure_instead_of_nan():
    # Two substeps per period (10 ms RK4 steps) are far beyond the friction's stability limit (~1.6 ms).
    traj = pamjax.simulate(presets.mas10_system("pwm"), pamjax.Constant(0.5), TS, stepping="pwm", substeps=2,
                           throw=False)
    if bool(traj.succeeded):
        assert np.all(np.isfinite(np.asarray(traj.position)))
    else:
        assert np.all(np.isnan(np.asarray(traj.position)))


def test_more_periods_than_the_minimum_change_neither_value_nor_frequency_derivative():
    """Output at a period boundary (0.3 s = 15 periods of 50 Hz): a grid of one period more ends in zero-length
    intervals there, which the output was read from (d/df 12x off); now both sizes give the FD derivative."""
    system, ts = presets.mas10_system("pwm"), jnp.linspace(0.0, 0.3, 4)
    n_min = pamjax.unchecked.num_periods(system.valve, 0.0, 0.3)

    def final(f, n):
        s = eqx.tree_at(lambda s: s.valve.pwm_frequency, system, f)
        tr = pamjax.unchecked.solve(s, pamjax.Constant(0.5), ts, None, 0.0, stepping="pwm", num_periods=n)
        return jnp.stack([tr.position[-1] / 1e-3, tr.pressure[-1] / 1e3])

    fd = (final(50.0 + 1e-5, n_min) - final(50.0 - 1e-5, n_min)) / 2e-5
    for n in (n_min, n_min + 1):
        np.testing.assert_allclose(final(50.0, n), final(50.0, n_min), rtol=1e-12)
        np.testing.assert_allclose(jax.jacfwd(lambda f: final(f, n))(50.0), fd, rtol=1e-4)


def test_fitting_the_pwm_frequency_on_the_pwm_grid_is_refused_by_name():
    model = presets.mas10_system("pwm", friction="karnopp")
    ts = np.linspace(0.0, 0.1, 11)
    signal = pamjax.Constant(0.5)
    rec = pamjax.synthetic_recording(model, signal, ts, channels=("pressure",))
    exp = pamjax.Experiment(rec, signal, scales={"pressure": 2e3})
    with pytest.raises(pamjax.PamjaxInputError, match=r"valve\.pwm_frequency.*PWM-synchronous grid.*mode='smooth'"):
        pamjax.fit(model, [exp], ["valve.pwm_frequency"], progress=False, max_steps=2)
