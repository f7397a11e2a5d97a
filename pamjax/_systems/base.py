"""The system contract: an ODE vector field over a named state pytree, driven by a command through a valve.

`vector_field(t, state, command)` returns the state's time derivative; `outputs(t, state, command)` the measurable
channels named in `output_names`; `state_scale()` a typical magnitude per state, used by the solvers to integrate in
scaled units so that one tolerance fits states of different units. States hold ABSOLUTE pressures.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu

from .._physics.friction import AbstractFriction
from .._physics.gas import Air
from .._physics.muscle import AbstractMuscle
from .._physics.valves.base import AbstractControlElement


class AbstractSystem(eqx.Module):
    """An ODE vector field over a named state pytree, driven by a command signal through `valve`.

    What the workflows ask of a system (`simulate`, `sweep`, `fit`, `linearise`, the controllers):

    - `valve`: the element its command drives (a valve, or a regulator for paper 001's systems): its command range,
      whether it switches, its period, edges and max step (`AbstractControlElement`); the first of `actuators`.
    - `actuators`: every element its command drives, by what it is (its field's name): {"valve": ...} for a valve's
      system, {"regulator": ...} for a regulator's, {"flexor_regulator": ..., "extensor_regulator": ...} for the
      antagonistic joint, whose command drives both.
    - `command_range`: the valid commands (the valve's).
    - `output_names`: the channels `outputs` returns, in order (a class attribute).
    - `state_scale()`, `initial_state(...)`, `vector_field(...)`, `outputs(...)` (abstract, below).
    - `hybrid`: whether it has discrete modes switched at events (stick-slip friction); a hybrid system also defines
      `event_function` and `event_update`, which the fixed-grid integrator (`pamjax._solve.grid`) uses.
    - `with_supply_pressure(p)`: the system with its valve fed at another supply pressure (a rig's runs).
    - `start_pressures(state)`: the ABSOLUTE pressures a state holds, by their path in it, which `simulate` and
      `sweep` check in a start state `y0` (> 0, not bar or gauge by magnitude).
    - `start_positions(state)`: the displacements [m] a state holds, by their path, each with the stroke it must lie
      in (or None), which `simulate` checks in a start state `y0` (not mm by magnitude; inside the stroke).
    - `discrete_step(...)`: one step of its discrete-time model (explicit Euler unless the system says otherwise).
    """

    valve: eqx.AbstractVar[AbstractControlElement]
    air: eqx.AbstractVar[Air]
    output_names = ()

    @property
    def actuators(self):
        """{name: element} of every control element the command drives (`valve` first), each named by the field that
        holds it."""
        return {"valve": self.valve}

    @property
    def command_range(self):
        """The closed interval of valid commands (its valve's)."""
        return self.valve.command_range

    @abc.abstractmethod
    def initial_state(self, **kwargs):
        """The state at rest (absolute pressures; keyword arguments such as `pressure` [Pa abs] set its conditions)."""

    @abc.abstractmethod
    def vector_field(self, t, state, command):
        """The state's time derivative at time `t` [s] for the command the valve acts on (`valve.read_command`)."""

    @abc.abstractmethod
    def outputs(self, t, state, command):
        """{name: value} of the measurable channels `output_names` (SI, pressures absolute)."""

    @abc.abstractmethod
    def state_scale(self):
        """A typical magnitude of each state (a pytree like the state): the solvers integrate state / scale."""

    @property
    def hybrid(self):
        """Whether the system has discrete modes switched at events (e.g. stick-slip friction)."""
        return False

    def event_function(self, t, state, command):
        """Hybrid systems: a scalar that stays ≥ 0 while the current mode holds and crosses below 0 where it ends
        (the fixed-grid integrator locates that crossing inside the step). A system without modes never ends one."""
        return jnp.ones(())

    def event_update(self, t, state, command):
        """Hybrid systems: the state just after the event at `state` (the new mode; velocities reset)."""
        return state

    def with_supply_pressure(self, pressure):
        """This system with every one of its `actuators` fed at `pressure` [Pa abs]
        (`AbstractControlElement.with_supply_pressure`)."""
        elements = tuple(self.actuators.values())
        return eqx.tree_at(lambda s: tuple(s.actuators.values()), self,
                           tuple(e.with_supply_pressure(pressure) for e in elements))

    def start_pressures(self, state):
        """{path: ABSOLUTE pressure [Pa]} of the pressures `state` (a state of this system, e.g. `simulate`'s `y0`)
        holds, each named by its path in the state ("pressure", "regulator.pressure"): what `simulate` and `sweep`
        check in a start state (> 0, and not bar or gauge by its magnitude). By default the state's own `pressure`,
        if it has one; a system whose state keeps its pressures deeper (in a regulator's state) names them."""
        return state_leaves(state, ("pressure",))

    def start_positions(self, state):
        """{path: (displacement [m], stroke)} of the displacements `state` (a state of this system, e.g. `simulate`'s
        `y0`) holds, each named by its path in the state ("position"), with the (lowest, highest) values [m] its
        system allows, or None where it sets none: what `simulate` checks in a start state (not mm by its
        magnitude, inside the stroke). By default the state's own `position`, if it has one, with no stroke; a muscle
        system gives its muscle's."""
        return {name: (x, None) for name, x in state_leaves(state, ("position",)).items()}

    def discrete_step(self, t, state, command, sample_time):
        """One explicit Euler step of `sample_time` [s] from `state` at `t` [s] with `command` held (paper 000 eq. 18
        for every state); systems whose discrete-time model differs override it."""
        rate = self.vector_field(t, state, command)
        return jax.tree_util.tree_map(lambda y, dy: y + sample_time * dy, state, rate)


def state_leaves(state, paths):
    """{path: leaf} of the leaves of `state` at the dotted `paths` ("pressure", "regulator.pressure") it has (a state
    of another structure has none of them)."""
    leaves = jtu.tree_flatten_with_path(state)[0]
    return {name: leaf for name, leaf in ((jtu.keystr(k, simple=True, separator="."), v) for k, v in leaves)
            if name in paths}


class AbstractMuscleSystem(AbstractSystem):
    """A system that moves one muscle against a payload (paper 000's plant, paper 001's regulated muscle): what the
    muscle-specific workflows ask of it besides the system contract (a closed loop's stroke, the sliding-mode
    controller's model, an experiment design's stroke and force limits, a force map, a solver's stiffness hint).

    - `muscle`: its `AbstractMuscle` (stroke limits, force law, volume).
    - `friction`: the `AbstractFriction` on its motion.
    - `payload_mass` [kg]: the mass it moves.

    Its outputs include `position`, `velocity` and `pressure`."""

    muscle: eqx.AbstractVar[AbstractMuscle]
    friction: eqx.AbstractVar[AbstractFriction]
    payload_mass: eqx.AbstractVar[jax.Array]

    def start_positions(self, state):
        """The state's `position` with the muscle's stroke (`min_position`, `max_position`) [m]."""
        stroke = (self.muscle.min_position, self.muscle.max_position)
        return {name: (x, stroke) for name, x in state_leaves(state, ("position",)).items()}
