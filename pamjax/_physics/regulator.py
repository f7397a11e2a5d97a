"""Paper 001's Festo VPPM proportional pressure regulator (0-10 V reference → outlet pressure).

Three regulators, one interface (`AbstractRegulator`); each carries its own part of the state pytree, whose
`pressure` is the ABSOLUTE outlet pressure [Pa] (the outlet is the chamber: paper 001 assumes very short tubes):

- `LinearRegulator`: eq. 5 superposition of eq. 6 (reference voltage) and eq. 7 (flow disturbance).
- `FeedbackRegulator`: eq. 8's feedback form with the paper's unnamed gains K1, K2.
- `ISO6358Regulator`: a physical version. Eq. 6 drives an internal pilot pressure; the main stage opens its charging
  (supply → outlet) or discharging (outlet → exhaust) path in proportion to the pilot-outlet error, and the outlet
  flow through each path is limited by the ISO 6358 law with tabulated C(p), b(p) (Tables 1-2), so a large volume
  fills no faster than the valve allows.

Units of eq. 5-8 as printed: V_ref in V, P_out in bar (gauge), Q_in in l/min. Paper 001 reports its flows in l/min
(Sect. 6.1) without saying at which conditions; ISO 8778 reference conditions (ANR) are assumed here.

The VPPM as built (`vppm_regulator`): an `ISO6358Regulator` with the regulator's internal volume (paper 001 Fig. 6:
its inlet flow differs from its outlet flow), the 50 mbar pressure hysteresis (`PressureHysteresis`), the 2 %
accuracy band (`accuracy_band`) and the operating modes fast / universal / precise (Sect. 2). The Festo data sheet
[29] is not available here: the numbers the paper prints are used, every other one is marked as an assumption.
"""

import abc
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import check_overrides
from .._core.custom_types import Array, FloatScalar, Real, RealScalar, RealScalarLike, StateLike
from .._core.errors import (
    PamjaxInputError,
    check_finite,
    check_in_closed_interval,
    check_nonnegative,
    check_positive,
    concrete_values,
)
from .._core.fitting import parameter, positive
from .._core.units import ATMOSPHERE, BAR, FLOW_UNIT, check_absolute_pressure, check_pressure_span
from .._papers import datasheets, paper001
from .calibration import VOLTAGE_RANGE, VoltageCalibration
from .chamber import chamber_flow, pressure_rate
from .gas import AbstractRestriction, Air, check_restriction
from .hysteresis import EXPONENT_BOUNDS, bouc_wen_rate, exponent_field
from .regulator_checks import (
    calibration_range,
    check_calibration_voltage,
    check_paper_flow_gain,
    check_si_flow_gain,
    check_time_constants,
)
from .smooth import smooth_relu
from .tabulated import paper001_charging_restriction, paper001_discharging_restriction
from .valves.base import AbstractControlElement


# --- paper 001 numbers (`pamjax._papers.paper001`) in the units the code uses --------------------------------------
def paper001_air() -> Air:
    """Paper 001's air: R = 286.9 J/(kg K), T = 298 K (paper 001, eq. 1-3 text)."""
    return Air(gas_constant=paper001.GAS_CONSTANT, temperature=paper001.TEMPERATURE)


def __getattr__(name):
    # PAPER001_AIR is built on first use, so that importing pamjax creates no JAX arrays (JAX's device settings,
    # e.g. `jax_num_cpu_devices`, can still be changed after `import pamjax`).
    if name == "PAPER001_AIR":
        return paper001_air()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


EQ6_TIME_CONSTANTS = paper001.EQ6_TIME_CONSTANTS  # s
EQ7_FLOW_GAIN = paper001.EQ7_GAIN * BAR / FLOW_UNIT  # Pa per kg/s (≈ -4.67e9): eq. 7's gain in SI
TANK_VOLUME = paper001.TANK_VOLUME  # m³
# m³, a regulator's internal volume: 5 × the VPPM's 2.06e-4 (paper 001 Fig. 6); more is litres or cm³ typed as m³
# (0.206 or 206 for its 206 cm³, which left the outlet at 0.02 bar of a 3 bar set point after 1 s)
MAX_INTERNAL_VOLUME = 1e-3


class RegulatorState(eqx.Module):
    """Regulator state: `pilot` [Pa abs] the first stage of eq. 6's two poles, `pressure` the outlet [Pa abs]."""

    pilot: StateLike
    pressure: StateLike


class FeedbackRegulatorState(eqx.Module):
    """Eq. 8 realisation: `voltage_stage`, `voltage_output` (G_Vref's two poles), `flow_stage` (G_Qin's first pole),
    all in Pa; `pressure` the outlet [Pa abs]."""

    voltage_stage: StateLike
    voltage_output: StateLike
    flow_stage: StateLike
    pressure: StateLike


class AbstractRegulator(AbstractControlElement):
    """A pressure regulator feeding a chamber of volume V(t); its state holds the outlet pressure [Pa abs]. The
    command is the reference voltage, within `command_range`: its calibration's table (0-10 V by default, paper 001,
    Sect. 2; beyond a shorter table the calibration would hold its end value), 0-10 V without one; the regulator is
    continuous (`switches` False).

    - `needs_volume`: whether the outlet must be a chamber of volume > 0 (a regulator that integrates the chamber's
      pressure, eq. 12); False where an ideal closed port (V = 0) is allowed.
    - `max_gauge_pressure(air)`: the highest GAUGE outlet pressure [Pa] it can be set to (its calibration at 10 V,
      and its supply), or None for a regulator without a voltage calibration.
    """

    needs_volume = False

    @property
    def command_range(self):
        return calibration_range(getattr(self, "calibration", None))

    @abc.abstractmethod
    def initial_state(self, pressure, air=None):
        """The state at rest with the outlet at `pressure` [Pa abs] and no flow: every derivative zero under the voltage
        that sets it (cal⁻¹(p − p_atm); `FeedbackRegulator.rest_voltage`), p_atm `air`'s (default 101325 Pa)."""

    @abc.abstractmethod
    def state_rate(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        """The state's time derivative for reference `voltage` [V], chamber `volume` [m³] and `volume_rate` [m³/s]
        (`polytropic_index` n = 1: isothermal, paper 001), and `outlet_flow` [kg/s] drawn from the outlet besides the
        chamber (eq. 5's Q_in at a closed port)."""

    @abc.abstractmethod
    def delivered_flow(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        """The mass flow leaving the regulator [kg/s] (eq. 3 for the chamber); arguments as `state_rate`."""

    @abc.abstractmethod
    def state_scale(self):
        """A typical magnitude per state (a pytree like the state), for integrating in scaled units."""

    def inlet_flow(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        """The mass flow into the regulator's inlet port [kg/s]; arguments as `state_rate`. A regulator without
        separate seats or an internal volume (the linear models) has one flow: the delivered one."""
        return self.delivered_flow(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)

    def max_gauge_pressure(self, air):
        return None


class LinearRegulator(AbstractRegulator):
    """Eq. 5: P_out = G_Vref V_ref + G_Qin Q_in, with (eq. 6, eq. 7 after its pole-zero cancellation)

    G_Vref = cal(V) / ((1 + τ₁ s)(1 + τ₂ s)),  G_Qin = k_q / ((1 + τ₁ s)(1 + τ₂ s)).

    Q_in is the flow the outlet delivers: into the chamber by eq. 3, plus any `outlet_flow`.

    **Arguments:**

    - `calibration`: `VoltageCalibration` (1.01 bar/V, eq. 6's static gain).
    - `time_constants`: (τ₁, τ₂) [s]; (0.041, 0.023) (eq. 6).
    - `flow_gain`: k_q [Pa/(kg/s)]; −0.922 bar per l/min ANR = −4.67e9 (eq. 7).
    """

    calibration: VoltageCalibration = eqx.field(default_factory=VoltageCalibration)
    time_constants: Real[Array, "2"] = parameter(EQ6_TIME_CONSTANTS, unit="s", shape="array")
    flow_gain: RealScalar = parameter(EQ7_FLOW_GAIN, unit="Pa/(kg/s)")

    def __check_init__(self):
        check_time_constants(self.time_constants, f"{type(self).__name__}.time_constants")
        check_si_flow_gain(self.flow_gain, f"{type(self).__name__}.flow_gain")

    def initial_state(self, pressure, air=None):
        p = jnp.asarray(pressure, dtype=float)
        return RegulatorState(pilot=p, pressure=p)

    def _rates(self, state, voltage, volume, volume_rate, air, n, outlet_flow):
        tau1, tau2 = self.time_constants[0], self.time_constants[1]
        dp = (state.pilot - state.pressure) / tau2
        q = chamber_flow(volume, volume_rate, state.pressure, dp, air, n) + outlet_flow
        target = air.atmospheric_pressure + self.calibration(voltage) + self.flow_gain * q
        return RegulatorState(pilot=(target - state.pilot) / tau1, pressure=dp), q

    def state_rate(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[0]

    def delivered_flow(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[1]

    def state_scale(self):
        return RegulatorState(pilot=jnp.asarray(BAR), pressure=jnp.asarray(BAR))

    def max_gauge_pressure(self, air):
        return self.calibration(VOLTAGE_RANGE[1])


def _eq8_default_gains(voltage_gain=paper001.EQ6_GAIN, flow_gain=paper001.EQ7_GAIN):
    """(K1, K2) that give eq. 8 the static gains of eq. 5 (1.01 bar/V, −0.922 bar per l/min); the paper gives none."""
    loop = voltage_gain * flow_gain
    return voltage_gain * (1.0 + loop) / loop, 1.0 + loop


class FeedbackRegulator(AbstractRegulator):
    """Eq. 8: P_out = K1 G_V G_Q / (1 + G_V G_Q) V_ref + K2 G_Q / (1 + G_V G_Q) Q_in, in paper units (V, bar gauge,
    l/min ANR), with G_V = g_v/((1+τ₁s)(1+τ₂s)) (eq. 6) and G_Q = g_q/((1+τ₁s)(1+τ₂s)) (eq. 7).

    Realised as the loop v = G_V (K1 V_ref − P_out), P_out = G_Q (v + K2 Q_in): four states.

    **Arguments:** `voltage_gain` g_v [bar/V] (1.01, eq. 6); `flow_gain` g_q [bar/(l/min)] (−0.922, eq. 7);
    `time_constants` (0.041, 0.023) s; `k1` [-], `k2` [-] (paper: unnamed; defaults −0.0746 and 0.0688 make eq. 8's
    static gains equal eq. 5's).
    """

    voltage_gain: RealScalar = parameter(paper001.EQ6_GAIN, unit="bar/V")
    flow_gain: RealScalar = parameter(paper001.EQ7_GAIN, unit="bar/(l/min)")
    time_constants: Real[Array, "2"] = parameter(EQ6_TIME_CONSTANTS, unit="s", shape="array")
    k1: RealScalar = parameter(_eq8_default_gains()[0], unit="-")
    k2: RealScalar = positive(_eq8_default_gains()[1], unit="-")

    def __check_init__(self):
        check_time_constants(self.time_constants, "FeedbackRegulator.time_constants")
        check_paper_flow_gain(self.flow_gain, "FeedbackRegulator.flow_gain", self.voltage_gain)
        for name in ("voltage_gain", "k1", "k2"):
            check_finite(getattr(self, name), f"FeedbackRegulator.{name}")

    def initial_state(self, pressure, air=None):
        """At rest at gauge g = p − p_atm: G_Q's stage at g, the voltage stages at g/g_q (no flow), under `rest_voltage`
        (g/1.01 bar/V with the default gains). With stages at 0 (as was) 3.03 bar gauge fell to 0.55 in 0.1 s."""
        p = jnp.asarray(pressure, dtype=float)
        gauge = p - (ATMOSPHERE if air is None else air.atmospheric_pressure)
        stage = gauge / self.flow_gain  # flow_stage = g_q × voltage_output at rest
        return FeedbackRegulatorState(voltage_stage=stage, voltage_output=stage, flow_stage=gauge, pressure=p)

    def rest_voltage(self, pressure, air=None):
        """The reference voltage [V] of `initial_state(pressure, air)`: k1 V − g/BAR = stage/(BAR g_v) for V."""
        rest = self.initial_state(pressure, air)
        return (rest.voltage_stage / (BAR * self.voltage_gain) + rest.flow_stage / BAR) / self.k1

    def _rates(self, state, voltage, volume, volume_rate, air, n, outlet_flow):
        tau1, tau2 = self.time_constants[0], self.time_constants[1]
        dp = (state.flow_stage + air.atmospheric_pressure - state.pressure) / tau2
        q = chamber_flow(volume, volume_rate, state.pressure, dp, air, n) + outlet_flow
        gauge_bar = (state.pressure - air.atmospheric_pressure) / BAR
        error = self.k1 * voltage - gauge_bar  # paper units (V and bar mixed, as eq. 8 is printed)
        d_vs = (BAR * self.voltage_gain * error - state.voltage_stage) / tau1
        d_vo = (state.voltage_stage - state.voltage_output) / tau2
        u = state.voltage_output / BAR + self.k2 * q / FLOW_UNIT  # G_Q's input, paper units
        d_fs = (BAR * self.flow_gain * u - state.flow_stage) / tau1
        return FeedbackRegulatorState(voltage_stage=d_vs, voltage_output=d_vo, flow_stage=d_fs, pressure=dp), q

    def state_rate(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[0]

    def delivered_flow(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[1]

    def state_scale(self):
        s = jnp.asarray(BAR)
        return FeedbackRegulatorState(voltage_stage=s, voltage_output=s, flow_stage=s, pressure=s)


class ISO6358RegulatorState(eqx.Module):
    """`pilot`, `pilot_output`: eq. 6's two stages [Pa abs]; `pressure`: the outlet/chamber [Pa abs];
    `hysteresis`: the branch u ∈ [−1, 1] of a `PressureHysteresis` (None without one)."""

    pilot: StateLike
    pilot_output: StateLike
    pressure: StateLike
    hysteresis: StateLike | None = None


class PressureHysteresis(eqx.Module):
    """The regulator's pressure hysteresis (paper 001 Sect. 2: "pressure maximal hysteresis 50 mbar"): the outlet
    settles h/2 below its set pressure after the set pressure rose and h/2 above after it fell, so the rising and
    falling static curves are h apart. A play operator with rounded corners on the main stage's set pressure:

        offset = −(h/2) u,   (h/2) u̇ = ṗ_set − ½ ṗ_set |u|ⁿ − ½ |ṗ_set| u |u|ⁿ⁻¹   (normalised Bouc–Wen, β = ½)

    With the transition length h/2 (in Pa of set pressure) the outlet stays still for the first h of set-point change
    after a reversal, the dead band of a main stage held by friction; n rounds its corners.

    **Arguments:** `width` h [Pa]; 5e3 (the paper's 50 mbar maximum, taken as the loop width); `exponent` n [-];
    2 (assumed: no loop shape is published); `rate_width` [Pa/s] smoothing |ṗ_set|; 100 (numerical, 1e-3 bar/s).
    """

    width: RealScalar = positive(paper001.HYSTERESIS, unit="Pa")
    exponent: RealScalar = exponent_field(2.0)  # assumed (see above)
    rate_width: RealScalar = positive(1e2, unit="Pa/s")

    def __check_init__(self):
        check_pressure_span(self.width, "PressureHysteresis.width")
        check_in_closed_interval(self.exponent, *EXPONENT_BOUNDS, "PressureHysteresis.exponent")
        check_positive(self.rate_width, "PressureHysteresis.rate_width")

    def rate(self, set_rate, u):
        """u̇ [1/s] for the set pressure's rate `set_rate` [Pa/s]."""
        return bouc_wen_rate(set_rate, u, self.exponent, 0.5, self.rate_width) / (0.5 * self.width)

    def offset(self, u):
        """The main stage's set-pressure offset [Pa] on branch u: −h/2 after a rise, +h/2 after a fall."""
        return -0.5 * self.width * u


def smooth_opening(x, width):
    """≈ clip(x, 0, 1) with smooth corners of width `width` [-] (softplus difference)."""
    return smooth_relu(x, width) - smooth_relu(x - 1.0, width)


class ISO6358Regulator(AbstractRegulator):
    """Physical VPPM: eq. 6 sets a pilot pressure; the main stage's flow is limited by ISO 6358 (eq. 1-2, 13-14).

    p_pilot = p_atm + cal(V) / ((1 + τ₁ s)(1 + τ₂ s));  e = p_pilot + offset(u) − p;
    ṁ = o(e/Δ) ṁ_charge(p_s → p) − o(−e/Δ) ṁ_discharge(p → p_atm);  ṗ = n (R T ṁ − p V̇) / (V + V_r)  (eq. 12).

    o is a smooth clip to [0, 1]. At a closed port (small V) the outlet follows the pilot, i.e. eq. 6; a large
    chamber is filled at most at the charging path's choked flow ρ₀ C(p_s) p_s. The regulator's own volume V_r
    (between its seats and its outlet port, at the outlet pressure) stores air: the flow it takes at its inlet
    (`inlet_flow`, the charging seat) then differs from the flow it delivers at its outlet (`delivered_flow`,
    ṁ − V_r ṗ/(n R T)), paper 001's Fig. 6. `offset(u)` is the `hysteresis`'s (0 without one).

    **Arguments:**

    - `calibration` (1.01 bar/V, eq. 6); `time_constants` (0.041, 0.023) s (eq. 6).
    - `charging`, `discharging`: restrictions supply → outlet and outlet → exhaust (paper 001 Tables 1 and 2 as
      `TabulatedISO6358Restriction`).
    - `supply_pressure` p_s [Pa abs]; 7e5 (paper 001, Sect. 3).
    - `full_opening_error` Δ [Pa]; 5e3 (assumed, of the size of the paper's 50 mbar hysteresis: the main stage's
      steady droop is Δ ṁ/ṁ_max, ≤ 50 mbar, inside the 2 % accuracy band; the data sheet's flow curve is not here).
    - `opening_width` [-]: corner smoothing of o; 1e-3.
    - `internal_volume` V_r [m³]; 0 (paper 001 assumes very short tubes and gives no regulator volume;
      `vppm_regulator()` uses the one its Fig. 6 implies).
    - `hysteresis`: a `PressureHysteresis`, or None (default: none).
    """

    calibration: VoltageCalibration = eqx.field(default_factory=VoltageCalibration)
    time_constants: Real[Array, "2"] = parameter(EQ6_TIME_CONSTANTS, unit="s", shape="array")
    charging: AbstractRestriction = eqx.field(default_factory=paper001_charging_restriction)
    discharging: AbstractRestriction = eqx.field(default_factory=paper001_discharging_restriction)
    supply_pressure: RealScalar = positive(paper001.SUPPLY_PRESSURE, unit="Pa abs")
    full_opening_error: RealScalar = parameter(paper001.HYSTERESIS, unit="Pa")
    opening_width: RealScalar = parameter(1e-3, unit="-")
    internal_volume: RealScalar = parameter(0.0, unit="m³")
    hysteresis: PressureHysteresis | None = None

    needs_volume = True  # eq. 12 divides by the chamber's volume

    def __check_init__(self):
        for name, part in (("charging", self.charging), ("discharging", self.discharging)):
            check_restriction(part, f"ISO6358Regulator.{name}", "ISO6358Restriction(7e-9, 0.3)")
        check_time_constants(self.time_constants, "ISO6358Regulator.time_constants")
        check_positive(self.supply_pressure, "ISO6358Regulator.supply_pressure")
        check_absolute_pressure(self.supply_pressure, "ISO6358Regulator.supply_pressure", above_atmosphere=True)
        check_pressure_span(self.full_opening_error, "ISO6358Regulator.full_opening_error")  # 0.05 (bar) refused
        check_positive(self.opening_width, "ISO6358Regulator.opening_width")
        check_nonnegative(self.internal_volume, "ISO6358Regulator.internal_volume")
        volume = concrete_values(self.internal_volume)
        if volume is not None and np.any(volume > MAX_INTERNAL_VOLUME):
            raise PamjaxInputError(f"ISO6358Regulator.internal_volume = {np.max(volume):g} m³: more than "
                                   f"{MAX_INTERNAL_VOLUME:g} m³ (5 × the VPPM's); that looks like cm³ or litres "
                                   "(pamjax takes SI units: m³)")

    def initial_state(self, pressure, air=None):
        """At rest at `pressure` [Pa abs]; a hysteresis in its virgin state (u = 0, between its branches)."""
        p = jnp.asarray(pressure, dtype=float)
        u = None if self.hysteresis is None else jnp.zeros_like(p)
        return ISO6358RegulatorState(pilot=p, pilot_output=p, pressure=p, hysteresis=u)

    def pilot_rate(self, state, voltage, air):
        """Eq. 6 (unit static gain on the calibration) for the pilot pair; returns d(pilot)/dt [Pa/s]."""
        target = air.atmospheric_pressure + self.calibration(voltage)
        return (target - state.pilot) / self.time_constants[0]

    def seat_flows(self, set_pressure, pressure, air):
        """(charging, venting) mass flows [kg/s] through the main stage's seats for its set pressure `set_pressure`
        and outlet `pressure` [Pa abs]: supply → regulator, regulator → exhaust."""
        e = (set_pressure - pressure) / self.full_opening_error
        charge = smooth_opening(e, self.opening_width) * self.charging.mass_flow(self.supply_pressure, pressure, air)
        vent = smooth_opening(-e, self.opening_width) * self.discharging.mass_flow(
            pressure, air.atmospheric_pressure, air
        )
        return charge, vent

    def outlet_mass_flow(self, pilot_output, pressure, air):
        """Net mass flow through the seats into the regulator's outlet side [kg/s] for main-stage set pressure
        `pilot_output` (without a hysteresis offset)."""
        charge, vent = self.seat_flows(pilot_output, pressure, air)
        return charge - vent

    def set_pressure(self, state):
        """The main stage's set pressure [Pa abs]: eq. 6's output plus the hysteresis offset on its branch."""
        if self.hysteresis is None:
            return state.pilot_output
        if state.hysteresis is None:
            raise PamjaxInputError("this ISO6358Regulator has a hysteresis: its state needs `hysteresis` (the "
                                   "branch u); build states with regulator.initial_state(pressure)")
        return state.pilot_output + self.hysteresis.offset(state.hysteresis)

    def _rates(self, state, voltage, volume, volume_rate, air, n, outlet_flow):
        charge, vent = self.seat_flows(self.set_pressure(state), state.pressure, air)
        d_output = (state.pilot - state.pilot_output) / self.time_constants[1]
        dp = pressure_rate(charge - vent - outlet_flow, state.pressure, volume + self.internal_volume, volume_rate,
                           n, air)
        du = None if self.hysteresis is None else self.hysteresis.rate(d_output, state.hysteresis)
        rates = ISO6358RegulatorState(pilot=self.pilot_rate(state, voltage, air), pilot_output=d_output, pressure=dp,
                                      hysteresis=du)
        stored = self.internal_volume * dp / (n * air.gas_constant * air.temperature)
        return rates, charge, charge - vent - stored

    def state_rate(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[0]

    def delivered_flow(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        """The mass flow out of the outlet port [kg/s]: the seats' net flow less what the internal volume stores."""
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[2]

    def inlet_flow(self, state, voltage, volume, volume_rate, air, polytropic_index=1.0, outlet_flow=0.0):
        """The mass flow into the inlet port [kg/s]: the charging seat's (paper 001 Fig. 6's inlet flow)."""
        return self._rates(state, voltage, volume, volume_rate, air, polytropic_index, outlet_flow)[1]

    def static_outlet_pressure(self, voltage, mass_flow, air, branch=1.0):
        """The steady outlet pressure [Pa abs] at `voltage` [V] while `mass_flow` [kg/s] leaves the outlet (> 0;
        < 0 flows back in): the main stage's droop, plus the hysteresis offset on `branch` (+1: the set pressure last
        rose, −1: it fell). The data sheet's pressure-against-flow curve. Bisection between atmosphere and supply
        (the seats' net flow falls with the outlet pressure). A concrete `voltage` outside the calibration's range
        (0-10 V) raises `PamjaxInputError` (the calibration would hold its end value)."""
        self._check_voltage(voltage)
        target = air.atmospheric_pressure + self.calibration(voltage)
        if self.hysteresis is not None:
            target = target + self.hysteresis.offset(jnp.asarray(branch, dtype=float))

        def excess(p):
            charge, vent = self.seat_flows(target, p, air)
            return charge - vent - mass_flow

        def halve(_, bracket):
            lo, hi = bracket
            mid = 0.5 * (lo + hi)
            above = excess(mid) > 0
            return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

        lo = jnp.asarray(air.atmospheric_pressure, dtype=float) + 0.0 * target
        hi = jnp.asarray(self.supply_pressure, dtype=float) + 0.0 * target
        lo, hi = jax.lax.fori_loop(0, 60, halve, (lo, hi))  # to ~1e-12 of the span
        return 0.5 * (lo + hi)

    def accuracy_band(self, voltage, air, accuracy=paper001.ACCURACY):
        """(lowest, highest) outlet pressure [Pa abs] within the accuracy band at `voltage` [V]: the set pressure
        ± `accuracy` × the full scale (the calibration at 10 V; paper 001: "standard accuracy 2 %", of the full
        scale assumed, as a regulator's data sheet states it; 0.2 bar for the 10 bar VPPM). A concrete `voltage`
        outside the calibration's range (0-10 V) raises `PamjaxInputError`."""
        self._check_voltage(voltage)
        set_pressure = air.atmospheric_pressure + self.calibration(voltage)
        band = accuracy * self.calibration(VOLTAGE_RANGE[1])
        return set_pressure - band, set_pressure + band

    def _check_voltage(self, voltage):
        check_calibration_voltage(self.calibration, voltage)

    def state_scale(self):
        s = jnp.asarray(BAR)
        u = None if self.hysteresis is None else jnp.asarray(1.0)
        return ISO6358RegulatorState(pilot=s, pilot_output=s, pressure=s, hysteresis=u)

    def max_gauge_pressure(self, air):
        """Its calibration at 10 V, and below its supply (a regulator cannot raise its outlet above its supply)."""
        return jnp.minimum(self.calibration(VOLTAGE_RANGE[1]), self.supply_pressure - air.atmospheric_pressure)


def max_charging_flow(regulator: ISO6358Regulator, air: Air | None = None) -> FloatScalar:
    """The most mass flow [kg/s] the charging path can deliver: choked, fully open, ρ₀ C(p_s) p_s sqrt(T₀/T).
    `air` defaults to paper 001's (`paper001_air()`)."""
    air = paper001_air() if air is None else air
    return regulator.charging.mass_flow(regulator.supply_pressure, 0.0 * regulator.supply_pressure + 1.0, air)


def vppm_regulator(mode: Literal["universal", "fast", "precise"] = "universal", *,
                   internal_volume: RealScalarLike = datasheets.VPPM_INTERNAL_VOLUME,
                   hysteresis: bool | PressureHysteresis | None = True, **fields: Any) -> ISO6358Regulator:
    """Paper 001's Festo VPPM as built: an `ISO6358Regulator` with its internal volume, its pressure hysteresis and
    an operating mode.

    **Arguments:**

    - `mode`: "universal" (paper 001's, Sect. 3: eq. 6's time constants and the 50 mbar full-opening error), "fast"
      or "precise" (Sect. 2 names them; the data sheet is not available here, so their factors on the time constants
      and on the full-opening error, `pamjax._papers.datasheets.VPPM_MODE_FACTORS`, are ASSUMED: 0.5/2 and 2/0.5).
    - `internal_volume` V_r [m³]: 2.06e-4, derived from paper 001 Fig. 6's 20 % inlet-outlet difference
      (`datasheets.VPPM_INTERNAL_VOLUME`); 0 for none.
    - `hysteresis`: True (`PressureHysteresis()`: 50 mbar), False, or a `PressureHysteresis`.
    - any other `ISO6358Regulator` field (e.g. `supply_pressure`), which overrides the mode's.
    """
    if not isinstance(mode, str) or mode not in datasheets.VPPM_MODE_FACTORS:  # a list: a raw unhashable TypeError
        raise PamjaxInputError(f"mode must be one of {sorted(datasheets.VPPM_MODE_FACTORS)} (paper 001 Sect. 2), got "
                               f"{mode!r}")
    check_overrides(ISO6358Regulator, fields, "vppm_regulator")  # a misspelt field was a raw TypeError
    if hysteresis is True:
        hysteresis = PressureHysteresis()
    elif hysteresis is False or hysteresis is None:
        hysteresis = None
    elif not isinstance(hysteresis, PressureHysteresis):
        raise PamjaxInputError(f"hysteresis must be True, False or a PressureHysteresis, got {hysteresis!r}")
    time_factor, error_factor = datasheets.VPPM_MODE_FACTORS[mode]
    settings = dict(time_constants=time_factor * jnp.asarray(EQ6_TIME_CONSTANTS),
                    full_opening_error=error_factor * paper001.HYSTERESIS, internal_volume=internal_volume,
                    hysteresis=hysteresis)
    settings.update(fields)
    return ISO6358Regulator(**settings)
