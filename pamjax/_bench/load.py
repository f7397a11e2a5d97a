"""Bench directories: one recording per experiment and a `meta.json` that describes them (the hybrid-reference layout,
`pamjax/data/hybrid-reference-bench/README.md`, the copy shipped with pamjax; a real rig's CSV files,
`shared/data/bench-realistic/README.md`).

`meta.json` holds `experiments` (name → kind and conditions: `tank_charge` / `tank_discharge` with `V_tank`, `u`,
`p0`; `muscle_triangle` with `lo`, `hi`, `f_tri`; `muscle_run` (any recorded duty, e.g. a designed experiment);
`muscle_PI` closed-loop runs; `init` "unknown…" for a run logged from the middle; `supply_Pa` ± `supply_sd_Pa`, a
reference gauge's reading of the run's supply pressure [Pa abs]), `noise` (`p_std_Pa`,
`x_std_m`), `fitted_keys` (the parameters to identify, named as below) and, optionally, `units` (channel → unit, for
columns whose file gives none: NPZ, MAT, a CSV header without units) and `atmosphere_Pa` (the ambient pressure gauge
readings are referred to, and the model's; default 101325 Pa). Simulated benches also list their true `params` and
`nuisance`: never read here (a fit starts from the model it is given, e.g. the presets).

Recordings: `<name>.npz`, `<name>.csv` or `<name>.mat`, one per experiment, with time, the duty the rig commanded
(`u` / `duty` / `command`, held per PWM period), pressure and position (short names `t, u, p, x` or full ones; CSV
headers give units, `pressure [barg]`, `position [mm]`; gauge pressures become absolute with the stated
atmosphere). The command that drives a run is the one the rig logged: meta.json's duty or triangle, where given, is
checked against it (a contradiction is an error naming both), and only a recording without a command column is
driven from meta.json (said in the notes; refused for a run logged mid-way, whose triangle phase is unknown).

`load_bench` turns such a directory into `Experiment`s for `pamjax.fit`, optionally with the rig's nuisances free
(`nuisance=True`: `pamjax.Rig`); `BENCH_PARAMETERS` maps the bench's parameter names to pamjax parameter paths;
`pamjax._bench.report` reads a fit result back in the bench's names.
"""

import dataclasses
import os
import pathlib
from collections.abc import Sequence

import numpy as np

from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError
from .._fit.builds import TankFromModel
from .._fit.experiment import Experiment
from .._fit.measurement import Measurement
from .._fit.parameters import parameter_paths
from .._fit.rig import DEFAULT_GROUP, Rig, RunConditions, Sensors, StartState
from .._systems.base import AbstractSystem
from .checks import (
    check_at_rest,
    check_calibrations,
    check_runs,
    check_supply_reading,
    number,
    run_path,
    supply_reading,
    tank_start,
    tank_volume,
)
from .files import (
    FITTED_KINDS,
    MUSCLE_KINDS,
    TANK_KINDS,
    check_channels,
    load_recording,
    noise_levels,
    on_pwm_clock,
    payload_build,
    period_starts,
    read_meta,
    recording_file,
    run_command,
    start_estimate,
    unread_pressure,
    with_atmosphere,
)

# bench name → (pamjax parameter path, label of the value in a FitResult)
BENCH_PARAMETERS = {
    "Cv12": ("valve.inflate.discharge_coefficient", "valve.inflate.discharge_coefficient"),
    "b12": ("valve.inflate.critical_ratio", "valve.inflate.critical_ratio"),
    "Cv23": ("valve.exhaust.discharge_coefficient", "valve.exhaust.discharge_coefficient"),
    "b23": ("valve.exhaust.critical_ratio", "valve.exhaust.critical_ratio"),
    "v0": ("muscle.volume_law.v0", "muscle.volume_law.v0"),
    "v1": ("muscle.volume_law.v1", "muscle.volume_law.v1"),
    **{f"a{i}": ("muscle.force_law.max_force_coefficients", f"a{i}") for i in range(5)},
    "k0": ("muscle.force_law.k0", "muscle.force_law.k0"),
    "k1": ("muscle.force_law.k1", "muscle.force_law.k1"),
    "k2": ("muscle.force_law.k2", "muscle.force_law.k2"),
    "Fc": ("friction.coulomb_force", "friction.coulomb_force"),
    "Cf": ("friction.viscous_coefficient", "friction.viscous_coefficient"),
    # the switching valve's delays (paper 000: "approximately 2 ms"; its thresholds are t_on/T and 1 − t_off/T): free
    # them where a fit's diagnosis finds the valve faster or slower than the model's (pamjax._fit.rig_hints)
    "t_on": ("valve.switch_on_delay", "valve.switch_on_delay"),
    "t_off": ("valve.switch_off_delay", "valve.switch_off_delay"),
}
_FORCE_PATH = "muscle.force_law.max_force_coefficients"  # a0…a4: one array
# The nuisances `load_bench(..., nuisance=...)` can free (docs/fitting.md, "Identifying your own rig"), and those
# `nuisance=True` frees. The position sensor's offset only where a muscle run rests on a stroke limit: elsewhere a
# shift of the position origin is absorbed EXACTLY by the plant (F_max's quartic a0…a4, eq. 7's k0 − k1 x and eq. 14's
# v0 + v1 x are polynomials in x of degrees it keeps), so no recording determines it; it is then held at its
# calibration (`position_offset=`, default 0) and the plant is identified in the sensor's frame.
BENCH_NUISANCES = ("pressure_offset", "pressure_gain", "position_offset", "delay", "supply_pressure", "start")
DEFAULT_BENCH_NUISANCES = ("pressure_offset", "pressure_gain", "delay", "supply_pressure", "start")


@dataclasses.dataclass
class Bench:
    """A loaded bench directory: `experiments` (for `pamjax.fit`), `free` (the parameter paths to fit: the plant's
    from `fitted_keys`, prefixed `plant.` when nuisances are free, then the nuisances'), `fitted_keys`, `noise`
    (channel → standard deviation used as the residual scale), `skipped` (experiment → reason), `meta` (the parsed
    meta.json), `directory`, `rate` (None: as recorded); `model` (the start model of the fit: the plant, or a
    `pamjax.Rig` holding it with the nuisances' start values), `nuisance` (the nuisance paths in `free`), `notes`
    (what the loader found: commands checked, runs logged mid-way, start values estimated), `calibrated` (the
    sensors' calibrations given to `load_bench`: {"pressure_gain": value, "pressure_gain_sd": its uncertainty where
    given}). A calibrated gain with an uncertainty adds its `pamjax.Measurement` as the last of `experiments`."""

    experiments: list
    free: list
    fitted_keys: list
    noise: dict
    skipped: dict
    meta: dict
    directory: pathlib.Path
    rate: float | None
    model: AbstractSystem | Rig | None = None
    nuisance: list = dataclasses.field(default_factory=list)
    notes: list = dataclasses.field(default_factory=list)
    unknown_starts: list = dataclasses.field(default_factory=list)
    calibrated: dict = dataclasses.field(default_factory=dict)


def _free_paths(keys):
    """(keys as a list, their parameter paths) of bench names `keys`: a0…a4 name one array, so all five or none."""
    if isinstance(keys, (str, bytes)) or not np.iterable(keys) or not all(isinstance(k, str) for k in keys):
        raise PamjaxInputError(f"fitted_keys must be a list of bench parameter names (e.g. [\"Cv12\", \"Fc\"]), got "
                               f"{keys!r}")
    keys = list(keys)
    unknown = [k for k in keys if k not in BENCH_PARAMETERS]
    if unknown:
        raise PamjaxInputError(f"fitted_keys {unknown} are not bench parameters pamjax knows; valid: "
                               f"{sorted(BENCH_PARAMETERS)}")
    forces = [k for k in BENCH_PARAMETERS if k in keys and BENCH_PARAMETERS[k][0] == _FORCE_PATH]
    if forces and len(forces) < 5:  # was: all five freed, the others reported nowhere
        raise PamjaxInputError(f"fitted_keys name {forces} of a0…a4, the coefficients of F_max(x), which pamjax "
                               f"fits as one array ({_FORCE_PATH}, by its values at 5 nodes): give all five (a0, a1, "
                               "a2, a3, a4) or none")
    paths = []
    for k in keys:
        path = BENCH_PARAMETERS[k][0]
        if path not in paths:
            paths.append(path)
    return keys, paths


def _on_model(paths, model, notes):
    """`paths` as they are on `model`: a path the model has not, with a port held as the `first` of a restriction in
    series after it (the silenced preset's exhaust, `SeriesRestriction(port, silencer)`), is the port's. Cv23 and b23
    were `valve.exhaust.discharge_coefficient`, which the silenced model has not: `fit` refused a path the user never
    wrote. A path the model has not either way is left to `fit` to name."""
    valid, out = parameter_paths(model), []
    for path in paths:
        parts = path.split(".")
        ported = (".".join([*parts[:i], "first", *parts[i:]]) for i in range(1, len(parts)))
        mapped = path if path in valid else next((p for p in ported if p in valid), path)
        if mapped != path:
            notes.append(f"{path} is {mapped} on this model (a restriction in series after that port, e.g. a "
                         "silencer: fitted as it is)")
        out.append(mapped)
    return out


def _nuisance_names(nuisance):
    if nuisance is True:
        return set(DEFAULT_BENCH_NUISANCES)
    if not nuisance:
        return set()
    names = {nuisance} if isinstance(nuisance, str) else set(nuisance)
    unknown = names - set(BENCH_NUISANCES)
    if unknown:
        raise PamjaxInputError(f"nuisance names {sorted(unknown)} are not nuisances pamjax fits; valid: "
                               f"{list(BENCH_NUISANCES)} (or True for {list(DEFAULT_BENCH_NUISANCES)})")
    return names


def _rest_samples(rec, signal, valve, period):
    """Samples of a run that starts at rest at atmospheric pressure before the first PWM period whose duty opens its
    valve (`switching_gates`): the pressure there is the atmosphere, as the sensor reads it."""
    if period is None:
        return np.zeros(rec.t.shape, bool)
    idx = period_starts(rec.t, period)
    if "command" in rec.channels:
        duty = rec["command"][idx]
    else:
        import jax

        duty = np.asarray(jax.vmap(signal)(np.floor(rec.t[idx] / period + 1e-9) * period))
    opens = np.asarray(valve.switching_gates(duty)[0])
    first = rec.t[idx[np.argmax(opens)]] if np.any(opens) else rec.t[-1]
    return rec.t < first


# s: a run logged mid-way starts its solve this long before its first sample, so that the model can be read there
# when the sensors lag (acquisition delays of a few ms). Short, so that the fitted start is near the data: on
# realistic1 a 5 ms lead reached the lowest cost with finite standard errors of the start (0 ms: the first samples
# read the start state before it; 20 ms: a stuck-or-sliding start that the data cannot tell apart, errors infinite).
START_LEAD = 0.005


def load_bench(directory: str | os.PathLike, model: AbstractSystem, *, rate: RealScalarLike | None = None,
               kinds: Sequence[str] = FITTED_KINDS, fitted_keys: Sequence[str] | None = None, substeps: int = 16,
               nuisance: bool | Sequence[str] = False, atmosphere: RealScalarLike | None = None,
               position_offset: float | int = 0.0, pressure_gain: float | int | None = None,
               pressure_gain_sd: float | None = None, runs: Sequence[str] | None = None) -> "Bench":
    """Experiments of a bench directory for `pamjax.fit(bench.model, bench.experiments, bench.free)`.

    **Arguments:**

    - `directory`: a folder with `meta.json` and one recording per experiment (`<name>.npz`, `.csv` or `.mat`).
    - `model`: the plant to be fitted (e.g. `pamjax.presets.mas10_system(valve="pwm", friction="karnopp")`); its
      atmospheric and supply pressures set the tank tests' initial pressures (`p0` "p_atm" / "p_s").
    - `rate`: decimate the recordings to this rate [Hz] (`Recording.resampled`: recorded samples, no filter);
      None keeps them as recorded. A noise meta.json does not give is estimated at the recorded rate.
    - `kinds`: the experiment kinds to fit (default: tank charge/discharge and the muscle runs; the closed-loop
      `muscle_PI` runs are left out: pamjax's PWM grid reads a planned duty, not a controller's).
    - `fitted_keys`: bench parameter names to free (default: meta.json's `fitted_keys`).
    - `runs`: the experiments to fit, by name (e.g. `["E4"]`, a pilot run alone); default: every one of `kinds`.
    - `substeps`: RK4 nodes per PWM period of the fixed grid.
    - `nuisance`: False (default: ideal sensors, nominal supply, every run at rest unless meta.json gives its start),
      True (free the nuisances of a real rig that its recordings determine: the pressure sensor's offset and gain
      and the acquisition delay, shared by all runs; each run's supply pressure; the start state of runs whose
      `init` is "unknown…"), or a list of names from `BENCH_NUISANCES` ("position_offset" too: only where a run
      reaches a stop of known position, see `DEFAULT_BENCH_NUISANCES`). The fit's model is then `bench.model`, a
      `pamjax.Rig`.
    - `position_offset`: the position sensor's offset [m] as calibrated (what it reads at x = 0; default 0), held
      unless "position_offset" is freed.
    - `pressure_gain`: the pressure sensor's gain as calibrated (a two-point calibration, a reference gauge: what
      multiplies the gauge pressure), or None. Given, it is held (`nuisance=True` then frees the other nuisances)
      unless "pressure_gain" is named in `nuisance`, where it is the start value. Worth giving: with every run's
      supply pressure free, the recordings fix the gain only through the flow laws' absolute pressures, to ~0.3-0.4
      % (one standard error on realistic1-like rigs), and each supply and F_max follow its error
      (benchmarks/RESULTS.md, identify).
    - `pressure_gain_sd`: the calibration's standard uncertainty (absolute: 0.0005 for ±0.05 %), or None. Given,
      the gain is fitted with the recordings and the calibration enters the fit as one more datum, a
      `pamjax.Measurement` appended to `experiments` (residual (gain − pressure_gain)/sd): the fit weighs calibration
      and recordings by their uncertainties instead of trusting the calibration exactly. Needs `pressure_gain`.
    - `atmosphere`: the ambient pressure [Pa abs] that gauge readings (`barg`, `kPa gauge`) are referred to;
      default meta.json's `atmosphere_Pa`, else the model's atmospheric pressure. Given either way, it is the rig's
      ambient pressure: `bench.model`'s air takes it (its exhaust, a tank's "p_atm" start), said in `notes`.

    **Returns:** a `Bench`. **Raises:** `PamjaxInputError` naming the experiment, file and key for every mistake in
    the directory (missing or duplicated recordings, unreadable meta.json, an unknown kind, units, NaN, time order, a
    duty outside [0, 1], a V_tank beyond a test tank, meta.json contradicting a recording), before anything is fitted.
    Columns a run is not fitted from are ignored, unread, and said in `notes`.
    """
    directory, meta = read_meta(directory)
    where = f"bench {directory}"
    keys, free = _free_paths(meta.get("fitted_keys", []) if fitted_keys is None else fitted_keys)
    if not keys:
        raise PamjaxInputError(f"{where}: no parameters to fit: meta.json has no fitted_keys and none were given")
    names = _freed(nuisance, position_offset, pressure_gain, pressure_gain_sd)
    unknown_kinds = [k for k in kinds if k not in FITTED_KINDS]
    if unknown_kinds:
        raise PamjaxInputError(f"kinds {unknown_kinds} are not experiment kinds pamjax fits; valid: "
                               f"{list(FITTED_KINDS)}")
    notes, said = [], "meta.json atmosphere_Pa" if atmosphere is None else "the atmosphere given"
    free = _on_model(free, model, notes)  # a silenced exhaust's port is valve.exhaust.first
    if atmosphere is None:
        atmosphere = number(meta, "atmosphere_Pa", f"{where}/meta.json", 5e4, 1.2e5, "Pa abs")
    if atmosphere is not None:  # the rig's ambient pressure: the model's too
        model = with_atmosphere(model, atmosphere, said, notes)
    atmosphere = p_atm = float(model.air.atmospheric_pressure)
    period = None if model.valve.period is None else float(model.valve.period)
    specs, skipped, recordings, unknown = [], {}, [], []
    check_runs(runs, meta, kinds, where)
    for name, e in meta["experiments"].items():
        kind = e.get("kind")
        if runs is not None and name not in runs:
            skipped[name] = f"not in runs={list(runs)}"
            continue
        if kind not in kinds:
            skipped[name] = f"kind {kind!r} not fitted (kinds={list(kinds)})"
            continue
        rec = load_recording(recording_file(directory, name), name, meta, atmosphere, notes)
        check_channels(name, kind, rec, where, notes)
        start_unknown = str(e.get("init", "")).strip().lower().startswith("unknown")
        if start_unknown:
            unknown.append(name)
        rec = on_pwm_clock(name, rec, period, notes)
        signal = run_command(name, kind, e, rec, period, f"{where}/meta.json", notes, start_unknown)
        if kind in MUSCLE_KINDS and not start_unknown:  # fitted from rest: its first samples must read it
            check_at_rest(name, rec, p_atm, f"{where}/meta.json")
        # the noise from the recordings as recorded: decimating (`resampled` keeps recorded samples) leaves each
        # sample's noise as it was, but aliases the 50 Hz PWM ripple into the second differences (realistic1's 2 kPa
        # read 12-18 kPa at 200-100 Hz)
        recordings.append(rec)
        if rate is not None:
            rec = rec.resampled(rate)
        specs.append((name, kind, e, rec, signal))
    noise = noise_levels(meta, recordings, f"{where}/meta.json", notes)
    experiments = []
    for name, kind, e, rec, signal in specs:
        if kind in TANK_KINDS:
            experiments.append(_tank_test(name, kind, e, rec, signal, noise, p_atm, substeps, f"{where}/meta.json"))
        else:  # from rest at equilibrium, valve off, stuck (the model's default initial state) unless unknown
            channels = [c for c in ("pressure", "position") if c in rec.channels and np.ptp(rec[c]) > 0]
            missing = [c for c in channels if c not in noise]
            if missing:
                raise PamjaxInputError(f"{where}/meta.json: no noise level for {missing} (give 'noise')")
            lead = START_LEAD if name in unknown and "start" in names else 0.0  # solved from before the log
            experiments.append(Experiment(rec, signal, channels=channels, scales={c: noise[c] for c in channels},
                                          name=name, substeps=substeps, t0=rec.t[0] - lead,
                                          build=payload_build(e, model, f"{where}/meta.json: {name}", notes)))
    if not experiments:
        raise PamjaxInputError(f"{where}: no experiment of the kinds {list(kinds)}")
    bench = Bench(experiments, free, keys, noise, skipped, meta, directory, None if rate is None else float(rate),
                  model=model, notes=notes, unknown_starts=unknown)
    _unfreed_notes(notes, names, unknown, specs, where, p_atm)
    if names or position_offset or pressure_gain is not None:
        _with_nuisance(bench, specs, names, p_atm, float(position_offset), pressure_gain, by_default=nuisance is True,
                       pressure_gain_sd=pressure_gain_sd)
    return bench


def _tank_test(name, kind, e, rec, signal, noise, p_atm, substeps, where):
    """The `Experiment` of a tank test's meta.json entry `e` (its volume and start pressure checked)."""
    if "payload_kg" in e:
        raise PamjaxInputError(f"{where}: {name!r} is a tank test, which lifts no payload; payload_kg belongs to "
                               "muscle runs")
    volume = tank_volume(name, e, where)
    p0 = tank_start(name, kind, e, p_atm, where)  # "supply": the run's own supply pressure (its nuisance, if fitted)
    return Experiment(rec, signal, channels=["pressure"], scales={"pressure": noise["pressure"]},
                      build=TankFromModel(volume), initial={"pressure": p0}, name=name, substeps=substeps)


def _unfreed_notes(notes, names, unknown, specs, where, p_atm):
    """Notes on what the bench holds that the nuisances not freed leave unused: unknown starts, supply readings."""
    if unknown and "start" not in names:
        notes.append(f"{', '.join(unknown)}: start state unknown (meta.json init); fitted as if at rest unless the "
                     "start is freed (nuisance=True / --nuisance)")
    read = [name for name, _, e, _, _ in specs if supply_reading(e, f"{where}/meta.json: {name}", p_atm) is not None]
    if read and "supply_pressure" not in names:
        notes.append(f"{', '.join(read)}: supply pressures read by a reference gauge (meta.json supply_Pa), unused: "
                     "the supply pressures are not freed (nuisance=True / --nuisance fits them with the readings)")


def _freed(nuisance, position_offset, pressure_gain, pressure_gain_sd):
    """The nuisance names `load_bench` frees, the calibrations checked first: a calibrated gain is held
    (`nuisance=True` frees the others), a calibrated gain with its uncertainty is fitted (with its measurement)."""
    names = _nuisance_names(nuisance)
    check_calibrations(position_offset, pressure_gain, pressure_gain_sd)
    if pressure_gain is not None and nuisance is True:
        names.discard("pressure_gain")
    if pressure_gain_sd is not None:
        names.add("pressure_gain")
    return names


def _with_nuisance(bench, specs, names, p_atm, position_offset, pressure_gain=None, by_default=False,
                   pressure_gain_sd=None):
    """`bench` with its model a `Rig` (start values from the data: no solve, nothing of the truth) and the nuisance
    paths appended to `free`."""
    plant = bench.model
    valve = plant.valve
    period = None if valve.period is None else float(valve.period)
    compared = {c for e in bench.experiments for c in e.channels}
    # Pressure offset: where a run starts at rest at atmospheric pressure, the samples before its valve first opens.
    rest = []
    for (name, kind, e, rec, signal), exp in zip(specs, bench.experiments):
        starts_atm = (kind == "tank_charge" and not exp.start_at_supply and
                      abs(float(exp.initial.get("pressure", p_atm)) - p_atm) < 1.0) or \
                     (kind in MUSCLE_KINDS and name not in bench.unknown_starts)
        if starts_atm and "pressure" in rec.channels:
            rest.append(rec["pressure"][_rest_samples(rec, signal, valve, period)] - p_atm)
    rest = np.concatenate(rest) if rest else np.zeros(0)
    offset = float(np.median(rest)) if rest.size >= 3 else 0.0
    sensors = Sensors(pressure_offset=offset if "pressure_offset" in names else 0.0, position_offset=position_offset,
                      pressure_gain=1.0 if pressure_gain is None else float(pressure_gain))
    if pressure_gain is not None:
        bench.calibrated["pressure_gain"] = float(pressure_gain)
        if pressure_gain_sd is not None:
            bench.calibrated["pressure_gain_sd"] = float(pressure_gain_sd)
            bench.notes.append(f"the pressure sensor's gain: {float(pressure_gain):.6g} ± "
                               f"{float(pressure_gain_sd):.3g} as calibrated, fitted with the recordings (the "
                               "calibration a measurement of it)")
        else:
            bench.notes.append(f"the pressure sensor's gain: {float(pressure_gain):.6g} as calibrated, "
                               + ("its start value" if "pressure_gain" in names else "held"))
    levels = {name: _rest_level_at_stop(rec, plant, bench.noise) for name, kind, _, rec, _ in specs
              if kind in MUSCLE_KINDS}
    stops = [name for name, level in levels.items() if level is not None and abs(level) <= STOP_LEVEL]
    for name, level in levels.items():
        if level is not None and abs(level) > STOP_LEVEL and "position_offset" not in names:
            bench.notes.append(f"{name}: the payload rests {level * 1e3:+.2f} mm from a stroke limit (as the position "
                               f"sensor reads it): held by friction short of it, or on it with a sensor that reads "
                               f"{level * 1e3:+.2f} mm off; the recordings cannot tell which. The position sensor's "
                               "offset is held; if the payload sits on the stop, free it (--nuisance "
                               "...,position_offset or position_offset=...)")
    if stops and "position_offset" in names:
        bench.notes.append(f"{', '.join(stops)}: the payload rests on a stroke limit of known position: the position "
                           "sensor's offset is fitted")
    elif stops and by_default:  # nuisance=True: free it where the data determine it
        names = names | {"position_offset"}
        bench.notes.append(f"{', '.join(stops)}: the payload rests on a stroke limit of known position, which fixes "
                           "the position sensor's offset: fitted")
    free = []
    group = f"sensors[{DEFAULT_GROUP}]"
    for field, needs in (("pressure_offset", "pressure"), ("pressure_gain", "pressure"),
                         ("position_offset", "position"), ("delay", None)):
        if field in names and (needs is None or needs in compared):
            free.append(f"{group}.{field}")
    runs, gauges = {}, {}
    has_supply = _has_supply(valve)
    for (name, kind, e, rec, _), exp in zip(specs, bench.experiments):
        supply = start = None
        reading = supply_reading(e, f"bench {bench.directory}/meta.json: {name}", p_atm)
        if reading is not None and "pressure" in rec.channels:
            check_supply_reading(reading, unread_pressure(np.asarray(rec["pressure"]), sensors, p_atm),
                                 f"bench {bench.directory}/meta.json: {name}", p_atm)
        if "supply_pressure" in names and has_supply:
            supply = float(valve.supply())
            if exp.start_at_supply and "pressure" in rec.channels:  # a discharge from supply: its first samples
                supply = unread_pressure(float(np.median(rec["pressure"][:5])), sensors, p_atm)
            free.append(run_path(name, "supply_pressure", f"bench {bench.directory}/meta.json"))
            if reading is not None:  # a reference gauge's reading: the start value, and a measurement in the fit
                supply = reading[0]
                gauges[name] = Measurement(free[-1], *reading, name=GAUGE_NAME.format(name))
        if "start" in names and name in bench.unknown_starts:
            estimate, source = start_estimate(rec, sensors, p_atm, plant, START_LEAD)
            start = StartState(**estimate)
            free += [run_path(name, f"start.{k}", f"bench {bench.directory}/meta.json") for k in estimate]
            bench.notes.append(f"{name}: start state fitted (meta.json init unknown), from "
                               + ", ".join(f"{k} {v:.4g}" for k, v in estimate.items()) + f" ({source})")
        if supply is not None or start is not None:
            runs[name] = RunConditions(supply_pressure=supply, start=start)
    bench.model = Rig(plant, sensors={DEFAULT_GROUP: sensors}, runs=runs)
    bench.free = [f"plant.{p}" for p in bench.free] + free
    bench.nuisance = free
    _add_measurements(bench, gauges, pressure_gain, pressure_gain_sd)


def _add_measurements(bench, gauges, pressure_gain, pressure_gain_sd):
    """The measurements of freed nuisances, last among the experiments: the calibrated gain's, the supply gauges'
    (run name → `Measurement`)."""
    gain = f"sensors[{DEFAULT_GROUP}].pressure_gain"
    if pressure_gain_sd is not None and gain in bench.free:
        bench.experiments.append(Measurement(gain, float(pressure_gain), float(pressure_gain_sd),
                                             name=CALIBRATION_NAME))
    bench.experiments += gauges.values()
    if gauges:
        bench.notes.append(f"supply pressures read by a reference gauge (meta.json supply_Pa ± supply_sd_Pa) for "
                           f"{', '.join(gauges)}: each fitted with its reading as a measurement")


CALIBRATION_NAME = "calibration: pressure gain"  # the calibrated gain's `Measurement` among a bench's experiments
GAUGE_NAME = "gauge: {} supply"  # a run's supply reading's `Measurement` (the run's name in the braces)


# A muscle run rests near a stroke limit where its recorded position stays flat within STOP_NEAR of the plant's limit
# for at least STOP_SECONDS: the stop's position is a plant parameter, so the offset of the position sensor shows
# there (elsewhere a shift of the origin is absorbed by the force and volume laws: BENCH_NUISANCES' note). But a
# stick-slip payload can also hang still just short of the stop, held by friction, and the two look the same through
# an offset sensor: the offset is freed only where the rest level is within STOP_LEVEL of the stop — 0.3 mm, above
# the ±0.2 mm of a position sensor calibrated as realistic1's (the unseen rigs of benchmarks/unseen_rigs.py draw
# offsets there); an unseen rig hanging 0.57 mm short of its stop read 0.74 mm from it, and freeing the offset there
# put the payload on the stop and moved F_max by 3.9 % (benchmarks/RESULTS.md, identify). Farther, a note says so.
STOP_NEAR, STOP_SECONDS, STOP_LEVEL = 1e-3, 0.2, 3e-4  # m, s, m


def _rest_level_at_stop(rec, plant, noise):
    """The mean recorded position less the stroke limit [m] where a muscle run's recorded position rests near one (the
    plant's `min_position` / `max_position`): flat (within 3 noise standard deviations + 0.05 mm) within `STOP_NEAR`
    of it for `STOP_SECONDS`; None where it does not."""
    if "position" not in rec.channels or "position" not in noise:
        return None
    x, dt = rec["position"], float(np.median(np.diff(rec.t)))
    for stop in (float(plant.muscle.min_position), float(plant.muscle.max_position)):
        near = np.abs(x - stop) < STOP_NEAR
        if np.count_nonzero(near) * dt >= STOP_SECONDS and np.std(x[near]) < 3 * noise["position"] + 5e-5:
            return float(np.mean(x[near])) - stop
    return None


def _has_supply(valve):
    try:
        valve.supply()
    except PamjaxInputError:
        return False
    return True
