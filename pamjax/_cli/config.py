"""What the `pamjax` configs share: reading TOML (file and line named on a syntax error), checking keys and value
types, and building the model from a `[model]` table — a preset with options, or a model file, with `set` values
matched to their parameters by name and shape and checked for units.

    [model]
    preset = "mas10_system"                  # or file = "results/fit_example/model.json" (relative to the config)
    options = { valve = "averaged" }         # keyword arguments of the preset
    set = { "friction.coulomb_force" = 20.0, "muscle.force_law.max_force_coefficients" = [630.0, 0, 0, 0, 0] }
"""

import dataclasses
import inspect
import pathlib
import re
import tomllib

import equinox as eqx
import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import check_setting

PRESETS = ("mas10_system", "mas10_tank_system")
MODEL_KEYS = {"preset", "options", "set", "file"}
SIGNALS = ("Constant", "Triangle", "Sine", "Step", "recorded")
RECORDED_KEYS = {"kind", "period"}  # signal = { kind = "recorded", period = 0.02 }: the command channel, latched


def check_keys(table, valid, where):
    """`table` must be a TOML table whose keys are all in `valid`; else a `PamjaxInputError` naming `where`, the
    unknown keys and the valid ones."""
    if not isinstance(table, dict):
        raise PamjaxInputError(f"{where} must be a table (keys {sorted(valid)}), got {table!r}")
    unknown = set(table) - set(valid)
    if unknown:
        raise PamjaxInputError(f"{where}: unknown key(s) {sorted(unknown)}; valid keys are {sorted(valid)}")


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


def require(value, kind, where, example):
    """`value` must be of `kind` ("number", "positive number", "integer", "string", "list of strings", "table",
    "boolean"); else a `PamjaxInputError` naming `where`, the kind and an example."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    ok = {
        "number": number,
        "positive number": number and value > 0 and np.isfinite(value),
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


# -- the model --------------------------------------------------------------------------------------------------
def validate_model_table(model_cfg, where="[model]"):
    """Keys and types of a `[model]` table (nothing built)."""
    import pamjax as pj

    check_keys(model_cfg, MODEL_KEYS, where)
    if "file" in model_cfg:
        require(model_cfg["file"], "string", f"{where} file", '"results/fit_example/model.json"')
        both = sorted({"preset", "options"} & set(model_cfg))
        if both:
            raise PamjaxInputError(f"{where}: give either file (a model file) or preset (with options), not both; "
                                   f"remove {both}")
    preset = model_cfg.get("preset", "mas10_system")
    if preset not in PRESETS:
        raise PamjaxInputError(f"{where} preset must be one of {list(PRESETS)}, got {preset!r}")
    options = model_cfg.get("options", {})
    check_keys(options, inspect.signature(getattr(pj.presets, preset)).parameters,
               f"{where} options (keyword arguments of presets.{preset})")
    for key, value in options.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            check_setting(key, value, f"{where} options")
    if not isinstance(model_cfg.get("set", {}), dict):
        raise PamjaxInputError(f"{where} set must be a table of parameter path = value, got {model_cfg['set']!r}")


def build_model(model_cfg, root, where="[model]"):
    """The model a `[model]` table describes (`root`: the config's folder, for a relative `file`)."""
    import pamjax as pj

    from .._fit.model_io import load_model

    validate_model_table(model_cfg, where)
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
    from .._fit.model_io import checked
    from .._fit.parameters import _parse, join_path, parameter_paths

    if not values:
        return model
    valid = parameter_paths(model)
    for key, value in values.items():
        attrs, index = _parse(key)
        leaf = join_path(attrs)
        if leaf not in valid:
            listing = "\n  ".join(f"{p} {list(s) if s else ''}".rstrip() for p, s in sorted(valid.items()))
            raise PamjaxInputError(f"{where}: unknown parameter {key!r}; the model's parameters are:\n  {listing}")
        shape = valid[leaf]
        if index is not None:
            if len(index) != len(shape) or any(not 0 <= i < n for i, n in zip(index, shape)):
                raise PamjaxInputError(f"{where}: index {list(index)} of {key!r} is out of range for shape {shape}")
            shape = ()
        new = _array(value, f"{where}: {key!r}")
        if new.shape != shape:
            expected = "one number" if shape == () else f"shape {shape}"
            raise PamjaxInputError(f"{where}: {key!r} expects {expected}, got shape {new.shape} ({value!r}); each "
                                   "entry sets one parameter (index an element as 'path[i]')")
        check_setting(leaf, new, where)
        model = _set_leaf(model, attrs, index, new)
    return checked(model, where)


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
    import jax.numpy as jnp

    def get(m):
        for a in attrs:
            m = getattr(m, a)
        return m

    old = jnp.asarray(get(model))
    new = jnp.asarray(value, dtype=old.dtype) if index is None else old.at[index].set(float(value))
    if index is None and new.ndim == 0:
        new = jnp.asarray(float(value))  # a scalar as a component's converter makes it from a number
    return eqx.tree_at(get, model, new)


# -- signals ----------------------------------------------------------------------------------------------------
def signal_keys(spec, where):
    """The valid keys of a signal table: `kind` plus the fields of the named pamjax signal class (None for
    "recorded")."""
    import pamjax as pj

    if spec == "recorded":
        return None
    if not isinstance(spec, dict) or spec.get("kind") not in SIGNALS:
        raise PamjaxInputError(f"{where} signal must be 'recorded' or a table with kind in {list(SIGNALS)}, "
                               f"got {spec!r}")
    if spec["kind"] == "recorded":
        return RECORDED_KEYS
    return {"kind"} | {f.name for f in dataclasses.fields(getattr(pj, spec["kind"]))}


def make_signal(spec, where, recording=None):
    """The pamjax signal a table describes (`recording`'s `command` channel for "recorded")."""
    import pamjax as pj

    valid = signal_keys(spec, where)
    if valid is None or spec["kind"] == "recorded":
        if recording is None:
            raise PamjaxInputError(f"{where} signal 'recorded' needs a recording with a command channel")
        period = spec.get("period") if isinstance(spec, dict) else None
        if period is not None:
            require(period, "positive number", f"{where} signal period", "0.02 (s)")
        return pj.Sampled(recording.t, recording["command"], period=period)
    check_keys(spec, valid, f"{where} signal (kind = {spec['kind']!r})")
    kwargs = {k: v for k, v in spec.items() if k != "kind"}
    for k, v in kwargs.items():
        require(v, "number", f"{where} signal {k}", "0.5")
    try:
        return getattr(pj, spec["kind"])(**kwargs)
    except TypeError as err:
        raise PamjaxInputError(f"{where} signal: {err}") from err
