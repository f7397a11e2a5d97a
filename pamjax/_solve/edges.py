"""How an adaptive solve sees a switching valve's edges: a run that starts with the valve off (`StartsOff`), and the
exact-edge reference whose switching times are handed to the solver as jump times (`ScheduledValve`)."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from .._physics.signals import AbstractSignal
from .._physics.valves.base import AbstractControlElement, AbstractSwitchingValve


class StartsOff(AbstractSignal):
    """`signal` from `start` [s] on, 0 (valve off) before: the duty a switching valve's previous PWM period has at
    the start of a run."""

    signal: AbstractSignal
    start: jax.Array

    def __call__(self, t):
        return jnp.where(t < self.start - 1e-12, jnp.zeros_like(self.signal(t)), self.signal(t))

    def bounds(self):
        return self.signal.bounds()


class ScheduledValve(AbstractSwitchingValve):
    """A switching valve whose opening follows a precomputed edge schedule (its `edge_schedule`): the exact mode's
    valve inside an adaptive solve. The opening switches exactly at the schedule's times, the very numbers handed to
    the solver as jump times, so the solver's steps end one ulp before an edge and restart after it (a switch
    computed from the phase would land a few ulps off, and the solver would fail with "minimum step size")."""

    valve: AbstractSwitchingValve
    edges: jax.Array  # s, sorted
    states: jax.Array  # opening after each edge

    @property
    def pwm_frequency(self):
        return self.valve.pwm_frequency

    def command_time(self, t):
        return self.valve.command_time(t)

    def max_step(self):
        return self.valve.max_step()

    def switching_gates(self, command):
        return self.valve.switching_gates(command)

    def edge_phases(self, command):
        return self.valve.edge_phases(command)

    def edge_schedule(self, signal, t0, t1):
        return self.valve.edge_schedule(signal, t0, t1)

    def opening(self, t):
        if self.states.shape[0] == 0:  # no edge at all (e.g. duty 0 throughout): closed from start to end
            return jnp.zeros_like(jnp.asarray(t, dtype=float))
        index = jnp.searchsorted(self.edges, t, side="right") - 1
        return jnp.where(index >= 0, self.states[jnp.clip(index, 0, self.states.shape[0] - 1)], 0.0)

    def mass_flow_at_opening(self, opening, pressure, air):
        return self.valve.mass_flow_at_opening(opening, pressure, air)

    def mass_flow(self, t, command, pressure, air):
        return self.valve.mass_flow_at_opening(self.opening(t), pressure, air)


class EdgeClipController(dfx.AbstractAdaptiveStepSizeController):
    """A step-size controller (wrapping `controller`) whose steps end either side of every smoothed switching edge
    of `valve` (its `next_edge_step`): the next boundary is computed from the PWM period and the duty latched at its
    start, in constant time per step (diffrax's `ClipStepSizeController` with an array of all boundaries compares
    each step against the whole array: 3x the run time of a 25 s PWM run)."""

    controller: dfx.AbstractAdaptiveStepSizeController
    valve: AbstractControlElement
    signal: AbstractSignal

    @property
    def atol(self):
        return self.controller.atol

    @property
    def rtol(self):
        return self.controller.rtol

    @property
    def norm(self):
        return self.controller.norm

    def wrap(self, direction):
        return eqx.tree_at(lambda c: c.controller, self, self.controller.wrap(direction))

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t1, state = self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return jnp.minimum(t1, self.valve.next_edge_step(self.signal, t0)), state

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state):
        keep, next_t0, next_t1, made_jump, state, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, controller_state
        )
        next_t1 = jnp.minimum(next_t1, self.valve.next_edge_step(self.signal, next_t0))
        return keep, next_t0, next_t1, made_jump, state, result
