"""What a model file must hold beside its decoding (`_files/model_file.py`): the JSON itself read (a key given twice
in one table refused with its lines), every field of each component present (a missing one is never filled with the
class default), a static setting of its declared type, a parameter where the component takes one, and the helpers
that turn a parameter's JSON value into numbers and compare a rebuilt component with the file's values."""

import dataclasses
import inspect
import json
import re

import equinox as eqx
import numpy as np

# The static settings whose declared type is checked before the constructor runs (a text "0.999" for a float made
# numpy raise a TypeError inside the component's checks): JSON's types for each (an int is a float's whole number).
_SETTING_TYPES = {"float": (int, float), "int": (int,), "str": (str,), "bool": (bool,)}


class DuplicateKey(Exception):
    """A key given twice in one JSON object, with the lines of its occurrences."""

    def __init__(self, key, lines):
        self.key, self.lines = key, lines


def parse_json(text):
    """`json.loads(text)`, refusing a key given twice in one object (JSON itself keeps the last silently): the pure
    Python scanner, whose object parser is told where each object starts, so that the lines of the key's occurrences
    in that object can be named (`DuplicateKey`)."""
    import json.decoder
    import json.scanner

    def parse_object(s_and_end, strict, scan_once, object_hook, object_pairs_hook, memo=None, _w=None):
        start = s_and_end[1]
        pairs, end = json.decoder.JSONObject(s_and_end, strict, scan_once, object_hook, list, memo)
        keys = [k for k, _ in pairs]
        for k in keys:
            if keys.count(k) > 1:
                span = s_and_end[0][start:end]
                found = [m.start() for m in re.finditer(re.escape(json.dumps(k)) + r"\s*:", span)]
                found += [m.start() for m in re.finditer(re.escape(json.dumps(k, ensure_ascii=False)) + r"\s*:",
                                                          span) if m.start() not in found]
                lines = sorted(s_and_end[0].count("\n", 0, start + pos) + 1 for pos in found)
                raise DuplicateKey(k, lines)
        return dict(pairs), end

    decoder = json.JSONDecoder()
    decoder.parse_object = parse_object
    decoder.scan_once = json.scanner.py_make_scanner(decoder)
    return decoder.decode(text)


def missing_fields(cls, path, given):
    """What is wrong with a component of class `cls` at `path` whose file gives the fields `given`: the constructor's
    fields it lacks, by path (None if none). Filled with the class default they loaded another model than the one
    written (a 20 kg payload read as 9.6 kg): `save_model` writes every field, so a missing one is a damaged or
    hand-cut file, refused. Fields the constructor computes (`init=False`) are left to it."""
    missing = [f for f in dataclasses.fields(cls) if f.init and f.name not in given]
    if not missing:
        return None
    named = []
    for f in missing:
        full = f"{path}.{f.name}" if path else f.name
        kind = "parameter" if "unit" in f.metadata else "setting" if f.metadata.get("static") else "field"
        named.append(f"{kind} {full!r}")
    return (f"{', '.join(named)} {'is' if len(named) == 1 else 'are'} missing from the file; the class default is "
            "not filled in (the file would load another model than the one written): write it (a parameter: "
            "{\"array\": path} in the structure, its value and unit in 'parameters'; a setting: {\"value\": ...})")


def setting_problem(field, node, value, path):
    """What is wrong with the structure `node` (decoded: `value`) given for `field` (at `path`) of a component, where
    the node is a static setting (`{"value": ...}`), or None: a setting not of the field's declared type (a number
    in quotes, "0.999"; null is left to the constructor, as save_model writes a setting left unset), or a parameter
    of the component written as a setting (`{"value": null}` where an array goes)."""
    if not (isinstance(node, dict) and "value" in node):
        return None
    if "unit" in field.metadata and not field.metadata.get("static"):  # a parameter (pamjax._core.fitting)
        if value is None and field.default is None:
            return None  # an optional parameter left unset, as save_model writes it
        return (f"{json.dumps(node['value'])} is written as a setting, but {field.name} is a parameter: write "
                f"{{\"array\": {json.dumps(path)}}} here and its value and unit under {path!r} in 'parameters'")
    declared = field.type if isinstance(field.type, str) else getattr(field.type, "__name__", None)
    types = _SETTING_TYPES.get(declared) if isinstance(field.type, str | type) else None
    if types is None or value is None:
        return None
    if isinstance(value, types) and not (isinstance(value, bool) and declared != "bool"):  # True is no number here
        return None
    what = {"float": "a number", "int": "a whole number", "str": "text", "bool": "true or false"}[declared]
    hint = " without quotes" if isinstance(value, str) and declared in ("float", "int") else ""
    return f"{json.dumps(node['value'])} is not {what} ({field.name} is a {declared} setting): write {what}{hint}"


def same_leaves(obj, values):
    """Whether the component `obj` holds the array `values` the file gave it, unchanged (shape, dtype, bits)."""
    for k, v in values.items():
        got = getattr(obj, k, None)
        if eqx.is_array(v):
            if not (eqx.is_array(got) and got.shape == v.shape and got.dtype == v.dtype
                    and np.array_equal(np.asarray(got), np.asarray(v), equal_nan=True)):
                return False
    return True


def unit_hint(message, declared):
    """For a magnitude refused as another unit: how to say that unit in the file (which pamjax then converts)."""
    m = re.search(r"looks like ([^\s,;()]+)", message)
    if m is None:
        return ""
    likely = m.group(1)
    if declared in ("Pa abs", "Pa gauge"):
        likely += " abs" if declared == "Pa abs" else " gauge"
    return (f"; if the number is right in {m.group(1)}, say so in its entry (\"unit\": \"{likely}\") and pamjax "
            "converts it")


def flat(v):
    """The entries of a nested list (a parameter's JSON value), or [v] for one value."""
    return [x for item in v for x in flat(item)] if isinstance(v, list) else [v]


def from_json_value(v):
    """A parameter's JSON value with "nan", "inf" and "-inf" (how `save_model` writes non-finite values) as floats;
    any other text refused (`ValueError`): a number in quotes is a hand edit, not what the writer wrote."""
    if isinstance(v, list):
        return [from_json_value(x) for x in v]
    if isinstance(v, str):
        if v.strip().lower() not in ("nan", "inf", "-inf"):
            raise ValueError(f"{v!r} is text: write a number without quotes (only \"nan\", \"inf\" and \"-inf\" "
                             "are quoted)")
        return float(v)
    return v


def constructor_takes(cls, arguments):
    """Whether `cls(**arguments)` fits the constructor's signature (a TypeError it raises is then about a value, not
    about a constructor with a signature of its own, such as `Experiment(recording, ...)`)."""
    try:
        inspect.signature(cls).bind(**arguments)
    except (TypeError, ValueError):
        return False
    return True
