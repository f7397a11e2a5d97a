"""Sampled-data position controllers of a muscle system, called once per PWM period (`pamjax._control.closed_loop`
runs them).

A PWM valve takes one duty per period, so every controller here is a sampled-data controller: at each period start
t_k = k T it reads the plant state and the reference, returns the duty held over [t_k, t_k + T) and updates its own
state (a PI integrator, ...).

- `PIController`: paper 000's PI (P = 25, I = 150), duty saturation and clamping anti-windup.
- `SlidingModeController`: paper 000's proposal ("Analytic valve model"): the equivalent control from the averaged
  model (eq. 13 solved for the duty giving the mass flow that eq. 15 asks for), on a third-order sliding surface.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import FloatScalar, RealScalar, RealScalarLike
from .._core.errors import (
    PamjaxInputError,
    check_in_closed_interval,
    check_nonnegative,
    check_positive,
    concrete_values,
)
from .._core.fitting import parameter
from .._core.units import check_absolute_pressure
from .._papers import datasheets, paper000
from .._physics.gas import Air
from .._physics.signals import AbstractSignal
from .._physics.smooth import smooth_sign
from .._physics.valves.averaged import AveragedValve, check_broadcastable
from .._physics.valves.base import AbstractControlElement
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from .._systems.regulated import check_component

# s: the longest controller period taken. Pneumatic PWM runs at 10-500 Hz (paper 000's MHE2: 50 Hz, 20 ms) and a
# muscle's pressure settles in ~0.1 s: a period of a second or more holds one duty over the whole motion, and is
# milliseconds written as seconds (period=20.0 meant as 20 ms ran 20 s with one duty).
MAX_PERIOD = 1.0


# --- reference ------------------------------------------------------------------------------------------------------
def reference_derivatives(reference: AbstractSignal, t, order=3):
    """(r, ṙ, r̈, …) of a smooth reference signal at `t` [s] up to `order`, by nested forward-mode derivatives."""
    funcs = [reference]
    for _ in range(order):
        f = funcs[-1]
        funcs.append(lambda s, f=f: jax.jvp(f, (s,), (jnp.ones_like(s),))[1])
    return tuple(f(jnp.asarray(t, dtype=float)) for f in funcs)


# --- controllers ----------------------------------------------------------------------------------------------------
def fold_seed(seed: int, bits: int = 32) -> int:
    """An integer noise seed of any size (NumPy's generators take any; 2**32 in `LoopSensors` was a raw
    OverflowError) as a `bits`-bit signed int for `jax.random.key`: itself where it fits (the noise of every seed
    that ran before is unchanged), else 32 (64) bits of `numpy.random.SeedSequence` mixing all its digits and its
    sign: deterministic, and two distinct seeds share a key with probability 2^-bits."""
    seed, half = int(seed), 2 ** (bits - 1)
    if -half <= seed < half:
        return seed
    word = int(np.random.SeedSequence([abs(seed), int(seed < 0)]).generate_state(1, f"uint{bits}")[0])
    return word - 2 * half if word >= half else word


def check_duty_limits(lo, hi, name):
    for v, which in ((lo, "duty_min"), (hi, "duty_max")):
        arr = np.asarray(v, dtype=float) if not isinstance(v, jax.core.Tracer) else None
        if arr is not None and not np.all((arr >= 0) & (arr <= 1)):
            raise PamjaxInputError(f"{name}.{which} must be in [0, 1] (a PWM duty ratio), got {arr}")
    if not isinstance(lo, jax.core.Tracer) and not isinstance(hi, jax.core.Tracer):
        if not np.all(np.asarray(lo) < np.asarray(hi)):
            raise PamjaxInputError(f"{name}.duty_min ({lo}) must be below duty_max ({hi})")


def check_bias(bias, name):
    """The duty at zero error u0 in [0, 1], a PWM duty ratio as the duty limits are: bias=50 (50 % meant) ran with
    the duty pinned at duty_max, silently. A traced bias is checked at run time (`check_in_closed_interval`)."""
    v = concrete_values(bias)
    if v is not None and not np.all((v >= 0) & (v <= 1)):  # also NaN
        raise PamjaxInputError(f"{name}.bias must be in [0, 1] (the duty at zero error, a PWM duty ratio: 50 % is "
                               f"0.5), got {np.array2string(v, threshold=6)}")
    check_in_closed_interval(bias, 0.0, 1.0, f"{name}.bias")


class AbstractController(eqx.Module):
    """A sampled-data controller, called once per PWM period.

    - `initial_state()`: the controller's own state (a pytree; None if it has none).
    - `update(t, reference, plant_state, state, period)`: from the reference derivatives `(r, ṙ, r̈, r⃛)` [m, m/s,
      m/s², m/s³] at `t` [s], the plant's state (absolute pressure) and its own state, the duty in [0, 1] to hold over
      the next `period` [s] and its next state.
    """

    def initial_state(self):
        return None

    def check_loop(self, plant, period):
        """The controller's checks that need the loop's `plant` and `period` [s] (`ClosedLoop` runs them, as it is
        built and before every run); none by default."""

    @abc.abstractmethod
    def update(self, t, reference, plant_state, state, period):
        """(duty in [0, 1] held over the next `period` [s], the controller's next state) from the reference
        derivatives `(r, ṙ, r̈, r⃛)` at `t` [s], the plant's state (absolute pressure) and the controller's state."""


class PIController(AbstractController):
    """Discrete PI position control with duty saturation and clamping anti-windup (paper 000, "PI control").

    e_k = r_k − x_k,  u_k = clip(u0 + K_P e_k + K_I I_{k+1}, u_min, u_max),  I_{k+1} = I_k + T e_k,
    except that the integrator holds (I_{k+1} = I_k) while the unclipped duty is saturated and e_k drives it further
    into saturation ("conditional integration", as the hybrid bench's E5 runs).

    **Arguments:** `proportional_gain` K_P [1/m] (25, paper 000), `integral_gain` K_I [1/(m s)] (150, paper 000),
    `bias` u0 [-] (0.5, hybrid bench `meta.json`), `duty_min`, `duty_max` [-] (0, 1).
    """

    proportional_gain: RealScalar = parameter(paper000.PI_PROPORTIONAL_GAIN, unit="1/m")
    integral_gain: RealScalar = parameter(paper000.PI_INTEGRAL_GAIN, unit="1/(m s)")
    bias: RealScalar = parameter(datasheets.PI_BIAS, unit="-")
    duty_min: RealScalar = parameter(0.0, unit="-")
    duty_max: RealScalar = parameter(1.0, unit="-")

    def __check_init__(self):
        check_nonnegative(self.proportional_gain, "PIController.proportional_gain")
        check_nonnegative(self.integral_gain, "PIController.integral_gain")
        check_bias(self.bias, "PIController")
        check_duty_limits(self.duty_min, self.duty_max, "PIController")

    def initial_state(self):
        return jnp.zeros(())  # ∫e dt [m s]

    def update(self, t, reference, plant_state, state, period):
        error = reference[0] - plant_state.position
        proportional = self.bias + self.proportional_gain * error
        integral = state + period * error
        raw = proportional + self.integral_gain * integral
        winding_up = ((raw > self.duty_max) & (error > 0)) | ((raw < self.duty_min) & (error < 0))
        integral = jnp.where(winding_up, state, integral)
        # A digital saturation (not physics): the exact clip is what the controller does.
        duty = jnp.clip(proportional + self.integral_gain * integral, self.duty_min, self.duty_max)
        return duty, integral


def equivalent_duty(valve: AveragedValve, mass_flow: RealScalarLike, pressure: RealScalarLike,
                    air: Air) -> FloatScalar:
    """The duty u ∈ [0, 1] whose averaged flow (paper 000 eq. 13) is `mass_flow` [kg/s] at chamber `pressure`
    [Pa abs]: `valve.command_for_flow` of an averaged valve (`AveragedValve`: the increasing root of eq. 13's
    quadratic in u, clipped to [0, 1] where ṁ is out of reach).

    Concrete inputs are checked (a NaN flow or pressure gave duty 0, a pressure in bar a duty for 3 Pa abs); traced
    ones, as in a control loop, are not (no value to check, and the loop's program is left as it was)."""
    if not (isinstance(valve, AbstractControlElement) and valve.averaged):
        raise PamjaxInputError(
            f"equivalent_duty: valve must be an averaged valve (paper 000 eq. 13, AveragedValve, e.g. "
            f"presets.mas10_averaged_valve()), whose flow command_for_flow inverts; got {type(valve).__name__} (a "
            "switching valve's cycle average: fit_averaged_valve(valve, air) first)")
    # None gave a raw AttributeError deep in eq. 13
    check_component(air, Air, "equivalent_duty: air", "the gas's properties, an Air (pamjax.Air(), or model.air)")
    for name, value, unit in (("mass_flow", mass_flow, "kg/s"), ("pressure", pressure, "Pa abs")):
        if not _is_real(value):  # the string "1e-3" passed NumPy's float conversion, then failed as a raw TypeError
            raise PamjaxInputError(f"equivalent_duty: {name} must be a real number or array [{unit}], got "
                                   f"{type(value).__name__} {value!r}")
    check_broadcastable(("mass_flow", "pressure"), (mass_flow, pressure), "equivalent_duty",
                        "one flow per pressure, or one of them a scalar")  # (3 flows, 2 pressures: a raw TypeError)
    flow = concrete_values(mass_flow)
    if flow is not None and not np.all(np.isfinite(flow)):
        raise PamjaxInputError(f"equivalent_duty: mass_flow must be finite [kg/s], got {flow}")
    if concrete_values(pressure) is not None:
        check_positive(pressure, "equivalent_duty: pressure (absolute) [Pa]")
        check_absolute_pressure(pressure, "equivalent_duty: pressure")
    return valve.command_for_flow(mass_flow, pressure, air)


def _is_real(value):
    """`value` a number or an array of them (integer or floating point), concrete or traced: no string, no bool."""
    try:
        dtype = value.dtype if isinstance(value, jax.Array) else np.asarray(value).dtype
    except (TypeError, ValueError):  # a ragged list
        return False
    return dtype.kind in "iuf"


class SlidingModeController(AbstractController):
    """Sliding mode position control with the averaged model's equivalent control (paper 000, "Analytic valve
    model": "the equivalent desired mass flow may be estimated … the bi-polynomial can then be solved").

    Two sliding surfaces in cascade, both through the controller's `model` (a muscle system with an averaged valve):

    1. Motion, e = x − r: s = ė + 2λe + λ²∫e. The force F_d = M(r̈ − 2λė − λ²e − K sat(s/φ) + g) + F_f(ṙ) makes
       ṡ = −K sat(s/φ) under eq. 16 (friction F_f of eq. 8-9 compensated at the reference velocity). Eq. 7 (affine in
       p) inverted gives the desired pressure p_d.
    2. Pressure: σ = p − p_d; ṗ_d = ṗ_ref − η sat(σ/φ_p), with ṗ_ref the rate of the pressure that holds the
       reference trajectory. Eq. 15 inverted gives the mass flow ṁ_d = (V ṗ_d / n + p V̇) / (R T), and eq. 13 solved
       for u (`equivalent_duty`) the duty.

    The state (p, x, ẋ) is measured (paper 000 estimates it with an SVSF filter).

    **Arguments:**

    - `model`: a muscle system (`MuscleSystem`) whose valve is averaged (`AveragedValve`, eq. 13: `valve.averaged`)
      and whose friction has eq. 8-9's `coulomb_force` and `viscous_coefficient` (e.g. `CoulombViscousFriction`).
    - `bandwidth` λ [rad/s] (12; (d/dt + λ)² ∫e = 0 on the surface; below the 50 Hz sampling's 314 rad/s).
    - `switching_gain` K [m/s²] (6), `boundary_layer` φ [m/s] (0.06): linear gain K/φ = 100 1/s inside the layer.
      K bounds the force error the loop rejects (M K ≈ 58 N at 9.6 kg: the ±20 % plant perturbations of
      `fits/control.py`). Defaults: hand-tuned on `presets.mas10_system("pwm")` (1 rad/s test).
    - `pressure_switching_gain` η [Pa/s] (2e6), `pressure_boundary_layer` φ_p [Pa] (1e5): gain 20 1/s, below
      the 50 Hz sampling rate.
    - `integral_limit` [m s]: anti-windup clamp of |∫e| (0.1: λ²·0.1·M ≈ 60 N of force error at λ = 8).
    - `friction_velocity_width` [m/s]: width of the smooth sign in the friction compensation (5e-3).
    - `duty_min`, `duty_max` [-] (0, 1).
    """

    model: AbstractSystem
    bandwidth: RealScalar = parameter(12.0, unit="rad/s")
    switching_gain: RealScalar = parameter(6.0, unit="m/s²")
    boundary_layer: RealScalar = parameter(0.06, unit="m/s")
    pressure_switching_gain: RealScalar = parameter(2e6, unit="Pa/s")
    pressure_boundary_layer: RealScalar = parameter(1e5, unit="Pa")
    integral_limit: RealScalar = parameter(0.1, unit="m s")
    friction_velocity_width: RealScalar = parameter(5e-3, unit="m/s")
    duty_min: RealScalar = parameter(0.0, unit="-")
    duty_max: RealScalar = parameter(1.0, unit="-")

    def __check_init__(self):
        model = self.model
        # a muscle system's friction keeps eq. 8-9's coulomb_force and viscous_coefficient (`AbstractFriction`)
        if not (isinstance(model, AbstractMuscleSystem) and model.valve.averaged):
            valve = model.valve if isinstance(model, AbstractSystem) else None
            raise PamjaxInputError(
                "SlidingModeController.model must be a muscle system with an averaged valve (paper 000 eq. 13, "
                "AveragedValve), e.g. presets.mas10_system(valve='averaged'); got "
                f"{type(model).__name__} with {type(valve).__name__}"
            )
        for name in (
            "bandwidth",
            "boundary_layer",
            "pressure_boundary_layer",
            "integral_limit",
            "friction_velocity_width",
        ):
            check_positive(getattr(self, name), f"SlidingModeController.{name}")
        check_nonnegative(self.switching_gain, "SlidingModeController.switching_gain")
        check_nonnegative(self.pressure_switching_gain, "SlidingModeController.pressure_switching_gain")
        check_duty_limits(self.duty_min, self.duty_max, "SlidingModeController")

    def initial_state(self):
        return jnp.zeros(())  # ∫(x − r) dt [m s]

    def _pressure_for_force(self, force, position, velocity):
        """Absolute pressure [Pa] at which the model's muscle gives `force` [N] at `position` [m]: eq. 7 before the
        slack is affine in p, so one Newton step from p_atm is exact."""
        model = self.model
        p0 = model.air.atmospheric_pressure
        f = lambda p: model.muscle.static_force(position, p, model.air)  # noqa: E731
        f0, slope = jax.jvp(f, (jnp.asarray(p0, dtype=float),), (jnp.ones(()),))
        return p0 + (force - f0) / slope

    def _friction(self, velocity):
        """Eq. 8-9 with the sign smoothed over `friction_velocity_width` (compensation, not the model's width)."""
        friction = self.model.friction
        return (
            friction.coulomb_force * smooth_sign(velocity, self.friction_velocity_width)
            + friction.viscous_coefficient * velocity
        )

    def _holding_force(self, position, velocity, acceleration):
        """Muscle force [N] for the motion (x, ẋ, ẍ) under eq. 16: M(ẍ + g) + F_f(ẋ)."""
        model = self.model
        return model.payload_mass * (acceleration + model.gravity) + self._friction(velocity)

    def desired_pressure(self, reference, plant_state, integral):
        """(p_d [Pa abs], ṗ_ref [Pa/s], s [m/s]) of the motion surface (see the class docstring)."""
        r, dr, ddr, dddr = reference
        lam = self.bandwidth
        e, de = plant_state.position - r, plant_state.velocity - dr
        s = de + 2 * lam * e + lam**2 * integral
        acceleration = ddr - 2 * lam * de - lam**2 * e - self.switching_gain * jnp.clip(s / self.boundary_layer, -1, 1)
        force = self.model.payload_mass * (acceleration + self.model.gravity) + self._friction(dr)
        pressure = self._pressure_for_force(force, r, dr)

        def reference_pressure(r, dr, ddr):
            return self._pressure_for_force(self._holding_force(r, dr, ddr), r, dr)

        pressure_rate = jax.jvp(reference_pressure, (r, dr, ddr), (dr, ddr, dddr))[1]
        return pressure, pressure_rate, s

    def update(self, t, reference, plant_state, state, period):
        model = self.model
        desired, feedforward_rate, _ = self.desired_pressure(reference, plant_state, state)
        x, v, p = plant_state.position, plant_state.velocity, plant_state.pressure
        sigma = p - desired
        pressure_rate = feedforward_rate - self.pressure_switching_gain * jnp.clip(
            sigma / self.pressure_boundary_layer, -1, 1
        )
        volume = model.muscle.volume(x)
        volume_rate = model.muscle.volume_slope(x) * v
        air = model.air
        # Eq. 15 inverted: ṁ = (V ṗ / n + p V̇) / (R T).
        mass_flow = (volume * pressure_rate / model.polytropic_index + p * volume_rate) / (
            air.gas_constant * air.temperature
        )
        duty = jnp.clip(equivalent_duty(model.valve, mass_flow, p, air), self.duty_min, self.duty_max)
        error = x - reference[0]
        integral = jnp.clip(state + period * error, -self.integral_limit, self.integral_limit)
        return duty, integral
