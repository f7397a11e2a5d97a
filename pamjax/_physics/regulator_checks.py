"""The regulators' own argument checks (`pamjax._physics.regulator`): eq. 6's time constants, eq. 7's flow gain in
either of its units, and a reference voltage against a calibration's table, each refused by the unit its magnitude
says it was written in."""

import jax.numpy as jnp
import numpy as np

from .._core.errors import PamjaxInputError, check_finite, check_positive, concrete_values
from .._core.units import BAR, FLOW_UNIT
from .._papers import paper001
from .calibration import VOLTAGE_RANGE

# s: the longest regulator time constant taken. Eq. 6's are 0.041 and 0.023 s (paper 001) and the slowest VPPM mode
# doubles them; 10 s is a regulator that needs a minute to settle, and (41, 23) typed in ms left a 3 V step at
# 0.0016 bar after 1 s
MAX_TIME_CONSTANT = 10.0
# Pa/(kg/s): the least |k_q| taken by `LinearRegulator.flow_gain`. Eq. 7's -0.922 bar per l/min ANR is -4.67e9 in SI;
# below 1e6 (2e-4 of it: a 1e-3 kg/s draw drops 10 mbar) it is the printed bar/(l/min) value typed into the SI
# argument (-0.922 made eq. 7's droop vanish)
MIN_SI_FLOW_GAIN = 1e6
# bar/(l/min): the largest |g_q| taken by `FeedbackRegulator.flow_gain` (paper 001: -0.922); 1e3 drops the outlet
# 1000 bar per l/min, and the SI value -4.67e9 typed in ended in "maximum step size" at the solve
MAX_PAPER_FLOW_GAIN = 1e3
# bar/V: eq. 6's 1.01 is the VPPM's 10 bar over 10 V; 100 bar/V would span the regulator's range in 0.1 V, and
# 1.01e5 is its value in Pa/V
MAX_PAPER_VOLTAGE_GAIN = 100.0
EQ7_SI_FLOW_GAIN = paper001.EQ7_GAIN * BAR / FLOW_UNIT  # Pa/(kg/s), ≈ -4.67e9


def check_time_constants(value, name):
    """Eq. 6's (τ₁, τ₂) [s]: shape (2,), positive, and at most `MAX_TIME_CONSTANT` (milliseconds refused by name),
    where concrete."""
    if jnp.shape(value) != (2,):
        raise PamjaxInputError(f"{name} must be (τ1, τ2) [s], got shape {jnp.shape(value)}")
    check_positive(value, name)
    v = concrete_values(value)
    if v is not None and np.any(v > MAX_TIME_CONSTANT):
        tau1, tau2 = paper001.EQ6_TIME_CONSTANTS
        raise PamjaxInputError(
            f"{name} = {np.array2string(v)} s: more than {MAX_TIME_CONSTANT:g} s; that looks like milliseconds "
            f"(pamjax takes seconds: eq. 6's are ({tau1:g}, {tau2:g}) s, paper 001)")


def check_si_flow_gain(value, name):
    """`LinearRegulator.flow_gain` k_q [Pa/(kg/s)]: finite, and 0 or at least `MIN_SI_FLOW_GAIN` in magnitude (the
    paper's bar/(l/min) value refused by name), where concrete."""
    check_finite(value, name)
    v = concrete_values(value)
    if v is not None and np.any((v != 0) & (np.abs(v) < MIN_SI_FLOW_GAIN)):
        raise PamjaxInputError(
            f"{name} = {float(np.max(np.abs(v))):g} Pa/(kg/s) in magnitude: below {MIN_SI_FLOW_GAIN:g}; that looks "
            f"like bar/(l/min) as paper 001 prints it: this argument is SI, Pa/(kg/s) (eq. 7's {paper001.EQ7_GAIN:g} "
            f"bar/(l/min) = {EQ7_SI_FLOW_GAIN:.4g} Pa/(kg/s), 1 l/min ANR = {FLOW_UNIT:.4g} kg/s)")


def _refuse_above(value, name, limit, unit, advice):
    """Finite, and at most `limit` in magnitude where concrete, else `PamjaxInputError`: "{name} = … {unit} in
    magnitude: more than {limit}; {advice}" (a value typed in another unit)."""
    check_finite(value, name)
    v = concrete_values(value)
    if v is not None and np.any(np.abs(v) > limit):
        raise PamjaxInputError(f"{name} = {float(np.max(np.abs(v))):g} {unit} in magnitude: more than {limit:g}; "
                               f"{advice}")


def check_paper_flow_gain(value, name, voltage_gain=None):
    """`FeedbackRegulator.flow_gain` g_q [bar/(l/min)]: finite, at most `MAX_PAPER_FLOW_GAIN` in magnitude (the SI
    value refused by name), where concrete; with `voltage_gain` g_v [bar/V] (the same regulator's), that one finite
    and at most `MAX_PAPER_VOLTAGE_GAIN` (1.01e5, Pa/V, made the loop run to 4.6e61 Pa, a trajectory returned)."""
    _refuse_above(value, name, MAX_PAPER_FLOW_GAIN, "bar/(l/min)",
                  f"that looks like SI, Pa/(kg/s): this argument is in paper 001's units, bar per l/min ANR (eq. 7: "
                  f"{paper001.EQ7_GAIN:g}, = {EQ7_SI_FLOW_GAIN:.4g} Pa/(kg/s))")
    if voltage_gain is not None:
        _refuse_above(voltage_gain, name.rsplit(".", 1)[0] + ".voltage_gain", MAX_PAPER_VOLTAGE_GAIN, "bar/V",
                      f"that looks like Pa/V: this argument is in paper 001's units, bar per volt (eq. 6: "
                      f"{paper001.EQ6_GAIN:g} bar/V)")


def calibration_range(calibration):
    """(lowest, highest) reference voltage [V] of `calibration`'s table, where concrete: beyond it the calibration
    holds its end value (a 0-5 V table set the 5 V pressure at 7 V); else the VPPM's 0-10 V."""
    table = concrete_values(getattr(calibration, "voltage", None))
    if table is None or table.ndim != 1 or not table.size:
        return VOLTAGE_RANGE
    return float(table[0]), float(table[-1])


def check_calibration_voltage(calibration, voltage):
    """`voltage` [V], where concrete, finite and within the calibration's table (it holds its end values beyond
    it: 12 V would silently set the 10 V pressure)."""
    check_finite(voltage, "voltage")
    v, table = concrete_values(voltage), concrete_values(calibration.voltage)
    if v is not None and table is not None and not np.all((v >= table[0]) & (v <= table[-1])):
        raise PamjaxInputError(f"voltage must lie within the calibration's range [{table[0]:g}, {table[-1]:g}] V, "
                               f"got {np.array2string(v, threshold=6)}")
