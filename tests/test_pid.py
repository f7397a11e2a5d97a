"""`PIDController`: with no derivative gain and no noise it is `PIController`; its derivative term is K_D (ṙ − ẋ)
noise-free; its noise is seeded, per period, of the stated size and enters the derivative amplified by 1/T_s."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax._control.pid import PIDState
from pamjax._systems.muscle import MuscleState

PERIOD = 0.02  # s, 50 Hz PWM


# A controller's update and its noise draws jitted once per controller type (eagerly, each of their operations would
# compile a program of its own), the time as an array argument.
@eqx.filter_jit
def _update(controller, t, reference, plant, state):
    return controller.update(t, reference, plant, state, PERIOD)


_noise = eqx.filter_jit(lambda controller, ts: jax.vmap(lambda t: jnp.stack(controller.noise(t, PERIOD)))(ts))


def plant_state(x, v):
    return MuscleState(pressure=jnp.asarray(3e5), position=jnp.asarray(x), velocity=jnp.asarray(v))


@pytest.mark.parametrize("x, integral", [(0.025, 0.0), (0.031, 1e-3), (0.02, 0.4), (0.05, -0.4)])
def test_without_derivative_and_noise_it_is_the_pi(x, integral):
    """Same duty and integrator as `PIController` in the linear range and in both saturations (anti-windup)."""
    reference = (jnp.asarray(0.03), jnp.asarray(0.01), jnp.asarray(0.0), jnp.asarray(0.0))
    pid = pj.PIDController()
    t = np.asarray(1.0)
    duty, state = _update(pid, t, reference, plant_state(x, 0.004), PIDState(integral=jnp.asarray(integral)))
    duty_pi, integral_pi = _update(pj.PIController(), t, reference, plant_state(x, 0.004), jnp.asarray(integral))
    assert float(duty) == pytest.approx(float(duty_pi), abs=1e-15)
    assert float(state.integral) == pytest.approx(float(integral_pi), abs=1e-15)


def test_derivative_term_acts_on_the_velocity_error():
    reference = (jnp.asarray(0.03), jnp.asarray(0.01), jnp.asarray(0.0), jnp.asarray(0.0))
    base = pj.PIDController(proportional_gain=0.0, integral_gain=0.0, bias=0.5)
    pid = pj.PIDController(proportional_gain=0.0, integral_gain=0.0, bias=0.5, derivative_gain=4.0)
    state = pid.initial_state()
    d0, _ = _update(base, np.asarray(0.0), reference, plant_state(0.03, 0.004), state)
    d1, _ = _update(pid, np.asarray(0.0), reference, plant_state(0.03, 0.004), state)
    assert float(d1) - float(d0) == pytest.approx(4.0 * (0.01 - 0.004), rel=1e-12)


def test_noise_is_seeded_per_period_and_of_the_stated_size():
    pid = pj.PIDController(measurement_noise=1e-4, seed=3)
    times = PERIOD * np.arange(4000)
    draws = np.asarray(_noise(pid, times))
    assert np.std(draws) == pytest.approx(1e-4, rel=0.05)  # 8000 draws: 1.6 % standard error of the std
    assert abs(np.corrcoef(draws[:, 0], draws[:, 1])[0, 1]) < 0.05  # the two samples are independent
    again = np.asarray(_noise(pid, times))
    np.testing.assert_array_equal(draws, again)
    other = pj.PIDController(measurement_noise=1e-4, seed=4)
    assert not np.allclose(draws[:10], np.asarray(_noise(other, times[:10])))


def test_noise_enters_the_derivative_amplified_by_the_sample_time():
    reference = (jnp.asarray(0.03), jnp.asarray(0.0), jnp.asarray(0.0), jnp.asarray(0.0))
    # 1e-7 m of noise keeps the duty inside [0, 1]: the derivative noise is (n − n')/T_s ≈ 1e-3 m/s
    pid = pj.PIDController(proportional_gain=0.0, integral_gain=0.0, bias=0.5, derivative_gain=1.0,
                           measurement_noise=1e-7)
    n, n_earlier = np.asarray(_noise(pid, np.zeros(1)))[0]  # at t = 0
    duty, _ = _update(pid, np.asarray(0.0), reference, plant_state(0.03, 0.0), pid.initial_state())
    assert float(duty) == pytest.approx(0.5 - (float(n) - float(n_earlier)) / 1e-4, rel=1e-12)


def test_bad_input_is_named():
    with pytest.raises(pj.PamjaxInputError, match="derivative_gain"):
        pj.PIDController(derivative_gain=-1.0)
    with pytest.raises(pj.PamjaxInputError, match="sample_time"):
        pj.PIDController(sample_time=0.0)
    with pytest.raises(pj.PamjaxInputError, match="duty_min"):
        pj.PIDController(duty_min=0.8, duty_max=0.2)


def test_bias_seed_and_times_in_other_units_are_refused():
    """bias=50 (50 % meant) and bias=-2 ran with the duty pinned at a limit, seed=1.5 failed inside the solve with a
    raw JAX TypeError, sample_time=20.0 (ms meant) ran; in a loop, measurement_noise=0.1 (0.1 mm meant) ran as 100 mm
    of noise on the MAS-10's 95 mm stroke, which `LoopSensors.noise` refuses. Each refused by name; the bench's values
    still pass, also where the loop is checked again before a run (after eqx.tree_at)."""
    plant = pj.presets.mas10_system("averaged")
    ref = pj.Sine(0.03, 0.01, 0.3)
    for make, match in (
        (lambda: pj.PIController(bias=50.0), r"PIController\.bias must be in \[0, 1\] \(the duty at zero error"),
        (lambda: pj.PIDController(bias=-2.0), r"PIDController\.bias must be in \[0, 1\]"),
        (lambda: pj.PIDController(seed=1.5), r"PIDController\.seed must be an int"),
        (lambda: pj.PIDController(sample_time=20.0), r"sample_time is 20\.0 s, longer than 1\.0 s: that looks like "
                                                     r"milliseconds"),
        (lambda: pj.ClosedLoop(plant, pj.PIDController(measurement_noise=0.1), ref),
         r"PIDController\.measurement_noise.* = 0\.1 m is 1\.1 of the muscle's whole stroke"),
        (lambda: pj.ClosedLoop(plant, pj.PIDController(sample_time=0.1), ref),
         r"sample_time \(0\.1 s\) must not exceed the loop's period \(0\.02 s\)"),
        (lambda: pj.simulate_closed_loop(eqx.tree_at(lambda lp: lp.controller.measurement_noise,
                                                     pj.ClosedLoop(plant, pj.PIDController(), ref), 0.1), 0.1),
         r"PIDController\.measurement_noise.* = 0\.1 m"),
    ):
        with pytest.raises(pj.PamjaxInputError, match=match):
            make()
    loop = pj.ClosedLoop(plant, pj.PIDController(measurement_noise=1e-4, seed=np.int64(2), bias=1.0), ref)
    assert loop.controller.seed == 2 and float(pj.PIController(bias=0.0).bias) == 0.0


def test_a_seed_of_any_size_is_taken():
    # 2**64 (an entropy-sized seed) was a raw OverflowError; seeds that fit are kept as they are
    assert pj.PIDController(seed=2**40).seed == 2**40
    big, other = pj.PIDController(seed=2**64), pj.PIDController(seed=2**64 + 1)
    assert -(2**63) <= big.seed < 2**63 and big.seed != other.seed
    assert pj.PIDController(seed=2**64).seed == big.seed  # deterministic
