"""Paper 000's plant: one muscle lifting a payload, fed by a valve (its system tests).

Outputs: pressure [Pa abs], position [m], velocity [m/s], force [N] (muscle), friction_force [N], mass_flow [kg/s],
volume [m³].
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import RealScalar, StateLike
from .._core.errors import PamjaxInputError, check_in_open_interval, check_positive, concrete_values
from .._core.fitting import bounded, positive
from .._papers import paper000
from .._physics.chamber import pressure_rate
from .._physics.friction import AbstractFriction, CoulombViscousFriction
from .._physics.gas import POLYTROPIC_RANGE, Air
from .._physics.muscle import AbstractMuscle, EndStops, Muscle, stroke_root
from .._physics.regulator import AbstractRegulator
from .._physics.valves.base import AbstractValve
from .base import AbstractMuscleSystem


class MuscleState(eqx.Module):
    """State of a muscle lifting a payload: `pressure` [Pa abs], `position` x [m] (positive = contraction, payload
    up), `velocity` ẋ [m/s], `friction` the friction model's own state (None for memoryless friction)."""

    pressure: StateLike
    position: StateLike
    velocity: StateLike
    friction: StateLike | None = None


def _check_parts(system):
    """Refuse a part of the wrong kind (None, a number, a string: each ended as an AttributeError inside the solve),
    named, as the constructor is called (and before a solve, for a part set with `eqx.tree_at`)."""
    for name, part, kind, example in (
        ("valve", system.valve, AbstractValve, "presets.mas10_valve(), AveragedValve"),
        ("muscle", system.muscle, AbstractMuscle, "presets.mas10_muscle()"),
        ("friction", system.friction, AbstractFriction, "CoulombViscousFriction(), KarnoppFriction()"),
        ("end_stops", system.end_stops, EndStops, "EndStops()"),
        ("air", system.air, Air, "Air()"),
    ):
        if not isinstance(part, kind):
            hint = ("; a muscle fed by a pressure regulator is a RegulatedMuscleSystem(regulator, muscle)"
                    if isinstance(part, AbstractRegulator) else "")
            raise PamjaxInputError(f"MuscleSystem.{name} must be an {kind.__name__} (e.g. {example}), got "
                                   f"{type(part).__name__}{hint}")



def check_hybrid_stops(system, name):
    """Refuse `end_stops` other than the default beside a hybrid (stick-slip) friction, which takes the stroke limits
    as inelastic stops (events) and never reads them: `EndStops(1e4, 200, 1e-3)`, a soft bumper, left an 80 kg drop
    exactly as the default stops did (concrete values only; a sweep's traced ones are the sweep's checks')."""
    if not system.friction.hybrid:
        return
    default = jax.tree_util.tree_leaves(EndStops())
    given = [concrete_values(leaf) for leaf in jax.tree_util.tree_leaves(system.end_stops)]
    if any(g is not None and not np.array_equal(g, np.asarray(d, dtype=float)) for g, d in zip(given, default)):
        raise PamjaxInputError(
            f"{name}.end_stops: with a stick-slip friction ({type(system.friction).__name__}) the stroke limits are "
            "inelastic stops handled as events, and end_stops would be ignored: drop end_stops, or use a smooth "
            "friction (CoulombViscousFriction, BristleFriction) for elastic stops")


class MuscleSystem(AbstractMuscleSystem):
    """Paper 000's plant: a muscle lifting a payload against gravity, fed by a valve.

    ṗ = n/V(x) (R T ṁ(t, u, p) − p V'(x) ẋ)                      (eq. 15)
    M ẍ = F_muscle(x, p) − F_friction(ẋ, z) − M g + F_stops(x, ẋ)   (eq. 16, eq. 8-9)

    **Arguments:**

    - `valve`, `muscle`, `friction` (`CoulombViscousFriction()` by default), `end_stops` (`EndStops()`).
    - `payload_mass` M [kg] (9.6, paper 000); `gravity` g [m/s²] (9.81).
    - `air`, `polytropic_index` n (1.4 adiabatic, paper 000 eq. 15).
    """

    valve: AbstractValve
    muscle: Muscle
    payload_mass: RealScalar = positive(paper000.PAYLOAD_MASS, unit="kg")
    friction: AbstractFriction = eqx.field(default_factory=CoulombViscousFriction)
    end_stops: EndStops = eqx.field(default_factory=EndStops)
    air: Air = eqx.field(default_factory=Air)
    gravity: RealScalar = positive(paper000.GRAVITY, unit="m/s²")
    polytropic_index: RealScalar = bounded(paper000.POLYTROPIC_INDEX, bounds=POLYTROPIC_RANGE, unit="-")

    output_names = ("pressure", "position", "velocity", "force", "friction_force", "mass_flow", "volume")

    def __check_init__(self):
        _check_parts(self)
        check_hybrid_stops(self, "MuscleSystem")
        check_positive(self.payload_mass, "MuscleSystem.payload_mass")
        check_positive(self.gravity, "MuscleSystem.gravity")
        check_in_open_interval(self.polytropic_index, *POLYTROPIC_RANGE, "MuscleSystem.polytropic_index")

    def equilibrium_position(self, pressure):
        """Position [m] where the muscle force at `pressure` [Pa abs] carries the payload's weight (friction-free),
        clipped to the stroke limits. Bisection plus one Newton step, so its derivative is the implicit one."""
        return _payload_equilibrium(self.muscle, self.air, self.payload_mass * self.gravity,
                                    jnp.asarray(pressure, dtype=float))

    def initial_state(self, pressure=None, position=None, velocity=0.0):
        """State at rest: `pressure` [Pa abs] (atmospheric by default) and `position` [m] (by default the static
        equilibrium with the payload at that pressure). One state: each argument one number (an array of pressures
        failed inside the equilibrium's bisection with JAX's raw carry-type error; several: `jax.vmap` over it)."""
        for name, value in (("pressure", pressure), ("position", position), ("velocity", velocity)):
            if value is not None and jnp.ndim(value) != 0:
                raise PamjaxInputError(f"initial_state: {name} must be one number, got shape {jnp.shape(value)}: one "
                                       "state at a time (several: jax.vmap(system.initial_state) or pamjax.sweep)")
        p = self.air.atmospheric_pressure if pressure is None else jnp.asarray(pressure, dtype=float)
        x = self.equilibrium_position(p) if position is None else jnp.asarray(position, dtype=float)
        return MuscleState(
            pressure=jnp.asarray(p, dtype=float),
            position=jnp.asarray(x, dtype=float),
            velocity=jnp.asarray(velocity, dtype=float),
            friction=self.friction.initial_state(velocity),
        )

    @property
    def hybrid(self):
        return self.friction.hybrid

    def _forces(self, t, state, command):
        x, v = state.position, state.velocity
        muscle = self.muscle.force(x, state.pressure, self.air)
        friction = self.friction.force(v, state.friction)
        if self.hybrid:  # the stroke limits are inelastic stops, handled as events (event_function)
            stops = jnp.zeros_like(x)
        else:
            stops = self.end_stops.force(x, v, self.muscle.min_position, self.muscle.max_position)
        return muscle, friction, stops

    def _held_force(self, x, muscle):
        """Net driving force on a payload at rest [N] (muscle − weight), with what an end stop holds removed: at the
        upper stop only a downward force can move it, at the lower stop only an upward one (hybrid systems)."""
        net = muscle - self.payload_mass * self.gravity
        at_upper = x >= self.muscle.max_position - 1e-12
        at_lower = x <= self.muscle.min_position + 1e-12
        return jnp.where(at_upper, jnp.minimum(net, 0.0), jnp.where(at_lower, jnp.maximum(net, 0.0), net))

    def vector_field(self, t, state, command):
        x, v, p = state.position, state.velocity, state.pressure
        mdot = self.valve.mass_flow(t, command, p, self.air)
        muscle, friction, stops = self._forces(t, state, command)
        dv = (muscle - friction + stops) / self.payload_mass - self.gravity
        dx = v
        stuck = self.friction.is_stuck(state.friction)
        if self.hybrid:  # stuck: the payload holds still (its velocity is exactly 0 after the event)
            dx = jnp.where(stuck, 0.0, v)
            dv = jnp.where(stuck, 0.0, dv)
        volume = self.muscle.volume(x)
        volume_rate = self.muscle.volume_slope(x) * dx
        dp = pressure_rate(mdot, p, volume, volume_rate, self.polytropic_index, self.air)
        return MuscleState(pressure=dp, position=dx, velocity=dv, friction=self.friction.state_rate(v, state.friction))

    def event_function(self, t, state, command):
        """Stuck: (F_c − |F_net|)/(M g), crossing 0 when the net force breaks the payload free. Sliding in
        direction z: min(z ẋ / 1 cm/s, distance to the stop ahead / 1 cm), crossing 0 when it comes to rest or
        reaches a stop."""
        x, v, z = state.position, state.velocity, state.friction
        weight = self.payload_mass * self.gravity
        held = self._held_force(x, self.muscle.force(x, state.pressure, self.air))
        stuck_margin = (self.friction.coulomb_force - jnp.abs(held)) / weight
        gap = jnp.where(z > 0, self.muscle.max_position - x, x - self.muscle.min_position)
        sliding_margin = jnp.minimum(z * v / 1e-2, gap / 1e-2)
        stuck = self.friction.is_stuck(z)
        # a stuck start given a velocity (a y0 edited after initial_state, a sweep over "y0.velocity"): an event at
        # once, whose update slides in the velocity's direction (stuck holds v = 0 exactly between events, so only a
        # start state meets this; its velocity was zeroed: the run of a 0.2 m/s start was the resting one)
        return jnp.where(stuck & (v != 0), -1.0, jnp.where(stuck, stuck_margin, sliding_margin))

    def event_update(self, t, state, command):
        """At rest (velocity 0; a stop is inelastic), on a stop if at one, then stuck or sliding by the net force; a
        stuck start with a velocity slides on in its direction."""
        x = jnp.clip(state.position, self.muscle.min_position, self.muscle.max_position)
        held = self._held_force(x, self.muscle.force(x, state.pressure, self.air))
        moving = self.friction.is_stuck(state.friction) & (state.velocity != 0)
        return MuscleState(
            pressure=state.pressure,
            position=x,
            velocity=jnp.where(moving, state.velocity, jnp.zeros_like(state.velocity)),
            friction=jnp.where(moving, jnp.sign(state.velocity), self.friction.mode_after_event(state.friction, held)),
        )

    def outputs(self, t, state, command):
        muscle, friction, _ = self._forces(t, state, command)
        if self.hybrid:  # stuck: static friction balances the net force
            stuck = self.friction.is_stuck(state.friction)
            friction = jnp.where(stuck, self._held_force(state.position, muscle), friction)
        return dict(
            pressure=state.pressure,
            position=state.position,
            velocity=state.velocity,
            force=muscle,
            friction_force=friction,
            mass_flow=self.valve.mass_flow(t, command, state.pressure, self.air),
            volume=self.muscle.volume(state.position),
        )

    def discrete_step(self, t, state, command, sample_time):
        """Paper 000 eq. 18-20: p and ẋ by explicit Euler, x with the NEW velocity (semi-implicit Euler, eq. 19); a
        friction state of its own by explicit Euler."""
        rate = self.vector_field(t, state, command)
        velocity = state.velocity + sample_time * rate.velocity  # eq. 20
        friction = None if state.friction is None else state.friction + sample_time * rate.friction
        return MuscleState(
            pressure=state.pressure + sample_time * rate.pressure,  # eq. 18
            position=state.position + sample_time * velocity,  # eq. 19
            velocity=velocity,
            friction=friction,
        )

    def state_scale(self):
        friction = self.friction.initial_state()
        friction_scale = None if friction is None else jnp.asarray(1.0 if self.hybrid else 1e-4)
        return MuscleState(
            pressure=jnp.asarray(1e5), position=jnp.asarray(1e-2), velocity=jnp.asarray(1e-2), friction=friction_scale
        )


# One program for the equilibrium (`equinox.filter_jit`: compiled once per muscle model, whatever the valve or the
# friction, and inlined in an enclosing trace). Called eagerly (`system.initial_state()` at the top level: a user's
# script, a bench loader, a design), the bisection's 60-step loop was compiled anew at every call (its body a new
# closure each time) and each of its operations dispatched on its own: ~65 ms per call on the 2-core CPU, ~0.3 ms now
# after the first.
@eqx.filter_jit
def _payload_equilibrium(muscle, air, weight, pressure):
    def residual(model, x):
        m, a = model
        return m.force(x, pressure, a) - weight  # decreasing in x

    x, interior, newton, (lo0, hi0) = stroke_root(residual, (muscle, air), muscle.min_position, muscle.max_position)
    # At a stroke limit the position IS that limit: return the limit itself so the derivative follows it.
    at_limit = jnp.where(x >= 0.5 * (lo0 + hi0), muscle.max_position, muscle.min_position)
    return jnp.where(interior, newton, at_limit)
