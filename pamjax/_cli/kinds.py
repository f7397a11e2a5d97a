"""The kinds of value a `pamjax` config key takes, and their checks: `Key` (a key's kind, example, unit, choices),
`check_table` and `check_value`, and the structured kinds (a signal, the free parameters, a sweep's axis, a table of
numbers, ...). `schema.py` declares which key of which table is of which kind; every error names the key's path.
"""

import dataclasses
from typing import NamedTuple

import numpy as np

from .._control.controllers import MAX_PERIOD
from .._core.errors import PamjaxInputError
from .._core.units import check_absolute_pressure, check_setting
from .._fit.parameters import FREE_ENTRY_KEYS

SIGNALS = ("Constant", "Triangle", "Sine", "Step", "recorded")
RECORDED_KEYS = {"kind", "period"}  # signal = { kind = "recorded", period = 0.02 }: the command channel, latched
PERIOD_HINT = "write the period in seconds: 0.02 for 20 ms (paper 000's 50 Hz PWM)"
AXIS_KEYS = {"start", "stop", "num", "log"}  # a [sweep] axis as a table


class Key(NamedTuple):
    """One key of a table: its kind (a name of `KINDS`), an example (a TOML value), the value's unit or meaning (shown
    after the example), whether it is a physical setting checked for units by its magnitude (`check_setting`: bar
    for Pa, mm for m, cm³ for m³, ...), the values it may take, and for a table of values the example of one entry and
    the entry names it allows."""

    kind: str
    example: str = ""
    unit: str = ""
    setting: bool = False
    choices: tuple = ()
    entry: str = ""
    fields: tuple = ()

    @property
    def shown(self):
        """The example as errors show it: with its unit or meaning."""
        return f"{self.example} ({self.unit})" if self.unit else self.example

    @property
    def entry_shown(self):
        """The example of one entry of a table of values, with its unit or meaning."""
        return f"{self.entry} ({self.unit})" if self.unit else self.entry


def check_keys(table, valid, where):
    """`table` must be a TOML table whose keys are all in `valid`; else a `PamjaxInputError` naming `where`, the
    unknown keys and the valid ones."""
    if not isinstance(table, dict):
        raise PamjaxInputError(f"{where} must be a table (keys {sorted(valid)}), got {table!r}")
    unknown = set(table) - set(valid)
    if unknown:
        raise PamjaxInputError(f"{where}: unknown key(s) {sorted(unknown)}; valid keys are {sorted(valid)}")


def is_number(value):
    """A TOML integer or float (not a boolean)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def require(value, kind, where, example):
    """`value` must be of `kind` ("number", "positive number", "integer", "positive integer", "string", "list of
    strings", "table", "boolean"); else a `PamjaxInputError` naming `where`, the kind and an example."""
    number = is_number(value) and np.isfinite(value)
    ok = {
        "number": number,
        "positive number": number and value > 0,
        "integer": isinstance(value, int) and not isinstance(value, bool),
        "positive integer": isinstance(value, int) and not isinstance(value, bool) and value > 0,
        "string": isinstance(value, str),
        "list of strings": isinstance(value, list) and bool(value) and all(isinstance(v, str) for v in value),
        "table": isinstance(value, dict),
        "boolean": isinstance(value, bool),
    }[kind]
    if not ok:
        hint = " (a single string where a list is expected: put it in brackets)" if (
            kind.startswith("list") and isinstance(value, str)) else ""
        raise PamjaxInputError(f"{where} must be a {kind}, e.g. {example}; got {value!r}{hint}")
    return value


def check_table(table, keys, label, *, valid=None, valid_label=None, required=None):
    """The keys of `table` (those of `keys`, or `valid`), its `required` ones (name → message) and every value (see
    `check_value`); `label` names the table in errors (`valid_label` in the unknown-key error)."""
    check_keys(table, keys if valid is None else valid, valid_label or label)
    for name, message in (required or {}).items():
        if name not in table:
            raise PamjaxInputError(message)
    for name, value in table.items():
        check_value(value, keys[name], f"{label} {name}", label, name)


def check_value(value, key, where, table, name):
    """One value against its `Key`: kind, choices, and for a physical setting its units (`check_setting` under the
    name `name`, in `table`)."""
    kind = key.kind
    if kind in _CHECKS:
        _CHECKS[kind](value, key, where, table, name)
    else:
        require(value, kind, where, key.shown)
    if key.choices and kind == "string" and value not in key.choices:
        raise PamjaxInputError(f"{where} must be one of {list(key.choices)}, got {value!r}")
    if key.choices and kind == "list of strings":
        unknown = [v for v in value if v not in key.choices]
        if unknown:
            raise PamjaxInputError(f"{where} names {unknown}, not one of {list(key.choices)}")
    if key.setting and is_number(value):
        check_setting(name, value, table)


def _table_of(kind):
    def check(value, key, where, table, name):
        require(value, "table", where, key.shown)
        if key.fields:
            check_keys(value, set(key.fields), where)
        for k, v in value.items():
            require(v, kind, f"{where}.{k}", key.entry_shown)
            if key.setting:
                check_setting(k, v, where)

    return check


def _boolean_or_list(value, key, where, table, name):
    if not isinstance(value, bool):
        require(value, "list of strings", where, key.shown)


def _pair(value, key, where, table, name):
    if not (isinstance(value, list) and len(value) == 2 and all(is_number(v) for v in value)):
        raise PamjaxInputError(f"{where} must be [lo, hi] (two numbers), e.g. {key.shown}; got {value!r}")


def _number_or_auto(value, key, where, table, name):
    if value != "auto" and not (is_number(value) and np.isfinite(value)):
        raise PamjaxInputError(f"{where} must be \"auto\" or a number, e.g. 0.025; got {value!r}")


def _positive_or_auto(value, key, where, table, name):
    if value != "auto" and not (is_number(value) and np.isfinite(value) and value > 0):
        raise PamjaxInputError(f"{where} must be \"auto\" or a number > 0, e.g. {key.shown}; got {value!r}")


def _force_or_false(value, key, where, table, name):
    if value is not False and not (is_number(value) and np.isfinite(value)):
        raise PamjaxInputError(f"{where} must be a force [N] (e.g. 20.0) or false for no limit, got {value!r}")


def _spread(value, key, where, table, name):
    """A design's `spread`: one fraction for every free parameter, or a table of them by label (range checked by
    `pamjax.design_experiment`, which knows the labels)."""
    if isinstance(value, dict):
        for k, v in value.items():
            require(v, "number", f"{where}.{k}", "0.2")
    elif not (is_number(value) and np.isfinite(value)):
        raise PamjaxInputError(f"{where} must be a fraction (0.2: every free parameter within ±20 %) or a table of "
                               f'them by label ({{ "muscle.force_law.k1" = 0.2 }}), got {value!r}')


def _duty_or_file(value, key, where, table, name):
    if not (isinstance(value, str) or (is_number(value) and np.isfinite(value))):
        raise PamjaxInputError(f"{where} must be a constant duty or a design CSV path, got {value!r}")


PLANNED_RUN_KEYS = {"name", "signal", "duration", "tank_volume", "payload_kg"}  # a design's prior_runs / baseline_runs


def _planned_runs(value, key, where, table, name):
    """A design's `prior_runs` / `baseline_runs`: a non-empty list of runs not recorded, each a table with `signal` (a
    signal table, not "recorded": there is no recording), `duration` [s], and optionally `name` and what it runs on
    as a fit experiment says it: `tank_volume` [m³] (a tank test of the model's valve) or `payload_kg` [kg]."""
    if not isinstance(value, list) or not value:
        raise PamjaxInputError(f"{where} must be a non-empty list of runs, e.g. {key.example}, got {value!r}")
    for k, run in enumerate(value):
        at = f"{where}[{k}]"
        check_keys(run, PLANNED_RUN_KEYS, at)
        for needed in ("signal", "duration"):
            if needed not in run:
                raise PamjaxInputError(f"{at} needs '{needed}' (e.g. {key.example})")
        if run["signal"] == "recorded" or (isinstance(run["signal"], dict) and run["signal"].get("kind") == "recorded"):
            raise PamjaxInputError(f"{at} signal: a planned run has no recording to read a command from; give a "
                                   "signal table (kind = \"Triangle\", ...), or a fit config as prior / baseline")
        check_signal(run["signal"], key, f"{at} signal")
        require(run["duration"], "positive number", f"{at} duration", "25.0 (s)")
        if "name" in run:
            require(run["name"], "string", f"{at} name", '"E3"')
        for field, unit in (("tank_volume", "5e-5 (m³)"), ("payload_kg", "30.0 (kg)")):
            if field in run:
                require(run[field], "positive number", f"{at} {field}", unit)
                check_setting(field, run[field], at)
        if "tank_volume" in run and "payload_kg" in run:
            raise PamjaxInputError(f"{at}: tank_volume (a tank test) or payload_kg (a muscle run), not both")


def _options(value, key, where, table, name):
    """`[model] options`: a table checked in `check_model`, which knows the preset."""
    require(value, "table", where, key.shown)


def _set(value, key, where, table, name):
    if not isinstance(value, dict):
        raise PamjaxInputError(f"{where} must be a table of parameter path = value, got {value!r}")


def _sensors(value, key, where, table, name):
    """`[rig] sensors`: start values of `pamjax.Sensors` (`{ pressure_gain = 1.0 }`), or one such table per sensor
    group (`{ left = {...}, right = {...} }`, which [[experiment]] sensors name)."""
    if not isinstance(value, dict):
        raise PamjaxInputError(f"{where} must be a table of start values, got {value!r}")
    for group, values in sensor_groups(value).items():
        check_keys(values, set(key.fields), where + ("" if group == "rig" else f".{group}"))
        for k, v in values.items():
            require(v, "number", f"{where}.{k}", key.entry)


def sensor_groups(sensors):
    """group → start values of a `[rig] sensors` table (one group, "rig", when it holds values directly)."""
    return sensors if sensors and all(isinstance(v, dict) for v in sensors.values()) else {"rig": sensors}


def check_signal(spec, key, where, table=None, name=None):
    """A signal: "recorded" (the recording's command channel), or a table with `kind` (a pamjax signal class) and
    that class's fields, numbers each, or `{ kind = "recorded", period = 0.02 }` (latched per PWM period [s], at most
    `MAX_PERIOD`, a controller's longest: 20.0 is 20 ms written as seconds; against the recording:
    `check_recorded_period`)."""
    import pamjax as pj

    if spec == "recorded":
        return
    if not isinstance(spec, dict) or spec.get("kind") not in SIGNALS:
        raise PamjaxInputError(f"{where} must be 'recorded' or a table with kind in {list(SIGNALS)}, got {spec!r}")
    if spec["kind"] == "recorded":
        check_keys(spec, RECORDED_KEYS, f"{where} (kind = 'recorded')")
        if "period" in spec:
            require(spec["period"], "positive number", f"{where} period", "0.02 (s)")
            if spec["period"] > MAX_PERIOD:  # 20.0 for 20 ms held the first sample's duty all run, silently
                raise PamjaxInputError(f"{where} period = {spec['period']:g} s is longer than {MAX_PERIOD:g} s, no "
                                       "PWM valve's (pneumatic PWM runs at 10-500 Hz): the latched command would hold "
                                       f"one duty over the whole motion; {PERIOD_HINT}")
        return
    fields = dataclasses.fields(getattr(pj, spec["kind"]))
    check_keys(spec, {"kind"} | {f.name for f in fields}, f"{where} (kind = {spec['kind']!r})")
    for k, v in spec.items():
        if k != "kind":
            require(v, "number", f"{where} {k}", "0.5")
    missing = [f.name for f in fields if f.name not in spec and f.init and f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING]
    if missing:
        raise PamjaxInputError(f"{where} (kind = {spec['kind']!r}) needs {missing}")


def check_recorded_period(period, times, where):
    """A recorded command's latch `period` [s] against the recording's `times` [s]: a period as long as the recording
    latches one sample (or two) for the whole run, a constant command: a unit slip (ms), refused naming `where`."""
    span = float(times[-1] - times[0])
    if period >= span:
        raise PamjaxInputError(f"{where} = {period:g} s is not shorter than the recording ({span:g} s): the latched "
                               f"command would hold its first sample all run; {PERIOD_HINT}")


def check_free(free, key, where, table=None, name=None):
    """`free`: a non-empty list of parameter paths, or tables { path, transform, bounds, scale } (as `pamjax.fit`
    takes them; the paths are checked against the model when it is built)."""
    if isinstance(free, str) or not isinstance(free, list):
        raise PamjaxInputError(f"{where} must be a non-empty list of parameter paths, got {free!r}"
                               + (" (a single string where a list is expected: put it in brackets)"
                                  if isinstance(free, str) else ""))
    if not free:
        raise PamjaxInputError(f"{where} must be a non-empty list of parameter paths, e.g. "
                               '["friction.coulomb_force"]')
    for entry in free:
        if isinstance(entry, str):
            continue
        check_keys(entry, FREE_ENTRY_KEYS, f"{where} entry")
        if "path" not in entry:
            raise PamjaxInputError(f"{where} entry {entry!r} needs a path")
        if "bounds" in entry:
            b = entry["bounds"]
            if not (isinstance(b, list) and len(b) == 2 and all(is_number(x) for x in b)):
                raise PamjaxInputError(f"{where} entry {entry['path']!r}: bounds must be [lo, hi] (two numbers), "
                                       f"got {b!r}")


def axis(spec, name):
    """The values of a `[sweep]` axis: a non-empty list of numbers, or `{ start, stop, num[, log] }`; absolute
    pressures for `pressures`, positive frequencies for `frequencies` (`commands` are checked against the model's
    command range by `commands`, once the model is built)."""
    if isinstance(spec, list) and spec and all(is_number(v) for v in spec):
        values = np.asarray(spec, dtype=float)
    elif isinstance(spec, dict) and {"start", "stop", "num"} <= set(spec):
        check_keys(spec, AXIS_KEYS, f"[sweep] {name}")
        start, stop = _number(spec["start"], f"[sweep] {name} start"), _number(spec["stop"], f"[sweep] {name} stop")
        if not (isinstance(spec["num"], int) and not isinstance(spec["num"], bool) and spec["num"] >= 1):
            raise PamjaxInputError(f"[sweep] {name} num must be a positive integer, got {spec['num']!r}")
        log = spec.get("log", False)
        if not isinstance(log, bool):
            raise PamjaxInputError(f"[sweep] {name} log must be true or false, got {log!r}")
        if log and not (start > 0 and stop > 0):
            raise PamjaxInputError(f"[sweep] {name}: a log axis needs start and stop > 0, got {start}, {stop}")
        values = (np.geomspace if log else np.linspace)(start, stop, spec["num"])
    else:
        raise PamjaxInputError(f"[sweep] {name} must be a non-empty list of numbers or a table "
                               f"{{start, stop, num[, log]}}, got {spec!r}"
                               + (" (a single string where a list is expected)" if isinstance(spec, str) else ""))
    if not np.all(np.isfinite(values)):
        raise PamjaxInputError(f"[sweep] {name} must be finite numbers, got {spec!r}")
    if name == "pressures":
        check_absolute_pressure(values, "[sweep] pressures")
    if name == "frequencies" and not np.all(values > 0):
        raise PamjaxInputError(f"[sweep] frequencies must be > 0 [Hz], got {values.min():g}")
    return values


class Command(NamedTuple):
    """A model's command as a sweep writes and draws it: the CSV column, the axis label, the unit of a gain per
    command, and whether the valve's dead bands (duty < 0.1, > 0.9: paper 000, Sect. 2) are shaded."""

    column: str
    label: str
    unit: str
    dead_bands: bool


DUTY = Command("duty", "duty ratio u [-]", "unit duty", True)
VOLTAGE = Command("command_v", "reference voltage [V]", "V", False)


def command_bounds(model):
    """The model's command range as two floats: [0, 1] for a valve's duty ratio, 0-10 V for a regulator's reference
    (paper 001, Sect. 2)."""
    lo, hi = model.command_range
    return float(np.min(lo)), float(np.max(hi))


def command_of(model):
    """`DUTY` for a valve's model, `VOLTAGE` for a regulator's."""
    return DUTY if command_bounds(model) == (0.0, 1.0) else VOLTAGE


def commands(sw, model, num):
    """A `[sweep]` map's commands: `commands` if given, else `num` points over the model's command range; refused,
    naming the range, where any lies outside it."""
    lo, hi = command_bounds(model)
    values = axis(sw.get("commands", {"start": lo, "stop": hi, "num": num}), "commands")
    if not np.all((values >= lo) & (values <= hi)):
        duty = command_of(model) is DUTY
        hint = " (these look like percent: divide by 100)" if duty and np.all((values >= 0) & (values <= 100)) else ""
        what = "duty ratios" if duty else f"reference voltages of the model's {type(model).__name__} [V]"
        raise PamjaxInputError(f"[sweep] commands are {what} in [{lo:g}, {hi:g}], got {values.min():g} … "
                               f"{values.max():g}{hint}")
    return values


def _number(value, where):
    if not (is_number(value) and np.isfinite(value)):
        raise PamjaxInputError(f"{where} must be a number, got {value!r}")
    return float(value)


def _axis(value, key, where, table, name):
    axis(value, name)


def over_paths(over, prefix=""):
    """`[sweep] over` (parameter path → axis) with nested tables flattened into dotted paths, as `[model] set`'s: TOML
    reads an unquoted dotted key, `friction.coulomb_force = [10.0, 20.0]`, as a table `friction` holding
    `coulomb_force` (was: "over.friction must be a non-empty list of numbers or a table"). A table with an axis's
    keys (`start`, `stop`, `num`, `log`) is an axis, not a path; a path given both ways is refused."""
    out = {}
    for key, spec in over.items():
        path = f"{prefix}{key}"
        nested = isinstance(spec, dict) and spec and not AXIS_KEYS & set(spec)
        for p, v in (over_paths(spec, f"{path}.") if nested else {path: spec}).items():
            if p in out:
                raise PamjaxInputError(f"[sweep] over: {p!r} is given twice (quoted and as a dotted key): give it once")
            out[p] = v
    return out


def _over(over, key, where, table, name):
    if not isinstance(over, dict):
        raise PamjaxInputError(f"{where} must be a table of parameter path = values, got {over!r}")
    for path, spec in over.items():
        check_setting(path, axis(spec, f"over.{path}"), where)


_CHECKS = {
    "table of numbers": _table_of("number"),
    "table of positive numbers": _table_of("positive number"),
    "table of strings": _table_of("string"),
    "boolean or list of strings": _boolean_or_list,
    "pair of numbers": _pair,
    "number or auto": _number_or_auto,
    "positive number or auto": _positive_or_auto,
    "force or false": _force_or_false,
    "duty or file": _duty_or_file,
    "spread": _spread,
    "options": _options,
    "set": _set,
    "sensors": _sensors,
    "signal": check_signal,
    "planned runs": _planned_runs,
    "free": check_free,
    "axis": _axis,
    "over": _over,
}
KINDS = ("number", "positive number", "integer", "positive integer", "string", "list of strings", "table",
         "boolean", *_CHECKS)
