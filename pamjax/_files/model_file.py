"""Model files: a complete pamjax model (every parameter, not only the fitted ones, with units and its structure) as
one readable JSON file, read back exactly. Written by `pamjax fit` (`model.json`), read by `pamjax.load_model`, by
`[model] file = ...` in every config, by `pamjax simulate` and `pamjax sweep`. Format: `docs/cli.md`.

    {"format": "pamjax-model", "format_version": 1, "pamjax_version": ..., "class": "MuscleSystem",
     "parameters": {"payload_mass": {"value": 9.6, "unit": "kg"}, "valve.coefficients": {"value": [[...]], ...}},
     "structure": {"class": "MuscleSystem", "fields": {"payload_mass": {"array": "payload_mass"}, "valve": {...}}},
     "provenance": {...}}

`parameters` lists every array leaf by path (the paths `pamjax.parameter_paths` gives and `fit`'s `free` takes), its
value (a number or nested lists; float64 written with Python's `repr`, which round-trips exactly) and its unit (the
component's own field comment); `dtype` only where it is not float64. `structure` gives the classes and the static
settings (e.g. a valve's `mode`). Classes are looked up among pamjax's own model classes only (and those passed as
`classes=`): loading a model file runs no code from it. Components are rebuilt through their constructors, so a
hand-edited value is checked as if typed in Python.
"""

import dataclasses
import datetime
import functools
import json
import math
import os
import pathlib
import sys
from collections.abc import Sequence

import equinox as eqx
import numpy as np

from .._core.arrays import as_scalar, device_array
from .._core.errors import PamjaxInputError, require_float64
from .._core.fitting import field_units
from .._core.jsonio import plain
from .._core.metadata import version
from .._core.units import ATMOSPHERE, check_setting, parameter_to_si
from .._physics.signals import AbstractSignal
from .._solve.checks import batched_parameters, describe_batched
from .model_checks import (
    DuplicateKey,
    constructor_takes,
    flat,
    from_json_value,
    missing_fields,
    parse_json,
    same_leaves,
    setting_problem,
    unit_hint,
)

FORMAT = "pamjax-model"
FORMAT_VERSION = 1
# A stored dtype other than float64 must hold the value written to float32's precision at least (2⁻²⁴ relative): a
# float32 model round-trips exactly, while "int8" (9.6 kg → 9 kg) or float16 (101325 Pa → inf) are refused.
_DTYPE_RTOL = 2.0**-24
# The keys of each kind of structure node (the kind: its first key present, in this order, as `decode` reads it).
_NODE_KEYS = {"array": {"array"}, "class": {"class", "fields"}, "value": {"value", "type"}, "tuple": {"tuple"},
              "list": {"list"}, "dict": {"dict"}}
# Units of fields declared without one in their metadata (the docstring gives it).
_UNIT_FALLBACK = {"velocity_width": "m/s"}


def _registry(extra=()):
    """name → class for every equinox Module defined in pamjax (and `extra`): those of every pamjax module imported,
    which is all of them, as importing any part of pamjax runs `pamjax/__init__.py` first."""
    classes = {}
    for module_name, module in list(sys.modules.items()):
        if module is None or not (module_name == "pamjax" or module_name.startswith("pamjax.")):
            continue
        for obj in vars(module).values():
            # the MRO, not issubclass: ABCMeta's subclass check walks every Module subclass in the process for each
            # class that is not one (0.1 s per registry)
            if isinstance(obj, type) and obj.__module__.startswith("pamjax") and eqx.Module in obj.__mro__:
                classes[obj.__name__] = obj
    for cls in extra:
        classes[_class_name(cls)] = cls
    return classes


def _class_name(cls):
    return cls.__name__ if cls.__module__.startswith("pamjax") else f"{cls.__module__}.{cls.__qualname__}"


@functools.cache
def _units_of(cls):
    """field → unit of a component class, from its fields' metadata (`positive(16.0, unit="N")`,
    `parameter(..., unit=...)`, ... of `pamjax._core.fitting`): declared with the field, never read from source."""
    return field_units(cls) if dataclasses.is_dataclass(cls) else {}


def _is_parameter(field):
    """Whether a component's `field` is an array parameter (declared with a unit and not static:
    `pamjax._core.fitting`), as `model_checks.setting_problem` tells it."""
    return "unit" in field.metadata and not field.metadata.get("static")


def _to_json_value(a):
    if a.ndim == 0:
        v = a.item()
        return v if not isinstance(v, float) or math.isfinite(v) else repr(v)
    return [_to_json_value(x) for x in a]


def _encode(obj, path, parameters, classes):
    if eqx.is_array(obj) or isinstance(obj, np.ndarray):
        a = np.asarray(obj)
        entry = {"value": _to_json_value(a)}
        if a.dtype != np.float64:
            entry["dtype"] = str(a.dtype)
        if a.size == 0:
            entry["shape"] = list(a.shape)
        parameters[path] = entry
        return {"array": path}
    if isinstance(obj, eqx.Module):
        cls = type(obj)
        name = _class_name(cls)
        if name not in classes:
            raise PamjaxInputError(f"cannot save {path or 'the model'}: {cls.__module__}.{cls.__qualname__} is not a "
                                   "pamjax model class (pass your own component classes as classes=[...])")
        units = _units_of(cls)
        fields = {}
        for f in dataclasses.fields(obj):
            child = f"{path}.{f.name}" if path else f.name
            value = getattr(obj, f.name)
            if _is_parameter(f) and isinstance(value, int | float) and not isinstance(value, bool):
                # `eqx.tree_at(..., model, 20.0)` leaves a Python float where the constructor makes an array: saved
                # as the parameter it is (a float64 scalar, as `jnp.asarray(20.0)`), not refused as a setting
                value = np.asarray(float(value), dtype=np.float64)
            fields[f.name] = _encode(value, child, parameters, classes)
            if child in parameters and "unit" not in parameters[child]:
                parameters[child]["unit"] = units.get(f.name, _UNIT_FALLBACK.get(f.name, ""))
        return {"class": name, "fields": fields}
    if obj is None or isinstance(obj, (bool, int, str)) or (isinstance(obj, float) and math.isfinite(obj)):
        return {"value": obj}
    if isinstance(obj, float):
        return {"value": repr(obj), "type": "float"}
    if isinstance(obj, (tuple, list)):
        return {type(obj).__name__: [_encode(v, f"{path}.{i}", parameters, classes) for i, v in enumerate(obj)]}
    if isinstance(obj, dict) and all(isinstance(k, str) for k in obj):
        return {"dict": {k: _encode(v, f"{path}.{k}", parameters, classes) for k, v in obj.items()}}
    raise PamjaxInputError(f"cannot save {path}: a {type(obj).__name__} is not a model parameter or setting")


def model_document(model, provenance=None, classes=()):
    """The JSON document of `model` (a dict; see the module docstring)."""
    if not isinstance(model, eqx.Module):
        raise PamjaxInputError(f"model must be a pamjax model (an equinox Module), got {type(model).__name__}")
    if isinstance(model, AbstractSignal):
        raise PamjaxInputError(f"model must be a pamjax model (a system or a component), got the signal "
                               f"{type(model).__name__}: a signal is an input, given to simulate beside the model")
    parameters = {}
    structure = _encode(model, "", parameters, _registry(classes))
    provenance = _provenance(provenance)
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "pamjax_version": version(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "class": structure["class"],
        "parameters": parameters,
        "structure": structure,
        "provenance": provenance,
    }


def _provenance(provenance):
    """`provenance` as strict JSON holds it, as pamjax's other writers store results (`pamjax._core.jsonio.plain`):
    NumPy/JAX numbers and arrays as numbers and lists, a non-finite number as the text "inf", "-inf" or "nan" (a fit's
    undetermined standard error); anything else JSON cannot hold is refused by name (it raised a raw TypeError or
    ValueError from `json` after the model was encoded)."""
    if provenance is None:
        return {}
    if not isinstance(provenance, dict):
        raise PamjaxInputError(f"provenance must be a dict (JSON-able: numbers, text, lists, dicts), got "
                               f"{type(provenance).__name__}")
    provenance = plain(provenance)
    try:
        json.dumps(provenance, allow_nan=False)
    except (TypeError, ValueError) as err:
        raise PamjaxInputError(f"provenance must hold numbers, text, lists and dicts only (JSON): {err}") from None
    return provenance


def model_json(model, provenance=None, classes=()):
    """`model_document` as JSON text (what `save_model` writes): one line per parameter, the rest indented."""
    document = model_document(model, provenance, classes)
    lines = ["{"]
    for key, value in document.items():
        if key == "parameters":
            entries = [f"  {json.dumps(p)}: {json.dumps(e, ensure_ascii=False, allow_nan=False)}"
                       for p, e in value.items()]
            text = "{\n" + ",\n".join(entries) + "\n }" if entries else "{}"
        else:
            text = json.dumps(value, indent=1, ensure_ascii=False, allow_nan=False).replace("\n", "\n ")
        lines.append(f" {json.dumps(key)}: {text},")
    lines[-1] = lines[-1][:-1]
    return "\n".join(lines) + "\n}\n"


def save_model(path: str | os.PathLike, model: eqx.Module, *, overwrite: bool = False,
               provenance: dict | None = None, classes: Sequence[type] = ()) -> pathlib.Path:
    """Write `model` (every parameter, its units and structure) to the JSON file `path`; `load_model(path)` reads it
    back equal, bitwise. Refuses to replace an existing file unless `overwrite=True`. `provenance`: a JSON-able dict
    stored beside (e.g. how the model was fitted). `classes`: your own component classes used in the model."""
    if isinstance(path, eqx.Module) and isinstance(model, str | os.PathLike):
        raise PamjaxInputError(f"save_model takes the path first: save_model({str(model)!r}, model), got the model "
                               "first")
    if not isinstance(path, str | os.PathLike):
        raise PamjaxInputError(f"save_model: path must be a file path (str or os.PathLike), got "
                               f"{type(path).__name__}")
    path = pathlib.Path(path)
    if path.is_dir():  # replaced by overwrite=True it was a raw IsADirectoryError from os.replace
        raise PamjaxInputError(f"save_model: {path} is a folder; give the model file's path (e.g. "
                               f"{path / 'model.json'})")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    document = model_document(model, provenance, classes)
    # what load_model would refuse is not written: the same checks, run on the document itself
    _check_document(_Decoder(f"cannot save {path}", document, _registry(classes)), document)
    return replace_text(path, model_json(model, provenance, classes))


def replace_text(path, text):
    """Write `text` to `path` through a temporary file in the same folder renamed over it (`os.replace`, atomic on
    one file system): a crash or a full disk while writing leaves the previous file whole, never a truncated one."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")  # the process's own: two writers never share one
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


class _Decoder:
    def __init__(self, where, document, classes):
        self.where, self.classes = where, classes
        self.parameters = document.get("parameters")
        self.used = set()
        structure = document.get("structure")
        # a Rig's runs and sensors are measured on its plant's bench: their gauge pressures are relative to its air
        self.rig = isinstance(structure, dict) and structure.get("class") == "Rig"

    def fail(self, message):
        raise PamjaxInputError(f"{self.where}: {message}")

    def array(self, path, declared=None):
        """The parameter `path` of the file: its value in the component's unit `declared` (the file's `unit`
        converted, or refused by name), in a dtype that holds it, checked for a magnitude that betrays another unit
        (`pamjax._core.units.check_setting`, as for `[model] set`)."""
        if path not in self.parameters:
            self.fail(f"parameter {path!r} is missing from 'parameters'")
        entry = self.parameters[path]
        if not isinstance(entry, dict) or "value" not in entry:
            self.fail(f"parameter {path!r} must be {{\"value\": ..., \"unit\": ...}}, got {entry!r}")
        unknown = set(entry) - {"value", "unit", "dtype", "shape"}
        if unknown:
            self.fail(f"parameter {path!r} has unknown key(s) {sorted(unknown)}; an entry holds value, unit and "
                      "(optionally) dtype and shape")
        self.used.add(path)
        name = f"parameter {path!r}"
        counted = declared in (None, "") and entry.get("unit") in (None, "")  # unitless: may be a count or seed
        dtype = self._dtype(entry.get("dtype", "float64"), name, counted)
        raw = entry["value"]
        if any(isinstance(v, bool) for v in flat(raw)):
            self.fail(f"{name}: {raw!r} is not a number or a list of numbers")
        try:
            value = np.asarray(from_json_value(raw), dtype=np.float64)
        except (TypeError, ValueError) as err:
            self.fail(f"{name}: {raw!r} is not a number or a list of numbers ({err})")
        if "shape" in entry:
            try:
                value = value.reshape(entry["shape"])
            except (TypeError, ValueError) as err:
                self.fail(f"{name}: shape {entry['shape']!r} does not fit its value ({err})")
        if value.size == 0:  # loaded as shape (0,), and simulate failed with a raw JAX error about the scan's carry
            self.fail(f"{name}: {raw!r} holds no number; write its value (a number, or a list of numbers where the "
                      "model takes several)")
        unit = entry.get("unit")
        try:
            value = parameter_to_si(declared, None if unit in (None, "") else unit, value, name,
                                    self.atmosphere_for(path))
            check_setting(path, value, "parameter")
        except PamjaxInputError as err:
            self.fail(f"{err}{unit_hint(str(err), declared)}")
        if dtype != np.float64:
            stored = value.astype(dtype)
            back = stored.astype(np.float64)
            lossy = ~((back == value) | (np.abs(back - value) <= _DTYPE_RTOL * np.abs(value)))
            if np.any(lossy & ~np.isnan(value)):
                k = int(np.flatnonzero(lossy)[0])
                self.fail(f"{name}: dtype {dtype.name!r} cannot hold {float(value.ravel()[k])!r} (it would be "
                          f"{float(back.ravel()[k])!r}); remove \"dtype\" (float64)")
            value = stored
        if value.ndim == 0 and dtype == np.float64:
            return as_scalar(value.item())  # a scalar as `jnp.asarray(9.6)` makes it (the components' converter)
        return device_array(value)

    def atmosphere_for(self, path):
        """The atmospheric pressure [Pa abs] a gauge unit of parameter `path` is relative to: the file's nearest
        enclosing `air.atmospheric_pressure` (a bench at 1,600 m: 6 barg at 83.4 kPa is 683.4 kPa abs, not the 701.3
        of the standard atmosphere; for a Rig's runs and sensors, its plant's), else ISO 2533's; an entry that is no
        number is left to its own decoding."""
        best, atmosphere = -1, ATMOSPHERE
        if self.rig and path.split(".")[0] in ("runs", "sensors"):  # `Rig`'s NUISANCE_ROOTS: the plant's air
            path = f"plant.{path}"
        for key, entry in self.parameters.items():
            parts = key.split(".")
            if parts[-2:] != ["air", "atmospheric_pressure"] or not isinstance(entry, dict):
                continue
            owner = ".".join(parts[:-2])
            if (owner == "" or path.startswith(owner + ".")) and len(owner) > best:
                try:
                    value = float(parameter_to_si("Pa abs", entry.get("unit") or None, entry.get("value"), key))
                except (PamjaxInputError, TypeError, ValueError):
                    continue
                if np.isfinite(value) and value > 0:
                    best, atmosphere = len(owner), value
        return atmosphere

    def _dtype(self, spec, name, counted=False):
        """The entry's dtype: floating point, or an integer one for a unitless setting (`counted`: a seed, a count,
        as `save_model` writes `LoopSensors.seed`; the values must then be whole numbers, checked by `array`)."""
        try:
            dtype = np.dtype(spec)
        except TypeError:
            self.fail(f"{name}: dtype {spec!r} is not a dtype")
        if dtype.kind != "f" and not (counted and dtype.kind in "iu"):
            self.fail(f"{name}: dtype {spec!r}: a model parameter is a floating-point number (an integer dtype would "
                      "cut 9.6 to 9); remove \"dtype\" (float64)")
        return dtype

    def decode(self, node, path, unit=None):
        if not isinstance(node, dict) or len(node) == 0:
            self.fail(f"structure at {path or 'the top'} must be a table, got {node!r}")
        for kind, keys in _NODE_KEYS.items():  # a key beside them ("unit" by "array", "klass") had no effect
            if kind in node and set(node) - keys:
                self.fail(f"structure at {path or 'the top'} has unknown key(s) {sorted(set(node) - keys)}; a "
                          f"{kind!r} node holds {sorted(keys)} only (a parameter's unit goes in 'parameters')")
        if "array" in node:
            if not isinstance(node["array"], str):
                self.fail(f"structure at {path or 'the top'}: \"array\" must name a parameter (its path, such as "
                          f"\"payload_mass\"), got {node['array']!r}")
            return self.array(node["array"], unit)
        if "class" in node:
            return self.module(node, path)
        if "value" in node:
            return self.setting(node, path)
        for kind in ("tuple", "list"):
            if kind in node:
                if not isinstance(node[kind], list):
                    self.fail(f"structure at {path or 'the top'}: \"{kind}\" must be a list, got {node[kind]!r}")
                items = [self.decode(v, f"{path}.{i}") for i, v in enumerate(node[kind])]
                return tuple(items) if kind == "tuple" else items
        if "dict" in node:
            if not isinstance(node["dict"], dict):
                self.fail(f"structure at {path or 'the top'}: \"dict\" must be a table, got {node['dict']!r}")
            return {k: self.decode(v, f"{path}.{k}") for k, v in node["dict"].items()}
        self.fail(f"structure at {path or 'the top'} has no class, array or value: {node!r}")

    def setting(self, node, path):
        """A static setting (`{"value": ...}`; a non-finite float as `{"value": "inf", "type": "float"}`)."""
        if node.get("type") != "float":
            return node["value"]
        try:
            return float(node["value"])
        except (TypeError, ValueError):
            self.fail(f"structure at {path or 'the top'}: {node['value']!r} is not a float (\"inf\", \"-inf\" or "
                      "\"nan\" in quotes, else a number)")

    def module(self, node, path):
        name = node["class"]
        if not isinstance(name, str):
            self.fail(f"structure at {path or 'the top'}: \"class\" must be a class name (text such as "
                      f"\"MuscleSystem\"), got {name!r}")
        cls = self.classes.get(name)
        if cls is None:
            hint = " (pass your own component classes as classes=[...])" if "." in name else ""
            self.fail(f"class {name!r} at {path or 'the top'} is not a pamjax model class{hint}")
        fields = {f.name: f for f in dataclasses.fields(cls)}
        given = node.get("fields", {})
        if not isinstance(given, dict):
            self.fail(f"{name} at {path or 'the top'}: \"fields\" must be a table of field → structure, got "
                      f"{given!r}")
        unknown = set(given) - set(fields)
        if unknown:
            self.fail(f"{name} at {path or 'the top'} has no field(s) {sorted(unknown)}; its fields are "
                      f"{sorted(fields)}")
        where = f"{path} ({name})" if path else name
        missing = missing_fields(cls, path, given)
        if missing:
            self.fail(f"{where}: {missing}")
        units = _units_of(cls)
        values = {k: self.decode(v, f"{path}.{k}" if path else k, units.get(k, _UNIT_FALLBACK.get(k)))
                  for k, v in given.items()}
        for k, v in given.items():
            full = f"{path}.{k}" if path else k
            problem = setting_problem(fields[k], v, values[k], full)
            if problem:
                self.fail(f"structure at {full} ({name}.{k}): {problem}")
        arguments = {k: v for k, v in values.items() if fields[k].init}
        try:  # through the constructor: converters and value checks run as in Python
            obj = cls(**arguments)
        except PamjaxInputError as err:
            self.fail(f"{where}: {err}")
        except (TypeError, ValueError) as err:
            if constructor_takes(cls, arguments):  # a value it cannot take: its checks stopped there, never skipped
                self.fail(f"{where}: {type(err).__name__}: {err} (a value of the wrong kind in its fields "
                          f"{sorted(arguments)}?)")
            obj = None  # a constructor with its own signature: rebuilt field by field below
        if obj is None or not same_leaves(obj, values):
            obj = object.__new__(cls)
            for k, v in values.items():
                object.__setattr__(obj, k, v)
            missing = set(fields) - set(values)
            if missing:
                self.fail(f"{where}: field(s) {sorted(missing)} missing")
        return obj


def load_model(path: str | os.PathLike, *, classes: Sequence[type] = ()) -> eqx.Module:
    """Read a model written by `save_model` or `pamjax fit` (`model.json`): the same classes, structure and every
    parameter bitwise. Raises `PamjaxInputError` naming the file and the entry for a malformed file, an unknown class
    or a value the component refuses. `classes`: your own component classes, if the model uses any."""
    require_float64("pamjax.load_model")
    path = pathlib.Path(path)
    if not path.is_file():
        raise PamjaxInputError(f"model file {path} does not exist" + (" (it is a folder)" if path.is_dir() else ""))
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark (Notepad's "UTF-8 with BOM") skipped
        document = parse_json(text)
    except DuplicateKey as dup:
        raise PamjaxInputError(f"model file {path}: key {dup.key!r} appears twice in one table (lines "
                               f"{', '.join(map(str, dup.lines))}); JSON would keep only the last one and drop the "
                               "other silently: remove one") from None
    except json.JSONDecodeError as err:
        raise PamjaxInputError(f"model file {path}, line {err.lineno}, column {err.colno}: not valid JSON: "
                               f"{err.msg}") from None
    except UnicodeDecodeError as err:
        raise PamjaxInputError(f"model file {path} is not a text (JSON) file: {err}") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise PamjaxInputError(f"model file {path} is not a pamjax model file (no \"format\": \"{FORMAT}\"); "
                               "model files are written by pamjax fit (model.json) or pamjax.save_model")
    if document.get("format_version") != FORMAT_VERSION:
        raise PamjaxInputError(f"model file {path} has format_version {document.get('format_version')!r}; this "
                               f"pamjax reads version {FORMAT_VERSION}")
    return _check_document(_Decoder(f"model file {path}", document, _registry(classes)), document)


def _check_document(decoder, document, batched=True):
    """The model `document` describes, rebuilt and checked by `decoder` (every parameter used, none batched: the
    latter a shape inference of the vector field, skipped with `batched=False`)."""
    if decoder.parameters is None:
        decoder.fail("no 'parameters' table (path → {value, unit}): a model file lists every parameter there")
    if not isinstance(decoder.parameters, dict):
        decoder.fail("'parameters' must be a table of path → {value, unit}")
    model = decoder.decode(document.get("structure"), "")
    named = document.get("class")  # the summary the file states at its top: a hand edit left it contradicting
    if named is not None and named != _class_name(type(model)):
        decoder.fail(f"its \"class\" is {named!r}, but its structure builds a {_class_name(type(model))}: edit both "
                     "alike (the structure is what is built)")
    unused = set(decoder.parameters) - decoder.used
    if unused:
        decoder.fail(f"parameter(s) {sorted(unused)} are not part of the model's structure (misspelt paths?)")
    found = batched_parameters(model) if batched else []
    if found:
        decoder.fail(describe_batched(found))
    return model


def checked(model, where, batched=True):
    """`model` rebuilt through its components' constructors, so that their value checks run (a model changed with
    `eqx.tree_at` skips them); an error names `where`. Values and structure are unchanged. `batched=False` skips the
    check for parameters with axes too many, for a caller that kept every parameter's shape of a model that passed
    it (a config's `[model] set`; ~0.07 s of shape inference in each `pamjax` command's set-up)."""
    document = model_document(model)
    return _check_document(_Decoder(where, document, _registry()), document, batched)
