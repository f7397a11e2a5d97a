"""The VPPM's static calibration (paper 001, Fig. 3): reference voltage [V] → set gauge pressure [Pa], a monotone
PCHIP through a table (`VoltageCalibration`), and its prepared form for a solve (`PreparedVoltageCalibration`)."""

import jax.numpy as jnp
import numpy as np

from .._core.custom_types import Table
from .._core.errors import PamjaxInputError, check_finite, check_in_closed_interval, concrete_values
from .._core.fitting import parameter
from .._core.units import ATMOSPHERE, BAR
from .._papers import paper001
from .tabulated import PreparesTables, check_table_axis, pchip, pchip_at, pchip_table

VOLTAGE_RANGE = paper001.VOLTAGE_RANGE  # V
# Pa: a calibration whose largest set pressure is below this was written in bar or MPa (1e3 Pa = 10 mbar; the VPPM
# sets up to 10 bar over its 0-10 V, paper 001 Sect. 2)
MIN_FULL_SCALE = 1e3
# Pa: a calibration whose largest set pressure is below this (0.2 bar) was written in kPa or mbar (the VPPM's 10.1 bar
# is 1010 kPa, 10100 mbar); no proportional regulator for a pneumatic muscle spans less than 0.2 bar
MIN_KPA_FULL_SCALE = 2e4
# -: a set pressure at 0 V within this fraction of one atmosphere of 101325 Pa is an ABSOLUTE table (the VPPM sets 0
# gauge at 0 V; an absolute table set every pressure 1 bar too high)
ABSOLUTE_AT_ZERO = 0.1


def check_voltage(voltage, name="reference voltage"):
    """Reference voltage within the VPPM's 0-10 V (paper 001, Sect. 2), else `PamjaxInputError`."""
    check_finite(voltage, name)
    check_in_closed_interval(voltage, *VOLTAGE_RANGE, f"{name} [V]")


class VoltageCalibration(PreparesTables):
    """Static calibration (paper 001, Fig. 3): reference voltage [V] → set GAUGE pressure [Pa], a monotone PCHIP
    through the table. Default: the straight line of eq. 6's static gain, 1.01 bar/V over 0-10 V.

    **Arguments:** `voltage` [V] strictly increasing within 0-10 V; `gauge_pressure` [Pa] strictly increasing.
    """

    voltage: Table = parameter(VOLTAGE_RANGE, unit="V", shape="table")
    gauge_pressure: Table = parameter((0.0, VOLTAGE_RANGE[1] * paper001.EQ6_GAIN * BAR), unit="Pa", shape="table")

    def __check_init__(self):
        check_table_axis(self.voltage, "VoltageCalibration.voltage")
        check_voltage(self.voltage, "VoltageCalibration.voltage")
        check_table_axis(self.gauge_pressure, "VoltageCalibration.gauge_pressure")
        if jnp.shape(self.voltage) != jnp.shape(self.gauge_pressure):
            raise PamjaxInputError(
                f"VoltageCalibration.gauge_pressure must have the shape of .voltage {jnp.shape(self.voltage)}, got "
                f"{jnp.shape(self.gauge_pressure)}"
            )
        check_calibration_units(self.voltage, self.gauge_pressure)

    def __call__(self, voltage):
        """Set gauge pressure [Pa] at `voltage` [V]."""
        return pchip(self.voltage, self.gauge_pressure, voltage)

    def inverse(self, gauge_pressure):
        """The voltage [V] setting `gauge_pressure` [Pa]: PCHIP with the axes swapped (exact for the linear
        default, monotone for any table)."""
        return pchip(self.gauge_pressure, self.voltage, gauge_pressure)

    def prepared(self):
        return PreparedVoltageCalibration(self.voltage, self.gauge_pressure,
                                          pchip_table(self.voltage, self.gauge_pressure),
                                          pchip_table(self.gauge_pressure, self.voltage))


class PreparedVoltageCalibration(VoltageCalibration):
    """A `VoltageCalibration` with both interpolants' tables computed (`prepared()`, inside a solve); the same
    values."""

    table: Table | None = None
    inverse_table: Table | None = None

    def prepared(self):
        return self

    def __call__(self, voltage):
        return pchip_at(self.table, voltage)

    def inverse(self, gauge_pressure):
        return pchip_at(self.inverse_table, gauge_pressure)


def check_calibration_units(voltage, gauge_pressure):
    """A calibration's set pressures, where concrete: GAUGE Pa (not bar, MPa, kPa or mbar by the full scale, not
    absolute by the 0 V value, and none below vacuum, −1 atm gauge)."""
    g, v = concrete_values(gauge_pressure), concrete_values(voltage)
    if g is None or not g.size:
        return
    top = float(np.max(np.abs(g)))
    name = "VoltageCalibration.gauge_pressure"
    if top < MIN_FULL_SCALE:
        raise PamjaxInputError(f"{name} reaches {top:g} Pa at most: that looks like bar or MPa; the table is GAUGE "
                               "pressure in Pa (the VPPM's 0-10 V span 0-10.1 bar = 1.01e6 Pa)")
    if top < MIN_KPA_FULL_SCALE:
        raise PamjaxInputError(f"{name} reaches {top:g} Pa at most (below {MIN_KPA_FULL_SCALE:g} Pa = 0.2 bar): that "
                               "looks like kPa or mbar; the table is GAUGE pressure in Pa (the VPPM's 0-10 V span "
                               "0-10.1 bar = 1010 kPa = 1.01e6 Pa)")
    if float(np.min(g)) < -ATMOSPHERE:
        raise PamjaxInputError(f"{name} reaches {float(np.min(g)):g} Pa: below vacuum ({-ATMOSPHERE:g} Pa gauge); the "
                               "table is GAUGE pressure in Pa (0 at atmosphere)")
    if v is not None and v.shape == g.shape and np.any(v == 0.0):
        at_zero = float(g[np.argmax(v == 0.0)])
        if abs(at_zero - ATMOSPHERE) < ABSOLUTE_AT_ZERO * ATMOSPHERE:
            raise PamjaxInputError(f"{name} = {at_zero:g} Pa at 0 V: that looks like an ABSOLUTE pressure; the table "
                                   f"is GAUGE pressure in Pa (subtract the atmosphere, {ATMOSPHERE:g} Pa: the VPPM "
                                   "sets 0 gauge at 0 V)")
