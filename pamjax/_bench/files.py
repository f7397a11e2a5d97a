"""Reading a bench directory: meta.json (checked key by key), one recording per experiment (NPZ, CSV with units in its
header, MATLAB .mat), and the command that drove each run (the recorded duty, checked against meta.json's). Every
mistake is a `PamjaxInputError` naming the experiment, the file and the key, with what to write instead.
`pamjax._bench.load` builds the experiments from what this reads."""

import difflib
import json
import pathlib
import re

import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import check_setting
from .._fit.builds import PayloadFromModel
from .._fit.recording import Recording
from .._physics.signals import Constant, Sampled, Triangle
from .._systems.base import AbstractMuscleSystem
from .checks import number, unique_keys

TANK_KINDS = ("tank_charge", "tank_discharge")
MUSCLE_KINDS = ("muscle_triangle", "muscle_run")
FITTED_KINDS = TANK_KINDS + MUSCLE_KINDS
# Kinds a meta.json may list that no fit takes: the hybrid bench's closed-loop runs (pamjax's PWM grid reads a planned
# duty, not a controller's). Any other kind is a typo, refused by name (was: the run silently left out).
UNFITTED_KINDS = ("muscle_PI",)
KNOWN_KINDS = FITTED_KINDS + UNFITTED_KINDS
RECORDING_SUFFIXES = (".npz", ".csv", ".mat")
# The channels a bench run is fitted from (`Recording.load(..., channels=...)`): every other column of its file is
# left unread, whatever it holds (docs/fitting.md: "other columns ignored"), and said in the notes.
BENCH_CHANNELS = ("command", "pressure", "position")
# A recorded duty agrees with meta.json's when every PWM period's value is within this of it: a logger writes the
# duty with 6 decimals (shared/data/bench-realistic), far below any duty step that changes a valve's behaviour.
_DUTY_TOLERANCE = 1e-3


# The keys a meta.json may hold; any other is refused by name with the closest known one (was: "payload_kgs" or
# "atmosphere_pa" silently ignored: the model's payload, 101325 Pa). Read: what `read_meta` and `load_bench` use.
# Informational, never read: a simulated bench's truth (`params`, `nuisance`: docs/fitting.md), what the shared
# benches and the benchmarks' rigs record of themselves (shared/data/*/meta.json, benchmarks/unseen_rigs.py,
# design_unseen.py: a run's t_end, a muscle_PI run's controller), free text (`description`, `comment`, `notes`).
_TEXT_KEYS = ("description", "comment", "notes")
META_KEYS = ("experiments", "noise", "fitted_keys", "units", "atmosphere_Pa")
META_INFO_KEYS = ("params", "nuisance", "params_seed", "set", "files", "conventions", "sampling_hz", "non_identifiable",
                  "x_eq_patm", "perturbation", "generated_by", "switching_time_s", *_TEXT_KEYS)
EXPERIMENT_KEYS = ("kind", "V_tank", "u", "p0", "lo", "hi", "f_tri", "init", "payload_kg", "supply_Pa", "supply_sd_Pa")
EXPERIMENT_INFO_KEYS = ("t_end", "phase_s", "w", "kp", "ki", "u0", "x_mid", "amp", "anti_windup", *_TEXT_KEYS)


def check_keys(table, known, what, informational=()):
    """Every key of `table` (a meta.json table) is in `known` or `informational`: else a `PamjaxInputError` naming
    `what` (the file and the table) and the key, with the closest known key (case aside, else difflib)."""
    allowed = (*known, *informational)
    for key in table:
        if key in allowed:
            continue
        close = [k for k in allowed if k.lower() == str(key).lower()] or difflib.get_close_matches(str(key), allowed)
        raise PamjaxInputError(f"{what} has key {key!r}, which pamjax does not know" + (
            f" (did you mean {close[0]!r}?)" if close else "") + f"; the keys read there: {list(known)}")


_META_TEMPLATE = ('{"experiments": {"E1": {"kind": "tank_charge", "V_tank": 5e-5, "u": 0.5, "p0": "p_atm"}, '
                  '"E3": {"kind": "muscle_run"}}, "noise": {"p_std_Pa": 2000, "x_std_m": 1e-4}, '
                  '"fitted_keys": ["Cv12", "b12", "Cv23", "b23", "v0", "v1", "Fc", "Cf"]}')


def read_meta(directory):
    directory = pathlib.Path(directory)
    if not directory.is_dir():
        raise PamjaxInputError(f"bench directory {directory} does not exist or is not a directory")
    path = directory / "meta.json"
    if not path.exists():
        files = sorted(p.name for p in directory.iterdir() if p.suffix.lower() in RECORDING_SUFFIXES)
        found = f" It holds {len(files)} recording(s) ({', '.join(files[:4])}{', ...' if len(files) > 4 else ''})" \
            if files else " It holds no recording (.npz, .csv or .mat) either."
        raise PamjaxInputError(
            f"bench directory {directory} has no meta.json describing its experiments.{found} Write one beside them, "
            f"e.g. {_META_TEMPLATE} (each experiment named as its file; the layout: docs/fitting.md, 'Identifying "
            "your own rig')")
    try:
        # utf-8-sig: a byte-order mark (Notepad's "UTF-8 with BOM") skipped, and UTF-8 whatever the platform's code page
        meta = json.loads(path.read_text(encoding="utf-8-sig"), object_pairs_hook=unique_keys(str(path)))
    except json.JSONDecodeError as err:
        raise PamjaxInputError(f"{path} is not valid JSON: {err}") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("experiments"), dict) or not meta["experiments"]:
        raise PamjaxInputError(f"{path} needs an 'experiments' table (name → kind and conditions), e.g. "
                               f"{_META_TEMPLATE}")
    check_keys(meta, META_KEYS, str(path), META_INFO_KEYS)
    if isinstance(meta.get("noise"), dict):
        check_keys(meta["noise"], [key for key, _, _ in _NOISE_KEYS], f"{path}: 'noise'")
    for name, e in meta["experiments"].items():
        if not isinstance(e, dict) or "kind" not in e:
            raise PamjaxInputError(f"{path}: experiment {name!r} must be a table with a 'kind' (one of "
                                   f"{list(KNOWN_KINDS)}), got {e!r}")
        check_keys(e, EXPERIMENT_KEYS, f"{path}: experiment {name!r}", EXPERIMENT_INFO_KEYS)
        if e["kind"] not in KNOWN_KINDS:
            close = difflib.get_close_matches(str(e["kind"]), KNOWN_KINDS, n=1)
            raise PamjaxInputError(
                f"{path}: experiment {name!r} has kind {e['kind']!r}, which pamjax does not know"
                + (f" (did you mean {close[0]!r}?)" if close else "") + f"; write one of {list(FITTED_KINDS)} (fitted) "
                f"or {list(UNFITTED_KINDS)} (known, not fitted)")
    return directory, meta


_NOISE_KEYS = (("p_std_Pa", "pressure", "Pa"), ("x_std_m", "position", "m"))  # meta.json key, channel, unit


def noise_levels(meta, recordings, where, notes=None):
    """Noise standard deviations: meta.json's `noise` where given, else estimated from the recordings, said in
    `notes`. The estimate: 1.4826 MAD of the second differences / √6 (white noise of standard deviation σ has second
    differences of standard deviation √6 σ; a signal that changes smoothly from sample to sample adds little to
    them). First differences (/ √2), used before, take a fast pressure's slope for noise: 2.0-2.9× the true
    2,000 Pa on realistic1, the hybrid bench and three unseen rigs, against +4-13 % with second differences (the
    position's 0.1 mm within 2 % either way); what is left is the switching valve's kinks in the pressure."""
    given = meta.get("noise", {})
    if not isinstance(given, dict):
        raise PamjaxInputError(f"{where}: 'noise' must be a table {{'p_std_Pa': ..., 'x_std_m': ...}}, got {given!r}")
    out = {}
    for key, channel, unit in _NOISE_KEYS:
        if key in given:
            value = given[key]
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise PamjaxInputError(f"{where}: noise {key} must be the sensor's noise standard deviation, a "
                                       f"number > 0 [{unit}], got {value!r} (leave it out to estimate it from the "
                                       "recordings)")
            out[channel] = float(value)
    for key, c, unit in _NOISE_KEYS:
        if c not in out:
            diffs = [np.diff(r[c], n=2) for r in recordings if c in r.channels and np.ptp(r[c]) > 0 and len(r[c]) > 2]
            if diffs:
                d = np.concatenate(diffs)
                out[c] = float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(6.0))
                if not (np.isfinite(out[c]) and out[c] > 0):  # most second differences zero: a coarse or held sensor
                    raise PamjaxInputError(
                        f"{where}: the {c} noise cannot be estimated from the recordings (most of their second "
                        f"differences are zero: a sensor whose resolution is coarser than its noise?); give the "
                        f"sensor's noise standard deviation as 'noise': {{\"{key}\": ...}} [{unit}]")
                if notes is not None:
                    notes.append(f"{c} noise estimated from the recordings: {out[c]:.4g} {unit} (meta.json 'noise' "
                                 f"{key} gives the sensor's, where known)")
    return out


def recording_file(directory, name):
    """The one recording of experiment `name` in `directory`: `<name>.npz`, `.csv` or `.mat`, the extension in any
    capitals (`E1.CSV`, as loggers on Windows write it)."""
    found = sorted(p for p in directory.iterdir() if p.suffix.lower() in RECORDING_SUFFIXES
                   and p.name[:-len(p.suffix)] == name and p.is_file())
    if not found:
        others = sorted(p.name for p in directory.iterdir() if p.suffix.lower() in RECORDING_SUFFIXES)
        raise PamjaxInputError(
            f"bench {directory}: experiment {name!r} of meta.json has no recording {name}.npz, {name}.csv or "
            f"{name}.mat" + (f" (the folder holds {', '.join(others[:6])}{', ...' if len(others) > 6 else ''})"
                             if others else " (the folder holds no recording)"))
    if len(found) > 1:
        raise PamjaxInputError(f"bench {directory}: experiment {name!r} has {len(found)} recordings "
                               f"({', '.join(p.name for p in found)}); keep one")
    return found[0]


def load_recording(path, name, meta, atmosphere, notes=None):
    """The recording of experiment `name` at `path`: its time and `BENCH_CHANNELS` (other columns left unread, said
    in `notes`), meta.json's `units` for the columns whose file gives none (a CSV header's own unit that differs is
    refused, naming both), a NaN/inf sample refused naming the file and line."""
    units = meta.get("units")
    if units is not None and not isinstance(units, dict):
        raise PamjaxInputError(f"meta.json 'units' must be a table channel → unit (e.g. {{\"p\": \"barg\"}}), got "
                               f"{units!r}")
    rec = Recording.load(path, name=name, atmosphere=atmosphere, mask_nan=True, channels=BENCH_CHANNELS,
                         default_units={str(k): str(v) for k, v in (units or {}).items()})
    if rec.ignored and notes is not None:
        notes.append(f"{name}: {path.name}'s " + ", ".join(
            f"{k!r}" + ("" if why == "not a channel read" else f" ({why})") for k, (_, why) in rec.ignored.items())
            + " ignored (a bench run is fitted from its time, duty, pressure and position)")
    for channel, valid in rec.mask.items():
        if not np.all(valid):
            row = int(np.argmin(valid))
            raise PamjaxInputError(
                f"{rec.locate(row)}: column {rec.columns.get(channel, channel)!r} (channel {channel!r}) of "
                f"experiment {name!r} is NaN/inf at row {row} (0-based data row; t = {rec.t[row]:g} s): a bench "
                "recording must be complete; fix or delete that line, or cut the recording before the bad rows")
    return rec


_PRESSURE_UNIT = re.compile(r"^\s*(pa|hpa|kpa|mpa|mbar|bar|psi)", re.IGNORECASE)  # how a pressure unit begins


def check_channels(name, kind, rec, where, notes):
    """A run's recording has what its kind is fitted from: a tank test its pressure, a muscle run its pressure or its
    position (without a pressure: said in `notes`). Where the pressure is missing and a column left unread carries a
    pressure unit (`presure [barg]`), that column is named with the header to write."""
    if "pressure" in rec.channels:
        return
    units = {k: unit for k, (unit, _) in rec.ignored.items() if unit and _PRESSURE_UNIT.match(unit)}
    if units:
        column, unit = next(iter(units.items()))
        raise PamjaxInputError(
            f"{rec.source}: column {column!r} is in a pressure unit ({unit!r}) but is not a channel pamjax reads, and "
            f"experiment {name!r} has no pressure column: if it is the pressure, head it 'pressure [{unit}]' (p and "
            "Pressure read as the pressure too); if it is not (the run recorded no pressure), delete that column")
    if kind in TANK_KINDS:
        raise PamjaxInputError(f"{where}: tank test {name!r} has no pressure column (columns of {rec.source}: "
                               f"{sorted([*rec.columns.values(), *rec.ignored])}); head it 'pressure [barg]' (or p)")
    if "position" not in rec.channels:
        raise PamjaxInputError(f"{where}: {name!r} records neither pressure nor position (columns of {rec.source}: "
                               f"{sorted([*rec.columns.values(), *rec.ignored])})")
    notes.append(f"{name}: no pressure column in {pathlib.Path(rec.source).name}: fitted on its position alone (a "
                 "pressure is headed 'pressure [barg]', or p)")


def period_starts(t, period):
    """Indices of the first sample in each PWM period the recording covers."""
    k = np.floor(t / period + 1e-9).astype(np.int64)
    idx = np.concatenate([[0], np.nonzero(np.diff(k))[0] + 1])
    return idx[idx < t.size - 1] if idx.size > 1 else idx  # a last row alone in its period is the logger's end


def _triangle_phase(signal, t, u, period):
    """The time φ [s] into `signal` (a Triangle) at which the recording starts, if the recorded duty `u` is that
    triangle delayed by φ (a run logged from the middle): searched on a 1 ms grid over one triangle period and
    refined at the PWM period's resolution; None if no φ fits within the duty tolerance."""
    idx = period_starts(t, period)
    ts, us = t[idx], u[idx]
    low, high, frequency = float(signal.low), float(signal.high), float(signal.frequency)
    phis = np.arange(0.0, 1.0 / frequency, 1e-3)
    errors = np.empty(phis.size)
    for start in range(0, phis.size, 256):  # `Triangle.__call__` in NumPy, 256 candidate phases at a time
        x = np.floor((ts[None, :] + phis[start:start + 256, None]) / period + 1e-9) * period * frequency
        ref = low + (high - low) * (1.0 - np.abs(2.0 * (x - np.floor(x)) - 1.0))
        errors[start:start + 256] = np.max(np.abs(ref - us[None, :]), axis=1)
    best = int(np.argmin(errors))  # the first of equal errors, as a scan from φ = 0 finds it
    return float(phis[best]) if errors[best] <= _DUTY_TOLERANCE else None


def run_command(name, kind, e, rec, valve_period, where, notes, unknown_start):
    """The signal that drives the run: the recorded duty (checked against meta.json's where both exist), else
    meta.json's."""
    here = f"{where}: experiment {name!r}"
    recorded = "command" in rec.channels
    if recorded:
        _check_duty_range(name, rec)
    if kind in TANK_KINDS:
        duty = number(e, "u", here, 0.0, 1.0)
        if recorded and duty is not None:
            off = float(np.max(np.abs(rec["command"] - duty)))
            if off > _DUTY_TOLERANCE:
                raise PamjaxInputError(
                    f"{where}: meta.json gives experiment {name!r} duty u = {duty:g}, but its recording's duty is "
                    f"{np.min(rec['command']):g}..{np.max(rec['command']):g}: one of them is wrong (the recording "
                    "is what the rig commanded)")
        if not recorded and duty is None:
            raise PamjaxInputError(f"{where}: experiment {name!r} has neither a recorded duty column nor meta.json's "
                                   "'u'")
        if not recorded:
            notes.append(f"{name}: no recorded duty column; driven by meta.json's duty u = {duty:g}")
            return Constant(duty)
    else:
        keys = [k for k in ("lo", "hi", "f_tri") if k in e]
        triangle = None
        if keys:
            missing = [k for k in ("lo", "hi", "f_tri") if k not in e]
            if missing:
                raise PamjaxInputError(
                    f"{where}: experiment {name!r} gives a triangle duty without {missing} (a triangle needs lo, hi "
                    "and f_tri [Hz]; a run with a recorded duty column needs none of them: kind 'muscle_run')")
            lo, hi = number(e, "lo", here, 0.0, 1.0), number(e, "hi", here, 0.0, 1.0)
            f = number(e, "f_tri", here, 0.0, None, "Hz")
            if not (lo < hi and f > 0):
                raise PamjaxInputError(f"{where}: experiment {name!r} needs lo < hi and f_tri > 0, got lo={lo}, "
                                       f"hi={hi}, f_tri={f}")
            triangle = Triangle(lo, hi, f)
        if not recorded and triangle is None:
            raise PamjaxInputError(
                f"{where}: experiment {name!r} has no recorded duty column (u / duty) and meta.json gives no "
                "triangle (lo, hi, f_tri): pamjax cannot know what drove the run; record the commanded duty")
        if not recorded:
            if unknown_start:
                raise PamjaxInputError(
                    f"{where}: experiment {name!r} was logged mid-way (its \"init\" is unknown), and its recording "
                    f"{rec.source} has no duty column (columns: {sorted(rec.channels)}): the triangle's phase at its "
                    "first sample is unknown, so meta.json's triangle cannot drive it; record the commanded duty (a "
                    "column u / duty) in the file")
            notes.append(f"{name}: no recorded duty column; driven by meta.json's triangle (lo={lo:g}, hi={hi:g}, "
                         f"f_tri={f:g} Hz) from the run's start, unchecked (a recorded duty is checked against it)")
            return triangle
        if triangle is not None:  # its phase counted from the first sample (a logger's clock need not start at 0)
            t, u = rec.t - rec.t[0], rec["command"]
            idx = period_starts(t, valve_period)
            ref = np.asarray(triangle(np.floor(t[idx] / valve_period + 1e-9) * valve_period))
            if float(np.max(np.abs(ref - u[idx]))) > _DUTY_TOLERANCE:
                phase = _triangle_phase(triangle, t, u, valve_period)
                if phase is None:
                    raise PamjaxInputError(
                        f"{where}: experiment {name!r}'s recorded duty is not meta.json's triangle (lo={e['lo']}, "
                        f"hi={e['hi']}, f_tri={e['f_tri']}) at any phase: one of them is wrong (the recording is what "
                        "the rig commanded)")
                if not unknown_start:
                    raise PamjaxInputError(
                        f"{where}: experiment {name!r}'s recorded duty is meta.json's triangle {phase:.3f} s in: the "
                        "run was logged from the middle, so its start is not at rest; mark it with \"init\": "
                        "\"unknown\" (its start state is then fitted with --nuisance)")
                notes.append(f"{name}: logged {phase:.3f} s into its triangle (recorded duty); driven by the recorded "
                             "duty")
            else:
                notes.append(f"{name}: recorded duty = meta.json's triangle (checked); driven by the recorded duty")
    return Sampled(rec.t, rec["command"], period=valve_period)


def on_pwm_clock(name, rec, period, notes):
    """`rec` with its times on the valve's PWM clock (periods starting at multiples of `period` [s], as the model's
    valve counts them). A logger's clock need not be: it may start at 12.345 s, or a run may be logged from the
    middle of a period, and a valve switched 7 ms off its recorded edges leaves a tank charge's residuals at 11× the
    noise. Where the recorded duty changes, it changes at period starts: those fix the periods' phase (to within a
    sample; the file's clock kept where it agrees). A run without a change (a constant duty) is taken to start its
    periods with its first sample, as a triangle's phase is counted from it. Each move is said in `notes`."""
    if period is None:
        return rec
    t0, reason = float(rec.t[0]), None
    found = _pwm_phase(rec, period)
    if found is not None:
        phase, width = found  # period starts at `phase` (mod period) on the file's clock, or up to `width` before it
        if phase > period * (1.0 - 1e-9):
            phase -= period  # just below a whole period: at its start
        if -1e-9 * period <= phase < width:
            return rec  # the file's clock agrees with the recorded duty's changes
        shift, reason = -phase, "where its recorded duty changes"
    else:
        k = t0 / period
        if abs(k - round(k)) < 1e-6:
            return rec
        shift, reason = -t0, "from its first sample: a constant duty shows no period start"
    moved = rec.shifted(shift)
    notes.append(f"{name}: its PWM periods start at {-shift % period * 1e3:.3g} ms after a multiple of "
                 f"{period * 1e3:g} ms on the file's clock ({reason}): its times moved by {shift:.6g} s onto the "
                 "valve's clock")
    return moved


def _pwm_phase(rec, period):
    """(phase, width) [s]: where on the file's clock (mod `period`) the recorded duty's changes put the PWM period
    starts, and how far before that they may lie: a change is logged by the first sample at or after its period start,
    so each change allows (t_c − dt, t_c]; `phase` is the latest start all allow (the change's own sample: a logger
    clocked with the valve samples the period start itself). None without a duty change, or where the changes
    disagree (a duty not held per period)."""
    if "command" not in rec.channels or rec.t.size < 3:
        return None
    u, t = rec["command"], rec.t
    at = np.nonzero(np.diff(u) != 0)[0] + 1
    if at.size == 0:
        return None
    dt = float(np.median(np.diff(t)))
    ref = float(t[at[0]])
    offsets = (t[at] - ref + 0.5 * period) % period - 0.5 * period  # each change relative to the first, in (-T/2, T/2]
    lo, hi = float(np.max(offsets - dt)), float(np.min(offsets))  # a period start in (t_c - dt, t_c] for each
    if lo >= hi + 1e-9 * period:
        return None
    return (ref + hi) % period, hi - lo


def _check_duty_range(name, rec):
    """A recorded duty lies in [0, 1]: else an error naming the file, its duty column and the first bad row (a CSV's
    line), with the percent hint where the values look like percent (none negative, some above 1.5, none above
    100)."""
    u = rec["command"]
    bad = (u < -1e-9) | (u > 1 + 1e-9)
    if not np.any(bad):
        return
    row = int(np.argmax(bad))
    column = rec.columns.get("command", "command")
    low, high = float(np.min(u)), float(np.max(u))
    csv = rec.source is not None and str(rec.source).lower().endswith((".csv", ".txt"))
    if low >= 0 and 1.5 < high <= 100:
        fix = ("it looks like percent: write its header 'duty [%]'" if csv else
               f"it looks like percent: give meta.json \"units\": {{\"{column}\": \"%\"}}")
    else:
        fix = "a duty ratio lies in [0, 1] (0.5: half of each PWM period open): correct that value"
    raise PamjaxInputError(f"{rec.locate(row)}: the duty column {column!r} of experiment {name!r} reads {u[row]:g} "
                           f"there, outside [0, 1] (its range: [{low:g}, {high:g}]); {fix}")


# A straight line through the first samples of a run logged mid-way needs two, and a third so that one noisy sample
# does not set its slope: at a low `rate` (25 Hz: one sample in the 20 ms window; was numpy's "SVD did not converge")
# the window takes the first three, said in the notes by the time they span.
START_SAMPLES = 3


def start_estimate(rec, sensors, p_atm, plant, lead, window=0.02):
    """A run logged mid-way: its start (pressure, position, velocity) `lead` s before its first sample, from the
    first `window` seconds of data, at least its first `START_SAMPLES` (the median pressure, a straight line through
    the position), each read back through the rig's `sensors` (`Sensors.observe` inverted: a calibrated gain of 1.05
    left the start pressure 5 % of its gauge value off, a calibrated position offset its whole size). A pressure the
    run did not record is the one at which the model rests at that position (`holding_pressure`). Returns (name →
    start value, what it came from: for the notes)."""
    keep = rec.t <= rec.t[0] + window
    keep[:START_SAMPLES] = True
    span = max(window, float(rec.t[np.count_nonzero(keep) - 1] - rec.t[0]))
    out, said = {}, [f"first {span * 1e3:g} ms of data"]
    if "pressure" in rec.channels:
        out["pressure"] = unread_pressure(float(np.median(rec["pressure"][keep])), sensors, p_atm)
    if "position" in rec.channels and np.ptp(rec["position"]) > 0:
        slope, intercept = np.polyfit(rec.t[keep] - rec.t[0], rec["position"][keep], 1)
        position = float(intercept - slope * lead) - float(sensors.position_offset)
        if "pressure" not in out and isinstance(plant, AbstractMuscleSystem):
            out["pressure"] = holding_pressure(plant, position)
            said.append("the pressure, not recorded, where the model rests at that position")
        out.update(position=position, velocity=float(slope))
    return out, "; ".join(said)


def unread_pressure(measured, sensors, p_atm):
    """The plant's pressure [Pa abs] that `sensors` read as `measured`: `Sensors.observe` inverted."""
    return p_atm + (measured - p_atm - float(sensors.pressure_offset)) / float(sensors.pressure_gain)


def holding_pressure(plant, position):
    """The pressure [Pa abs] at which `plant` (an `AbstractMuscleSystem`) rests at `position` [m]: its start state at
    rest (`initial_state(pressure=...)`, the static balance of muscle and payload) inverted on a 2.5 kPa grid from the
    atmosphere up 1 MPa (an end of it where the position lies beyond)."""
    import jax

    p_atm = float(plant.air.atmospheric_pressure)
    pressures = np.linspace(p_atm, p_atm + 1e6, 401)
    rest = np.asarray(jax.vmap(lambda p: plant.initial_state(pressure=p).position)(pressures))
    above = np.nonzero(rest >= position)[0]
    if above.size == 0:
        return float(pressures[-1])
    k = int(above[0])
    if k == 0:
        return p_atm
    share = (position - rest[k - 1]) / (rest[k] - rest[k - 1])
    return float(pressures[k - 1] + share * (pressures[k] - pressures[k - 1]))


def with_atmosphere(model, atmosphere, said, notes):
    """`model` with its air's atmospheric pressure the bench's `atmosphere` [Pa abs] (the ambient pressure its gauge
    readings refer to, as `said`: meta.json's atmosphere_Pa or `load_bench`'s atmosphere), which the valve's exhaust,
    a tank's "p_atm" start and a run at rest then refer to too; said in `notes`. `model` itself where they agree."""
    import equinox as eqx
    import jax.numpy as jnp

    try:
        value = float(atmosphere) if not isinstance(atmosphere, (bool, str)) else np.nan
    except (TypeError, ValueError):
        value = np.nan
    if not (np.isfinite(value) and 5e4 <= value <= 1.2e5):
        raise PamjaxInputError(f"{said} must be the ambient pressure in Pa abs (50-120 kPa), got {atmosphere!r}")
    old = model.air.atmospheric_pressure
    if abs(value - float(old)) < 0.5:
        return model
    notes.append(f"the model's atmospheric pressure set to {value:.6g} Pa ({said}; the model had {float(old):.6g} "
                 "Pa): the gauge readings, the valve's exhaust and the tank tests' p_atm refer to it")
    return eqx.tree_at(lambda m: m.air.atmospheric_pressure, model, jnp.asarray(value, jnp.result_type(old)))


def payload_build(e, model, where, notes):
    """`PayloadFromModel` for a muscle run whose meta.json entry gives `payload_kg` (weights added or taken off),
    else None (the model's payload)."""
    mass = number(e, "payload_kg", where, unit="kg")
    if mass is None:
        return None
    if mass <= 0:
        raise PamjaxInputError(f"{where}: payload_kg must be > 0 [kg] (the mass the muscle lifts in this run), got "
                               f"{e['payload_kg']!r}")
    check_setting("payload_kg", mass, f"{where}:")  # 9600 (grams) loaded as 9.6 t, as a config refuses it
    if not isinstance(model, AbstractMuscleSystem):
        raise PamjaxInputError(f"{where}: payload_kg is given but the model ({type(model).__name__}) lifts no payload")
    notes.append(f"{where.rsplit(': ', 1)[-1]}: payload {mass:g} kg (payload_kg; the model's is "
                 f"{float(model.payload_mass):g} kg)")
    return PayloadFromModel(mass)
