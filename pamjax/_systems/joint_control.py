"""Antagonistic joint control: the angle through the pressure difference, the stiffness through the pressure sum.

Paper 001 (Sect. 7, future work): "the ankle joint position will depend on the difference of both valve output
pressures, whereas the joint stiffness of the sum". With Δ = p_f − p_e and Σ = (p_f − p_atm) + (p_e − p_atm) (gauge),
`AntagonisticJointController` runs two channels on the measured angle θ and pressures:

- feed-forward through the static inverse: Δ*(θ_r, Σ_r) holds θ_r at sum Σ_r (`hold_difference`, the Newton
  form of `AntagonisticJoint.pressures_for`); in stiffness mode Σ_r(θ_r, K_r) gives the stiffness K_r at θ_r
  (`sum_for_stiffness`); plus a lead T_lead d/dt on both, for the regulators' lag (eq. 6);
- angle PI on e_θ = θ_r − θ added to Δ; pressure-sum PI on e_Σ = Σ_r − Σ added to Σ;
- p_f,e = p_atm + (Σ ± Δ)/2 → reference voltages through the inverse calibration, saturated to 0-10 V (and to
  the voltage of the supply pressure), back-calculation anti-windup on both integrators.

Joint stiffness here is the regulated one, K_θ = −∂τ/∂θ at held pressures (`regulated_stiffness`): the VPPMs
hold their set pressures against slow deflections. It is smaller than `AntagonisticJoint.stiffness` (closed chambers,
eq. 9), which describes deflections faster than the regulators.

`JointControlLoop` is the continuous-time closed loop as a pamjax system (controller integrators in the state), so
`simulate_joint_control` (`pamjax._control.joint`) is one diffrax solve: differentiable with respect to gains and
joint parameters.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import ArrayLike, FloatScalar, Real, RealScalar, RealScalarLike
from .._core.errors import PamjaxInputError, check_nonnegative, check_positive, concrete_values
from .._core.fitting import parameter
from .._physics.regulator import EQ6_TIME_CONSTANTS, VOLTAGE_RANGE
from .._physics.signals import AbstractSignal
from .base import AbstractSystem
from .joint import AntagonisticJoint, JointState, check_joint_pressures
from .regulated import check_component, check_operating_point

# The static inverses' root finds (safeguarded Newton, `increasing_root`): the torque is affine in Δ and the stiffness
# nearly affine in Σ where both muscles pull (Newton: 2-4 steps), flat where one is slack (bisection there). A step
# below ROOT_TOLERANCE [Pa] (1e-11 bar; the round-off of a Newton step here is ~1e-10 Pa for Δ, ~1e-9 Pa for Σ) ends
# the search. At least every second step halves the bracket, and 43 halvings narrow the widest (8e6 Pa) to it, so
# ROOT_STEPS bounds every search.
ROOT_TOLERANCE = 1e-6
ROOT_STEPS = 100
# Pa: `hold_difference` searches Δ within ±(Σ + this): 40 bar gauge in one muscle, far beyond any muscle's rating
# (DMSP-40: 6 bar), so the holding difference lies inside unless no pressure holds the angle
DIFFERENCE_SPAN = 4e6

# Default gains, designed on two DMSP-40s, ISO6358Regulators, default joint (reasoning per line):
# ∂τ/∂Δ = 2.70e-4 N m/Pa and K_θ ≈ 115-180 N m/rad, so the static angle gain is ≈ 1.9e-6 rad/Pa.
# Hand-tuned on the 0.5 Hz `GaitAngle` at K_θ = 140-165 N m/rad (grid K_P 0-3e6, K_I 0-2e7, docs/joint_control.md).
ANGLE_PROPORTIONAL_GAIN = 1.0e6  # Pa/rad: static loop gain ≈ 1.9; 1.5e6-2e6 already oscillates (regulator lag)
ANGLE_INTEGRAL_GAIN = 1.0e7  # Pa/(rad s): integral corner K_I/K_P = 10 rad/s, ≈ 3 × the gait's 2nd harmonic
SUM_PROPORTIONAL_GAIN = 0.0  # -: off. When one regulator's exhaust is flow-limited, sum feedback drives the
# other muscle the wrong way and corrupts the difference (angle RMSE 0.033 → 0.044 rad at K_θ = 140, measured)
SUM_INTEGRAL_GAIN = 2.0  # 1/s: slow removal of static sum (hence stiffness) errors, time constant 0.5 s
LEAD_TIME = EQ6_TIME_CONSTANTS[0] + EQ6_TIME_CONSTANTS[1]  # s, 0.064: first-order inverse of eq. 6's two poles
# s: the longest lead taken. It inverts the regulators' lag (eq. 6: 64 ms); a lead of a second or more would run the
# references a half gait cycle ahead (0.5 Hz) and is milliseconds written as seconds (64.0 meant as eq. 6's 64 ms)
MAX_LEAD_TIME = 1.0
TRACKING_TIME = 0.1  # s, back-calculation time constant: Åström-Hägglund's T_t ≈ T_i (= K_P/K_I = 0.1 s)


# --- static inverse -------------------------------------------------------------------------------------------------
def regulated_stiffness(joint: AntagonisticJoint, angle: RealScalarLike, flexor_pressure: RealScalarLike,
                        extensor_pressure: RealScalarLike) -> FloatScalar:
    """K_θ = −∂τ/∂θ [N m/rad] at held absolute pressures [Pa] (regulated muscles), by autodiff of the torque.
    Concrete values are checked, as `AntagonisticJoint.initial_state` checks them (traced ones are not): `angle`
    [rad] inside the joint's `angle_range` (10 for 10° gave 15,365 N m/rad against 137 at 0.1 rad), the pressures
    finite and ABSOLUTE pascal (4.01 for 4.01 bar gave −0.076); else `PamjaxInputError` naming the argument."""
    check_component(joint, AntagonisticJoint, "joint", "an AntagonisticJoint (a muscle's own stiffness: "
                    "pj.muscle_stiffness)")
    check_operating_point(dict(angle=angle), "for several angles, jax.vmap over regulated_stiffness (jax.grad of "
                          "the torque takes one)")  # the pressures broadcast
    joint.check_angle(angle)
    check_joint_pressures(flexor_pressure=flexor_pressure, extensor_pressure=extensor_pressure)
    return _torque_stiffness(joint, angle, flexor_pressure, extensor_pressure)


def _torque_stiffness(joint, angle, flexor_pressure, extensor_pressure):
    """`regulated_stiffness` unchecked: `held_stiffness` takes it where the holding pressures leave the plausible
    range (a slack muscle's gauge pressure below 0 where the sum cannot hold the angle)."""
    return -jax.grad(lambda a: joint.torque(a, flexor_pressure, extensor_pressure))(jnp.asarray(angle, dtype=float))


def _pressures(joint, pressure_sum, difference):
    p_atm = joint.air.atmospheric_pressure
    return p_atm + 0.5 * (pressure_sum + difference), p_atm + 0.5 * (pressure_sum - difference)


def increasing_root(fun, lower, upper, start):
    """x in [`lower`, `upper`] where the nondecreasing `fun` (x ↦ (value, slope)) vanishes: Newton's method
    safeguarded by bisection (Numerical Recipes' `rtsafe`): every evaluation narrows the bracket, and a Newton step
    that leaves it, or that would not halve the step before last (a flat stretch, a kink), is replaced by the
    bracket's midpoint. A root outside the bracket gives its nearer end. A `jax.lax.while_loop` (no derivatives):
    callers stop the gradient of what goes in and differentiate one Newton step at the result (`newton_step`)."""

    def cond(carry):
        _, _, _, step, _, k = carry
        return jnp.any(jnp.abs(step) > ROOT_TOLERANCE) & (k < ROOT_STEPS)

    def body(carry):
        x, lo, hi, step, before, k = carry  # the last step and the one before it
        value, slope = fun(x)
        lo, hi = jnp.where(value < 0, x, lo), jnp.where(value > 0, x, hi)
        newton = x - value / jnp.where(slope > 0, slope, 1.0)
        fast = (slope > 0) & (newton >= lo) & (newton <= hi) & (jnp.abs(2.0 * value) <= jnp.abs(before * slope))
        new = jnp.where(value == 0, x, jnp.where(fast, newton, 0.5 * (lo + hi)))
        return new, lo, hi, new - x, step, k + 1

    lower, upper = jnp.broadcast_arrays(jnp.asarray(lower, dtype=float), jnp.asarray(upper, dtype=float))
    x0 = jnp.clip(start, lower, upper)
    return jax.lax.while_loop(cond, body, (x0, lower, upper, upper - lower, upper - lower, 0))[0]


def newton_step(residual, root, lower, upper):
    """One Newton step of `residual` (differentiable) from `root` (found with the gradient stopped), kept in
    [`lower`, `upper`]: the root again, now carrying the implicit-function derivatives. Where the slope vanishes (a
    flat stretch) the root is kept; where the root is a bracket's end (none inside) the step cannot leave it."""
    value, slope = jax.value_and_grad(residual)(root)
    flat = ~(slope > 0)
    return jnp.clip(jnp.where(flat, root, root - value / jnp.where(flat, 1.0, slope)), lower, upper)


def hold_difference(joint: AntagonisticJoint, angle, pressure_sum):
    """Δ = p_f − p_e [Pa] whose static torque vanishes at `angle` [rad] with gauge sum `pressure_sum` [Pa]:
    safeguarded Newton from Δ = 0 within ±(Σ + `DIFFERENCE_SPAN`) (`increasing_root`: the torque rises with Δ; it
    is affine where both muscles pull, flat where both are slack). Where Σ is too small to hold the angle, Δ leaves
    ±Σ (one gauge pressure below 0: that muscle slack). Same root as `AntagonisticJoint.pressures_for`'s bisection
    wherever that one holds the angle; one Newton step at the root gives the implicit-function derivatives. One
    compiled program (eagerly, its loop would compile at every call)."""
    return _hold_difference(joint, jnp.asarray(angle, dtype=float), jnp.asarray(pressure_sum, dtype=float))


@eqx.filter_jit
def _hold_difference(joint, angle, pressure_sum):
    def tau(j, d, a, s):
        return j.torque(a, *_pressures(j, s, d))

    frozen = jax.lax.stop_gradient((joint, angle, pressure_sum))
    span = jnp.abs(jnp.asarray(frozen[2], dtype=float)) + DIFFERENCE_SPAN
    d = increasing_root(lambda d: jax.value_and_grad(tau, argnums=1)(frozen[0], d, *frozen[1:]), -span, span,
                        jnp.zeros_like(span))
    return newton_step(lambda d: tau(joint, d, angle, pressure_sum), d, -span, span)


def hold_pressures(joint: AntagonisticJoint, angle, pressure_sum):
    """(p_f, p_e) [Pa abs] that hold `angle` [rad] statically at gauge sum `pressure_sum` [Pa]."""
    return _pressures(joint, pressure_sum, hold_difference(joint, angle, pressure_sum))


def held_stiffness(joint: AntagonisticJoint, angle, pressure_sum):
    """Regulated stiffness [N m/rad] at `angle` [rad] held with gauge sum `pressure_sum` [Pa]."""
    return _torque_stiffness(joint, angle, *hold_pressures(joint, angle, pressure_sum))


def stiffness_range(joint: AntagonisticJoint, angle):
    """(K_min, K_max) [N m/rad]: the regulated stiffness at `angle` [rad] held with gauge sums from 0 (the muscle
    that holds the angle alone, the other slack) to twice the regulators' `max_gauge_pressure` (the stiffness does
    not fall as the sum rises)."""
    top = 2.0 * max_gauge_pressure(joint)
    return held_stiffness(joint, angle, 0.0 * top), held_stiffness(joint, angle, top)


def sum_for_stiffness(joint: AntagonisticJoint, angle, stiffness, initial_sum=4e5):
    """Gauge pressure sum Σ [Pa] giving regulated stiffness `stiffness` [N m/rad] at `angle` [rad] held statically:
    safeguarded Newton on Σ from `initial_sum` [Pa] within [0, 2 × the regulators' `max_gauge_pressure`]
    (`increasing_root`: K is nearly affine in Σ where both muscles pull, flat where one is slack), one Newton step
    at the root differentiated. Concrete values outside `stiffness_range` raise `PamjaxInputError` naming the range;
    traced ones give the nearer end of the bracket."""
    angle, stiffness = jnp.asarray(angle, dtype=float), jnp.asarray(stiffness, dtype=float)
    if all(concrete_values(v) is not None for v in jax.tree_util.tree_leaves((joint, angle, stiffness))):
        low, high = (float(k) for k in _stiffness_range(joint, angle))
        k = concrete_values(stiffness)
        if not np.all((k >= low) & (k <= high)):
            raise PamjaxInputError(
                f"stiffness {_text(k)} N m/rad is not reached at angle {_text(concrete_values(angle))} rad: the "
                f"joint's regulated stiffness there spans [{low:.4g}, {high:.4g}] N m/rad (gauge pressure sums 0 to "
                f"{2.0 * float(max_gauge_pressure(joint)):.4g} Pa)")
    return _sum_for_stiffness(joint, angle, stiffness, jnp.asarray(initial_sum, dtype=float))


def _text(values):
    return f"{float(values):g}" if np.size(values) == 1 else np.array2string(values, threshold=6)


_stiffness_range = eqx.filter_jit(stiffness_range)


@eqx.filter_jit
def _sum_for_stiffness(joint, angle, stiffness, initial_sum):
    def residual(j, q, a, k):
        return held_stiffness(j, a, q) - k

    frozen = jax.lax.stop_gradient((joint, angle, stiffness))
    top = jax.lax.stop_gradient(2.0 * max_gauge_pressure(joint)) + 0.0 * frozen[2]
    s = increasing_root(lambda q: jax.value_and_grad(residual, argnums=1)(frozen[0], q, *frozen[1:]), 0.0 * top, top,
                        initial_sum + 0.0 * top)
    return newton_step(lambda q: residual(joint, q, angle, stiffness), s, 0.0, top)


def max_gauge_pressure(joint: AntagonisticJoint):
    """Highest gauge pressure [Pa] both regulators can hold (each one's `max_gauge_pressure`: its 10 V calibration,
    and its supply where that limits it)."""
    limits = []
    for reg in (joint.flexor_regulator, joint.extensor_regulator):
        limit = reg.max_gauge_pressure(joint.air)
        if limit is None:
            raise PamjaxInputError(
                "AntagonisticJointController needs regulators with a VoltageCalibration (LinearRegulator or "
                f"ISO6358Regulator) to turn pressures into voltages, got {type(reg).__name__}"
            )
        limits.append(limit)
    return jnp.min(jnp.stack(limits))


def _voltage(regulator, gauge_pressure):
    """Inverse calibration: the voltage [V] setting `gauge_pressure` [Pa] (PCHIP with the axes swapped: exact for
    the linear default, monotone for any table)."""
    return regulator.calibration.inverse(gauge_pressure)


# --- controller -----------------------------------------------------------------------------------------------------
class AntagonisticJointController(eqx.Module):
    """Angle and stiffness (or pressure sum) control of an `AntagonisticJoint` (see the module docstring).

    Δ = Δ* + T_lead Δ̇* + K_Pθ e_θ + I_θ,   Σ = Σ_r + T_lead Σ̇_r + K_PΣ e_Σ + I_Σ,
    İ_θ = K_Iθ e_θ + (Δ_sat − Δ)/T_t,      İ_Σ = K_IΣ e_Σ + (Σ_sat − Σ)/T_t  (back-calculation anti-windup),

    Δ_sat, Σ_sat: the pressures the saturated voltages ask for.

    **Arguments:** `angle_proportional_gain` K_Pθ [Pa/rad] (1e6), `angle_integral_gain` K_Iθ [Pa/(rad s)] (1e7),
    `sum_proportional_gain` K_PΣ [-] (0), `sum_integral_gain` K_IΣ [1/s] (2), `lead_time` T_lead [s] (0.064,
    eq. 6's τ₁ + τ₂; at most `MAX_LEAD_TIME`, 1 s), `tracking_time` T_t [s] (0.1); reasons beside the module
    constants.
    """

    angle_proportional_gain: RealScalar = parameter(ANGLE_PROPORTIONAL_GAIN, unit="Pa/rad")
    angle_integral_gain: RealScalar = parameter(ANGLE_INTEGRAL_GAIN, unit="Pa/(rad s)")
    sum_proportional_gain: RealScalar = parameter(SUM_PROPORTIONAL_GAIN, unit="-")
    sum_integral_gain: RealScalar = parameter(SUM_INTEGRAL_GAIN, unit="1/s")
    lead_time: RealScalar = parameter(LEAD_TIME, unit="s")
    tracking_time: RealScalar = parameter(TRACKING_TIME, unit="s")

    def __check_init__(self):
        for name in (
            "angle_proportional_gain",
            "angle_integral_gain",
            "sum_proportional_gain",
            "sum_integral_gain",
            "lead_time",
        ):
            check_nonnegative(getattr(self, name), f"AntagonisticJointController.{name}")
        check_positive(self.tracking_time, "AntagonisticJointController.tracking_time")
        lead = concrete_values(self.lead_time)
        if lead is not None and np.any(lead > MAX_LEAD_TIME):
            raise PamjaxInputError(f"AntagonisticJointController.lead_time is {_text(lead)} s, longer than "
                                   f"{MAX_LEAD_TIME:g} s: that looks like milliseconds (eq. 6's τ₁ + τ₂ = 64 ms is "
                                   "0.064) [s]")

    def command(self, joint, targets, target_rates, angle, pressures, integrals):
        """Reference voltages (V_f, V_e) [V] and the integrators' rates [Pa/s] from the targets (θ_r [rad], Σ_r
        [Pa gauge]) and their rates, the measured angle [rad], pressures (p_f, p_e) [Pa abs] and the integrators
        (I_θ, I_Σ) [Pa]."""
        (theta_r, sum_r), (dtheta_r, dsum_r) = targets, target_rates
        p_atm = joint.air.atmospheric_pressure
        diff_ff, ddiff_ff = jax.jvp(lambda a, s: hold_difference(joint, a, s), (theta_r, sum_r), (dtheta_r, dsum_r))
        e_angle = theta_r - angle
        e_sum = sum_r - (pressures[0] + pressures[1] - 2.0 * p_atm)
        diff = diff_ff + self.lead_time * ddiff_ff + self.angle_proportional_gain * e_angle + integrals[0]
        total = sum_r + self.lead_time * dsum_r + self.sum_proportional_gain * e_sum + integrals[1]
        regs = (joint.flexor_regulator, joint.extensor_regulator)
        gauge = (0.5 * (total + diff), 0.5 * (total - diff))
        v_max = jnp.minimum(VOLTAGE_RANGE[1], jnp.stack([_voltage(r, max_gauge_pressure(joint)) for r in regs]))
        raw = jnp.stack([_voltage(r, g) for r, g in zip(regs, gauge)])
        # Controller output saturation (not physics): the exact clip is what the controller does.
        volts = jnp.clip(raw, VOLTAGE_RANGE[0], v_max)
        realised = [r.calibration(v) for r, v in zip(regs, volts)]
        rates = jnp.stack(
            [
                self.angle_integral_gain * e_angle + ((realised[0] - realised[1]) - diff) / self.tracking_time,
                self.sum_integral_gain * e_sum + ((realised[0] + realised[1]) - total) / self.tracking_time,
            ]
        )
        return volts, rates


# --- references -----------------------------------------------------------------------------------------------------
class GaitAngle(AbstractSignal):
    """Gait-like ankle angle [rad]: `offset` + a₁ sin(2π f t) + a₂ sin(4π f t + 1) (push-off and swing, the shape of
    `fits/ankle.py`), a₁ = 0.18 rad, a₂ = 0.08 rad (≈ ±15°, the ankle's sagittal range in walking, Winter)."""

    frequency: RealScalar = parameter(0.5, unit="Hz")
    offset: RealScalar = parameter(0.0, unit="rad")
    first: RealScalar = parameter(0.18, unit="rad")
    second: RealScalar = parameter(0.08, unit="rad")

    def __check_init__(self):
        check_positive(self.frequency, "GaitAngle.frequency")

    def cycle_frequency(self):
        return self.frequency

    def __call__(self, t):
        w = 2 * jnp.pi * self.frequency * t
        return self.offset + self.first * jnp.sin(w) + self.second * jnp.sin(2 * w + 1.0)

    def bounds(self):
        t = np.linspace(0.0, 1.0 / float(self.frequency), 2001)
        v = np.asarray(jax.vmap(self)(jnp.asarray(t)))
        return float(v.min()), float(v.max())


# --- closed loop ----------------------------------------------------------------------------------------------------
class JointControlState(eqx.Module):
    """`plant`: the joint's `JointState` (absolute pressures); `integrals`: (I_θ, I_Σ) [Pa]."""

    plant: JointState
    integrals: Real[ArrayLike, " *batch 2"]


class JointControlLoop(AbstractSystem):
    """An `AntagonisticJoint` under `AntagonisticJointController`, following `angle_reference` [rad] and
    `target`: a stiffness [N m/rad] (`target_kind="stiffness"`) or a gauge pressure sum [Pa] (`"pressure_sum"`).
    A pamjax system whose command is ignored (the references live in the loop)."""

    joint: AntagonisticJoint
    controller: AntagonisticJointController
    angle_reference: AbstractSignal
    target: AbstractSignal
    target_kind: str = eqx.field(static=True, default="stiffness")

    output_names = (*AntagonisticJoint.output_names, "voltage")

    def __check_init__(self):
        if not isinstance(self.joint, AntagonisticJoint):
            raise PamjaxInputError(f"JointControlLoop.joint must be an AntagonisticJoint, got {type(self.joint)}")
        if not isinstance(self.controller, AntagonisticJointController):
            raise PamjaxInputError(
                f"JointControlLoop.controller must be an AntagonisticJointController, got {type(self.controller)}"
            )
        for name in ("angle_reference", "target"):
            if not isinstance(getattr(self, name), AbstractSignal):
                raise PamjaxInputError(
                    f"JointControlLoop.{name} must be a pamjax signal, got {type(getattr(self, name))}"
                )
        if self.target_kind not in ("stiffness", "pressure_sum"):
            raise PamjaxInputError(f"target_kind must be 'stiffness' or 'pressure_sum', got {self.target_kind!r}")
        max_gauge_pressure(self.joint)  # regulators must have a calibration

    @property
    def valve(self):
        return self.joint.valve

    @property
    def actuators(self):
        return self.joint.actuators

    @property
    def air(self):
        return self.joint.air

    def targets(self, t):
        """(θ_r [rad], Σ_r [Pa gauge]) at `t` [s]."""
        theta = self.angle_reference(t)
        target = self.target(t)
        if self.target_kind == "pressure_sum":
            return theta, target
        return theta, sum_for_stiffness(self.joint, theta, target)

    def _command(self, t, state):
        t = jnp.asarray(t, dtype=float)
        targets, rates = jax.jvp(self.targets, (t,), (jnp.ones_like(t),))
        plant = state.plant
        pressures = (plant.flexor.pressure, plant.extensor.pressure)
        return self.controller.command(self.joint, targets, rates, plant.angle, pressures, state.integrals)

    def start_pressures(self, state):
        """The joint's pressures in the loop's state: "plant.flexor.pressure", "plant.extensor.pressure" [Pa abs]
        (`simulate_joint_control` checks them in its `y0`, as `simulate` checks the joint's)."""
        plant = getattr(state, "plant", None)
        return {} if plant is None else {f"plant.{k}": v for k, v in self.joint.start_pressures(plant).items()}

    def initial_state(self, t0=0.0):
        """At rest holding the references at `t0` [s] statically, integrators reset."""
        theta, total = self.targets(jnp.asarray(t0, dtype=float))
        pf, pe = hold_pressures(self.joint, theta, total)
        return JointControlState(plant=self.joint.initial_state(pf, pe, angle=theta), integrals=jnp.zeros(2))

    def vector_field(self, t, state, command):
        volts, rates = self._command(t, state)
        return JointControlState(plant=self.joint.vector_field(t, state.plant, volts), integrals=rates)

    def outputs(self, t, state, command):
        volts, _ = self._command(t, state)
        out = self.joint.outputs(t, state.plant, volts)
        out["voltage"] = volts
        return out

    def state_scale(self):
        return JointControlState(plant=self.joint.state_scale(), integrals=jnp.full(2, 1e5))


def joint_angle_range(joint: AntagonisticJoint):
    """(θ_min, θ_max) [rad] where both muscles stay inside their strokes: x₀ ± r θ ∈ [x_min, x_max]
    (`AntagonisticJoint.angle_range`)."""
    return joint.angle_range()


def check_joint_control_loop(loop, name="loop"):
    """A `PamjaxInputError` naming the argument unless `loop` is a `JointControlLoop` (the type check of the
    joint-control workflows, kept beside the class)."""
    if not isinstance(loop, JointControlLoop):
        raise PamjaxInputError(f"{name} must be a JointControlLoop, got {type(loop).__name__}")
    return loop
