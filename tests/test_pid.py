"""`PIDController`: with no derivative gain and no noise it is `PIController`; its derivative term is K_D (ṙ − ẋ)
noise-free; its noise is seeded, per period, of the stated size and enters the derivative amplified by 1/T_s."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax._pid import PIDState
from pamjax._system import MuscleState

PERIOD = 0.02  # s, 50 Hz PWM


def plant_state(x, v):
    return MuscleState(pressure=jnp.asarray(3e5), position=jnp.asarray(x), velocity=jnp.asarray(v))


@pytest.mark.parametrize("x, integral", [(0.025, 0.0), (0.031, 1e-3), (0.02, 0.4), (0.05, -0.4)])
def test_without_derivative_and_noise_it_is_the_pi(x, integral):
    """Same duty and integrator as `PIController` in the linear range and in both saturations (anti-windup)."""
    reference = (jnp.asarray(0.03), jnp.asarray(0.01), jnp.asarray(0.0), jnp.asarray(0.0))
    pid = pj.PIDController()
    duty, state = pid.update(1.0, reference, plant_state(x, 0.004), PIDState(integral=jnp.asarray(integral)), PERIOD)
    duty_pi, integral_pi = pj.PIController().update(1.0, reference, plant_state(x, 0.004), jnp.asarray(integral),
                                                    PERIOD)
    assert float(duty) == pytest.approx(float(duty_pi), abs=1e-15)
    assert float(state.integral) == pytest.approx(float(integral_pi), abs=1e-15)


def test_derivative_term_acts_on_the_velocity_error():
    reference = (jnp.asarray(0.03), jnp.asarray(0.01), jnp.asarray(0.0), jnp.asarray(0.0))
    base = pj.PIDController(proportional_gain=0.0, integral_gain=0.0, bias=0.5)
    pid = pj.PIDController(proportional_gain=0.0, integral_gain=0.0, bias=0.5, derivative_gain=4.0)
    state = pid.initial_state()
    d0, _ = base.update(0.0, reference, plant_state(0.03, 0.004), state, PERIOD)
    d1, _ = pid.update(0.0, reference, plant_state(0.03, 0.004), state, PERIOD)
    assert float(d1 - d0) == pytest.approx(4.0 * (0.01 - 0.004), rel=1e-12)


def test_noise_is_seeded_per_period_and_of_the_stated_size():
    pid = pj.PIDController(measurement_noise=1e-4, seed=3)
    times = PERIOD * jnp.arange(4000)
    draws = np.asarray(jax.vmap(lambda t: jnp.stack(pid.noise(t, PERIOD)))(times))
    assert np.std(draws) == pytest.approx(1e-4, rel=0.05)  # 8000 draws: 1.6 % standard error of the std
    assert abs(np.corrcoef(draws[:, 0], draws[:, 1])[0, 1]) < 0.05  # the two samples are independent
    again = np.asarray(jax.vmap(lambda t: jnp.stack(pid.noise(t, PERIOD)))(times))
    np.testing.assert_array_equal(draws, again)
    other = pj.PIDController(measurement_noise=1e-4, seed=4)
    assert not np.allclose(draws[:10], np.asarray(jax.vmap(lambda t: jnp.stack(other.noise(t, PERIOD)))(times[:10])))


def test_noise_enters_the_derivative_amplified_by_the_sample_time():
    reference = (jnp.asarray(0.03), jnp.asarray(0.0), jnp.asarray(0.0), jnp.asarray(0.0))
    # 1e-7 m of noise keeps the duty inside [0, 1]: the derivative noise is (n − n')/T_s ≈ 1e-3 m/s
    pid = pj.PIDController(proportional_gain=0.0, integral_gain=0.0, bias=0.5, derivative_gain=1.0,
                           measurement_noise=1e-7)
    n, n_earlier = pid.noise(0.0, PERIOD)
    duty, _ = pid.update(0.0, reference, plant_state(0.03, 0.0), pid.initial_state(), PERIOD)
    assert float(duty) == pytest.approx(0.5 - float(n - n_earlier) / 1e-4, rel=1e-12)


def test_bad_input_is_named():
    with pytest.raises(pj.PamjaxInputError, match="derivative_gain"):
        pj.PIDController(derivative_gain=-1.0)
    with pytest.raises(pj.PamjaxInputError, match="sample_time"):
        pj.PIDController(sample_time=0.0)
    with pytest.raises(pj.PamjaxInputError, match="duty_min"):
        pj.PIDController(duty_min=0.8, duty_max=0.2)
