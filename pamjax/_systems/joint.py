"""An antagonistic pair of muscles, each fed by its own regulator, on a revolute (ankle) joint (paper 001, Sect. 7).

Kinematics (pulley of radius r): the flexor shortens by x_f = x₀ + r θ, the extensor by x_e = x₀ − r θ, θ the
joint angle [rad] (positive = dorsiflexion). Dynamics:

I θ̈ = r (F_f(x_f, p_f) − F_e(x_e, p_e)) − m g l cos θ − c θ̇,

each pressure from its regulator with V = V(x), V̇ = V'(x) ẋ. With equal muscles the angle is set by the pressure
difference (θ = 0 at p_f = p_e without load) and the joint stiffness K_θ = r² (K_f + K_e) (eq. 9 per muscle) grows
with the pressure sum, as paper 001 proposes. The command is the pair of reference voltages (V_f, V_e) [V].
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import RealScalar, StateLike
from .._core.errors import (
    PamjaxInputError,
    check_finite,
    check_in_open_interval,
    check_nonnegative,
    check_positive,
    concrete_values,
)
from .._core.fitting import bounded, parameter, positive
from .._core.units import check_absolute_pressure, check_plausible
from .._papers import paper000, paper001
from .._physics.gas import POLYTROPIC_RANGE, Air
from .._physics.muscle import AbstractMuscle, EndStops, Muscle
from .._physics.regulator import AbstractRegulator, paper001_air
from .._physics.signals import AbstractSignal
from .base import AbstractSystem, state_leaves
from .regulated import MUSCLE_KINDS, REGULATOR_KINDS, check_component, muscle_stiffness

PULLEY_RADIUS = 0.03  # m, assumed (orthosis lever; ±0.35 rad swings x by ±10 mm of the DMSP-40's 100 mm stroke)
PRE_CONTRACTION = 0.01  # m, assumed: 2.5 % contraction at θ = 0, where the DMSP-40 preset pulls from ≈ 0.7 bar gauge
JOINT_INERTIA = 0.05  # kg m², assumed: foot (≈ 1.3 kg) plus orthosis shell about the ankle
FOOT_MASS = 1.3  # kg, ≈ 1.45 % of paper 001's 91.3 kg subject (Winter's segment tables)
FOOT_ARM = 0.06  # m, ankle to foot centre of mass (assumed)
JOINT_DAMPING = 2.0  # N m s/rad, assumed
MAX_ANGLE = 0.6  # rad, the range `equilibrium_angle` searches (±34°: beyond an ankle's ±0.35 rad gait swing)
# Pa: a GAUGE pressure sum below this was written in bar or MPa (10 mbar holds no joint; the threshold of
# `pamjax._core.units.check_setting`'s gauge p_max check)
MIN_GAUGE_SUM = 1e3
# m: the lever arms of muscle-driven joints are centimetres (orthoses 0.03-0.1 m); on a 0.5 m pulley a DMSP-40's
# 100 mm stroke turns the joint by 0.2 rad (±6°), so more is a radius in mm or cm (30 for 0.03 m)
MAX_PULLEY_RADIUS = 0.5
# m: a foot's centre of mass lies ≈ 0.06 m from the ankle (a whole leg's ≈ 0.4 m from the hip); more than a metre is
# mm or cm
MAX_FOOT_ARM = 1.0


def check_length(value, name, limit, what):
    """A concrete length [m] `name` finite and at most `limit` in size (`what` says why); more looks like mm."""
    check_finite(value, name)
    v = concrete_values(value)
    if v is not None and np.any(np.abs(v) > limit):
        raise PamjaxInputError(f"{name} = {float(np.max(np.abs(v))):g} m: more than {limit:g} m ({what}); that looks "
                               "like mm or cm (pamjax takes SI units: m)")


def check_scalar(name, **values):
    """Each of the named `values` one number (shape ()): `name` (the method) takes one operating point."""
    shapes = {key: np.shape(v) for key, v in values.items()}
    if any(shape != () for shape in shapes.values()):
        got = ", ".join(f"{key} {shape}" for key, shape in shapes.items())
        raise PamjaxInputError(f"{name} takes one number each for {', '.join(values)} (one operating point), got "
                               f"shapes {got}: for several, call it once per point or jax.vmap over it")


def check_joint_pressures(**pressures):
    """Each of the named ABSOLUTE pressures [Pa] finite and not in bar or gauge (`check_absolute_pressure`), named."""
    for name, pressure in pressures.items():
        check_finite(pressure, name)
        check_absolute_pressure(pressure, name)


class JointState(eqx.Module):
    """`flexor`, `extensor`: the regulators' states (their `pressure` [Pa abs]); `angle` θ [rad];
    `angular_velocity` [rad/s]."""

    flexor: eqx.Module
    extensor: eqx.Module
    angle: StateLike
    angular_velocity: StateLike


class VoltagePair(AbstractSignal):
    """The joint's command: (flexor, extensor) reference voltages [V] from two signals."""

    flexor: AbstractSignal
    extensor: AbstractSignal

    def __check_init__(self):
        for name in ("flexor", "extensor"):
            check_component(getattr(self, name), AbstractSignal, f"VoltagePair.{name}",
                            "a pamjax signal of voltage [V] (pj.Constant(3.0), pj.Step(...), pj.Sampled(...))")

    def __call__(self, t):
        return jnp.stack([jnp.asarray(self.flexor(t), dtype=float), jnp.asarray(self.extensor(t), dtype=float)])

    def bounds(self):
        (a, b), (c, d) = self.flexor.bounds(), self.extensor.bounds()
        return min(a, c), max(b, d)


class AntagonisticJoint(AbstractSystem):
    """Two muscles on a pulley, each fed by its own regulator (`valve` is the flexor's regulator, whose 0-10 V range
    both commands obey).

    **Arguments:** `flexor_regulator`, `extensor_regulator`; `flexor`, `extensor`: `Muscle`s; `pulley_radius` r [m]
    (0.03); `pre_contraction` x₀ [m] (0.01); `inertia` I [kg m²] (0.05); `foot_mass` m [kg] (1.3) and `foot_arm` l
    [m] (0.06) of the gravity load; `damping` c [N m s/rad] (2); `gravity` [m/s²] (9.81); `end_stops`; `air`
    (paper 001); `polytropic_index` (1, isothermal). Assumed values are marked in the module.
    """

    flexor_regulator: AbstractRegulator
    extensor_regulator: AbstractRegulator
    flexor: Muscle
    extensor: Muscle
    pulley_radius: RealScalar = positive(PULLEY_RADIUS, unit="m")
    pre_contraction: RealScalar = parameter(PRE_CONTRACTION, unit="m")
    inertia: RealScalar = positive(JOINT_INERTIA, unit="kg m²")
    foot_mass: RealScalar = parameter(FOOT_MASS, unit="kg")
    foot_arm: RealScalar = parameter(FOOT_ARM, unit="m")
    damping: RealScalar = positive(JOINT_DAMPING, unit="N m s/rad")
    gravity: RealScalar = parameter(paper000.GRAVITY, unit="m/s²")
    end_stops: EndStops = eqx.field(default_factory=EndStops)
    air: Air = eqx.field(default_factory=paper001_air)
    polytropic_index: RealScalar = bounded(paper001.POLYTROPIC_INDEX, bounds=POLYTROPIC_RANGE, unit="-")

    output_names = ("pressure", "mass_flow", "angle", "angular_velocity", "force", "volume")

    def __check_init__(self):
        order = "; the arguments are (flexor_regulator, extensor_regulator, flexor, extensor)"
        for name, kind, what in (("flexor_regulator", AbstractRegulator, REGULATOR_KINDS),
                                 ("extensor_regulator", AbstractRegulator, REGULATOR_KINDS),
                                 ("flexor", AbstractMuscle, MUSCLE_KINDS), ("extensor", AbstractMuscle, MUSCLE_KINDS)):
            check_component(getattr(self, name), kind, f"AntagonisticJoint.{name}", what, order)
        check_positive(self.pulley_radius, "AntagonisticJoint.pulley_radius")
        check_length(self.pulley_radius, "AntagonisticJoint.pulley_radius", MAX_PULLEY_RADIUS, "a joint's lever arm")
        check_length(self.foot_arm, "AntagonisticJoint.foot_arm", MAX_FOOT_ARM, "ankle to the foot's centre of mass")
        check_finite(self.gravity, "AntagonisticJoint.gravity")
        check_positive(self.inertia, "AntagonisticJoint.inertia")
        check_nonnegative(self.foot_mass, "AntagonisticJoint.foot_mass")
        check_plausible(self.foot_mass, "AntagonisticJoint.foot_mass")  # 1300 (grams) refused
        check_nonnegative(self.damping, "AntagonisticJoint.damping")
        check_in_open_interval(self.polytropic_index, *POLYTROPIC_RANGE, "AntagonisticJoint.polytropic_index")
        self._check_pre_contraction()

    def _check_pre_contraction(self):
        """x₀ finite and inside both muscles' strokes (θ = 0 must be a pose of the joint)."""
        check_finite(self.pre_contraction, "AntagonisticJoint.pre_contraction")
        x0 = concrete_values(self.pre_contraction)
        for name in ("flexor", "extensor"):
            muscle = getattr(self, name)
            lo, hi = concrete_values(muscle.min_position), concrete_values(muscle.max_position)
            if x0 is None or lo is None or hi is None or np.all((lo <= x0) & (x0 <= hi)):
                continue
            in_mm = np.all((lo <= x0 / 1e3) & (x0 / 1e3 <= hi))
            hint = "; that looks like mm (pamjax takes SI units: m)" if in_mm else ""
            raise PamjaxInputError(
                f"AntagonisticJoint.pre_contraction = {x0.max() if x0.size == 1 else x0:g} m lies outside the {name}'s "
                f"stroke [{float(lo):g}, {float(hi):g}] m (its min_position, max_position): x₀ is both muscles' "
                f"contraction at θ = 0, which must be a pose of the joint{hint}")

    def angle_range(self):
        """(θ_min, θ_max) [rad] where both muscles stay inside their strokes, x₀ ± r θ ∈ [x_min, x_max], as floats;
        None where one of these parameters is traced."""
        values = [concrete_values(v) for v in (self.pulley_radius, self.pre_contraction, self.flexor.min_position,
                                               self.flexor.max_position, self.extensor.min_position,
                                               self.extensor.max_position)]
        if any(v is None or v.shape != () for v in values):
            return None
        r, x0, f_lo, f_hi, e_lo, e_hi = (float(v) for v in values)
        return max((f_lo - x0) / r, (x0 - e_hi) / r), min((f_hi - x0) / r, (x0 - e_lo) / r)

    def check_angle(self, angle, name="angle"):
        """A concrete `angle` [rad] finite and inside `angle_range` (a start beyond it is on an end stop; 20 for
        20° looks like degrees); traced values, or a joint with traced parameters, are not checked."""
        check_finite(angle, name)
        a, bounds = concrete_values(angle), self.angle_range()
        if a is None or bounds is None:
            return
        lo, hi = bounds
        if not np.all((a >= lo) & (a <= hi)):
            worst = float(a.flat[np.argmax(np.maximum(lo - a, a - hi))])
            hint = (f": that looks like degrees ({worst:g}° = {np.radians(worst):.4g} rad; pamjax takes radians)"
                    if lo <= np.radians(worst) <= hi else "")
            raise PamjaxInputError(f"{name} = {worst:g} rad lies outside the joint's range [{lo:.4g}, {hi:.4g}] rad "
                                   f"(both muscles inside their strokes){hint}")

    @property
    def valve(self):
        return self.flexor_regulator

    @property
    def actuators(self):
        """Both regulators: the command is the pair of their reference voltages (V_f, V_e)."""
        return {"flexor_regulator": self.flexor_regulator, "extensor_regulator": self.extensor_regulator}

    def contractions(self, angle):
        """(x_f, x_e) [m] at joint angle [rad]."""
        return self.pre_contraction + self.pulley_radius * angle, self.pre_contraction - self.pulley_radius * angle

    def muscle_forces(self, angle, velocity, flexor_pressure, extensor_pressure):
        """(F_f, F_e) [N] including the end stops, at absolute pressures [Pa]."""
        xf, xe = self.contractions(angle)
        vf, ve = self.pulley_radius * velocity, -self.pulley_radius * velocity
        ff = self.flexor.force(xf, flexor_pressure, self.air) + self.end_stops.force(
            xf, vf, self.flexor.min_position, self.flexor.max_position
        )
        fe = self.extensor.force(xe, extensor_pressure, self.air) + self.end_stops.force(
            xe, ve, self.extensor.min_position, self.extensor.max_position
        )
        return ff, fe

    def torque(self, angle, flexor_pressure, extensor_pressure, velocity=0.0):
        """Net joint torque [N m] (muscles, gravity, damping)."""
        ff, fe = self.muscle_forces(angle, velocity, flexor_pressure, extensor_pressure)
        load = self.foot_mass * self.gravity * self.foot_arm * jnp.cos(angle)
        return self.pulley_radius * (ff - fe) - load - self.damping * velocity

    def stiffness(self, angle, flexor_pressure, extensor_pressure):
        """Joint stiffness K_θ = −dτ/dθ = r² (K_f + K_e) − m g l sin θ [N m/rad]; K_f, K_e: eq. 9, closed."""
        xf, xe = self.contractions(angle)
        kf = muscle_stiffness(self.flexor, xf, flexor_pressure, self.air, None, self.polytropic_index)
        ke = muscle_stiffness(self.extensor, xe, extensor_pressure, self.air, None, self.polytropic_index)
        gravity = -self.foot_mass * self.gravity * self.foot_arm * jnp.sin(angle)
        return self.pulley_radius**2 * (kf + ke) + gravity

    def equilibrium_angle(self, flexor_pressure, extensor_pressure, max_angle=MAX_ANGLE):
        """Angle [rad] in [−max_angle, max_angle] where the static torque at the ABSOLUTE pressures [Pa] vanishes:
        bisection, then a Newton step (which carries the implicit derivative) kept within the range. Concrete values
        are checked: pressures in bar or gauge, and pressures whose torque keeps one sign over the whole range (the
        joint would come to rest beyond it, on an end stop), raise `PamjaxInputError`; traced ones are not (there the
        end of the range nearest the rest angle is returned)."""
        check_scalar("AntagonisticJoint.equilibrium_angle", flexor_pressure=flexor_pressure,
                     extensor_pressure=extensor_pressure)
        check_joint_pressures(flexor_pressure=flexor_pressure, extensor_pressure=extensor_pressure)
        ends = concrete_values(self.torque(jnp.asarray([-max_angle, max_angle]), flexor_pressure, extensor_pressure))
        if ends is not None and not ends[0] >= 0.0 >= ends[1]:  # the torque falls with the angle
            raise PamjaxInputError(
                f"flexor_pressure {float(flexor_pressure):.6g} Pa and extensor_pressure {float(extensor_pressure):.6g} "
                f"Pa hold the joint at no angle in [−{max_angle:g}, {max_angle:g}] rad (max_angle): the static torque "
                f"is {ends[0]:.4g} N m at −{max_angle:g} rad and {ends[1]:.4g} N m at {max_angle:g} rad, one sign "
                "over the range, so the joint would rest beyond it (on an end stop)"
            )
        return self._bisected_angle(flexor_pressure, extensor_pressure, max_angle)

    def _bisected_angle(self, flexor_pressure, extensor_pressure, max_angle):
        """`equilibrium_angle` without its checks (traceable): the end of the range where no angle inside holds."""

        def tau(joint, a):
            return joint.torque(a, flexor_pressure, extensor_pressure)  # decreasing in a

        frozen = jax.lax.stop_gradient(self)

        def body(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            above = jax.lax.stop_gradient(tau(frozen, mid)) > 0
            return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

        lo, hi = jax.lax.fori_loop(0, 60, body, (jnp.asarray(-max_angle), jnp.asarray(max_angle)))
        a = 0.5 * (lo + hi)
        slope = jax.grad(lambda q: tau(frozen, q))(a)
        # the Newton step stays in the range: from a bracket's end (no root inside) it would leave it
        return jnp.clip(a - tau(self, a) / jnp.where(slope < 0, slope, -1.0), -max_angle, max_angle)

    def pressures_for(self, angle, pressure_sum):
        """(p_f, p_e) [Pa abs] holding `angle` [rad] statically with GAUGE pressure sum `pressure_sum` [Pa]
        (feed-forward: the difference sets the angle, the sum the stiffness). Bisection on the difference, within
        ±`pressure_sum` (neither muscle below atmosphere). Concrete values are checked: a sum < 0, in bar (below
        `MIN_GAUGE_SUM`) or not finite, and an angle that no split of the sum holds (the range it reaches named),
        raise `PamjaxInputError`; traced ones are not (there the nearest split is returned: one muscle vented)."""
        p_atm = self.air.atmospheric_pressure
        check_scalar("AntagonisticJoint.pressures_for", angle=angle, pressure_sum=pressure_sum)
        check_finite(angle, "angle")
        check_finite(pressure_sum, "pressure_sum")
        total = concrete_values(pressure_sum)
        if total is not None and not np.all(total >= MIN_GAUGE_SUM) and not np.all(total == 0.0):
            raise PamjaxInputError(
                f"pressure_sum must be a GAUGE pressure sum >= {MIN_GAUGE_SUM:g} Pa (or 0), got {total}: "
                + ("negative" if np.any(total < 0) else "that looks like bar or MPa (5 bar = 5e5 Pa)")
            )

        def tau(delta):
            return self.torque(angle, p_atm + 0.5 * (pressure_sum + delta), p_atm + 0.5 * (pressure_sum - delta))

        ends = concrete_values(tau(jnp.stack([-jnp.asarray(pressure_sum), jnp.asarray(pressure_sum)])))
        if ends is not None and not ends[0] <= 0.0 <= ends[1]:  # the torque rises with the difference
            grid, full = np.linspace(-MAX_ANGLE, MAX_ANGLE, 241), p_atm + pressure_sum  # one evaluation, interpolated
            torques = np.asarray(self.torque(grid, jnp.asarray([[p_atm], [full]]), jnp.asarray([[full], [p_atm]])))
            reach = [float(np.interp(0.0, -row, grid)) for row in torques]  # where each torque (falling) crosses 0
            lo, hi = (f"{a:.4g} rad" if abs(a) < MAX_ANGLE else f"{a:g} rad or beyond" for a in reach)
            raise PamjaxInputError(
                f"angle {float(angle):g} rad cannot be held with pressure_sum {float(pressure_sum):g} Pa: that sum "
                f"holds the joint from {lo} (all of it in the extensor) to {hi} (all in the flexor); a larger "
                "sum reaches further"
            )

        def body(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            low = tau(mid) < 0  # torque increases with the difference
            return jnp.where(low, mid, lo), jnp.where(low, hi, mid)

        lo, hi = jax.lax.fori_loop(0, 80, body, (-pressure_sum, pressure_sum))
        delta = 0.5 * (lo + hi)
        return p_atm + 0.5 * (pressure_sum + delta), p_atm + 0.5 * (pressure_sum - delta)

    def initial_state(self, flexor_pressure=None, extensor_pressure=None, angle=None):
        """At rest with the given absolute pressures [Pa] (atmospheric by default) at their static equilibrium angle
        (`equilibrium_angle`), or at `angle` [rad], which must lie in `angle_range` (`PamjaxInputError`)."""
        pf = jnp.asarray(self.air.atmospheric_pressure if flexor_pressure is None else flexor_pressure, dtype=float)
        pe = jnp.asarray(self.air.atmospheric_pressure if extensor_pressure is None else extensor_pressure, dtype=float)
        check_joint_pressures(flexor_pressure=pf, extensor_pressure=pe)
        if angle is None:
            try:
                a = self.equilibrium_angle(pf, pe)
            except PamjaxInputError as err:
                raise PamjaxInputError(f"AntagonisticJoint.initial_state: {err}; or give the start `angle`") from None
        else:
            self.check_angle(angle)
            a = jnp.asarray(angle, dtype=float)
        return JointState(
            flexor=self.flexor_regulator.initial_state(pf, self.air),
            extensor=self.extensor_regulator.initial_state(pe, self.air),
            angle=a,
            angular_velocity=jnp.zeros(()),
        )

    def start_pressures(self, state):
        """Both muscles' pressures, in their regulators' states: "flexor.pressure", "extensor.pressure" [Pa abs]."""
        return state_leaves(state, ("flexor.pressure", "extensor.pressure"))

    def _chambers(self, state):
        xf, xe = self.contractions(state.angle)
        rv = self.pulley_radius * state.angular_velocity
        return (
            (self.flexor.volume(xf), self.flexor.volume_slope(xf) * rv),
            (self.extensor.volume(xe), -self.extensor.volume_slope(xe) * rv),
        )

    def _check_command(self, command):
        if jnp.shape(command) != (2,):
            raise PamjaxInputError(
                f"AntagonisticJoint's command must be (flexor, extensor) voltages, shape (2,), got {jnp.shape(command)}"
            )

    def vector_field(self, t, state, command):
        self._check_command(command)
        (vf, dvf), (ve, dve) = self._chambers(state)
        n = self.polytropic_index
        d_f = self.flexor_regulator.state_rate(state.flexor, command[0], vf, dvf, self.air, n)
        d_e = self.extensor_regulator.state_rate(state.extensor, command[1], ve, dve, self.air, n)
        tau = self.torque(state.angle, state.flexor.pressure, state.extensor.pressure, state.angular_velocity)
        return JointState(flexor=d_f, extensor=d_e, angle=state.angular_velocity, angular_velocity=tau / self.inertia)

    def outputs(self, t, state, command):
        self._check_command(command)
        (vf, dvf), (ve, dve) = self._chambers(state)
        n = self.polytropic_index
        pf, pe = state.flexor.pressure, state.extensor.pressure
        ff, fe = self.muscle_forces(state.angle, state.angular_velocity, pf, pe)
        return dict(
            pressure=jnp.stack([pf, pe]),
            mass_flow=jnp.stack(
                [
                    self.flexor_regulator.delivered_flow(state.flexor, command[0], vf, dvf, self.air, n),
                    self.extensor_regulator.delivered_flow(state.extensor, command[1], ve, dve, self.air, n),
                ]
            ),
            angle=state.angle,
            angular_velocity=state.angular_velocity,
            force=jnp.stack([ff, fe]),
            volume=jnp.stack([vf, ve]),
        )

    def state_scale(self):
        return JointState(
            flexor=self.flexor_regulator.state_scale(),
            extensor=self.extensor_regulator.state_scale(),
            angle=jnp.asarray(0.1),
            angular_velocity=jnp.asarray(0.1),
        )
