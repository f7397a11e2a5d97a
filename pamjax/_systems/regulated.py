"""Systems fed by a proportional pressure regulator (paper 001), and the muscle-side relations of its eq. 9-11.

- `RegulatorSystem`: a regulator feeding a constant volume (the 0.04 m³ tank of the appendix, or the closed outlet
  port of eq. 6's identification), with an extra outlet mass flow `outlet_flow` (eq. 5's Q_in input).

Both output the flow the regulator delivers at its outlet (`mass_flow`) and the flow it takes at its inlet
(`inlet_flow`; they differ where the regulator has an internal volume, paper 001 Fig. 6).
- `RegulatedMuscleSystem`: a regulator feeding a muscle that lifts a hanging load (paper 001: DMSP-40-400, 893 N).

The command is the reference voltage [V] in 0-10 V. States hold ABSOLUTE pressures (the regulator's state carries
the outlet pressure). Both serve `simulate`, fitting and `linearise` alike.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import FloatScalar, RealScalar, RealScalarLike, StateLike
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
from .._papers import datasheets, paper000, paper001
from .._physics.chamber import chamber_flow
from .._physics.friction import AbstractFriction, CoulombViscousFriction
from .._physics.gas import POLYTROPIC_RANGE, Air
from .._physics.muscle import AbstractMuscle, EndStops, Muscle, stroke_root
from .._physics.regulator import AbstractRegulator, paper001_air
from .base import AbstractMuscleSystem, AbstractSystem, state_leaves

# a shortening may leave the stroke by the end stops' give (along a run): by 5 % of the stroke, the margin `simulate`
# admits a start state by (pamjax._solve.checks.START_STROKE_MARGIN)
STROKE_MARGIN = 0.05
REGULATOR_KINDS = "a pressure regulator (ISO6358Regulator(), LinearRegulator(), FeedbackRegulator(), vppm_regulator())"
MUSCLE_KINDS = "a Muscle (e.g. pj.presets.dmsp40_muscle())"


def check_component(value, kind, name, what, hint=""):
    """A `PamjaxInputError` naming `name` unless `value` is a `kind` (`what` says which, with an example; `hint`
    follows): a component of the wrong type (regulators and muscles swapped, None) failed much later with a raw
    AttributeError."""
    if not isinstance(value, kind):
        raise PamjaxInputError(f"{name} must be {what}, got {type(value).__name__}{hint}")


def check_one_voltage(command, pressure, system):
    """A one-regulator `system`'s command: one reference voltage [V] per state (no more axes than its `pressure`); a
    `VoltagePair` (an `AntagonisticJoint`'s two) failed in the solve with JAX's raw TypeError on shapes."""
    if jnp.ndim(command) > jnp.ndim(pressure):
        raise PamjaxInputError(
            f"{system}'s command must be one reference voltage [V] (a signal such as pj.Constant(3.0)), got shape "
            f"{jnp.shape(command)}: a VoltagePair (flexor, extensor) commands an AntagonisticJoint's two regulators")


def check_operating_point(values, hint):
    """`muscle_stiffness`'s, `stiffness_rate`'s and `regulated_stiffness`'s arguments ({name: value}): one
    operating point (0-d; jax.grad needs a scalar output), else `PamjaxInputError` naming the first array."""
    for name, value in values.items():
        if value is not None and np.ndim(value) > 0:
            raise PamjaxInputError(f"{name} must be one number (one operating point), got shape {np.shape(value)}: "
                                   f"{hint}")


ONE_POINT_HINT = "for several, jax.vmap over the function (e.g. jax.vmap(lambda x: pj.muscle_stiffness(m, x, p, air)))"


class RegulatorSystem(AbstractSystem):
    """A regulator feeding a constant volume V with an extra outlet mass flow Q (kg/s): ṗ from the regulator.

    **Arguments:** `regulator`; `volume` V [m³] (0.04, paper 001's tank; 0 for an ideal closed port with a linear
    regulator); `outlet_flow` [kg/s] (0; a parameter so `linearise` can take it as eq. 5's second input);
    `air` (paper 001: R = 286.9, T = 298 K); `polytropic_index` n (1: isothermal, paper 001 eq. 3, 12).
    """

    regulator: AbstractRegulator
    volume: RealScalar = positive(paper001.TANK_VOLUME, unit="m³")
    outlet_flow: RealScalar = parameter(0.0, unit="kg/s")
    air: Air = eqx.field(default_factory=paper001_air)
    polytropic_index: RealScalar = bounded(paper001.POLYTROPIC_INDEX, bounds=POLYTROPIC_RANGE, unit="-")

    output_names = ("pressure", "mass_flow", "inlet_flow", "volume")

    def __check_init__(self):
        check_component(self.regulator, AbstractRegulator, "RegulatorSystem.regulator", REGULATOR_KINDS)
        if self.regulator.needs_volume:
            check_positive(self.volume, f"RegulatorSystem.volume (an {type(self.regulator).__name__} needs a chamber)")
        else:
            check_nonnegative(self.volume, "RegulatorSystem.volume")
        check_plausible(self.volume, "RegulatorSystem.volume")  # 40 (litres) for paper 001's 0.04 m³ tank refused
        check_in_open_interval(self.polytropic_index, *POLYTROPIC_RANGE, "RegulatorSystem.polytropic_index")
        check_finite(self.outlet_flow, "RegulatorSystem.outlet_flow")  # NaN ended in "maximum step size" at the solve
        check_plausible(self.outlet_flow, "RegulatorSystem.outlet_flow")  # 2.79 (l/min as kg/s) ran to 1713 bar

    @property
    def valve(self):
        return self.regulator

    @property
    def actuators(self):
        return {"regulator": self.regulator}

    def initial_state(self, pressure=None):
        """Outlet at rest at `pressure` [Pa abs]; atmospheric by default."""
        p = self.air.atmospheric_pressure if pressure is None else pressure
        return self.regulator.initial_state(jnp.asarray(p, dtype=float), self.air)

    def _args(self):
        return self.volume, 0.0, self.air, self.polytropic_index, self.outlet_flow

    def vector_field(self, t, state, command):
        check_one_voltage(command, state.pressure, "RegulatorSystem")
        return self.regulator.state_rate(state, command, *self._args())

    def outputs(self, t, state, command):
        check_one_voltage(command, state.pressure, "RegulatorSystem")
        return dict(
            pressure=state.pressure,
            mass_flow=self.regulator.delivered_flow(state, command, *self._args()),
            inlet_flow=self.regulator.inlet_flow(state, command, *self._args()),
            volume=self.volume + 0.0 * state.pressure,
        )

    def state_scale(self):
        return self.regulator.state_scale()


class RegulatedMuscleState(eqx.Module):
    """`regulator`: the regulator's state (its `pressure` is the muscle's, Pa abs); `position` x [m] (shortening);
    `velocity` [m/s]; `friction`: the friction model's state (None if memoryless)."""

    regulator: eqx.Module
    position: StateLike
    velocity: StateLike
    friction: StateLike | None = None


@eqx.filter_jit  # one program: called eagerly, the bisection's loop would compile at every call (systems/muscle.py)
def load_equilibrium(muscle: Muscle, load_force, pressure, air: Air):
    """Shortening x [m] at which the muscle's force at `pressure` [Pa abs] equals `load_force` [N], clipped to the
    stroke. Bisection, then one Newton step that carries the implicit derivative."""

    def residual(m, x):
        return m.force(x, pressure, air) - load_force  # decreasing in x

    x, interior, newton, _ = stroke_root(residual, muscle, muscle.min_position, muscle.max_position)
    return jnp.where(interior, newton, x)


def check_muscle_point(muscle, x, pressure, x_name="x", pressure_name="pressure"):
    """The operating point of `muscle_stiffness` and `stiffness_rate`, where concrete (traced values, inside jit, vmap
    or grad, are not checked): `pressure` finite and ABSOLUTE pascal (4.01 for 4.01 bar gave K = −0.0), `x` [m]
    finite and inside the muscle's stroke give or take `STROKE_MARGIN` (30 for 30 mm gave −1.4e13 N/m, −0.5 m 9.3e7);
    else `PamjaxInputError` naming the argument, as `simulate` names a start state."""
    check_finite(pressure, pressure_name)
    check_absolute_pressure(pressure, pressure_name)
    check_finite(x, x_name)
    v, lo, hi = (concrete_values(b) for b in (x, muscle.min_position, muscle.max_position))
    if v is None or lo is None or hi is None:
        return
    margin = STROKE_MARGIN * (hi - lo)
    outside = (v < lo - margin) | (v > hi + margin)
    if np.any(outside):
        worst = float(np.reshape(v, -1)[np.argmax(np.reshape(outside, -1))])
        hint = (f": that looks like mm ({worst:g} mm = {worst / 1e3:g} m; pamjax takes metres)"
                if abs(worst) > 1.0 and lo <= worst / 1e3 <= hi else "")  # a metre: `check_setting`'s limit
        raise PamjaxInputError(f"{x_name} = {worst:g} m lies outside the muscle's stroke [{float(lo):.4g}, "
                               f"{float(hi):.4g}] m (min_position, max_position; {STROKE_MARGIN:.0%} of it beyond "
                               f"either end admitted, for the end stops' give){hint}")


def volume_derivatives(muscle: Muscle, x):
    """(V, dV/dx, d²V/dx²) [m³, m², m] at shortening `x` [m], by autodiff of the volume law (paper 001 eq. 4)."""
    x = jnp.asarray(x, dtype=float)
    dv = jax.grad(muscle.volume)
    return muscle.volume(x), dv(x), jax.grad(dv)(x)


def muscle_stiffness(muscle: Muscle, x: RealScalarLike, pressure: RealScalarLike, air: Air,
                     pressure_slope: RealScalarLike | None = None,
                     polytropic_index: RealScalarLike = 1.0) -> FloatScalar:
    """Paper 001 eq. 9 by autodiff: K = −dF/dx = −(∂F/∂x + ∂F/∂p · dp/dx) [N/m], x the shortening [m].

    `pressure_slope` dp/dx [Pa/m] along the motion; default the closed chamber, dp/dV = −n p/V (eq. 9's first
    term), so dp/dx = −n p V'/V. For the virtual-work force F = p_g V'(x) this is eq. 9 exactly:
    K = −(V')² dp/dV − V'' p_g. The isobaric stiffness (eq. 9's second term) is `pressure_slope=0`.
    Concrete `x` and `pressure` are checked (`check_muscle_point`: metres inside the stroke, ABSOLUTE pascal; one
    operating point each: jax.vmap over several), `polytropic_index` within `POLYTROPIC_RANGE` and `pressure_slope`
    finite.
    """
    check_component(muscle, AbstractMuscle, "muscle", MUSCLE_KINDS)
    check_component(air, Air, "air", "an Air (e.g. pamjax._physics.regulator.paper001_air(), or a system's .air)")
    check_operating_point(dict(x=x, pressure=pressure), ONE_POINT_HINT)  # jax.grad of the force in both
    check_muscle_point(muscle, x, pressure)
    check_finite(polytropic_index, "polytropic_index")  # NaN gave a NaN stiffness
    check_in_open_interval(polytropic_index, *POLYTROPIC_RANGE, "polytropic_index")  # as every system's
    if pressure_slope is not None:
        check_finite(pressure_slope, "pressure_slope")
    x = jnp.asarray(x, dtype=float)
    pressure = jnp.asarray(pressure, dtype=float)
    if pressure_slope is None:
        v, dv, _ = volume_derivatives(muscle, x)
        pressure_slope = -polytropic_index * pressure * dv / v
    dfdx, dfdp = jax.grad(muscle.force, argnums=(0, 1))(x, pressure, air)
    return -(dfdx + dfdp * pressure_slope)


def stiffness_rate(muscle: Muscle, x: RealScalarLike, velocity: RealScalarLike, pressure: RealScalarLike,
                   pressure_rate: RealScalarLike) -> FloatScalar:
    """Paper 001 eq. 10 (second line), in x = shortening [m]: V'(x) ṗ + V''(x) ẋ p [N/s], V', V'' by autodiff.

    Eq. 10 as printed is the time derivative of the virtual-work force p V'(x), i.e. K ẋ; paper 001 calls it the
    stiffness rate of change. With paper 001's x = (L − L0)/L0 its value is L0 times this one (same sign).
    Concrete `x` and `pressure` are checked as `muscle_stiffness`'s (`x` one number; the others broadcast);
    `velocity` and `pressure_rate` finite.
    """
    check_component(muscle, AbstractMuscle, "muscle", MUSCLE_KINDS)
    check_operating_point(dict(x=x), ONE_POINT_HINT.replace("muscle_stiffness(m, x, p, air)",  # jax.grad in x
                                                            "stiffness_rate(m, x, v, p, dp)"))
    check_muscle_point(muscle, x, pressure)
    check_finite(velocity, "velocity")
    check_finite(pressure_rate, "pressure_rate")
    _, dv, d2v = volume_derivatives(muscle, x)
    return dv * pressure_rate + d2v * velocity * pressure


class RegulatedMuscleSystem(AbstractMuscleSystem):
    """Paper 001's PPRV-PAM set-up: a regulator feeding a muscle that lifts a hanging load.

    ṗ and the delivered flow from the regulator with V = V(x), V̇ = V'(x) ẋ (eq. 3, 4);
    M ẍ = F_muscle(x, p) − F_friction(ẋ) + F_stops(x, ẋ) − F_load.

    **Arguments:** `regulator` (`ISO6358Regulator()`); `muscle` (DMSP-40-400, `presets.dmsp40_muscle()`);
    `load_force` [N] (893, paper 001); `payload_mass` [kg] (893 N / 9.81 m/s²: a hanging weight); `friction`
    (viscous 3000 N s/m, assumed); `end_stops`; `air` (paper 001); `polytropic_index` (1: isothermal, paper 001).
    """

    regulator: AbstractRegulator
    muscle: Muscle
    load_force: RealScalar = parameter(paper001.LOAD_FORCE, unit="N")
    payload_mass: RealScalar = positive(paper001.LOAD_FORCE / paper000.GRAVITY, unit="kg")
    friction: AbstractFriction = eqx.field(
        default_factory=lambda: CoulombViscousFriction(0.0, datasheets.DMSP40_VISCOUS_COEFFICIENT))
    end_stops: EndStops = eqx.field(default_factory=EndStops)
    air: Air = eqx.field(default_factory=paper001_air)
    polytropic_index: RealScalar = bounded(paper001.POLYTROPIC_INDEX, bounds=POLYTROPIC_RANGE, unit="-")

    output_names = ("pressure", "position", "velocity", "force", "friction_force", "mass_flow", "inlet_flow",
                    "volume")

    def __check_init__(self):
        check_component(self.regulator, AbstractRegulator, "RegulatedMuscleSystem.regulator", REGULATOR_KINDS)
        check_component(self.muscle, AbstractMuscle, "RegulatedMuscleSystem.muscle", MUSCLE_KINDS)
        # no events here: a Karnopp friction stayed in its start mode (its Coulomb force lost, or with the motion)
        if isinstance(self.friction, AbstractFriction) and self.friction.hybrid:
            raise PamjaxInputError(
                f"RegulatedMuscleSystem.friction: a stick-slip friction ({type(self.friction).__name__}) needs its "
                "modes switched at events, which the regulated system does not locate (its Coulomb force was lost, "
                "or pushed with the motion from a moving start): use CoulombViscousFriction or BristleFriction "
                "(stick-slip on paper 000's MuscleSystem)")
        check_nonnegative(self.load_force, "RegulatedMuscleSystem.load_force")
        check_positive(self.payload_mass, "RegulatedMuscleSystem.payload_mass")
        check_in_open_interval(self.polytropic_index, *POLYTROPIC_RANGE, "RegulatedMuscleSystem.polytropic_index")

    @property
    def valve(self):
        return self.regulator

    @property
    def actuators(self):
        return {"regulator": self.regulator}

    def initial_state(self, pressure=None, position=None, velocity=0.0):
        """At rest: `pressure` [Pa abs] (atmospheric by default), `position` [m] (default: the load equilibrium)."""
        p = jnp.asarray(self.air.atmospheric_pressure if pressure is None else pressure, dtype=float)
        x = load_equilibrium(self.muscle, self.load_force, p, self.air) if position is None else position
        return RegulatedMuscleState(
            regulator=self.regulator.initial_state(p, self.air),
            position=jnp.asarray(x, dtype=float),
            velocity=jnp.asarray(velocity, dtype=float),
            friction=self.friction.initial_state(velocity),
        )

    def start_pressures(self, state):
        """The muscle's pressure, in the regulator's state: {"regulator.pressure": p [Pa abs]}."""
        return state_leaves(state, ("regulator.pressure",))

    def _chamber(self, state):
        volume = self.muscle.volume(state.position)
        return volume, self.muscle.volume_slope(state.position) * state.velocity

    def _forces(self, state):
        x, v, p = state.position, state.velocity, state.regulator.pressure
        muscle = self.muscle.force(x, p, self.air)
        friction = self.friction.force(v, state.friction)
        stops = self.end_stops.force(x, v, self.muscle.min_position, self.muscle.max_position)
        return muscle, friction, stops

    def vector_field(self, t, state, command):
        check_one_voltage(command, state.regulator.pressure, "RegulatedMuscleSystem")
        volume, volume_rate = self._chamber(state)
        d_reg = self.regulator.state_rate(
            state.regulator, command, volume, volume_rate, self.air, self.polytropic_index
        )
        muscle, friction, stops = self._forces(state)
        dv = (muscle - friction + stops - self.load_force) / self.payload_mass
        return RegulatedMuscleState(
            regulator=d_reg,
            position=state.velocity,
            velocity=dv,
            friction=self.friction.state_rate(state.velocity, state.friction),
        )

    def discrete_step(self, t, state, command, sample_time):
        """Paper 000 eq. 18-20 as `MuscleSystem` steps them: the regulator's state, ẋ and a friction state by explicit
        Euler, x with the NEW velocity (semi-implicit Euler, eq. 19; the generic explicit step moved x by the old
        one, which changes the stability of the DMSP-40's lightly damped mass and spring)."""
        rate = self.vector_field(t, state, command)
        stepped = jax.tree_util.tree_map(lambda y, dy: y + sample_time * dy, state, rate)
        return eqx.tree_at(lambda s: s.position, stepped, state.position + sample_time * stepped.velocity)

    def outputs(self, t, state, command):
        check_one_voltage(command, state.regulator.pressure, "RegulatedMuscleSystem")
        volume, volume_rate = self._chamber(state)
        muscle, friction, _ = self._forces(state)
        return dict(
            pressure=state.regulator.pressure,
            position=state.position,
            velocity=state.velocity,
            force=muscle,
            friction_force=friction,
            mass_flow=self.regulator.delivered_flow(
                state.regulator, command, volume, volume_rate, self.air, self.polytropic_index
            ),
            inlet_flow=self.regulator.inlet_flow(
                state.regulator, command, volume, volume_rate, self.air, self.polytropic_index
            ),
            volume=volume,
        )

    def stiffness(self, state):
        """Eq. 9, closed-chamber muscle stiffness −dF/dx [N/m] at `state`."""
        return muscle_stiffness(
            self.muscle, state.position, state.regulator.pressure, self.air, None, self.polytropic_index
        )

    def stiffness_rate(self, t, state, command):
        """Eq. 10 [N/s] at `state`, with ṗ and ẋ from the vector field."""
        rate = self.vector_field(t, state, command)
        return stiffness_rate(
            self.muscle, state.position, state.velocity, state.regulator.pressure, rate.regulator.pressure
        )

    def eq11_flow(self, t, state, command):
        """Eq. 11: q = (V ṗ + V' ẋ p)/(n R T) [kg/s] at `state`, with ṗ and ẋ from the vector field."""
        rate = self.vector_field(t, state, command)
        volume, volume_rate = self._chamber(state)
        return chamber_flow(
            volume, volume_rate, state.regulator.pressure, rate.regulator.pressure, self.air, self.polytropic_index
        )

    def state_scale(self):
        friction = self.friction.initial_state()
        return RegulatedMuscleState(
            regulator=self.regulator.state_scale(),
            position=jnp.asarray(1e-2),
            velocity=jnp.asarray(1e-2),
            friction=None if friction is None else jnp.asarray(1e-4),
        )
