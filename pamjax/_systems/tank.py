"""A constant-volume tank fed by a valve (paper 000's valve tests, paper 001's appendix)."""

import equinox as eqx
import jax.numpy as jnp

from .._core.custom_types import RealScalar, StateLike
from .._core.errors import PamjaxInputError, check_in_open_interval, check_positive
from .._core.fitting import bounded, positive
from .._core.units import check_plausible
from .._papers import paper000
from .._physics.chamber import pressure_rate
from .._physics.gas import POLYTROPIC_RANGE, Air
from .._physics.regulator import AbstractRegulator
from .._physics.valves.base import AbstractValve
from .base import AbstractSystem


class TankState(eqx.Module):
    """State of a constant-volume tank: `pressure` [Pa abs]."""

    pressure: StateLike


class TankSystem(AbstractSystem):
    """A constant-volume tank fed by a valve: ṗ = n R T ṁ(t, u, p) / V (paper 000 eq. 12 with V̇ = 0).

    **Arguments:** `valve`; `volume` V [m³]; `air` (`Air()`); `polytropic_index` n [-] (1.4 adiabatic, paper 000;
    1.0 isothermal).
    """

    valve: AbstractValve
    volume: RealScalar = positive(unit="m³")
    air: Air = eqx.field(default_factory=Air)
    polytropic_index: RealScalar = bounded(paper000.POLYTROPIC_INDEX, bounds=POLYTROPIC_RANGE, unit="-")

    output_names = ("pressure", "mass_flow")

    def __check_init__(self):
        if not isinstance(self.valve, AbstractValve):
            raise PamjaxInputError(
                f"TankSystem.valve must be a valve (an AbstractValve: mass flow from a duty ratio), got "
                f"{type(self.valve).__name__}" + (": a tank fed by a pressure regulator is a RegulatorSystem("
                "regulator, volume)" if isinstance(self.valve, AbstractRegulator) else ""))
        check_positive(self.volume, "TankSystem.volume")
        check_plausible(self.volume, "TankSystem.volume")  # 5 (litres) for a 5 l tank refused
        check_in_open_interval(self.polytropic_index, *POLYTROPIC_RANGE, "TankSystem.polytropic_index")

    def initial_state(self, pressure=None):
        """Tank at `pressure` [Pa abs]; atmospheric by default."""
        p = self.air.atmospheric_pressure if pressure is None else jnp.asarray(pressure, dtype=float)
        return TankState(pressure=jnp.asarray(p, dtype=float))

    def vector_field(self, t, state, command):
        mdot = self.valve.mass_flow(t, command, state.pressure, self.air)
        return TankState(
            pressure=pressure_rate(mdot, state.pressure, self.volume, 0.0, self.polytropic_index, self.air)
        )

    def outputs(self, t, state, command):
        return dict(pressure=state.pressure, mass_flow=self.valve.mass_flow(t, command, state.pressure, self.air))

    def state_scale(self):
        return TankState(pressure=jnp.asarray(1e5))
