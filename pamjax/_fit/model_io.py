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
import pathlib
import sys

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.errors import PamjaxInputError, require_float64
from .._core.fitting import field_units
from .._core.metadata import version

FORMAT = "pamjax-model"
FORMAT_VERSION = 1
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
                                   "pamjax model class")
        units = _units_of(cls)
        fields = {}
        for f in dataclasses.fields(obj):
            child = f"{path}.{f.name}" if path else f.name
            fields[f.name] = _encode(getattr(obj, f.name), child, parameters, classes)
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
    parameters = {}
    structure = _encode(model, "", parameters, _registry(classes))
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "pamjax_version": version(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "class": structure["class"],
        "parameters": parameters,
        "structure": structure,
        "provenance": provenance or {},
    }


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


def save_model(path, model, *, overwrite=False, provenance=None, classes=()):
    """Write `model` (every parameter, its units and structure) to the JSON file `path`; `load_model(path)` reads it
    back equal, bitwise. Refuses to replace an existing file unless `overwrite=True`. `provenance`: a JSON-able dict
    stored beside (e.g. how the model was fitted). `classes`: your own component classes used in the model."""
    path = pathlib.Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    text = model_json(model, provenance, classes)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path


class _Decoder:
    def __init__(self, where, document, classes):
        self.where, self.classes = where, classes
        self.parameters = document["parameters"]
        self.used = set()

    def fail(self, message):
        raise PamjaxInputError(f"{self.where}: {message}")

    def array(self, path):
        if path not in self.parameters:
            self.fail(f"parameter {path!r} is missing from 'parameters'")
        entry = self.parameters[path]
        if not isinstance(entry, dict) or "value" not in entry:
            self.fail(f"parameter {path!r} must be {{\"value\": ..., \"unit\": ...}}, got {entry!r}")
        self.used.add(path)
        dtype = entry.get("dtype", "float64")
        try:
            value = np.asarray(_from_json_value(entry["value"]), dtype=dtype)
        except (TypeError, ValueError) as err:
            self.fail(f"parameter {path!r}: {entry['value']!r} is not a {dtype} array ({err})")
        if "shape" in entry:
            value = value.reshape(entry["shape"])
        if value.ndim == 0 and dtype == "float64":
            return jnp.asarray(value.item())  # a scalar as `jnp.asarray(9.6)` makes it (the components' converter)
        return device_array(value)

    def decode(self, node, path):
        if not isinstance(node, dict) or len(node) == 0:
            self.fail(f"structure at {path or 'the top'} must be a table, got {node!r}")
        if "array" in node:
            return self.array(node["array"])
        if "class" in node:
            return self.module(node, path)
        if "value" in node:
            return float(node["value"]) if node.get("type") == "float" else node["value"]
        for kind in ("tuple", "list"):
            if kind in node:
                items = [self.decode(v, f"{path}.{i}") for i, v in enumerate(node[kind])]
                return tuple(items) if kind == "tuple" else items
        if "dict" in node:
            return {k: self.decode(v, f"{path}.{k}") for k, v in node["dict"].items()}
        self.fail(f"structure at {path or 'the top'} has no class, array or value: {node!r}")

    def module(self, node, path):
        name = node["class"]
        cls = self.classes.get(name)
        if cls is None:
            hint = " (pass your own component classes as classes=[...])" if "." in name else ""
            self.fail(f"class {name!r} at {path or 'the top'} is not a pamjax model class{hint}")
        fields = {f.name: f for f in dataclasses.fields(cls)}
        given = node.get("fields", {})
        unknown = set(given) - set(fields)
        if unknown:
            self.fail(f"{name} at {path or 'the top'} has no field(s) {sorted(unknown)}; its fields are "
                      f"{sorted(fields)}")
        values = {k: self.decode(v, f"{path}.{k}" if path else k) for k, v in given.items()}
        where = f"{path} ({name})" if path else name
        try:  # through the constructor: converters and value checks run as in Python
            obj = cls(**{k: v for k, v in values.items() if fields[k].init})
        except PamjaxInputError as err:
            self.fail(f"{where}: {err}")
        except TypeError:
            obj = None  # a constructor with its own signature: rebuilt field by field below
        if obj is None or not _same_leaves(obj, values):
            obj = object.__new__(cls)
            for k, v in values.items():
                object.__setattr__(obj, k, v)
            missing = set(fields) - set(values)
            if missing:
                self.fail(f"{where}: field(s) {sorted(missing)} missing")
        return obj


def _same_leaves(obj, values):
    for k, v in values.items():
        got = getattr(obj, k, None)
        if eqx.is_array(v):
            if not (eqx.is_array(got) and got.shape == v.shape and got.dtype == v.dtype
                    and np.array_equal(np.asarray(got), np.asarray(v), equal_nan=True)):
                return False
    return True


def _from_json_value(v):
    if isinstance(v, list):
        return [_from_json_value(x) for x in v]
    if isinstance(v, str):
        return float(v)  # "nan", "inf", "-inf"
    return v


def load_model(path, *, classes=()):
    """Read a model written by `save_model` or `pamjax fit` (`model.json`): the same classes, structure and every
    parameter bitwise. Raises `PamjaxInputError` naming the file and the entry for a malformed file, an unknown class
    or a value the component refuses. `classes`: your own component classes, if the model uses any."""
    require_float64("pamjax.load_model")
    path = pathlib.Path(path)
    if not path.is_file():
        raise PamjaxInputError(f"model file {path} does not exist" + (" (it is a folder)" if path.is_dir() else ""))
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
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
    decoder = _Decoder(f"model file {path}", document, _registry(classes))
    if not isinstance(decoder.parameters, dict):
        decoder.fail("'parameters' must be a table of path → {value, unit}")
    model = decoder.decode(document.get("structure"), "")
    unused = set(decoder.parameters) - decoder.used
    if unused:
        decoder.fail(f"parameter(s) {sorted(unused)} are not part of the model's structure (misspelt paths?)")
    return model


def checked(model, where):
    """`model` rebuilt through its components' constructors, so that their value checks run (a model changed with
    `eqx.tree_at` skips them); an error names `where`. Values and structure are unchanged."""
    document = model_document(model)
    return _Decoder(where, document, _registry()).decode(document["structure"], "")
