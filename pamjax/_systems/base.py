"""The system contract: an ODE vector field over a named state pytree, driven by a command through a valve.

`vector_field(t, state, command)` returns the state's time derivative; `outputs(t, state, command)` the measurable
channels; `state_scale()` a typical magnitude per state, used by the solvers to integrate in scaled units so that one
tolerance fits states of different units. States hold ABSOLUTE pressures.
"""

import equinox as eqx

from .._physics.gas import Air
from .._physics.valve import AbstractValve


class AbstractSystem(eqx.Module):
    """An ODE vector field over a named state pytree, driven by a command signal through a valve."""

    valve: eqx.AbstractVar[AbstractValve]
    air: eqx.AbstractVar[Air]

    def initial_state(self, **kwargs):
        raise NotImplementedError

    def vector_field(self, t, state, command):
        raise NotImplementedError

    def outputs(self, t, state, command):
        raise NotImplementedError

    def state_scale(self):
        raise NotImplementedError

    @property
    def hybrid(self):
        """Whether the system has discrete modes switched at events (e.g. stick-slip friction)."""
        return False

    def event_function(self, t, state, command):
        """Hybrid systems only: a scalar that stays ≥ 0 while the current mode holds and crosses below 0 where it
        ends. The fixed-grid integrator (`pamjax._solve.grid`) locates that crossing inside the step."""
        raise NotImplementedError

    def event_update(self, t, state, command):
        """Hybrid systems only: the state just after the event at `state` (the new mode; velocities reset)."""
        raise NotImplementedError
