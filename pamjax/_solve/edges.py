"""How an adaptive solve sees a switching valve's edges: a run that starts with the valve off (`StartsOff`), and the
exact-edge reference whose switching times are handed to the solver as jump times (`ScheduledValve`)."""

import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.errors import concrete_values
from .._physics.signals import AbstractSignal
from .._physics.valves.base import AbstractSwitchingValve


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


def command_jumps(signal, t0, t_end):
    """The times where a continuous valve's command jumps (`signal.jump_times()`: a `Step`'s, a `Sampled` table's
    hold changes), as step boundaries for the adaptive solve, or None. Stepped over, a jump is not seen by the
    solver's error estimate: the averaged MAS-10 from duty 0.97 to 0.2 ended 349 Pa / 22 µm off a tight solve at the
    default tolerances (2 Pa without the jump); with the boundary it is solved as two smooth pieces. Concrete times
    are those inside (t0, t_end), sorted; traced ones (a `Step.time` differentiated or vmapped) are kept as traced
    boundaries, so that the solution's derivative with respect to a jump time flows through the step that ends there
    (without one it was exactly 0), in forward and reverse mode alike. (Reverse mode stepped over the jumps for a
    while: RODAS5's reverse pass through a boundary came out NaN for some jump times, from a rejected trial step
    after the jump whose stages overflowed; `rodas5_step` now bounds its stages.)"""
    jumps = type(signal).jump_times(signal)  # not `signal.jump_times`: equinox makes a bound method a module (~80 µs)
    if not jumps:  # (most signals: nothing read, nothing moved to the host)
        return None
    if any(concrete_values(x) is None for x in jumps):  # traced: every jump, sorted on the device
        return jnp.sort(jnp.concatenate([jnp.ravel(jnp.asarray(x, dtype=float)) for x in jumps]))
    bounds = [concrete_values(x) for x in (t0, t_end)]
    if any(v is None or v.ndim for v in bounds):
        return None
    lo, hi = (float(v) for v in bounds)
    every = np.concatenate([np.ravel(concrete_values(x)) for x in jumps])
    inside = np.unique(every[(every > lo) & (every < hi)])
    return device_array(inside) if inside.size else None
