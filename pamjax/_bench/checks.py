"""Checks of a bench's values, each a `PamjaxInputError` naming the file, the key or the argument, with what to write
instead: meta.json's numbers (`number`, a tank test's volume and start pressure, a reference gauge's supply reading,
a key written twice), `load_bench`'s arguments (the runs, the sensors' calibrations), a run's name as a parameter path
(`run_path`, also for `pamjax fit`'s [rig]) and a muscle run fitted from rest against its first samples
(`check_at_rest`). `pamjax._bench.files` and `pamjax._bench.load` call them while they read a bench; nothing here
reads a file or solves."""

import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import MAX_ABSOLUTE_PA, MIN_ABSOLUTE_PA
from .._fit.parameters import Key, join_path, split_path

# m³: the largest V_tank meta.json may give. A tank test charges a rigid volume through the valve under test: paper
# 000's and the benches' are 50 cm³ (5e-5 m³); pneumatic test tanks and receivers go to some tens of litres. 0.1 m³
# (100 l) is also the model's own limit for a tank volume (`check_setting`'s "tank_volume"), so a value past it —
# litres or cm³ written as m³ (50 for 50 cm³) — is refused here, naming meta.json, instead of inside the fit.
MAX_TANK_VOLUME = 0.1
# A calibrated gain of a pressure sensor lies within ±20 % of 1: a transducer's gain error is a fraction of a percent
# to a few percent (realistic1's rig and the unseen ones: ±1 %), and a factor outside is a unit or scaling mistake
# (psi taken for bar: 0.069; bar for psi: 14.5), refused.
PRESSURE_GAIN_RANGE = (0.8, 1.2)
# A calibration's standard uncertainty above 5 % says less than the recordings do (they fix the gain to ~0.3-0.4 %
# with every supply free: benchmarks/RESULTS.md, identify): refused as a likely slip (a per cent for a fraction).
PRESSURE_GAIN_SD_MAX = 0.05
# Pa: a muscle run fitted from rest (no "init": "unknown") starts at the atmosphere with its valve shut, so its first
# samples read the atmosphere within the pressure sensor's offset and noise (realistic1: +1.8 kPa offset, 2 kPa
# noise; the unseen rigs of benchmarks/unseen_rigs.py draw offsets within ±3 kPa; the shared benches' runs from rest
# read -3..+4 kPa). 30 kPa above it, 10× the largest of those offsets, is a run pressurised when its log began
# (realistic1's E4, logged 1.3 s into its triangle: +469 kPa). Only above: an absolute gauge at altitude, logged
# without meta.json's atmosphere_Pa, reads below it at rest.
REST_GAUGE_MAX = 3e4
# The first samples compared with the rest (their median: one spike decides nothing), taken at the recorded rate:
# 2 ms at 1 kHz, before a valve opened in the first PWM period (after its ~2 ms switching delay) fills the muscle.
REST_SAMPLES = 3
# Of a supply reading's gauge value: how far a run's recorded pressure may lie above it (sensor gain errors of a few
# per cent, a filling tank's last samples at the supply); a gauge reading taken for an absolute one lies an
# atmosphere (17-25 % of a 4-6 barg supply) below the full tank.
SUPPLY_EXCESS = 0.08


def number(e, key, where, lo=None, hi=None, unit=""):
    """meta.json's `e[key]` as a float (None where absent): a finite number (not a bool) within [lo, hi], else a
    `PamjaxInputError` naming `where` and the key."""
    if key not in e:
        return None
    v = e[key]
    if not (isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)):
        raise PamjaxInputError(f"{where}: {key} must be a number{f' [{unit}]' if unit else ''}, got {v!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        hint = " (a duty ratio: 0.5, not 50 %)" if key in ("u", "lo", "hi") and v > 1 else ""
        raise PamjaxInputError(f"{where}: {key} = {v!r} is outside [{lo}, {hi}]{hint}")
    return float(v)


def unique_keys(where):
    """A `json.loads` object_pairs_hook refusing a key written twice in one table (JSON keeps the last silently: two
    runs of one name in `experiments` were one run, the other's conditions lost), naming `where` and the key."""
    def hook(pairs):
        seen = set()
        for key, _ in pairs:
            if key in seen:
                raise PamjaxInputError(f"{where}: key {key!r} is written twice in one table (JSON keeps only the "
                                       "last: two experiments of one name are one); rename or delete one")
            seen.add(key)
        return dict(pairs)

    return hook


def tank_volume(name, e, where):
    """A tank test's `V_tank` [m³] from its meta.json entry `e`: > 0 and at most `MAX_TANK_VOLUME`."""
    volume = number(e, "V_tank", f"{where}: {name}", 0.0, None, "m^3")
    if volume is None or volume <= 0:
        raise PamjaxInputError(f"{where}: tank test {name!r} needs V_tank, its volume > 0 [m^3]")
    if volume > MAX_TANK_VOLUME:
        raise PamjaxInputError(
            f"{where}: tank test {name!r} has V_tank = {volume:g} m^3, more than {MAX_TANK_VOLUME:g} m^3 ("
            f"{MAX_TANK_VOLUME * 1e3:g} litres), beyond any bench's test tank: V_tank is in m^3, and this looks like "
            f"litres ({volume:g} l = {volume * 1e-3:g} m^3) or cm^3 ({volume:g} cm^3 = {volume * 1e-6:g} m^3)")
    return volume


def tank_start(name, kind, e, p_atm, where):
    """A tank test's start pressure from its meta.json entry `e`: "supply" (`p0` "p_s", the default of a discharge:
    the run's own supply pressure), `p_atm` ("p_atm", a charge's default) or a number [Pa abs] within
    [MIN_ABSOLUTE_PA, MAX_ABSOLUTE_PA] (a bar or gauge value refused by name: it was a start at 1 Pa)."""
    p0 = e.get("p0", "p_atm" if kind == "tank_charge" else "p_s")
    if p0 == "p_s":
        return "supply"
    if p0 == "p_atm":
        return p_atm
    if not (isinstance(p0, (int, float)) and not isinstance(p0, bool) and np.isfinite(p0) and
            MIN_ABSOLUTE_PA <= p0 <= MAX_ABSOLUTE_PA):
        raise PamjaxInputError(f"{where}: {name!r} p0 must be 'p_atm', 'p_s' or a pressure in Pa ABSOLUTE "
                               f"({MIN_ABSOLUTE_PA:g}..{MAX_ABSOLUTE_PA:g}; 1.01325 bar = 101325 Pa), got {p0!r}")
    return float(p0)


def supply_reading(e, where, p_atm):
    """A run's supply pressure as a reference gauge read it: meta.json's `supply_Pa` (ABSOLUTE [Pa], above the
    atmosphere `p_atm`) and its standard uncertainty `supply_sd_Pa` [Pa], or None where the entry has neither."""
    if "supply_Pa" not in e and "supply_sd_Pa" not in e:
        return None
    value = number(e, "supply_Pa", where, MIN_ABSOLUTE_PA, MAX_ABSOLUTE_PA, "Pa abs")
    sd = number(e, "supply_sd_Pa", where, 0.0, 1e5, "Pa")
    if value is None or sd is None or not sd > 0:
        raise PamjaxInputError(f"{where}: a supply reading needs supply_Pa (the run's supply pressure as a reference "
                               "gauge read it, ABSOLUTE [Pa]) and supply_sd_Pa (its standard uncertainty [Pa], > 0)")
    if value <= p_atm:
        raise PamjaxInputError(f"{where}: supply_Pa = {value:g} Pa is not above the atmosphere ({p_atm:g} Pa abs): "
                               "it is the supply's ABSOLUTE pressure (a gauge reading plus the atmosphere)")
    return value, sd


def check_supply_reading(reading, pressure, where, p_atm):
    """A reference gauge's supply reading (`supply_reading`) against the run's recorded pressure [Pa abs, as the
    plant's sensor reads it back]: no pressure fills above its supply. A supply written as a gauge reading (5 barg
    as 5e5 for 601 kPa abs) lies one atmosphere below the full tank's samples: refused where the samples exceed
    it by more than `SUPPLY_EXCESS` of its gauge value plus five of its standard uncertainties (the fitted supplies
    of realistic1 and the unseen rigs lie within 0.5 % of their gauges; a sensor's gain error is at most a few %)."""
    value, sd = reading
    top = float(np.max(pressure)) if np.size(pressure) else -np.inf
    if top > value + SUPPLY_EXCESS * (value - p_atm) + 5.0 * sd:
        raise PamjaxInputError(f"{where}: supply_Pa = {value:g} Pa lies below the run's recorded pressure (up to "
                               f"{top:g} Pa abs): it is the supply's ABSOLUTE pressure (a gauge reading plus the "
                               f"atmosphere, {p_atm:g} Pa here)")


def check_runs(runs, meta, kinds, where):
    """`load_bench`'s `runs` (None: every experiment of `kinds`): names of meta.json's experiments, each of a kind
    fitted."""
    if runs is None:
        return
    if isinstance(runs, str) or not all(isinstance(r, str) for r in runs) or not runs:
        raise PamjaxInputError(f"runs must be a non-empty list of experiment names (e.g. [\"E4\"]), got {runs!r}")
    experiments = meta["experiments"]
    unknown = [r for r in runs if r not in experiments]
    if unknown:
        raise PamjaxInputError(f"{where}: runs {unknown} are not experiments of its meta.json; it has "
                               f"{sorted(experiments)}")
    unfitted = [r for r in runs if experiments[r].get("kind") not in kinds]
    if unfitted:
        raise PamjaxInputError(f"{where}: runs {unfitted} are of kinds "
                               f"{sorted({str(experiments[r].get('kind')) for r in unfitted})}, not among kinds="
                               f"{list(kinds)}")


def check_calibrations(position_offset, pressure_gain, pressure_gain_sd=None):
    """The sensors' calibrations given to `load_bench`, before anything is read: a named error for each mistake."""
    if pressure_gain_sd is not None:
        if pressure_gain is None:
            raise PamjaxInputError("pressure_gain_sd is the uncertainty of a calibrated gain: give pressure_gain too")
        if not (isinstance(pressure_gain_sd, (int, float)) and not isinstance(pressure_gain_sd, bool) and
                np.isfinite(pressure_gain_sd) and 0 < pressure_gain_sd <= PRESSURE_GAIN_SD_MAX):
            raise PamjaxInputError(f"pressure_gain_sd must be the calibration's standard uncertainty, a number in "
                                   f"(0, {PRESSURE_GAIN_SD_MAX}] (absolute: 0.0005 for ±0.05 %), got "
                                   f"{pressure_gain_sd!r}")
    if not (isinstance(position_offset, (int, float)) and np.isfinite(position_offset) and
            abs(position_offset) < 0.1):
        raise PamjaxInputError(f"position_offset must be the position sensor's calibrated offset in m (|x| < 0.1 m), "
                               f"got {position_offset!r}")
    if pressure_gain is not None and not (
            isinstance(pressure_gain, (int, float)) and not isinstance(pressure_gain, bool) and
            np.isfinite(pressure_gain) and PRESSURE_GAIN_RANGE[0] <= pressure_gain <= PRESSURE_GAIN_RANGE[1]):
        raise PamjaxInputError(f"pressure_gain must be the pressure sensor's calibrated gain, a number in "
                               f"{list(PRESSURE_GAIN_RANGE)} (1.0: reads true), got {pressure_gain!r}")


def run_path(name: str, field: str, where: str = "meta.json") -> str:
    """The parameter path of run `name`'s `field` in a `pamjax.Rig`, as pamjax writes paths (`join_path`):
    `runs[E4].supply_pressure`, a name that reads as a number quoted (`runs['1'].supply_pressure`; unquoted, it is an
    array index). A name no path can hold (a `]` in it, spaces or quotes around it) is a `PamjaxInputError` naming
    the run and `where`, before anything is fitted."""
    path = join_path(["runs", Key(name), *field.split(".")])
    try:
        held = split_path(path)[0][1] == name
    except PamjaxInputError:
        held = False
    if not held:
        raise PamjaxInputError(f"{where}: run {name!r} cannot be named in a parameter path (runs[<name>].{field}: a "
                               "name without ']' and without spaces or quotes around it); rename the run (its "
                               "recording and its entry)")
    return path


def check_at_rest(name, rec, p_atm, where):
    """A muscle run fitted from rest (its meta.json entry without "init": "unknown"): the median of its first
    `REST_SAMPLES` recorded pressures lies within `REST_GAUGE_MAX` above the atmosphere `p_atm` [Pa abs], else a
    `PamjaxInputError` with the advice a triangle logged from the middle gets (was: a `muscle_run` logged mid-way at
    5.7 bar fitted from rest at 1 bar, silently). A run without a pressure column is not checked: its rest position
    is the plant's, which the fit identifies (realistic1's runs rest at -16 mm, the presets' plant at -4.7 mm)."""
    if "pressure" not in rec.channels:
        return
    first = float(np.median(rec["pressure"][:REST_SAMPLES]))
    if first - p_atm > REST_GAUGE_MAX:
        raise PamjaxInputError(
            f"{where}: experiment {name!r} starts at {first:.6g} Pa abs ({(first - p_atm) / 1e5:+.3g} bar gauge, its "
            f"first {REST_SAMPLES} samples), but a run without \"init\" is fitted from rest at the atmosphere "
            f"({p_atm:.6g} Pa): the run was logged from the middle, so its start is not at rest; mark it with "
            "\"init\": \"unknown\" (its start state is then fitted with --nuisance)")
