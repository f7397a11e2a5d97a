"""What a command drives: the contract every valve and regulator keeps, so that solvers, sweeps, fits and controllers
ask it instead of looking at a concrete class.

Convention: `mass_flow(t, command, pressure, air)` is the mass flow INTO the chamber [kg/s] for chamber pressure
`pressure` [Pa abs]; negative while the chamber exhausts.
"""

import abc

import equinox as eqx
import jax

from ..._core.errors import PamjaxInputError
from ..gas import Air


class AbstractControlElement(eqx.Module):
    """The element a system's command drives (control engineering's final control element): a valve or a
    proportional pressure regulator. A system exposes each of its elements in `system.actuators` (named by the field
    that holds it), the first as `system.valve`.

    What the workflows ask of it:

    - `command_range`: the closed interval of valid commands (a duty ratio in [0, 1], a voltage in [0, 10] V).
    - `switches`: whether it switches on PWM edges (then it is an `AbstractSwitchingValve`: its fixed grid is the
      PWM-synchronous one, and `period`, its edges and its dead bands are defined).
    - `period`: the PWM period [s] of a switching element; None for a continuous one.
    - `max_step()`: the largest step [s] an adaptive solver may take without stepping over a switching window (None:
      any step).
    - `switching_time_scale()`: the time scale [s] of its smoothed switching edges, which a fixed step must resolve
      (None: no edges).
    - `exact_edges`: whether the solver must be handed its switching times (an exact-edge reference, which carries
      no derivative with respect to the edge times).
    - `smooth_edges`: whether its switching edges are smoothed steps that an adaptive solver must not straddle
      (then `next_edge_step(signal, t)` gives the next step boundary beside one).
    - `averaged`: whether its flow is a smooth cycle average that `command_for_flow` inverts (paper 000 eq. 13).
    - `command_time(t)`, `read_command(signal, t)`: when the command is read, and what the element acts on at `t`.
    - `supply()`, `with_supply_pressure(p)`: the supply pressure it is fed at, and the element fed at another one (a
      rig's run conditions).
    """

    command_range = (0.0, 1.0)
    switches = False
    exact_edges = False
    smooth_edges = False
    averaged = False

    @property
    def period(self):
        return None

    def max_step(self):
        return None

    def switching_time_scale(self):
        return None

    def next_edge_step(self, signal, t):
        """The first step boundary [s] after `t` (traceable) beside a smoothed switching edge, for an adaptive
        solver's step-size controller (`pamjax._solve.edge_clip.EdgeClipController`); only asked where
        `smooth_edges`."""
        raise TypeError(f"{type(self).__name__} has no smoothed switching edges (smooth_edges is False)")

    def command_time(self, t):
        return t

    def supply(self):
        """The supply pressure [Pa abs] the element is fed at (a tank test that starts "at supply" starts there)."""
        raise PamjaxInputError(f"{type(self).__name__} has no supply pressure of its own")

    def with_supply_pressure(self, pressure):
        """This element fed at the supply pressure `pressure` [Pa abs] (a rig whose supply differs from run to run).
        An element whose flow does not depend on a supply pressure of its own (paper 000's averaged valve, eq. 13, has
        the supply folded into its coefficients) refuses."""
        raise PamjaxInputError(f"{type(self).__name__} has no supply pressure that a run could change (its flow law "
                               "does not take one); fit the supply pressure with a valve that does (OnOffValve)")

    def read_command(self, signal, t):
        """The command the element acts on at time `t`: `signal(command_time(t))`."""
        return signal(self.command_time(t))


class AbstractValve(AbstractControlElement):
    """A valve between supply, chamber and exhaust, with a flow law in the command and the chamber pressure."""

    @abc.abstractmethod
    def mass_flow(self, t, command, pressure, air: Air):
        """Flow into the chamber [kg/s] at time `t` [s] for the command (what `read_command` returns: a duty ratio
        in [0, 1] for paper 000's valves) and the chamber's ABSOLUTE pressure [Pa]; negative while it exhausts. Finite,
        with finite gradients, for every finite input."""


class AbstractSwitchingValve(AbstractValve):
    """A valve that switches between two paths on PWM edges: open (supply → chamber) and closed (chamber →
    exhaust). The fixed PWM-synchronous grid (`pamjax._solve.synchronous`) places its steps on the edges that these
    methods give, and the exact-edge reference hands them to an adaptive solver.

    Besides `mass_flow`, a switching valve defines `pwm_frequency` [Hz] and:
    """

    switches = True
    pwm_frequency: eqx.AbstractVar[jax.Array]

    @property
    def period(self):
        """The PWM period T = 1/f [s]."""
        return 1.0 / self.pwm_frequency

    @abc.abstractmethod
    def switching_gates(self, command):
        """(opens, closes): whether a period of duty `command` switches the valve open (its on-pulse outlasts the
        switch-on delay) and closed again (its off-pulse outlasts the switch-off delay); booleans."""

    @abc.abstractmethod
    def edge_phases(self, command):
        """Phases [s] in [0, T] of a period's on edge and off edge, ordered (on ≤ off); when the on-pulse is too short
        to open the valve, the 'on edge' sits at the off edge (nothing happens between them)."""

    @abc.abstractmethod
    def mass_flow_at_opening(self, opening, pressure, air: Air):
        """Flow into the chamber [kg/s] at the valve opening `opening` ∈ [0, 1] (1: supply → chamber open, 0: chamber
        → exhaust open) and the chamber's ABSOLUTE pressure [Pa]."""

    @abc.abstractmethod
    def edge_schedule(self, signal, t0, t1):
        """The switching edges over [t0, t1] [s] for the command `signal` and the opening (0/1) after each, as
        concrete NumPy arrays `(edges, openings)`: the jump times handed to an adaptive solver (`exact_edges`)."""

    def open_at_period_end(self, command, open_before):
        """Whether the valve is open at the end of a period of duty `command` that it started open (`open_before`)
        or closed: a period that closes it ends closed, one that opens and does not close it ends open."""
        opens, closes = self.switching_gates(command)
        return jax.numpy.where(closes, False, jax.numpy.where(opens, True, open_before))
