"""Reading a `pamjax` config and building what the commands share. Every command's `load` runs the same straight
path (docs/architecture.md, "How a config is read"):

1. `read_toml(path)`: the file parsed (a syntax error names the file, line and column and shows the line);
2. `schema.validate(command, cfg, where)`: the whole config against the schema, nothing built or read;
3. `build_model(cfg["model"], root)`: a preset with options, or a model file, with `set` values matched to their
   parameters by name and shape and checked for units;
4. the command's own builder (experiments, the run's inputs, the sweep, the design), which checks what needs the
   model (parameter paths, `initial` keys: `check_initial`) before any data are read (`load_recording`);
5. the command runs.

    [model]
    preset = "mas10_system"                  # or file = "results/fit_example/model.json" (relative to the config)
    options = { valve = "averaged" }         # keyword arguments of the preset
    set = { "friction.coulomb_force" = 20.0, "muscle.force_law.max_force_coefficients" = [630.0, 0, 0, 0, 0] }
"""

import inspect
import pathlib
import re
import tomllib

import equinox as eqx
import jax
import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import check_setting
from .kinds import check_keys, check_recorded_period, command_bounds


def read_toml(path):
    """Parse a TOML config; a missing file or a syntax error is a `PamjaxInputError` naming the file, the line and
    the line's text."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise PamjaxInputError(f"config file {path} does not exist" + (" (it is a folder)" if path.is_dir() else ""))
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as err:
        raise PamjaxInputError(f"config file {path} is not UTF-8 text: {err}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(err))
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(err))
        if m is None:
            raise PamjaxInputError(f"config file {path} is not valid TOML: {message}") from None
        line, column = int(m.group(1)), int(m.group(2))
        lines = text.splitlines()
        shown = f"\n    {lines[line - 1]}\n    {' ' * (column - 1)}^" if 0 < line <= len(lines) else ""
        raise PamjaxInputError(f"{path}, line {line}, column {column}: not valid TOML: {message}{shown}") from None


# -- the model --------------------------------------------------------------------------------------------------
def build_model(model_cfg, root, where="[model]"):
    """The model a validated `[model]` table describes (`root`: the config's folder, for a relative `file`)."""
    import pamjax as pj

    from .._files.model_file import load_model

    if "file" in model_cfg:
        model = load_model(pathlib.Path(root) / model_cfg["file"])
    else:
        preset = model_cfg.get("preset", "mas10_system")
        model = getattr(pj.presets, preset)(**model_cfg.get("options", {}))
    return apply_set(model, model_cfg.get("set", {}), f"{where} set")


def apply_set(model, values, where):
    """`model` with each `path = value` of `values` set. Every entry is matched to its parameter by name and shape
    (a list where one number is expected, or a list of the wrong length, is an error naming the key, the expected
    and the given shape, never spread over the next parameters), checked for units, and the result is rebuilt
    through the components' constructors, so a value they refuse is named as if typed in Python."""
    from .._files.model_file import checked

    if not values:
        return model
    for key, value in flat_paths(values, where).items():
        leaf, steps, index, shape = parameter_shape(model, key, where)
        new = _array(value, f"{where}: {key!r}")
        if new.shape != shape:
            expected = "one number" if shape == () else f"shape {shape}"
            raise PamjaxInputError(f"{where}: {key!r} expects {expected}, got shape {new.shape} ({value!r}); each "
                                   "entry sets one parameter (index an element as 'path[i]')")
        check_setting(leaf, new, where)
        model = _set_leaf(model, steps, index, new)
    # every value has its parameter's shape (above), and the model before (a preset, or a model file, checked when
    # loaded) has no batched parameter: nor has the result, which skips that check's shape inference
    return checked(model, where, batched=False)


def flat_paths(values, where, prefix=""):
    """`values` (parameter path → value) with nested tables flattened into dotted paths: TOML reads an unquoted dotted
    key, `friction.coulomb_force = 20.0`, as a table `friction` holding `coulomb_force`, which means the parameter
    "friction.coulomb_force" (was: "unknown parameter 'friction'"). A path given both ways is refused."""
    out = {}
    for key, value in values.items():
        path = f"{prefix}{key}"
        for p, v in (flat_paths(value, where, f"{path}.") if isinstance(value, dict) else {path: value}).items():
            if p in out:
                raise PamjaxInputError(f"{where}: {p!r} is given twice (quoted and as a dotted key): give it once")
            out[p] = v
    return out


def parameter_shape(model, path, where):
    """(leaf, steps, index, shape) of parameter `path` of `model`: the leaf's path and steps (`split_path`), the
    element index (None for the whole leaf) and the shape a value for it has (() for one element); an unknown path
    lists the model's parameters, an index out of range names the leaf's shape."""
    from .._fit.parameters import join_path, parameter_paths, split_path

    valid = parameter_paths(model)
    steps, index = split_path(path)
    leaf = join_path(steps)
    if leaf not in valid:
        listing = "\n  ".join(f"{p} {list(s) if s else ''}".rstrip() for p, s in sorted(valid.items()))
        raise PamjaxInputError(f"{where}: unknown parameter {path!r}; the model's parameters are:\n  {listing}")
    shape = valid[leaf]
    if index is not None:
        if len(index) != len(shape) or any(not 0 <= i < n for i, n in zip(index, shape)):
            raise PamjaxInputError(f"{where}: index {list(index)} of {path!r} is out of range for shape {shape}")
        shape = ()
    return leaf, steps, index, shape


def _array(value, where):
    def flat(v):
        return [x for item in v for x in flat(item)] if isinstance(v, list) else [v]

    if isinstance(value, bool) or any(isinstance(v, (bool, str, dict)) for v in flat(value)):
        raise PamjaxInputError(f"{where} must be a number or a list of numbers, got {value!r}")
    try:
        a = np.asarray(value, dtype=float)
    except ValueError:
        raise PamjaxInputError(f"{where}: {value!r} is a ragged list; give one number per element") from None
    if not np.all(np.isfinite(a)):
        raise PamjaxInputError(f"{where} must be finite, got {value!r}")
    return a


def _set_leaf(model, attrs, index, value):
    from .._core.arrays import as_scalar, device_array
    from .._fit.parameters import Key

    def get(m):
        for a in attrs:
            m = m[a] if isinstance(a, Key) else getattr(m, a)
        return m

    old = np.asarray(get(model))  # the arrays made on the host (`jnp.asarray` and `.at[].set` compile programs)
    if index is None and old.ndim == 0:
        new = as_scalar(float(value))  # a scalar as a component's converter makes it from a number
    elif index is None:
        new = device_array(np.asarray(value, dtype=old.dtype))
    else:
        new = old.copy()
        new[index] = float(value)
        new = device_array(new)
    return eqx.tree_at(get, model, new)


def check_initial(system, values, where):
    """The keys of an `initial` (or `start`) table must be arguments of `system.initial_state`."""
    check_keys(values, set(inspect.signature(system.initial_state).parameters),
               f"{where} (keyword arguments of {type(system).__name__}.initial_state)")


# -- inputs -----------------------------------------------------------------------------------------------------
def build_signal(spec, where, recording=None):
    """The pamjax signal a validated signal table describes (`recording`'s `command` channel for "recorded")."""
    import pamjax as pj

    if spec == "recorded" or spec["kind"] == "recorded":
        if recording is None:
            raise PamjaxInputError(f"{where} signal 'recorded' needs a recording with a command channel")
        period = spec.get("period") if isinstance(spec, dict) else None
        if period is not None:
            check_recorded_period(period, recording.t, f"{where} signal period")
        return pj.Sampled(recording.t, recording["command"], period=period)
    return getattr(pj, spec["kind"])(**{k: v for k, v in spec.items() if k != "kind"})


def is_recorded(spec):
    """Whether a validated signal spec is the recording's command column ("recorded", or kind = "recorded")."""
    return spec == "recorded" or spec["kind"] == "recorded"


def experiment_signal(table, where, recording, system):
    """The signal of a validated [[experiment]] table (`build_signal`); a typed one checked against the recording's
    own command column, where it has one (`check_against_command`)."""
    spec = table.get("signal", "recorded")
    signal = build_signal(spec, where, recording)
    if not is_recorded(spec):
        check_against_command(signal, recording, f"{where} ({table.get('name', recording.name)}) signal", system)
    return signal


# A typed signal and the recording's command column differ where the bench ran another command than the config says
# (frequency 2.5 typed for the 0.25 Hz triangle run: up to 0.90 duty apart, fitted without a word, the misfit blamed
# on a delay). What they may differ by: each sample is compared with the signal anywhere within one PWM period (the
# latch: a logger writes the duty of the period begun, or the next) or one sample interval, whichever is longer; then
# by 5 % of the command range (0.05 duty, 0.5 V: far above a logged duty's quantisation, 1/255 = 0.004) at 5 % of the
# samples (a step's edge, a logger's odd sample).
COMMAND_TOLERANCE = 0.05  # of the command range
COMMAND_OUTLIERS = 0.05  # fraction of the samples
HOLD_POINTS = 9  # times the signal is evaluated at across the hold window


# A signal at an array of times as one compiled program per signal type: evaluated op by op (9 shifts of the
# recording's times) it compiled each operation on its own, 0.4-0.5 s of the main job's cold and warm runs.
_signal_at = eqx.filter_jit(lambda signal, times: jax.vmap(signal)(times))


def check_against_command(signal, recording, where, system):
    """Refuse a typed `signal` that contradicts `recording`'s command column (see `COMMAND_TOLERANCE`), naming
    `where`, the largest difference and its time; nothing to compare without a command column or a system with a
    command range."""
    import jax.numpy as jnp

    import pamjax as pj

    if "command" not in recording.channels or not isinstance(system, pj.AbstractSystem):
        return
    t, u = np.asarray(recording.t, dtype=float), np.asarray(recording["command"], dtype=float)
    t, u = t[np.isfinite(u)], u[np.isfinite(u)]
    if t.size < 2:
        return
    period = float(system.valve.period) if system.valve.switches else 0.0
    hold = max(period, float(np.median(np.diff(t))))
    shifted = (t[None, :] + np.linspace(-hold, hold, HOLD_POINTS)[:, None]).ravel()
    values = np.asarray(_signal_at(signal, jnp.asarray(shifted)), dtype=float)
    if values.shape != shifted.shape:
        return  # one command per actuator: a single command column is not comparable
    values = values.reshape(HOLD_POINTS, t.size)
    lo, hi = values.min(axis=0), values.max(axis=0)
    off = np.maximum(lo - u, u - hi)  # > 0: outside every value the signal takes within the hold
    low, high = command_bounds(system)
    tolerance = COMMAND_TOLERANCE * (high - low)
    bad = np.count_nonzero(off > tolerance)
    if bad <= COMMAND_OUTLIERS * t.size:
        return
    k = int(np.argmax(off))
    typed = float(values[HOLD_POINTS // 2, k])  # the shift 0 of the odd count
    raise PamjaxInputError(
        f"{where} contradicts the recording's own command column: they differ by more than {tolerance:g} "
        f"({COMMAND_TOLERANCE:.0%} of the command range [{low:g}, {high:g}], allowing {hold:g} s of latch or lag) at "
        f"{bad} of {t.size} samples ({bad / t.size:.0%}), the largest at t = {t[k]:g} s (signal {typed:.4g}, recorded "
        f"{u[k]:.4g}): the model would be driven by another command than the bench ran. Write signal = \"recorded\" "
        "(the column drives the model), or correct the signal")


def check_end(recording, t_end, where, reason):
    """Refuse a `t_end` [s] past `recording`'s last sample (more than one sample interval beyond it: a log ending at
    7.98 s takes t_end = 8.0) naming `where`, the recording's span and `reason` (what stops at its end); one a
    thousand times too long (8000 for an 8 s log, where 8 s is most of it) is named as milliseconds."""
    t = np.asarray(recording.t, dtype=float)
    slack, end = float(np.median(np.diff(t))), float(t[-1])
    if t_end <= end + slack:
        return
    in_ms = t[0] + 0.1 * (end - t[0]) <= t_end / 1000 <= end + slack
    ms = f"; t_end is in seconds: {t_end / 1000:g} for {t_end:g} ms" if in_ms else ""
    raise PamjaxInputError(f"{where} = {t_end:g} s is past the end of recording {recording.name!r}, which spans "
                           f"{t[0]:g} … {end:g} s ({end - t[0]:g} s): {reason}{ms}")


def check_start(recording, t0, where):
    """Refuse a `t0` [s] before `recording`'s first sample (more than one sample interval before it) where its
    command drives the model: the command before the log would be made up (was: the first sample held back to t0)."""
    t = np.asarray(recording.t, dtype=float)
    if t0 >= t[0] - float(np.median(np.diff(t))):
        return
    raise PamjaxInputError(f"{where} = {t0:g} s is before the start of recording {recording.name!r}, which spans "
                           f"{t[0]:g} … {t[-1]:g} s: its command drives the model and starts there (t0 = {t[0]:g}, or "
                           "remove t0 to start with the recording)")


def window_to(recording, t_end, where):
    """`recording` up to `t_end` [s] (an [[experiment]]'s `t_end`), one past its end refused (`check_end`)."""
    check_end(recording, t_end, where, "the experiment would end there, not at t_end (remove t_end to fit the whole "
              "recording)")
    return recording.window(None, t_end)


def load_recording(table, root):
    """The recording a validated table's `file` names (relative to `root`), with its `rename`, `units` and
    `unit_checks`."""
    import pamjax as pj

    return pj.Recording.load(pathlib.Path(root) / table["file"], rename=table.get("rename"), units=table.get("units"),
                             unit_checks=table.get("unit_checks", True))
