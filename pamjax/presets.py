"""Presets: paper 000's Festo MAS-10-300 + MHE2 plant and paper 001's DMSP-40-400 muscle, every number sourced.

Paper 000 gives no numbers for a0…a4, k0…k2, m1…m9, v0, v1 or C_f. They are derived here (the derivation is
re-run by `tests/test_presets.py` and `fits/derive_presets.py`):

1. **Force map shape (a0…a4, k0, k1, k2).** The real measured force map of the Festo DMSP-20-300 (Martens & Boblan,
   Actuators 2017, CC BY 4.0; bundled in `pamjax/data/`) is affine in pressure at each length, exactly eq. 7's
   structure. Per length, a straight line in pressure gives the force at p_max = 0.6 MPa gauge and the slope
   ∂F/∂p. A quartic in contraction ratio ε through the five 6-bar forces plus F = 0 at the datasheet's 25 % maximum
   contraction gives F_max(ε); a line through the slopes gives (k0 − k1 x)/k2. Same family, same 300 mm nominal
   length, same 25 % stroke: the MAS-10-300's curves are this shape scaled to its datasheet force of 630 N at 6 bar
   and 0 % contraction. k2 = 1e5 Pa is fixed by convention (only k0/k2 and k1/k2 are identifiable).
2. **Volume (v0, v1).** v0 = π/4 · D² · L0 for the datasheet's 10 mm inner diameter and 300 mm length (a cylinder, as
   paper 000 computes it). v1 is the least-squares slope over the stroke of the volume that virtual work (eq. 4,
   F = p dV/dx) assigns to the force map at p_max: V(x) − v0 = ∫₀ˣ F_max/p_max dx.
3. **Averaged valve (m1…m9).** Eq. 13 fitted by least squares to the cycle-averaged flow of the exact-edge switching
   valve (Table 1 paths, 2 ms delays, 50 Hz) on a 41 × 41 grid of duty 0…1 and chamber pressure p_atm…p_s
   (`pamjax.fit_averaged_valve`), constrained to zero flow at (u = 0, p_atm) and (u = 1, p_s) so that a chamber
   stays between atmosphere and supply. Fit quality: max error 12.8 %, RMSE 2.8 % of the flow range (paper 000,
   fitted to its measurements: 4.13 % and 1.16 %); the biquadratic cannot follow the 10 %/90 % dead-band steps.
4. **Viscous friction C_f = 250 N s/m.** Paper 000 shows C_f only as a plot (Fig. 6). 250 N s/m is ≈ 0.4 of the
   critical damping 2·sqrt(k M) of the 9.6 kg payload on the muscle's mid-stroke stiffness (≈ 1e4 N/m), the
   order of magnitude of Fig. 6's muscle friction; it is a fit parameter.
5. **Exhaust silencer (optional, `silencer=True`).** Paper 000 ran its valve tests with a silencer on port 3 and
   names it as the cause of Fig. 12's deflation offset, but gives neither its type nor data: "the effects of the
   silencer at higher upstream pressure levels are almost negligible", and "as the pressure drop across the valve
   decreases the silencer slows down the flow". A sintered silencer is a porous element (`PorousRestriction`,
   isothermal Darcy flow ṁ = K (p1² − p2²)) in series with the exhaust port (`SeriesRestriction`). K is the one
   number those two sentences fix once "almost negligible" is read as 2 %: with the silencer the exhaust path passes
   98 % of its unsilenced (choked) flow from the 0.65 MPa supply to atmosphere. Then the port's outlet sits at
   0.384 MPa and K = 1.9557e-14 kg/(s Pa²); at 0.2 MPa the silenced flow is 54 % of the unsilenced one, at 0.12 MPa
   21 %. An assumption to be replaced by a fit to one's own deflation tests
   (free parameter `valve.exhaust.second.permeance`).
6. **Stroke limits.** x_max = 0.075 m (25 % of 300 mm, datasheet); x_min = −0.02 m (stretch; paper 000 Fig. 3 shows
   negative displacements but no number, so −20 mm is assumed).

The hybrid reference bench (`pamjax/data/hybrid-reference-bench/meta.json`) was generated with independently chosen
values (a0 = 629.7, k0 = 105 N, k1 = 1400 N/m, v0 = 2.6e-5 m³, v1 = 1.9e-4 m², C_f = 250 N s/m); differences to the
values here are what a fit to that data must close.
"""

from types import MappingProxyType
from typing import Any, Literal

import jax.numpy as jnp

from ._core.arrays import as_scalar, check_overrides, device_array
from ._core.custom_types import RealScalarLike
from ._core.errors import PamjaxInputError
from ._papers import datasheets, paper000, paper001
from ._physics.friction import AbstractFriction, BristleFriction, CoulombViscousFriction, KarnoppFriction
from ._physics.gas import (
    AbstractRestriction,
    Air,
    EllipseRestriction,
    ISO6358Restriction,
    PorousRestriction,
    SeriesRestriction,
)
from ._physics.hysteresis import BoucWenFriction
from ._physics.muscle import CubicVolume, LinearVolume, Muscle, PolynomialForce
from ._physics.regulator import paper001_air
from ._physics.valves.averaged import AveragedValve
from ._physics.valves.base import AbstractControlElement, AbstractValve
from ._physics.valves.onoff import OnOffValve
from ._systems.muscle import MuscleSystem
from ._systems.tank import TankSystem

# The numbers, each with its source beside it in `pamjax._papers` (written once there; named here as before).
# --- paper 000, Table 1 and set-up ----------------------------------------------------------------------------
VALVE_AREA = paper000.VALVE_AREA  # m²
INFLATE_DISCHARGE_COEFFICIENT = paper000.INFLATE_DISCHARGE_COEFFICIENT  # C_v(1→2)
EXHAUST_DISCHARGE_COEFFICIENT = paper000.EXHAUST_DISCHARGE_COEFFICIENT  # C_v(2→3)
INFLATE_CRITICAL_RATIO = paper000.INFLATE_CRITICAL_RATIO  # b_v(1→2)
EXHAUST_CRITICAL_RATIO = paper000.EXHAUST_CRITICAL_RATIO  # b_v(2→3)
SUPPLY_PRESSURE = paper000.SUPPLY_PRESSURE  # Pa abs
PWM_FREQUENCY = paper000.PWM_FREQUENCY  # Hz
SWITCH_DELAY = paper000.SWITCH_DELAY  # s
PAYLOAD_MASS = paper000.PAYLOAD_MASS  # kg
COULOMB_FORCE = paper000.COULOMB_FORCE  # N
TANK_VOLUME = datasheets.HYBRID_BENCH_TANK_VOLUME  # m³, paper 000's valve-test tank (the hybrid bench's)

# --- MAS-10-300, derived (see the module docstring) ----------------------------------------------------------------
MAS10_MAX_FORCE_COEFFICIENTS = datasheets.MAS10_MAX_FORCE_COEFFICIENTS  # a0…a4 [N/mⁱ]
MAS10_K0 = datasheets.MAS10_K0  # N
MAS10_K1 = datasheets.MAS10_K1  # N/m
MAS10_K2 = datasheets.MAS10_K2  # Pa
MAS10_MAX_PRESSURE = paper000.MAX_PRESSURE  # Pa gauge
MAS10_V0 = datasheets.MAS10_V0  # m³
MAS10_V1 = datasheets.MAS10_V1  # m²
MAS10_MIN_POSITION = datasheets.MAS10_MIN_POSITION  # m
MAS10_MAX_POSITION = datasheets.MAS10_MAX_POSITION  # m
VISCOUS_COEFFICIENT = datasheets.MAS10_VISCOUS_COEFFICIENT  # N s/m
MAS10_AVERAGED_VALVE = datasheets.MAS10_AVERAGED_VALVE  # m1…m9 row-wise [kg/(s Paʲ)]
MAS10_SILENCER_PERMEANCE = datasheets.MAS10_SILENCER_PERMEANCE  # kg/(s Pa²)

# --- DMSP-40-400 (paper 001), derived the same way ------------------------------------------------------------
DMSP40_NOMINAL_LENGTH = paper001.DMSP40_NOMINAL_LENGTH  # m
DMSP40_MAX_FORCE_COEFFICIENTS = datasheets.DMSP40_MAX_FORCE_COEFFICIENTS  # a0…a4 [N/mⁱ]
DMSP40_K0 = datasheets.DMSP40_K0  # N
DMSP40_K1 = datasheets.DMSP40_K1  # N/m
DMSP40_VOLUME_CUBIC = datasheets.DMSP40_VOLUME_CUBIC  # (d, c, b, a) [m³]
DMSP40_LOAD_FORCE = paper001.LOAD_FORCE  # N

# --- paper 001: the VPPM regulator -------------------------------------------------------------------------------
PAPER001_SUPPLY_PRESSURE = paper001.SUPPLY_PRESSURE  # Pa abs
PAPER001_TANK_VOLUME = paper001.TANK_VOLUME  # m³
VPPM_HYSTERESIS = paper001.HYSTERESIS  # Pa
VPPM_VOLTAGE_RANGE = paper001.VOLTAGE_RANGE  # V, the reference voltage's range (Sect. 2)
EQ6_GAIN = paper001.EQ6_GAIN  # bar/V
EQ6_TIME_CONSTANTS = paper001.EQ6_TIME_CONSTANTS  # s
EQ7_GAIN = paper001.EQ7_GAIN  # bar per l/min ANR
# Paper 001 Tables 1-2 (C in m³/(s bar) → divide by 1e5 for SI).
# read-only views: the live dicts were exported, and an in-place edit of "a copy" changed every later default regulator
PAPER001_CHARGING_TABLE = MappingProxyType(paper001.CHARGING_TABLE)
PAPER001_DISCHARGING_TABLE = MappingProxyType(paper001.DISCHARGING_TABLE)


def mas10_silencer() -> PorousRestriction:
    """The exhaust silencer of paper 000's valve tests: a porous element with the derived permeance (docstring
    item 5; an assumption, paper 000 gives no silencer data)."""
    return PorousRestriction(MAS10_SILENCER_PERMEANCE)


def mas10_valve(mode: Literal["smooth", "exact"] | None = None, /,
                silencer: bool | AbstractRestriction | None = False, **kwargs: Any) -> OnOffValve:
    """Festo MHE2 3/2 on/off valve with paper 000's Table 1 paths, 0.65 MPa abs supply, 50 Hz, 2 ms delays.

    `mode`: "smooth" (the default, also for None) or "exact", given positionally or as `mode=` (not both).
    `silencer`: False (default, as Table 1 was identified), True (port 3 → `mas10_silencer()`, docstring item 5) or
    any restriction placed in series after the exhaust port. Keyword arguments override any `OnOffValve` field; an
    `exhaust=` override is the exhaust port, the silencer then sits after it (`SeriesRestriction(exhaust, silencer)`).
    """
    if mode is not None and "mode" in kwargs:  # mas10_valve("smooth", mode="exact"): Python's "multiple values"
        raise PamjaxInputError(f"mas10_valve got mode twice: {mode!r} (positionally) and mode={kwargs['mode']!r}; "
                               "give it once")
    check_overrides(OnOffValve, kwargs, "mas10_valve")
    exhaust = (kwargs.pop("exhaust") if "exhaust" in kwargs
               else EllipseRestriction(EXHAUST_DISCHARGE_COEFFICIENT, EXHAUST_CRITICAL_RATIO, VALVE_AREA))
    if silencer is True:
        silencer = mas10_silencer()
    if silencer is not False and silencer is not None:
        if not isinstance(silencer, AbstractRestriction):
            raise PamjaxInputError(f"silencer must be True, False or a restriction (e.g. PorousRestriction), got "
                                   f"{silencer!r}")
        exhaust = SeriesRestriction(exhaust, silencer)  # after the port, the user's own included (it was replaced)
    fields = dict(
        inflate=EllipseRestriction(INFLATE_DISCHARGE_COEFFICIENT, INFLATE_CRITICAL_RATIO, VALVE_AREA),
        exhaust=exhaust,
        supply_pressure=SUPPLY_PRESSURE,
        pwm_frequency=PWM_FREQUENCY,
        switch_on_delay=SWITCH_DELAY,
        switch_off_delay=SWITCH_DELAY,
        mode="smooth" if mode is None else mode,
    )
    fields.update(kwargs)
    return OnOffValve(**fields)


def mas10_averaged_valve() -> AveragedValve:
    """Eq. 13 averaged valve with the derived m1…m9 (module docstring, item 3)."""
    return AveragedValve(device_array(MAS10_AVERAGED_VALVE))


def mas10_muscle() -> Muscle:
    """Festo MAS-10-300 with eq. 7 force and eq. 14 linear volume (derived values, module docstring)."""
    return Muscle(
        force_law=PolynomialForce(
            max_force_coefficients=device_array(MAS10_MAX_FORCE_COEFFICIENTS),
            k0=MAS10_K0,
            k1=MAS10_K1,
            k2=MAS10_K2,
            max_pressure=MAS10_MAX_PRESSURE,
        ),
        volume_law=LinearVolume(MAS10_V0, MAS10_V1),
        min_position=MAS10_MIN_POSITION,
        max_position=MAS10_MAX_POSITION,
    )


ValveChoice = Literal["pwm", "smooth", "exact", "averaged"]  # paper 000's valve, switching or averaged


def _valve(valve, silencer=False):
    if not isinstance(valve, (str, AbstractControlElement)):  # None or a number: an AttributeError in the solve
        raise PamjaxInputError(
            f"valve must be 'pwm' (smooth edges), 'exact' or 'averaged', or a valve object (an AbstractValve, e.g. "
            f"mas10_valve()); got {type(valve).__name__} {valve!r:.80}"
        )
    if valve in ("pwm", "smooth"):
        return mas10_valve("smooth", silencer=silencer)
    if valve == "exact":
        return mas10_valve("exact", silencer=silencer)
    if silencer is not False and silencer is not None:
        raise PamjaxInputError(
            f"silencer applies to the switching valve (valve='pwm' or 'exact'), got valve={valve!r}: the averaged "
            "valve's m1…m9 were derived without one; build the silenced switching valve and pamjax.fit_averaged_valve"
        )
    if valve == "averaged":
        return mas10_averaged_valve()
    if isinstance(valve, str):
        raise PamjaxInputError(
            f"valve must be 'pwm' (smooth edges), 'exact' or 'averaged', or a valve object; got {valve!r}"
        )
    return valve


def mas10_system(valve: ValveChoice | AbstractValve = "pwm",
                 friction: Literal["coulomb", "karnopp", "bristle", "bouc_wen"] | AbstractFriction = "coulomb",
                 payload_mass: RealScalarLike = PAYLOAD_MASS,
                 silencer: bool | AbstractRestriction | None = False) -> MuscleSystem:
    """Paper 000's plant: MAS-10-300 lifting `payload_mass` (9.6 kg) through the MHE2 valve.

    **Arguments:** `valve`: "pwm" (smoothed switching), "exact" (exact-edge reference), "averaged" (eq. 13) or a
    valve; `friction`: "coulomb" (eq. 8-9, smooth sign: fast, creeps where the real payload sticks), "karnopp"
    (eq. 8-9 with exact stick-slip, integrated on the fixed grid: the model for identification), "bristle"
    (Dahl-type, holds still elastically), "bouc_wen" (`BoucWenFriction`: eq. 8-9's branches with a gradual transition
    between them after a reversal; F_c and C_f as eq. 8-9's here, its transition length 2 mm and exponent 2 are
    `BoucWenFriction`'s assumed defaults, paper 000 giving no loop shape) or a friction model; `silencer`: an exhaust
    silencer on the switching valve (see `mas10_valve`).
    """
    if not isinstance(friction, (str, AbstractFriction)):  # None or a number: an AttributeError in the solve
        raise PamjaxInputError(
            "friction must be 'coulomb', 'karnopp', 'bristle', 'bouc_wen' or a friction model (an AbstractFriction, "
            f"e.g. KarnoppFriction()); got {type(friction).__name__} {friction!r:.80}"
        )
    if friction == "coulomb":
        friction = CoulombViscousFriction(COULOMB_FORCE, VISCOUS_COEFFICIENT)
    elif friction == "karnopp":
        friction = KarnoppFriction(COULOMB_FORCE, VISCOUS_COEFFICIENT)
    elif friction == "bristle":
        friction = BristleFriction(coulomb_force=COULOMB_FORCE, viscous_coefficient=VISCOUS_COEFFICIENT)
    elif friction == "bouc_wen":
        friction = BoucWenFriction(coulomb_force=COULOMB_FORCE, viscous_coefficient=VISCOUS_COEFFICIENT)
    elif isinstance(friction, str):
        raise PamjaxInputError(
            f"friction must be 'coulomb', 'karnopp', 'bristle', 'bouc_wen' or a friction model; got {friction!r}")
    return MuscleSystem(
        valve=_valve(valve, silencer), muscle=mas10_muscle(), payload_mass=payload_mass, friction=friction
    )


def mas10_tank_system(valve: ValveChoice | AbstractValve = "pwm", volume: RealScalarLike = TANK_VOLUME,
                      silencer: bool | AbstractRestriction | None = False) -> TankSystem:
    """Paper 000's valve tests: the MHE2 valve feeding a constant volume (5e-5 m³ by default); `silencer` as for
    `mas10_valve` (paper 000 ran these tests with one, Fig. 12)."""
    return TankSystem(valve=_valve(valve, silencer), volume=volume)


def dmsp40_muscle() -> Muscle:
    """Festo DMSP-40-400 (paper 001): eq. 7 force scaled from the DMSP-20 map, paper 001 eq. 4 cubic volume."""
    return Muscle(
        force_law=PolynomialForce(
            max_force_coefficients=jnp.asarray(DMSP40_MAX_FORCE_COEFFICIENTS), k0=DMSP40_K0, k1=DMSP40_K1,
            k2=datasheets.DMSP40_K2,
        ),
        volume_law=CubicVolume(jnp.asarray(DMSP40_VOLUME_CUBIC), DMSP40_NOMINAL_LENGTH),
        min_position=datasheets.DMSP40_MIN_POSITION,  # m, assumed as for the MAS-10
        max_position=paper001.DMSP40_MAX_CONTRACTION * DMSP40_NOMINAL_LENGTH,  # m, 25 % maximum contraction
    )


def paper001_restriction(
    sonic_conductance_m3_per_s_bar: RealScalarLike = paper001.CHARGING_TABLE["sonic_conductance_m3_per_s_bar"][-1],
    critical_ratio: RealScalarLike = paper001.CHARGING_TABLE["critical_ratio"][-1],
) -> ISO6358Restriction:
    """An ISO 6358 restriction with paper 001's units converted (default: Table 1 at 6.943 bar)."""
    try:  # a text ("7e-4") was a raw TypeError of the unit conversion, naming no argument
        conductance = as_scalar(sonic_conductance_m3_per_s_bar)
    except (PamjaxInputError, TypeError, ValueError) as err:  # None: a raw ValueError of jnp.asarray
        raise PamjaxInputError(f"paper001_restriction: sonic_conductance_m3_per_s_bar must be a number [m³/(s bar)], "
                               f"e.g. 7e-4, got {sonic_conductance_m3_per_s_bar!r:.80} ({err})") from None
    if isinstance(sonic_conductance_m3_per_s_bar, (int, float)):  # divided on the host: no program compiled for it
        conductance = float(sonic_conductance_m3_per_s_bar)
    if critical_ratio is None or isinstance(critical_ratio, str):  # None: a raw ValueError of jnp.asarray
        raise PamjaxInputError(f"paper001_restriction: critical_ratio must be a number in (0, 1), e.g. 0.53, got "
                               f"{critical_ratio!r}")
    return ISO6358Restriction(sonic_conductance=conductance / 1e5, critical_ratio=critical_ratio)


__all__ = [
    "Air",
    "mas10_valve",
    "mas10_silencer",
    "mas10_averaged_valve",
    "mas10_muscle",
    "mas10_system",
    "mas10_tank_system",
    "dmsp40_muscle",
    "paper001_restriction",
    "paper001_air",
]
