"""The schema of every `pamjax` config, in one place: the tables and keys each command reads, each value's type, unit
and an example. `validate(command, cfg, where)` checks a parsed config against it, whole, before anything is built or
read; every error names its key path (`[fit] max_steps`, `[[experiment]] #2 scales.pressure`, `[sweep]
over.payload_mass`), what is expected and an example.

What needs the model is checked when the model is built, still before any data are read or anything is solved:
parameter paths, shapes and units of `set` and `free` (`config.apply_set`, `ParameterSpace`), the keys of an `initial`
table (`config.check_initial`). How a config is read, step by step: docs/architecture.md ("How a config is read").
"""

import inspect

import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import check_setting
from .kinds import Key, check_keys, check_table, is_number, over_paths

# -- the commands' tables ----------------------------------------------------------------------------------------
PRESETS = ("mas10_system", "mas10_tank_system")
STATE_FIELDS = ("pressure", "position", "velocity")  # a muscle run's start state (a tank's: pressure)
SENSOR_FIELDS = ("pressure_offset", "pressure_gain", "position_offset", "delay")  # pamjax.Sensors
RIG_FREE = SENSOR_FIELDS + ("supply_pressure", "start")  # the nuisances [rig] free may name
RUN_CONDITIONS = ("supply_pressure", "start", "sensors")  # [[experiment]] keys a rig applies ([rig], a bench's)

MODEL = {
    "preset": Key("string", '"mas10_system"', "a function of pamjax.presets", choices=PRESETS),
    "file": Key("string", '"results/fit_example/model.json"', "a model file, relative to the config"),
    "options": Key("options", '{ valve = "averaged" }', "keyword arguments of the preset"),
    "set": Key("set", '{ "friction.coulomb_force" = 20.0 }', "parameter path = value, in SI units"),
}

FIT_TABLES = {"model", "fit", "experiment", "bench", "rig", "measurement"}
FIT = {
    "free": Key("free", '["friction.coulomb_force"]', "parameter paths, or tables { path, transform, bounds, scale }"),
    "max_steps": Key("positive integer", "40"),
    "ftol": Key("positive number", "1e-10"),
    "xtol": Key("positive number", "1e-10"),
    "gtol": Key("positive number", "1e-10"),
    "out": Key("string", '"results/my_fit"'),
    "validation_fraction": Key("number", "0.4", "the last part of every run held out, in [0, 1)"),
}
BENCH = {
    "dir": Key("string", '"../data/my-bench"', "meta.json + one recording per experiment, relative to the config"),
    "rate": Key("positive number", "1000.0", "Hz"),
    "kinds": Key("list of strings", '["tank_charge", "muscle_triangle"]'),
    "fitted_keys": Key("list of strings", '["Cv12", "b12", "Fc"]'),
    "runs": Key("list of strings", '["E4"]', "the experiments to fit, by name (default: every one of kinds)"),
    "substeps": Key("positive integer", "16"),
    "staged": Key("boolean", "false"),
    "nuisance": Key("boolean or list of strings", '["delay", "pressure_offset", "supply_pressure"]',
                    "or true: every nuisance the bench determines"),
    "position_offset": Key("number", "0.0", "m"),
    "pressure_gain": Key("positive number", "1.0", "the pressure sensor's calibrated gain: held"),
    "pressure_gain_sd": Key("positive number", "0.0005", "the calibration's standard uncertainty: the gain is then "
                            "fitted with the calibration as a measurement"),
    "atmosphere": Key("positive number", "101325.0", "Pa abs"),
}
MEASUREMENT = {  # pamjax.Measurement: one parameter's independent measurement with its uncertainty
    "path": Key("string", '"sensors[rig].pressure_gain"', "a parameter path of the fitted model"),
    "value": Key("number", "1.0004", "in the parameter's SI unit"),
    "sd": Key("positive number", "0.0005", "the measurement's standard uncertainty, same unit"),
    "name": Key("string", '"gain calibration"'),
}
RIG = {
    "sensors": Key("sensors", "{ pressure_gain = 1.0 }", "start values of pamjax.Sensors, or one table per group",
                   entry="0.0", fields=SENSOR_FIELDS),
    "free": Key("list of strings", '["pressure_offset", "delay", "supply_pressure"]', choices=RIG_FREE),
}
EXPERIMENT = {
    "name": Key("string", '"triangle"'),
    "file": Key("string", '"triangle_025.csv"', "a CSV or NPZ recording, relative to the config"),
    "signal": Key("signal", '{ kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }'),
    "channels": Key("list of strings", '["pressure", "position"]'),
    "scales": Key("table of positive numbers", "{ pressure = 2e3, position = 1e-4 }",
                  "the channel's noise level, in its SI unit", entry="2e3"),
    "tank_volume": Key("positive number", "5e-5", "m³", setting=True),
    "payload_kg": Key("positive number", "30.0", "kg: this muscle run's payload, where it is not the model's",
                      setting=True),
    "initial": Key("table of numbers", "{ pressure = 101325.0 }", "keyword arguments of the system's initial_state",
                   setting=True, entry="101325.0"),
    "rate": Key("positive number", "100.0", "Hz"),
    "filter_hz": Key("positive number", "20.0", "Hz"),
    "sensors": Key("string", '"rig"', "a [rig] sensors group"),
    "supply_pressure": Key("positive number", "6.5e5", "Pa abs", setting=True),
    "start": Key("table of numbers", "{ pressure = 4e5, position = 0.01, velocity = 0.0 }",
                 "a run logged mid-way", setting=True, entry="4e5", fields=STATE_FIELDS),
    "t_end": Key("positive number", "8.0", "s, within the recording"),
    "max_steps": Key("positive integer", "200000"),
    "rename": Key("table of strings", '{ p = "pressure" }', entry='"pressure"'),
    "units": Key("table of strings", '{ position = "mm" }', entry='"bar abs"'),
    "unit_checks": Key("boolean", "false"),
    "stepping": Key("string", '"grid"', choices=("auto", "adaptive", "pwm", "grid")),
}

SIMULATE_TABLES = {"model", "input", "simulate"}
INPUT = {
    "signal": Key("signal", '{ kind = "Constant", value = 0.5 }'),
    "file": Key("string", '"bench.csv"', "a recording whose command channel drives the model"),
    "rename": Key("table of strings", '{ p = "pressure" }', entry='"pressure"'),
    "units": Key("table of strings", '{ position = "mm" }', entry='"bar abs"'),
    "unit_checks": Key("boolean", "false"),
}
SOLVERS = ("Tsit5", "Rodas5", "Dopri5", "Dopri8")
SIMULATE = {
    "t_end": Key("positive number", "8.0", "s"),
    "t0": Key("number", "0.0", "s"),
    "dt": Key("positive number", "0.01", "s"),
    "initial": Key("table of numbers", "{ pressure = 101325.0 }", "keyword arguments of the system's initial_state",
                   setting=True, entry="101325.0"),
    "tank_volume": Key("positive number", "5e-5", "m³", setting=True),
    # every stepping `pamjax.simulate` takes (its default "auto"), so its advice ("use stepping='grid'") can be followed
    "stepping": Key("string", '"pwm"', choices=("auto", "adaptive", "pwm", "grid")),
    "substeps": Key("positive integer", "16"),
    "grid_step": Key("positive number", "0.001", "s"),
    "solver": Key("string", '"Rodas5"', choices=SOLVERS),
    "rtol": Key("positive number", "1e-6"),
    "atol": Key("positive number", "1e-6"),
    "max_steps": Key("positive integer", "200000"),
}

SWEEP_TABLES = {"kind", "system", "model", "sweep"}
SWEEP_KINDS = ("steady_state", "flow_surface", "frequency_response")
SYSTEM = {  # paper 000's MAS-10 preset (flow_surface: its MHE2 valve alone)
    # the smoothed-edge switching valve or eq. 13 (an exact-edge valve: a [model] file; swept on the PWM grid)
    "valve": Key("string", '"pwm"', "smoothed switching, or eq. 13", choices=("pwm", "averaged")),
    "payload_mass": Key("positive number", "9.6", "kg", setting=True),
    "supply_pressure": Key("positive number", "6.5e5", "Pa abs", setting=True),
}
SYSTEM_KEYS = {  # the [system] keys each kind uses
    "flow_surface": {"supply_pressure"},
    "steady_state": {"valve", "payload_mass"},
    "frequency_response": {"valve", "payload_mass"},
}
SOLVER_KEYS = {"method", "dt", "chunk_size"}  # passed to pamjax.sweep
SWEEP = {
    "commands": Key("axis", "{ start = 0.0, stop = 1.0, num = 101 }", "duty ratios, or a list"),
    "pressures": Key("axis", "{ start = 101325.0, stop = 6.5e5, num = 41 }", "Pa abs, or a list"),
    "frequencies": Key("axis", "{ start = 0.05, stop = 5.0, num = 16, log = true }", "Hz, or a list"),
    "horizon": Key("positive number", "5.0", "s"),
    "window": Key("positive number", "1.0", "s, averaged at the end"),
    "sample_interval": Key("positive number", "0.01", "s"),
    "offset": Key("number", "0.5", "duty"),
    "amplitude": Key("number", "0.2", "duty"),
    "settle_periods": Key("positive integer", "3"),
    "periods": Key("positive integer", "3"),
    "samples_per_period": Key("positive integer", "40"),
    "method": Key("string", '"rk4"'),
    "dt": Key("positive number", "1e-3", "s"),
    "chunk_size": Key("positive integer", "64"),
    "over": Key("over", '{ "payload_mass" = [5.0, 9.6, 15.0] }', "parameter path = values: a grid with the map's axis"),
}
SWEEP_KEYS = {  # the [sweep] keys each kind uses
    "flow_surface": {"commands", "pressures", "over"},
    "steady_state": {"commands", "horizon", "window", "sample_interval", "over"} | SOLVER_KEYS,
    "frequency_response": {"frequencies", "offset", "amplitude", "settle_periods", "periods", "samples_per_period",
                           "over"} | SOLVER_KEYS,
}

DESIGN_TABLES = {"model", "design"}
_PLANNED = ('[{ name = "E3", signal = { kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.08 }, '
            'duration = 25.0 }]')
# free, duration, noise, prior, baseline, prior_runs, baseline_runs, initial, tank_volume, payload_kg, out; the rest:
# design_experiment's arguments
DESIGN = {
    "free": Key("free", '["friction.coulomb_force"]', "parameter paths, as [fit] free"),
    "duration": Key("positive number", "33.0", "s"),
    "noise": Key("table of positive numbers", "{ pressure = 2e3, position = 1e-4 }",
                 "the bench's noise standard deviation per channel, in its SI unit", entry="2e3"),
    "prior": Key("string", '"fit_example.toml"', "a fit config whose experiments are in hand, or a fit's fit.json "
                 "(its covariance: a rig's nuisances counted)"),
    "baseline": Key("string", '"my_current_runs.toml"', "a fit config whose experiments the design must beat"),
    "prior_runs": Key("planned runs", _PLANNED, "runs not recorded yet whose information counts as in hand"),
    "baseline_runs": Key("planned runs", _PLANNED, "runs not recorded yet (your protocol) the design must beat"),
    "initial": Key("duty or file", "0.6", 'a constant duty, or the design CSV to start from: "earlier/design.csv"'),
    "tank_volume": Key("positive number", "5e-5", "m³", setting=True),
    "payload_kg": Key("positive number or auto", "30.0", 'kg, or "auto": half the model\'s pull at zero contraction '
                      "and supply pressure (pamjax.PayloadFromModel.advised)", setting=True),
    "out": Key("string", '"results/design_example"'),
    "channels": Key("list of strings", '["pressure", "position"]'),
    "start": Key("table of numbers", "{ pressure = 101325.0 }", "keyword arguments of the system's initial_state",
                 setting=True, entry="101325.0"),
    "rate": Key("positive number", "1000.0", "Hz"),
    "criterion": Key("string", '"D"', choices=("D", "A")),
    "subset": Key("list of strings", '["friction.coulomb_force"]', "labels of free parameters"),
    "duty_band": Key("pair of numbers", "[0.1, 0.9]", "duty"),
    "duty_margin": Key("number or auto", '"auto"', "duty"),
    "stroke_margin": Key("number", "0.005", "m"),
    "max_pressure": Key("positive number", "6.5e5", "Pa abs"),
    "max_duty_step": Key("positive number", "0.2", "duty per PWM period"),
    "min_force": Key("force or false", "20.0", "N; false for no limit"),
    "parametrisation": Key("string", '"envelope"', choices=("envelope", "periods")),
    "knots": Key("positive integer", "12"),
    "steps": Key("integer", "30"),
    "seed": Key("integer", "0"),
    "baseline_margin": Key("positive number", "1.0"),
    "spread": Key("spread", "0.2", "the plant's relative spread around the model: designed over points drawn from it"),
    "spread_points": Key("positive integer", "4", "design points drawn from the spread beside the model's own"),
    "period": Key("positive number", "0.02", "s, the PWM period of a valve that has none"),
}
# the keyword arguments of pamjax.design_experiment
DESIGN_ARGS = tuple(k for k in DESIGN if k not in ("free", "duration", "noise", "prior", "baseline", "prior_runs",
                                                     "baseline_runs", "initial", "tank_volume", "payload_kg", "out"))


# -- one validation per config -----------------------------------------------------------------------------------
def check_model(table, where="[model]"):
    """A `[model]` table: a preset with options (the preset's keyword arguments, numbers checked for units) or a
    model file, and `set`."""
    import pamjax as pj

    check_table(table, MODEL, where)
    if "file" in table:
        both = sorted({"preset", "options"} & set(table))
        if both:
            raise PamjaxInputError(f"{where}: give either file (a model file) or preset (with options), not both; "
                                   f"remove {both}")
    preset = table.get("preset", "mas10_system")  # one of PRESETS (checked with the table)
    options, parameters = table.get("options", {}), inspect.signature(getattr(pj.presets, preset)).parameters
    check_keys(options, parameters, f"{where} options (keyword arguments of presets.{preset})")
    for key, value in options.items():
        default = parameters[key].default  # a number: the option is one (was: refused by the preset, key unnamed)
        if is_number(default) and not (is_number(value) and np.isfinite(value)):
            raise PamjaxInputError(f"{where} options {key} must be a number [SI], e.g. {key} = {default!r}; got "
                                   f"{value!r}" + (" (a number in quotes: remove them)" if isinstance(value, str)
                                                   else ""))
        if is_number(value):
            check_setting(key, value, f"{where} options")


def validate_fit(cfg, where="config"):
    """A `pamjax fit` config: [model], [fit], [[experiment]] tables, a [bench] directory, a [rig]."""
    check_keys(cfg, FIT_TABLES, where)
    check_model(cfg.get("model", {}))
    fit = cfg.get("fit", {})
    for old, new in (("rtol", "ftol"), ("atol", "xtol")):
        if isinstance(fit, dict) and old in fit:
            raise PamjaxInputError(f"[fit] {old} is no longer a setting: the fit stops on the relative cost decrease "
                                   f"({new} and its siblings ftol, xtol, gtol; docs/fitting.md)")
    check_table(fit, FIT, "[fit]")
    bench = cfg.get("bench")
    if bench is not None:
        check_table(bench, BENCH, "[bench]", required={"dir": "[bench] needs 'dir': a bench directory (meta.json + "
                                                              "<experiment>.npz), relative to the config"})
    if "rig" in cfg:
        check_keys(cfg["rig"], RIG, "[rig]")
        if bench is not None:
            raise PamjaxInputError("[rig] describes the nuisances of [[experiment]] tables; a [bench] directory "
                                   "takes them as [bench] nuisance = true (or a list)")
        check_table(cfg["rig"], RIG, "[rig]")
    if "free" not in fit and bench is None:
        raise PamjaxInputError("[fit] needs 'free': the list of parameter paths to fit")
    if not 0 <= fit.get("validation_fraction", 0.0) < 1:
        raise PamjaxInputError(f"[fit] validation_fraction must be in [0, 1), got {fit['validation_fraction']}")
    measurements = cfg.get("measurement", [])
    if not isinstance(measurements, list):
        raise PamjaxInputError("measurements are an array of tables: write [[measurement]] (double brackets)")
    for k, table in enumerate(measurements):
        here = f"[[measurement]] #{k + 1}"
        check_table(table, MEASUREMENT, here, required={
            key: f"{here} needs '{key}' ({MEASUREMENT[key].shown})"
            for key in ("path", "value", "sd")})
    experiments = cfg.get("experiment", [])
    if not isinstance(experiments, list):
        raise PamjaxInputError("experiments are an array of tables: write [[experiment]] (double brackets)")
    if not experiments and bench is None:
        raise PamjaxInputError("the config needs at least one [[experiment]] (or a [bench] directory)")
    for k, table in enumerate(experiments):
        here = f"[[experiment]] #{k + 1}"
        check_table(table, EXPERIMENT, here, required={
            "file": f"{here} needs 'file' (a CSV or NPZ recording, relative to the config)"})
        one_build(table, here)
        conditions = [key for key in RUN_CONDITIONS if key in table and not (key == "sensors" and bench is not None)]
        if conditions and "rig" not in cfg:  # without a rig they would change nothing: refused, not ignored
            raise PamjaxInputError(
                f"{here} {conditions[0]} is a run condition of a rig, which only a [rig] table applies: "
                + ("a [bench] directory takes its runs' conditions from its meta.json; remove it" if bench is not None
                   else "add a [rig] table (its sensors and the nuisances to fit; it may be empty)"))


def one_build(table, where):
    """`tank_volume` (a tank test of the model's valve) and `payload_kg` (a muscle run's payload) exclude each other."""
    if "tank_volume" in table and "payload_kg" in table:
        raise PamjaxInputError(f"{where}: give tank_volume (a tank test of the model's valve) or payload_kg (the "
                               "payload of a muscle run), not both")


def validate_simulate(cfg, where="simulate config"):
    """A `pamjax simulate` config: [model], [input] (a signal or a recording), [simulate]."""
    check_keys(cfg, SIMULATE_TABLES, where)
    check_model(cfg.get("model", {}))
    inp, sim = cfg.get("input", {}), cfg.get("simulate", {})
    check_table(inp, INPUT, "[input]")
    check_table(sim, SIMULATE, "[simulate]")
    if "signal" not in inp and "file" not in inp:
        raise PamjaxInputError("[input] needs a signal (e.g. signal = { kind = \"Constant\", value = 0.5 }) or a "
                               "file (a recording whose command channel drives the model)")
    signal = inp.get("signal", "recorded")
    if (signal == "recorded" or (isinstance(signal, dict) and signal.get("kind") == "recorded")) and "file" not in inp:
        raise PamjaxInputError("[input] signal 'recorded' needs file = a recording with a command channel")
    if "file" not in inp and "t_end" not in sim:
        raise PamjaxInputError("[simulate] needs t_end (s) when no recording gives the times")


def validate_sweep(cfg, where="sweep config"):
    """A `pamjax sweep` config: `kind`, then [system] (paper 000's preset) or [model] (any model), and [sweep], each
    with the keys that kind uses."""
    check_keys(cfg, SWEEP_TABLES, where)
    kind = cfg.get("kind")
    if kind not in SWEEP_KINDS:
        raise PamjaxInputError(f"kind must be one of {list(SWEEP_KINDS)}, got {kind!r}")
    if "model" in cfg and "system" in cfg:
        raise PamjaxInputError("give either [system] (paper 000's preset) or [model] (any model), not both")
    if "model" in cfg:
        check_model(cfg["model"])
    sweep = cfg.get("sweep")
    if isinstance(sweep, dict) and isinstance(sweep.get("over"), dict):
        sweep["over"] = over_paths(sweep["over"])  # unquoted dotted keys as parameter paths (TOML nests them)
    check_table(cfg.get("system", {}), SYSTEM, "[system]", valid=SYSTEM_KEYS[kind],
                valid_label=f"[system] (kind = {kind!r})")
    check_table(cfg.get("sweep", {}), SWEEP, "[sweep]", valid=SWEEP_KEYS[kind],
                valid_label=f"[sweep] (kind = {kind!r})")


def validate_design(cfg, where="config"):
    """A `pamjax design` config: [model] and [design] (`free`, `duration`, `noise` and the keyword arguments of
    `pamjax.design_experiment`; the limits are checked against the run's start once the model is built:
    `check_design`)."""
    check_keys(cfg, DESIGN_TABLES, where)
    if "design" not in cfg:
        raise PamjaxInputError(f"{where} needs a [design] table (free, duration, noise, ...)")
    check_table(cfg["design"], DESIGN, "[design]", required={k: f"[design] needs '{k}'"
                                                             for k in ("free", "duration", "noise")})
    one_build(cfg["design"], "[design]")
    check_model(cfg.get("model", {}))


_VALIDATORS = {"fit": validate_fit, "simulate": validate_simulate, "sweep": validate_sweep, "design": validate_design}
TABLES = {  # command → table ("": the top level) → its keys (for `describe` and the docs)
    "fit": {"[model]": MODEL, "[fit]": FIT, "[[experiment]]": EXPERIMENT, "[bench]": BENCH, "[rig]": RIG},
    "simulate": {"[model]": MODEL, "[input]": INPUT, "[simulate]": SIMULATE},
    "sweep": {"": {"kind": Key("string", '"steady_state"', choices=SWEEP_KINDS)}, "[model]": MODEL,
              "[system]": SYSTEM, "[sweep]": SWEEP},
    "design": {"[model]": MODEL, "[design]": DESIGN},
}


def validate(command, cfg, where=None):
    """Check a parsed config of `command` ("fit", "simulate", "sweep", "design") against the schema, whole: every
    table, key, value type, choice and unit, nothing built or read; `where` names the config (its file) in errors
    about its top level."""
    validator = _VALIDATORS[command]
    return validator(cfg) if where is None else validator(cfg, where)


def describe(command):
    """The keys of `command`'s config, one line each: table, key, kind, example and unit."""
    lines = []
    for table, keys in TABLES[command].items():
        for name, key in keys.items():
            choices = f" (one of {', '.join(key.choices)})" if key.choices and key.kind == "string" else ""
            lines.append(f"{table} {name}: {key.kind}{choices}, e.g. {key.shown}".lstrip())
    return "\n".join(lines)
