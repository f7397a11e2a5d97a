"""Units: the unit suffixes pamjax reads (CSV headers `position [mm]`, `Recording(units=...)`), their SI factors, and
the plausibility checks that catch a number written in another unit (millimetres under `[m]`, bar under `[Pa]`,
milliseconds under `[s]`) wherever numbers come in: recordings, configs, sweeps, initial states.

Every unit is either converted to SI or refused by name, never ignored. Pressures in pamjax are ABSOLUTE pascal; a
pressure unit other than `Pa` must say whether it is absolute or gauge (`bar abs`, `barg`, `kPa gauge`, `psia`):
bench software writes both, and a guess would be wrong by one atmosphere.
"""

import re

import numpy as np

from .errors import PamjaxInputError, check_positive, concrete_values

ATMOSPHERE = 101325.0  # Pa abs, ISO 2533 standard atmosphere (also `Air.atmospheric_pressure`'s default)
# No pneumatic muscle test runs below half an atmosphere absolute (a vented chamber reads ~101325 Pa abs).
MIN_ABSOLUTE_PA = 5e4  # Pa
# Nor above 50 bar: industrial pneumatics stops at ~16 bar; paper 000 supplies 0.65 MPa, paper 001 0.7 MPa abs.
MAX_ABSOLUTE_PA = 5e6  # Pa
# Sampling-interval checks need a run, not a handful of points (a 5-point test recording may be 1 s apart).
MIN_SAMPLES_FOR_RATE = 50
# m, a muscle's nominal length L0: Festo makes its longest muscles (MAS-40, DMSP-40) 9 m long, and most PAMs are a
# few decimetres (MAS-10-300: 0.3 m, DMSP-40-400: 0.4 m); 10 m and more is millimetres typed as metres (400 for 0.4 m).
MAX_MUSCLE_LENGTH = 10.0
# m³, a muscle's chamber volume (`LinearVolume.v0`): the largest muscle made, a 9 m MAS-40 (40 mm bore), holds
# π/4 · (40 mm)² · 9 m ≈ 0.011 m³; paper 000's MAS-10 holds 2.36e-5 m³ (24 cm³), paper 001's DMSP-40 ~5e-4 m³. A
# volume above 0.02 m³ (20 l, about twice the largest) is litres or cm³ typed as m³ (the MAS-10's 0.02356 l).
MAX_MUSCLE_VOLUME = 0.02
# s, a smoothed valve edge's time width (`OnOffValve.edge_width`, 1e-4 s by default): `OnOffValve` keeps it below 5 %
# of its PWM period (where the edge must fit); PWM drives of pneumatic on/off valves run at 5 Hz or faster (slower,
# the muscle follows each pulse: bang-bang, not PWM), so 10 ms (5 % of a 5 Hz period) bounds every edge; 0.1 for
# 0.1 ms is milliseconds typed as seconds.
MAX_EDGE_WIDTH = 0.01
# m³/(s Pa), an ISO 6358 sonic conductance C: C [dm³/(s bar)] ≈ effective area [mm²] / 5 (the usual conversion),
# so paper 000's MHE2 (3.14 mm²) and paper 001's VPPM have C ≈ 6-7e-9, the largest industrial valves ~1e-6, and a
# DN50 pipe's 1,960 mm² ~4e-6. Above 1e-5 the value is still in m³/(s bar) (paper 001's tables: 7e-4) or
# dm³/(s bar), not divided by 1e5 (or 1e8).
MAX_SONIC_CONDUCTANCE = 1e-5
# m³/(s Pa): a 0.03 mm orifice's C (7e-4 mm² / 5 = 1.4e-4 dm³/(s bar), 1.4e-12), below any pneumatic valve's; paper
# 001's 7.06e-4 m³/(s bar) typed as its SI value 7.06e-9 into an argument in m³/(s bar) gave 7.06e-14, a flow 1e5
# times too small, without a word
MIN_SONIC_CONDUCTANCE = 1e-12
PSI = 6894.757293168  # Pa per psi (NIST SP 811)
BAR = 1e5  # Pa per bar
LITRE_PER_MINUTE = 1e-3 / 60.0  # m³/s per l/min
# Reference conditions of ISO 8778 (ANR, "normal" litres): 100 kPa, 20 °C, density 1.185 kg/m³. ISO 6358 sonic
# conductances are expressed at these conditions (paper 001, eq. 1-2), and paper 001's l/min are read as ANR.
ISO8778_DENSITY = 1.185  # kg/m³
ISO8778_TEMPERATURE = 293.15  # K
FLOW_UNIT = ISO8778_DENSITY * LITRE_PER_MINUTE  # kg/s per l/min ANR

# dimension → {spelling: SI factor}; SI value = factor × value (+ one atmosphere for gauge pressures).
_FACTORS = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "min": 60.0},
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "μm": 1e-6, "in": 0.0254},
    "velocity": {"m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3},
    "force": {"N": 1.0, "kN": 1e3, "mN": 1e-3},
    "mass_flow": {"kg/s": 1.0, "g/s": 1e-3, "kg/h": 1.0 / 3600.0},
    "volume": {"m^3": 1.0, "m3": 1.0, "m³": 1.0, "l": 1e-3, "L": 1e-3, "cm^3": 1e-6, "cm3": 1e-6, "cm³": 1e-6,
               "ml": 1e-6, "mL": 1e-6},
    "ratio": {"1": 1.0, "-": 1.0, "": 1.0, "%": 0.01},
    "voltage": {"V": 1.0, "mV": 1e-3},
}
_PRESSURE_FACTORS = {"pa": 1.0, "hpa": 1e2, "kpa": 1e3, "mpa": 1e6, "mbar": 1e2, "bar": BAR, "psi": PSI}
_SI = {"time": "s", "length": "m", "velocity": "m/s", "force": "N", "mass_flow": "kg/s", "volume": "m^3",
       "ratio": "1", "voltage": "V", "pressure": "Pa"}
# "bar abs", "bar(a)", "bara", "bar_abs", "kPa gauge", "kPag", "psig", "Pa", "MPa (abs.)"
_PRESSURE = re.compile(
    r"^(pa|hpa|kpa|mpa|mbar|bar|psi)\s*[\s(_,-]?\s*(abs\.?|absolute|a|gauge|g|rel\.?|relative)?\s*\)?$", re.IGNORECASE)

# Channel names (after renaming) → dimension. Names not listed keep their unit as written.
_CHANNEL_DIMENSIONS = (("pressure", "pressure"), ("position", "length"), ("displacement", "length"),
                       ("velocity", "velocity"), ("friction_force", "force"), ("force", "force"),
                       ("mass_flow", "mass_flow"), ("volume", "volume"), ("command", "command"))


def channel_dimension(name):
    """The physical dimension of a channel by its name ('pressure', 'pressure_tank' → "pressure"), or None."""
    if name == "t":
        return "time"
    for prefix, dimension in _CHANNEL_DIMENSIONS:
        if name == prefix or name.startswith(prefix + "_"):
            return dimension
    return None


def parse_pressure_unit(unit):
    """(SI factor, offset [Pa]) for a pressure unit, or None if `unit` is not one; an unqualified pressure unit other
    than Pa (absolute or gauge?) raises."""
    m = _PRESSURE.match(unit.strip())
    if m is None:
        return None
    base, qualifier = m.group(1).lower(), (m.group(2) or "").lower().rstrip(".")
    factor = _PRESSURE_FACTORS[base]
    if qualifier in ("g", "gauge", "rel", "relative"):
        return factor, ATMOSPHERE
    if qualifier in ("a", "abs", "absolute") or base == "pa":  # Pa alone is absolute: pamjax's own convention
        return factor, 0.0
    return None


def _dimension_of_unit(unit):
    if unit.strip() and parse_pressure_unit(unit) is not None:
        return "pressure"
    for dimension, table in _FACTORS.items():
        if unit in table and unit:
            return dimension
    return None


def to_si(name, unit, values, where, atmosphere=None):
    """`values` of channel `name` written in `unit`, converted to SI: (values, SI unit). A unit that does not fit the
    channel, that pamjax does not know for a known channel, or a pressure unit that does not say absolute or gauge,
    raises a `PamjaxInputError` naming `where`, the channel and the unit. Gauge pressures become absolute by adding
    `atmosphere` [Pa] (default: the ISO 2533 standard atmosphere, `ATMOSPHERE`)."""
    unit = "" if unit is None else str(unit).strip()
    dimension = channel_dimension(name)
    if dimension == "command":  # a duty ratio [1] or a regulator's reference voltage [V]
        dimension = "voltage" if unit in _FACTORS["voltage"] else "ratio"
    values = np.asarray(values, dtype=float)
    if dimension is None:  # a channel pamjax does not model: converted if its unit is known, else kept as written
        dimension = _dimension_of_unit(unit)
        if dimension is None or unit == "":
            return values, unit
    if dimension == "pressure":
        base = re.match(r"^\s*(pa|hpa|kpa|mpa|mbar|bar|psi)\b", unit, re.IGNORECASE)
        parsed = parse_pressure_unit(unit) if unit else (1.0, 0.0)
        if parsed is None and base is not None:
            raise PamjaxInputError(
                f"{where}: channel {name!r} is in {unit!r}: say whether that is ABSOLUTE or GAUGE pressure, e.g. "
                f"'{name} [{base.group(1)} abs]' or '{name} [{base.group(1)} gauge]' in the CSV header (or "
                f"units={{{name!r}: '{base.group(1)} abs'}}); pamjax converts it to ABSOLUTE pressure in Pa"
            )
        if parsed is None:
            raise PamjaxInputError(
                f"{where}: channel {name!r} has unit {unit!r}, not a pressure unit pamjax knows; use Pa (absolute), "
                "or kPa, MPa, bar, mbar, psi with 'abs' or 'gauge' (pamjax expects ABSOLUTE pressure in Pa)"
            )
        factor, offset = parsed
        if offset and atmosphere is not None:
            offset = float(atmosphere)
        return values * factor + offset, "Pa"
    table = _FACTORS[dimension]
    if unit not in table:
        other = _dimension_of_unit(unit)
        what = f"a {other} unit" if other else "a unit pamjax does not know"
        raise PamjaxInputError(
            f"{where}: channel {name!r} has unit {unit!r} ({what}); a {dimension} channel takes one of "
            f"{[u for u in table if u]} (converted to {_SI[dimension]})"
        )
    factor = table[unit]
    return (values * factor if factor != 1.0 else values), _SI[dimension]


def _likely_pressure_unit(peak):
    """The unit a peak absolute pressure value most likely was written in, when it is far too small for Pa."""
    if peak <= 0.95:  # 0.1-0.9 MPa: paper 000's pressures in MPa
        return "MPa"
    if peak <= 15.0:  # 1.01325 bar is one atmosphere
        return "bar"
    if peak <= 150.0:
        return "psi"
    if peak <= 1500.0:
        return "kPa"
    return "hPa or mbar"


def check_magnitude(dimension, values, where, name):
    """Refuse values whose magnitude says another unit (the likely one named). `values` are SI, finite ones only."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return
    peak = float(np.max(np.abs(v)))
    if dimension == "time" and v.size >= MIN_SAMPLES_FOR_RATE:
        step = float(np.median(np.diff(v)))
        if step >= 1.0:
            likely = "ms" if step < 1000.0 else "µs"
            raise PamjaxInputError(
                f"{where}: {name!r} is sampled every {step:g} s (median): far too slow to record a muscle driven at "
                f"50 Hz; these look like {likely}: write '{name} [{likely}]' in the header"
            )
        if step < 1e-5:
            raise PamjaxInputError(
                f"{where}: {name!r} is sampled every {step:g} s (median), faster than 100 kHz, which no pneumatic "
                f"bench records; are these seconds written under a [ms] header? (write '{name} [s]')"
            )
    elif dimension == "length" and peak > 1.0:
        raise PamjaxInputError(
            f"{where}: channel {name!r} reaches {peak:g} m; no pneumatic muscle moves a metre (the MAS-10's stroke is "
            f"75 mm): these look like mm (or cm): write '{name} [mm]' in the header"
        )
    elif dimension == "velocity" and peak > 20.0:
        raise PamjaxInputError(
            f"{where}: channel {name!r} reaches {peak:g} m/s; these look like mm/s: write '{name} [mm/s]' in the header"
        )
    elif dimension == "mass_flow" and peak > 1.0:
        raise PamjaxInputError(
            f"{where}: channel {name!r} reaches {peak:g} kg/s, a thousand times a valve's flow; these look like g/s: "
            f"write '{name} [g/s]' in the header"
        )
    elif dimension == "pressure":
        check_absolute_pressure(v, f"{where}: channel {name!r}")


def check_absolute_pressure(values, name, *, above_atmosphere=False):
    """Refuse pressures that are not ABSOLUTE pascal: below half an atmosphere (bar, MPa, psi, kPa or gauge; the
    likely unit named), above 50 bar, or — for a supply pressure (`above_atmosphere`) — not above one atmosphere.
    Traced values (inside jit/vmap/grad) are not checked."""
    v = concrete_values(values)
    if v is None:
        return
    v = v[np.isfinite(v)]
    if v.size == 0:
        return
    low, high = float(np.min(v)), float(np.max(v))
    if high < MIN_ABSOLUTE_PA:
        raise PamjaxInputError(
            f"{name} is {high:.6g} Pa at most: that looks like {_likely_pressure_unit(high)} (or a GAUGE pressure); "
            f"pamjax expects ABSOLUTE pressure in Pa (e.g. 0.65 MPa abs = 6.5e5; add {ATMOSPHERE:g} Pa to gauge "
            "readings)"
        )
    if low < MIN_ABSOLUTE_PA:
        raise PamjaxInputError(
            f"{name} drops to {low:.6g} Pa, below half an atmosphere ({MIN_ABSOLUTE_PA:g} Pa abs): a vented muscle or "
            f"tank reads about {ATMOSPHERE:g} Pa ABSOLUTE, so this looks like a GAUGE pressure (add {ATMOSPHERE:g} "
            "Pa)"
        )
    if high > MAX_ABSOLUTE_PA:
        raise PamjaxInputError(
            f"{name} reaches {high:.6g} Pa = {high / 1e5:.4g} bar; pneumatic muscles run below ~10 bar: check the "
            "unit (pamjax expects ABSOLUTE pressure in Pa)"
        )
    if above_atmosphere and low <= ATMOSPHERE:
        raise PamjaxInputError(
            f"{name} must exceed atmospheric pressure ({ATMOSPHERE:g} Pa abs) to inflate anything, got {low:.6g} Pa; "
            f"a gauge supply pressure needs {ATMOSPHERE:g} Pa added (0.55 MPa gauge = 6.513e5 Pa abs)"
        )


# Parameters and settings checked by magnitude where users type them (configs, sweeps): last path component → check.
_PLAUSIBLE = {
    "payload_mass": ("kg", 1e3, "g"),  # no pneumatic muscle lifts a tonne (DMSP-40: 6000 N)
    "mass": ("kg", 1e3, "g"),
    "foot_mass": ("kg", 100.0, "g"),  # an ankle orthosis's foot: 1.3 kg (1300 typed in grams refused)
    "payload_kg": ("kg", 1e3, "g"),
    "min_position": ("m", 1.0, "mm"),
    "max_position": ("m", 1.0, "mm"),
    "position": ("m", 1.0, "mm"),
    "switch_on_delay": ("s", 0.1, "ms"),
    "switch_off_delay": ("s", 0.1, "ms"),
    "edge_width": ("s", MAX_EDGE_WIDTH, "ms"),
    # a tank: paper 001's is 0.04 m³ (40 l), so litres typed as m³ (0.05 for a 50 cm³ tank) are a real test tank too;
    # only what no pneumatic-muscle rig uses (100 l and more) is refused
    "volume": ("m³", 0.1, "cm³ or litres"),
    "tank_volume": ("m³", 0.1, "cm³ or litres"),
    "v0": ("m³", MAX_MUSCLE_VOLUME, "cm³ or litres"),
    "nominal_length": ("m", MAX_MUSCLE_LENGTH, "mm"),
    # a braid's strand b_s = √3 (1 − ε_max) L0 (paper 000 eq. 1 at cos²θ = 1/3) is at most √3 L0
    "strand_length": ("m", 3.0**0.5 * MAX_MUSCLE_LENGTH, "mm"),
    # a Bouc-Wen transition δ: the force reaches the other branch after ~2δ of travel, so 0.1 m spends twice the
    # MAS-10's and the DMSP-40's whole stroke on one transition (paper 000's loops turn within a few mm; default 2 mm)
    "transition_length": ("m", 0.1, "mm"),
    # a friction's smoothing of sign(ẋ) or |ẋ| (defaults 1e-5 and 1e-3): at 0.05 m/s tanh(5 mm/s / 0.05 m/s) leaves
    # 10 % of F_c at docs/hysteresis.md's 5 mm/s loop speed, Coulomb's step gone
    "velocity_width": ("m/s", 0.05, "mm/s"),
    # a muscle's rest radius r0 (eq. 6): 0.1 m is a muscle 20 cm across, five times the DMSP-40's 20 mm
    "radius": ("m", 0.1, "mm"),
    # a regulator's extra outlet draw (eq. 5's Q_in): the VPPM passes at most ~6e-3 kg/s (ISO 6358, choked at 7 bar);
    # 0.1 kg/s is ~5000 l/min ANR, and paper 001's 2.79 l/min typed as kg/s ran to 1713 bar
    "outlet_flow": ("kg/s", 0.1, f"l/min (1 l/min ANR = {FLOW_UNIT:.3g} kg/s, pamjax.units.FLOW_UNIT)"),
}
_ABSOLUTE_PRESSURES = {"pressure", "pressures", "atmospheric_pressure"}
# containers whose entries are spreads per state (an estimator's initial standard deviations and process noise: Pa,
# Pa/√s for the pressure), not states: their `pressure` is no absolute pressure
_SPREADS = {"initial_std", "process_noise"}
# K: the coldest air a pneumatic bench works in is far above this (-73 °C); a temperature below it was written in °C
# (paper 000's 293 K is 20 °C).
MIN_TEMPERATURE_K = 200.0
# Pa: below any bench transducer's noise (a 16-bit reading of 0-10 bar resolves 15 Pa; the hybrid reference bench's is
# 2 kPa): a smaller pressure noise is a unit slip, 0.02 meant in bar (2 kPa) or 2 in kPa (the estimator's, a design's,
# an experiment's scales and a synthetic recording's noise check it)
MIN_PRESSURE_NOISE = 1.0


def checks_setting(path):
    """Whether `check_setting` checks parameter `path` (by its last component) at all."""
    leaf = str(path).split(".")[-1].split("[")[0]
    return leaf in _PLAUSIBLE or leaf in _ABSOLUTE_PRESSURES or leaf in ("supply_pressure", "max_pressure",
                                                                          "temperature")


def check_setting(path, values, where):
    """Plausibility of a value a user typed for parameter `path` (e.g. 'valve.supply_pressure', 'payload_mass',
    'y0.pressure'): refused with the likely unit named when its magnitude says another unit."""
    parts = [part.split("[")[0] for part in str(path).split(".")]
    leaf = parts[-1]
    if len(parts) > 1 and parts[-2] in _SPREADS:
        return  # a spread (σ, noise intensity) keyed by state name: any magnitude ≥ 0, the component checks it
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]  # NaN and inf are the components' own checks to name ("must be finite")
    label = f"{where} {path}"
    if leaf == "supply_pressure":
        check_absolute_pressure(v, label, above_atmosphere=True)
    elif leaf in _ABSOLUTE_PRESSURES:
        check_absolute_pressure(v, label)
    elif leaf == "temperature" and v.size and np.nanmin(v) < MIN_TEMPERATURE_K:
        raise PamjaxInputError(
            f"{label} = {np.nanmin(v):g} K: colder than {MIN_TEMPERATURE_K:g} K (-73 °C); that looks like °C "
            "(pamjax takes kelvin: add 273.15)"
        )
    elif leaf == "max_pressure" and v.size and np.nanmax(np.abs(v)) < 1e3:
        raise PamjaxInputError(
            f"{label} = {np.nanmax(np.abs(v)):g} Pa: that looks like {_likely_pressure_unit(np.nanmax(np.abs(v)))}; "
            "p_max of eq. 7 is a GAUGE pressure in Pa (paper 000: 6e5)"
        )
    elif leaf in _PLAUSIBLE and v.size:
        _refuse_implausible(leaf, v, label)


def _refuse_implausible(leaf, v, label):
    unit, limit, likely = _PLAUSIBLE[leaf]
    peak = float(np.nanmax(np.abs(v)))
    if peak > limit:
        raise PamjaxInputError(f"{label} = {peak:g} {unit}: more than {limit:g} {unit}; that looks like {likely} "
                               f"(pamjax takes SI units: {unit})")


def check_plausible(values, name):
    """`check_setting`'s magnitude check of a component's own field as it is built (`name`:
    'CubicVolume.nominal_length', its last part the field): 400 for a 0.4 m nominal length looks like mm. Traced
    values are not checked."""
    v = concrete_values(values)
    if v is not None and np.isfinite(v).any():
        _refuse_implausible(name.split(".")[-1], v[np.isfinite(v)], name)


def check_pressure_span(values, name):
    """A pressure difference [Pa] a component holds (a regulator's hysteresis width): positive, and not below
    `MIN_PRESSURE_NOISE` (0.05 for paper 001's 50 mbar, typed in bar, made its loop 0.05 Pa wide: none). Traced values
    are not checked."""
    check_positive(values, name)
    v = concrete_values(values)
    if v is not None and np.isfinite(v).any() and float(np.min(v[np.isfinite(v)])) < MIN_PRESSURE_NOISE:
        low = float(np.min(v[np.isfinite(v)]))
        raise PamjaxInputError(f"{name} = {low:g} Pa is below {MIN_PRESSURE_NOISE:g} Pa, less than any transducer "
                               f"resolves: that looks like bar ({low:g} bar = {low * 1e5:g} Pa); pamjax takes Pa")


def check_sonic_conductance(values, name):
    """Refuse an ISO 6358 sonic conductance C [m³/(s Pa)] above `MAX_SONIC_CONDUCTANCE`, no valve's: still in
    m³/(s bar) or dm³/(s bar) (paper 001 tabulates m³/(s bar)). Traced values are not checked."""
    v = concrete_values(values)
    if v is None or not np.isfinite(v).any():
        return
    peak, low = float(np.max(v[np.isfinite(v)])), float(np.min(v[np.isfinite(v)]))
    if 0.0 < low < MIN_SONIC_CONDUCTANCE:
        raise PamjaxInputError(
            f"{name} = {low:g} m³/(s Pa): less than {MIN_SONIC_CONDUCTANCE:g}, a 0.03 mm orifice's (valves: ~1e-9 to "
            "1e-6); that looks like a value in m³/(s Pa) divided again by 1e5 (an argument in m³/(s bar) takes paper "
            "001's 7.06e-4, not 7.06e-9)"
        )
    if peak > MAX_SONIC_CONDUCTANCE:
        raise PamjaxInputError(
            f"{name} = {peak:g} m³/(s Pa): more than {MAX_SONIC_CONDUCTANCE:g}, a DN50 pipe's order (valves: ~1e-9 to "
            "1e-6); that looks like m³/(s bar) or dm³/(s bar): divide by 1e5 (m³/(s bar)) or 1e8 (dm³/(s bar)) for "
            "m³/(s Pa)"
        )


# -- units of model parameters (model files) ----------------------------------------------------------------------
# A parameter's unit is its component's own (the field comment: `payload_mass: ... # kg`); a model file may give a
# value in another unit of the same quantity, converted here, or in one pamjax cannot convert, refused by name.
_PARAMETER_FACTORS = {
    "kg": {"g": 1e-3, "mg": 1e-6, "t": 1e3},
    "m": _FACTORS["length"],
    "s": _FACTORS["time"],
    "m/s": _FACTORS["velocity"],
    "N": _FACTORS["force"],
    "kg/s": _FACTORS["mass_flow"],
    "m^3": {"l": 1e-3, "L": 1e-3, "dm^3": 1e-3, "cm^3": 1e-6, "ml": 1e-6, "mL": 1e-6, "mm^3": 1e-9},
    "m^2": {"cm^2": 1e-4, "mm^2": 1e-6},
    "Hz": {"kHz": 1e3},
    "rad": {"deg": np.pi / 180.0, "°": np.pi / 180.0},
    "V": {"mV": 1e-3},
    "N/m": {"N/mm": 1e3, "kN/m": 1e3},
    "N s/m": {"N s/mm": 1e3},
    "1": {"%": 1e-2},
}
_CELSIUS = ("°C", "degC", "C", "℃", "deg C")


def canonical_unit(unit):
    """A unit's spelling reduced to one form: superscripts and bare exponents as `^n` (m³, m3 → m^3), `·`/`*` as a
    space, dimensionless `-`, `1` and the empty string as "1"."""
    u = str(unit).strip().replace("²", "^2").replace("³", "^3").replace("·", " ").replace("*", " ")
    u = re.sub(r"(?<=[A-Za-z])(\d)", r"^\1", u)
    u = re.sub(r"\s+", " ", u)
    return "1" if u in ("", "-", "1") else u


def parameter_to_si(declared, given, values, name, atmosphere=ATMOSPHERE):
    """`values` of parameter `name`, given in unit `given`, in the component's own unit `declared` (SI): converted,
    or a `PamjaxInputError` naming `name`, the unit and the ones accepted. `declared` None (a parameter whose unit
    pamjax does not know) takes only the empty unit. Pressures: a field in `Pa abs` takes any pressure unit that says
    `abs` or `gauge` (`bar abs`, `barg`; Pa alone is absolute), one in `Pa gauge` likewise (`Pa` alone refused: say
    which), one in plain `Pa` (a pressure scale, neither) takes an unqualified unit (`kPa`, `bar`); gauge and absolute
    differ by `atmosphere` [Pa] (the model's own atmospheric pressure where it states one)."""
    values = np.asarray(values, dtype=float)
    if given is None:
        return values
    if not isinstance(given, str):
        raise PamjaxInputError(f"{name}: unit must be a string such as \"{declared or 'kg'}\", got {given!r}")
    have, want = canonical_unit(given), None if declared is None else canonical_unit(declared)
    if want is None:
        if have == "1":
            return values
        raise PamjaxInputError(f"{name}: unit {given!r}, but pamjax does not know this parameter's unit (its "
                               "component declares none), so it cannot convert it: give the value in the component's "
                               "own unit and remove \"unit\"")
    if have == want:
        return values
    if want in ("Pa abs", "Pa gauge", "Pa"):
        return _pressure_parameter(want, given, values, name, atmosphere)
    if want == "K" and given.strip() in _CELSIUS:
        return values + 273.15
    table = {canonical_unit(u): f for u, f in _PARAMETER_FACTORS.get(want, {}).items()}
    if have in table:
        return values * table[have]
    accepted = [declared] + sorted(set(table) - {want}) + (["°C"] if want == "K" else [])
    raise PamjaxInputError(f"{name}: unit {given!r} is not one pamjax converts to this parameter's unit "
                           f"{declared!r}; write the value in one of {accepted}")


def _pressure_parameter(want, given, values, name, atmosphere):
    m = _PRESSURE.match(given.strip())
    if m is None:
        raise PamjaxInputError(f"{name}: unit {given!r} is not a pressure unit; this parameter is in {want!r} (Pa, "
                               "hPa, kPa, MPa, mbar, bar or psi" + (" with 'abs' or 'gauge')" if want != "Pa" else ")"))
    base, qualifier = m.group(1), (m.group(2) or "").lower().rstrip(".")
    factor = _PRESSURE_FACTORS[base.lower()]
    if want == "Pa":  # a pressure scale or a difference: neither absolute nor gauge
        if qualifier:
            raise PamjaxInputError(f"{name}: unit {given!r} says absolute or gauge, but this parameter (in 'Pa') is "
                                   f"a pressure difference; write '{base}' alone")
        return values * factor
    gauge = qualifier in ("g", "gauge", "rel", "relative")
    absolute = qualifier in ("a", "abs", "absolute") or (not qualifier and base.lower() == "pa" and want == "Pa abs")
    if not (gauge or absolute):
        kind = "an ABSOLUTE" if want == "Pa abs" else "a GAUGE"
        raise PamjaxInputError(f"{name}: unit {given!r}: say whether that is absolute or gauge pressure ('{base} abs' "
                               f"or '{base} gauge'); this parameter is {kind} pressure in Pa")
    si = values * factor
    if want == "Pa abs":
        return si + atmosphere if gauge else si
    return si - atmosphere if absolute else si
