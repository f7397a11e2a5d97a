"""A sampled-data PID position controller whose position measurement may carry sensor noise (paper 000, "PI-Control":
"a reasonable performance was gained with a derivative gain in the controller during the simulations, but due to the
measurement noise it could not be used in the real system")."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import RealScalar, StateLike
from .._core.errors import PamjaxInputError, check_nonnegative, check_positive, concrete_values
from .._core.fitting import parameter
from .._papers import datasheets, paper000
from .controllers import MAX_PERIOD, AbstractController, check_bias, check_duty_limits, fold_seed
from .estimator import check_noise_scale


class PIDState(eqx.Module):
    """`integral` ∫e dt [m s]."""

    integral: StateLike


def _static_seed(seed: int) -> int:
    """An integer (Python or NumPy) as the Python int a static field holds (hashable, no array), folded into 64 bits
    (`fold_seed`: 2**64 was a raw OverflowError); anything else as it is, for `PIDController`'s check to name."""
    whole = isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_))
    return fold_seed(seed, 64) if whole else seed


class PIDController(AbstractController):
    """Discrete PID on a position sensor sampled every T_s with Gaussian noise n ~ N(0, σ²), seeded.

    The controller differentiates its last two samples, (y(t) − y(t − T_s))/T_s; at the PWM period start t_k, where
    the duty is set, that is ẋ(t_k) + (n_k − n'_k)/T_s to O(T_s ẍ) (two independent noise draws): noise enters the
    derivative amplified by √2/T_s. With y_k = x_k + n_k:

    e_k = r_k − y_k,  ė_k = ṙ_k − ẋ_k − (n_k − n'_k)/T_s,  u_k = clip(u0 + K_P e_k + K_I I_{k+1} + K_D ė_k, ...),
    I_{k+1} = I_k + T e_k, held while the unclipped duty is saturated and e_k drives it further (as `PIController`).
    The derivative acts on the measurement (no reference kick; ṙ from the smooth reference).

    **Arguments:** `proportional_gain` K_P [1/m] (25, paper 000), `integral_gain` K_I [1/(m s)] (150, paper 000),
    `derivative_gain` K_D [s/m] (0: the paper's PI), `bias` u0 [-] (0.5, as `PIController`), `duty_min`, `duty_max`
    [-] (0, 1), `measurement_noise` σ [m] (0; the hybrid bench's potentiometer: 1e-4), `sample_time` T_s [s] (1e-4:
    paper 000's "0.1 ms sampling time"; at most the loop's period: both samples lie in one period), `seed` (static
    int).

    **Raises:** `PamjaxInputError` for a negative gain or noise, a `bias` outside [0, 1], bad duty limits, a
    `sample_time` not > 0 or above `MAX_PERIOD` (1 s: milliseconds written as seconds), a `seed` that is no int;
    in a `ClosedLoop`, a `measurement_noise` of a tenth of the plant's stroke or more (0.1 meant in mm) and a
    `sample_time` longer than the loop's period.
    """

    proportional_gain: RealScalar = parameter(paper000.PI_PROPORTIONAL_GAIN, unit="1/m")
    integral_gain: RealScalar = parameter(paper000.PI_INTEGRAL_GAIN, unit="1/(m s)")
    derivative_gain: RealScalar = parameter(0.0, unit="s/m")
    bias: RealScalar = parameter(datasheets.PI_BIAS, unit="-")
    duty_min: RealScalar = parameter(0.0, unit="-")
    duty_max: RealScalar = parameter(1.0, unit="-")
    measurement_noise: RealScalar = parameter(0.0, unit="m")
    sample_time: RealScalar = parameter(paper000.SAMPLE_TIME, unit="s")
    seed: int = eqx.field(static=True, default=0, converter=_static_seed)

    def __check_init__(self):
        for name in ("proportional_gain", "integral_gain", "derivative_gain", "measurement_noise"):
            check_nonnegative(getattr(self, name), f"PIDController.{name}")
        check_positive(self.sample_time, "PIDController.sample_time")
        sample_time = concrete_values(self.sample_time)
        if sample_time is not None and np.any(sample_time > MAX_PERIOD):
            raise PamjaxInputError(f"PIDController.sample_time is {sample_time} s, longer than {MAX_PERIOD} s: that "
                                   "looks like milliseconds (paper 000's 0.1 ms sampling time is 1e-4) [s]")
        check_bias(self.bias, "PIDController")
        check_duty_limits(self.duty_min, self.duty_max, "PIDController")
        # static: no array (a noise key's seed; 1.5 failed inside the solve with a raw JAX TypeError)
        if isinstance(self.seed, (bool, np.bool_)) or not isinstance(self.seed, (int, np.integer)):
            raise PamjaxInputError(f"PIDController.seed must be an int (the sensor noise's seed), got {self.seed!r}")

    def check_loop(self, plant, period):
        """The sensor noise in metres by its magnitude against the plant's stroke (0.1 meant in mm ran as 100 mm of
        noise on the MAS-10's 95 mm stroke), as `LoopSensors.noise`; the sample time within the loop's period."""
        if np.ndim(self.measurement_noise) == 0:  # several values: refused by `simulate_closed_loop`, named
            check_noise_scale(plant, {"position": self.measurement_noise}, "PIDController.measurement_noise")
        sample_time, period = concrete_values(self.sample_time), concrete_values(period)
        if sample_time is not None and period is not None and np.any(sample_time > period):
            raise PamjaxInputError(
                f"PIDController.sample_time ({sample_time} s) must not exceed the loop's period ({period} s): the "
                "controller differentiates two position samples of one period (paper 000 samples every 1e-4 s)")

    def initial_state(self):
        return PIDState(integral=jnp.zeros(()))

    def noise(self, t, period):
        """The sensor noise (n_k, n'_k) [m] of the two samples the controller uses at the period starting at `t` [s]."""
        k = jnp.round(t / period).astype(jnp.int32)
        draws = jax.random.normal(jax.random.fold_in(jax.random.key(self.seed), k), (2,), dtype=jnp.float64)
        return self.measurement_noise * draws[0], self.measurement_noise * draws[1]

    def update(self, t, reference, plant_state, state, period):
        noise, earlier_noise = self.noise(t, period)
        error = reference[0] - (plant_state.position + noise)
        error_rate = reference[1] - plant_state.velocity - (noise - earlier_noise) / self.sample_time
        fixed = self.bias + self.proportional_gain * error + self.derivative_gain * error_rate
        integral = state.integral + period * error
        raw = fixed + self.integral_gain * integral
        winding_up = ((raw > self.duty_max) & (error > 0)) | ((raw < self.duty_min) & (error < 0))
        integral = jnp.where(winding_up, state.integral, integral)
        duty = jnp.clip(fixed + self.integral_gain * integral, self.duty_min, self.duty_max)  # digital saturation
        return duty, PIDState(integral=integral)
