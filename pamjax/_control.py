"""Closed-loop position control of a muscle system: sampled-data controllers and the closed loop that runs them.

A PWM valve takes one duty per period, so every controller here is a sampled-data controller: at each period start
t_k = k T it reads the plant state and the reference, returns the duty held over [t_k, t_k + T) and updates its own
state (a PI integrator, ...). `ClosedLoop` composes plant, controller and reference; `simulate_closed_loop` runs it
as a `lax.scan` over PWM periods, one diffrax solve of the plant per period, so the whole loop is differentiable with
respect to controller gains and plant parameters and vmaps over perturbed plants.

- `PIController`: paper 000's PI (P = 25, I = 150), duty saturation and clamping anti-windup.
- `SlidingModeController`: paper 000's proposal ("Analytic valve model"): the equivalent control from the averaged
  model (eq. 13 solved for the duty giving the mass flow that eq. 15 asks for), on a third-order sliding surface.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ._errors import PamjaxInputError, check_finite, check_nonnegative, check_positive
from ._friction import CoulombViscousFriction
from ._inputs import AbstractSignal, Step
from ._simulate import solve
from ._smooth import safe_sqrt, smooth_sign
from ._system import MuscleState, MuscleSystem
from ._valve import AveragedValve, OnOffValve


# --- reference ------------------------------------------------------------------------------------------------------
def reference_derivatives(reference: AbstractSignal, t, order=3):
    """(r, ṙ, r̈, …) of a smooth reference signal at `t` [s] up to `order`, by nested forward-mode derivatives."""
    funcs = [reference]
    for _ in range(order):
        f = funcs[-1]
        funcs.append(lambda s, f=f: jax.jvp(f, (s,), (jnp.ones_like(s),))[1])
    return tuple(f(jnp.asarray(t, dtype=float)) for f in funcs)


# --- controllers ----------------------------------------------------------------------------------------------------
def _check_duty_limits(lo, hi, name):
    for v, which in ((lo, "duty_min"), (hi, "duty_max")):
        arr = np.asarray(v, dtype=float) if not isinstance(v, jax.core.Tracer) else None
        if arr is not None and not np.all((arr >= 0) & (arr <= 1)):
            raise PamjaxInputError(f"{name}.{which} must be in [0, 1] (a PWM duty ratio), got {arr}")
    if not isinstance(lo, jax.core.Tracer) and not isinstance(hi, jax.core.Tracer):
        if not np.all(np.asarray(lo) < np.asarray(hi)):
            raise PamjaxInputError(f"{name}.duty_min ({lo}) must be below duty_max ({hi})")


class AbstractController(eqx.Module):
    """A sampled-data controller, called once per PWM period.

    - `initial_state()`: the controller's own state (a pytree; None if it has none).
    - `update(t, reference, plant_state, state, period)`: from the reference derivatives `(r, ṙ, r̈, r⃛)` [m, m/s,
      m/s², m/s³] at `t` [s], the plant's state (absolute pressure) and its own state, the duty in [0, 1] to hold over
      the next `period` [s] and its next state.
    """

    def initial_state(self):
        return None

    def update(self, t, reference, plant_state, state, period):
        raise NotImplementedError


class PIController(AbstractController):
    """Discrete PI position control with duty saturation and clamping anti-windup (paper 000, "PI control").

    e_k = r_k − x_k,  u_k = clip(u0 + K_P e_k + K_I I_{k+1}, u_min, u_max),  I_{k+1} = I_k + T e_k,
    except that the integrator holds (I_{k+1} = I_k) while the unclipped duty is saturated and e_k drives it further
    into saturation ("conditional integration", as the hybrid bench's E5 runs).

    **Arguments:** `proportional_gain` K_P [1/m] (25, paper 000), `integral_gain` K_I [1/(m s)] (150, paper 000),
    `bias` u0 [-] (0.5, hybrid bench `meta.json`), `duty_min`, `duty_max` [-] (0, 1).
    """

    proportional_gain: jax.Array = eqx.field(converter=jnp.asarray, default=25.0)  # 1/m
    integral_gain: jax.Array = eqx.field(converter=jnp.asarray, default=150.0)  # 1/(m s)
    bias: jax.Array = eqx.field(converter=jnp.asarray, default=0.5)  # -
    duty_min: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)  # -
    duty_max: jax.Array = eqx.field(converter=jnp.asarray, default=1.0)  # -

    def __check_init__(self):
        check_nonnegative(self.proportional_gain, "PIController.proportional_gain")
        check_nonnegative(self.integral_gain, "PIController.integral_gain")
        check_finite(self.bias, "PIController.bias")
        _check_duty_limits(self.duty_min, self.duty_max, "PIController")

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


def equivalent_duty(valve: AveragedValve, mass_flow, pressure, air):
    """The duty u ∈ [0, 1] whose averaged flow (paper 000 eq. 13) is `mass_flow` [kg/s] at chamber `pressure`
    [Pa abs]: the increasing root of c₂u² + c₁u + c₀ = ṁ, cᵢ = Σⱼ m[i, j] p_gʲ; clipped to [0, 1] where ṁ is out of
    reach. Written as u = 2(ṁ − c₀) / (c₁ + √(c₁² + 4c₂(ṁ − c₀))), stable as c₂ → 0."""
    p_gauge = pressure - air.atmospheric_pressure
    c0, c1, c2 = valve.coefficients @ jnp.stack([jnp.ones_like(p_gauge), p_gauge, p_gauge * p_gauge])
    demand = mass_flow - c0
    discriminant = c1 * c1 + 4.0 * c2 * demand
    root = 2.0 * demand / (c1 + safe_sqrt(discriminant))
    # No real root: the demand lies beyond the parabola's vertex; the nearest reachable duty is the saturated one.
    root = jnp.where(discriminant > 0, root, jnp.where(demand > 0, 1.0, 0.0))
    return jnp.clip(root, 0.0, 1.0)


class SlidingModeController(AbstractController):
    """Sliding mode position control with the averaged model's equivalent control (paper 000, "Analytic valve
    model": "the equivalent desired mass flow may be estimated … the bi-polynomial can then be solved").

    Two sliding surfaces in cascade, both through the controller's `model` (a `MuscleSystem` with an `AveragedValve`):

    1. Motion, e = x − r: s = ė + 2λe + λ²∫e. The force F_d = M(r̈ − 2λė − λ²e − K sat(s/φ) + g) + F_f(ṙ) makes
       ṡ = −K sat(s/φ) under eq. 16 (friction F_f of eq. 8-9 compensated at the reference velocity). Eq. 7 (affine in
       p) inverted gives the desired pressure p_d.
    2. Pressure: σ = p − p_d; ṗ_d = ṗ_ref − η sat(σ/φ_p), with ṗ_ref the rate of the pressure that holds the
       reference trajectory. Eq. 15 inverted gives the mass flow ṁ_d = (V ṗ_d / n + p V̇) / (R T), and eq. 13 solved
       for u (`equivalent_duty`) the duty.

    The state (p, x, ẋ) is measured (paper 000 estimates it with an SVSF filter).

    **Arguments:**

    - `model`: a `MuscleSystem` with an `AveragedValve` (eq. 13) and `CoulombViscousFriction` (eq. 8-9).
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

    model: MuscleSystem
    bandwidth: jax.Array = eqx.field(converter=jnp.asarray, default=12.0)  # rad/s
    switching_gain: jax.Array = eqx.field(converter=jnp.asarray, default=6.0)  # m/s²
    boundary_layer: jax.Array = eqx.field(converter=jnp.asarray, default=0.06)  # m/s
    pressure_switching_gain: jax.Array = eqx.field(converter=jnp.asarray, default=2e6)  # Pa/s
    pressure_boundary_layer: jax.Array = eqx.field(converter=jnp.asarray, default=1e5)  # Pa
    integral_limit: jax.Array = eqx.field(converter=jnp.asarray, default=0.1)  # m s
    friction_velocity_width: jax.Array = eqx.field(converter=jnp.asarray, default=5e-3)  # m/s
    duty_min: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)  # -
    duty_max: jax.Array = eqx.field(converter=jnp.asarray, default=1.0)  # -

    def __check_init__(self):
        if not isinstance(self.model, MuscleSystem) or not isinstance(self.model.valve, AveragedValve):
            raise PamjaxInputError(
                "SlidingModeController.model must be a MuscleSystem with an AveragedValve (paper 000 eq. 13), e.g. "
                f"presets.mas10_system(valve='averaged'); got {type(self.model).__name__} with "
                f"{type(getattr(self.model, 'valve', None)).__name__}"
            )
        if not isinstance(self.model.friction, CoulombViscousFriction):
            raise PamjaxInputError(
                "SlidingModeController.model.friction must be CoulombViscousFriction (paper 000 eq. 8-9), got "
                f"{type(self.model.friction).__name__}"
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
        _check_duty_limits(self.duty_min, self.duty_max, "SlidingModeController")

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


# --- closed loop ----------------------------------------------------------------------------------------------------
class ClosedLoopState(eqx.Module):
    """State of the closed loop at a period start: `plant` (a `MuscleState`, absolute pressure), `controller`
    (the controller's own state, e.g. the PI integrator [m s]) and `duty`, the duty of the period before (a PWM
    valve's state carries across periods: after a period above ~90 % it is still open)."""

    plant: MuscleState
    controller: object
    duty: jax.Array = eqx.field(default_factory=lambda: jnp.zeros(()))


class ClosedLoop(eqx.Module):
    """A muscle plant under sampled-data position control: plant, controller and position reference [m].

    The controller runs once per PWM period T = 1/f of the plant's valve (1/50 s for paper 000's MHE2); an
    `AveragedValve` plant uses `period` [s] (default 0.02 s).
    """

    plant: MuscleSystem
    controller: AbstractController
    reference: AbstractSignal
    period: jax.Array  # s

    def __init__(self, plant, controller, reference, period=None):
        self.plant = plant
        self.controller = controller
        self.reference = reference
        if period is None:
            period = 1.0 / plant.valve.pwm_frequency if isinstance(plant.valve, OnOffValve) else 0.02
        self.period = jnp.asarray(period, dtype=float)

    def __check_init__(self):
        if not isinstance(self.plant, MuscleSystem):
            raise PamjaxInputError(f"ClosedLoop.plant must be a MuscleSystem, got {type(self.plant).__name__}")
        if not isinstance(self.controller, AbstractController):
            raise PamjaxInputError(
                f"ClosedLoop.controller must be a pamjax controller, got {type(self.controller).__name__}"
            )
        if not isinstance(self.reference, AbstractSignal):
            raise PamjaxInputError(
                f"ClosedLoop.reference must be a pamjax signal (e.g. Sine), got {type(self.reference).__name__}"
            )
        if isinstance(self.plant.valve, OnOffValve) and self.plant.valve.mode == "exact":
            raise PamjaxInputError(
                "ClosedLoop needs a differentiable plant: use OnOffValve(mode='smooth') (presets.mas10_system('pwm'))"
            )
        check_positive(self.period, "ClosedLoop.period")

    def initial_state(self, plant_state=None):
        """Plant at rest in equilibrium at atmospheric pressure, valve off (the bench's E5 start), controller reset."""
        plant_state = self.plant.initial_state() if plant_state is None else plant_state
        return ClosedLoopState(plant=plant_state, controller=self.controller.initial_state(), duty=jnp.zeros(()))

    def step(self, t, state, sample_offsets, *, rtol, atol, max_steps):
        """One PWM period from `t`: the controller picks the duty, the plant runs with it held. Returns the next state
        and the plant's position and pressure at `t + sample_offsets` and the duty."""
        reference = reference_derivatives(self.reference, t)
        duty, controller_state = self.controller.update(t, reference, state.plant, state.controller, self.period)
        times = t + sample_offsets
        # this period's duty from t, the last period's before it: the valve latches both (OnOffValve.read_command)
        traj = solve(
            self.plant,
            Step(state.duty, duty, t),
            times,
            state.plant,
            t,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            starts_off=False,
            num_periods=1,  # a smoothed valve's edges get step boundaries of their own
        )
        plant_state = jtu.tree_map(lambda a: a[-1], traj.state)
        samples = dict(position=traj.position, pressure=traj.pressure, velocity=traj.velocity, result=traj.result)
        return ClosedLoopState(plant=plant_state, controller=controller_state, duty=duty), duty, samples


class ClosedLoopTrajectory(eqx.Module):
    """Result of `simulate_closed_loop`: `t` [s], `position` [m], `reference` [m], `pressure` [Pa abs], `velocity`
    [m/s] at the sample times; `period_start` [s] and `duty` [-] per PWM period; `final` the last `ClosedLoopState`;
    `result` 0 where every period's solve succeeded."""

    t: jax.Array
    position: jax.Array
    reference: jax.Array
    pressure: jax.Array
    velocity: jax.Array
    period_start: jax.Array
    duty: jax.Array
    final: ClosedLoopState
    result: jax.Array

    def tracking_error(self, start=0.0):
        """(RMSE, peak |e|) [m] of e = r − x over samples with t ≥ `start` [s] (traceable)."""
        weight = (self.t >= start).astype(float)
        error = (self.reference - self.position) * weight
        rmse = jnp.sqrt(jnp.sum(error**2) / jnp.sum(weight))
        return rmse, jnp.max(jnp.abs(error))


def _run(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps):
    period = loop.period
    offsets = period * jnp.arange(1, samples_per_period + 1) / samples_per_period
    state = loop.initial_state() if y0 is None else y0

    # Period starts are computed outside the loop: inside, XLA may fuse k·T + offset into an FMA in one place and not
    # another, and diffrax's check that the save times lie in [t0, t1] then fails by one rounding.
    starts = period * jnp.arange(num_periods, dtype=float)

    def body(state, t):
        state, duty, samples = loop.step(t, state, offsets, rtol=rtol, atol=atol, max_steps=max_steps)
        return state, (t, duty, samples)

    final, (starts, duties, samples) = jax.lax.scan(body, state, starts)
    t = (starts[:, None] + offsets[None, :]).reshape(-1)
    flat = {k: v.reshape(-1) for k, v in samples.items() if k != "result"}
    return ClosedLoopTrajectory(
        t=t,
        position=flat["position"],
        reference=jax.vmap(loop.reference)(t),
        pressure=flat["pressure"],
        velocity=flat["velocity"],
        period_start=starts,
        duty=duties,
        final=final,
        result=jnp.max(jnp.abs(samples["result"])),
    )


def run_closed_loop(loop, num_periods, samples_per_period=10, y0=None, rtol=1e-6, atol=1e-6, max_steps=2000):
    """The unchecked, traceable core of `simulate_closed_loop` (for use inside grad / vmap)."""
    return _run(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps)


_run_jit = eqx.filter_jit(_run)


def simulate_closed_loop(
    loop: ClosedLoop,
    duration,
    *,
    samples_per_period: int = 10,
    y0: ClosedLoopState | None = None,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    max_steps: int = 2000,
) -> ClosedLoopTrajectory:
    """Simulate a sampled-data closed loop for `duration` [s] (rounded up to whole PWM periods).

    Each PWM period the controller reads the plant state and the reference at the period start and sets the duty,
    which the plant holds for the period (one diffrax solve of the plant per period, `lax.scan` over periods).
    Differentiable with respect to controller gains and plant parameters (use `run_closed_loop` inside `jax.grad` /
    `eqx.filter_vmap`).

    **Arguments:** `loop` a `ClosedLoop`; `duration` [s]; `samples_per_period` output samples per period (10: 2 ms
    at 50 Hz, the position ripple resolved); `y0` initial `ClosedLoopState` (default: plant at rest in equilibrium
    at atmospheric pressure, valve off); `rtol`, `atol` as for `simulate` (scaled states); `max_steps` per period.

    **Raises:** `PamjaxInputError` for a reference outside the muscle's stroke or a bad duration, before any solve.
    """
    if not isinstance(loop, ClosedLoop):
        raise PamjaxInputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    duration = float(duration)
    if not np.isfinite(duration) or duration <= 0:
        raise PamjaxInputError(f"duration must be > 0 [s], got {duration}")
    if not (isinstance(samples_per_period, int) and samples_per_period >= 1):
        raise PamjaxInputError(f"samples_per_period must be a positive int, got {samples_per_period!r}")
    lo, hi = loop.reference.bounds()
    x_min, x_max = float(loop.plant.muscle.min_position), float(loop.plant.muscle.max_position)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo >= x_min and hi <= x_max):
        raise PamjaxInputError(
            f"reference must stay inside the muscle's stroke [{x_min}, {x_max}] m, but spans [{lo}, {hi}] m"
        )
    num_periods = int(np.ceil(duration / float(loop.period) - 1e-9))
    return _run_jit(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps)


# --- gradient-based tuning ------------------------------------------------------------------------------------------
def tracking_rmse(loop: ClosedLoop, num_periods: int, start=0.0, **kwargs):
    """RMSE [m] of r − x over t ≥ `start` [s] of a closed-loop run of `num_periods` PWM periods (traceable)."""
    return run_closed_loop(loop, num_periods, **kwargs).tracking_error(start)[0]


def tune_controller(
    loop: ClosedLoop,
    gains,
    duration,
    *,
    start=0.0,
    steps: int = 30,
    learning_rate: float = 0.05,
    samples_per_period: int = 5,
    callback=None,
):
    """Tune positive controller gains by gradient descent (Adam on their logarithms) on the tracking RMSE of the
    closed loop, differentiated through the whole sampled-data simulation (reverse mode).

    **Arguments:** `loop` a `ClosedLoop` (the plant it holds is the one tuned on); `gains` a tuple of attribute names
    of its controller (e.g. `("proportional_gain", "integral_gain")`); `duration` [s]; `start` [s] the RMSE window's
    start; `steps` Adam steps; `learning_rate` in log-gain units; `callback(step, rmse, gains)` for progress.

    **Returns:** `(tuned_loop, history)`: the loop with the best gains met and a list of (rmse [m], gains) per step.
    """
    if not isinstance(loop, ClosedLoop):
        raise PamjaxInputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    for name in gains:
        value = getattr(loop.controller, name, None)
        if value is None or not np.all(np.asarray(value) > 0):
            raise PamjaxInputError(f"tune_controller: gain {name!r} must be a positive controller field, got {value}")
    num_periods = int(np.ceil(float(duration) / float(loop.period) - 1e-9))
    get = lambda ctl: tuple(getattr(ctl, n) for n in gains)  # noqa: E731

    def loss(log_gains):
        controller = eqx.tree_at(get, loop.controller, tuple(jnp.exp(g) for g in log_gains))
        tuned = eqx.tree_at(lambda lp: lp.controller, loop, controller)
        return tracking_rmse(tuned, num_periods, start, samples_per_period=samples_per_period)

    value_and_grad = eqx.filter_jit(jax.value_and_grad(loss))
    params = tuple(jnp.log(jnp.asarray(g, dtype=float)) for g in get(loop.controller))
    m = jtu.tree_map(jnp.zeros_like, params)
    v = jtu.tree_map(jnp.zeros_like, params)
    beta1, beta2, eps = 0.9, 0.999, 1e-12
    history, best = [], (np.inf, params)
    for step in range(steps + 1):
        rmse, grad = value_and_grad(params)
        rmse = float(rmse)
        current = tuple(float(jnp.exp(p)) for p in params)
        history.append((rmse, current))
        if callback is not None:
            callback(step, rmse, current)
        if np.isfinite(rmse) and rmse < best[0]:
            best = (rmse, params)
        if step == steps or not all(np.all(np.isfinite(np.asarray(g))) for g in grad):
            break
        m = jtu.tree_map(lambda a, g: beta1 * a + (1 - beta1) * g, m, grad)
        v = jtu.tree_map(lambda a, g: beta2 * a + (1 - beta2) * g * g, v, grad)
        k = step + 1
        params = jtu.tree_map(
            lambda p, a, b: p - learning_rate * (a / (1 - beta1**k)) / (jnp.sqrt(b / (1 - beta2**k)) + eps),
            params,
            m,
            v,
        )
    controller = eqx.tree_at(get, loop.controller, tuple(jnp.exp(g) for g in best[1]))
    return eqx.tree_at(lambda lp: lp.controller, loop, controller), history
