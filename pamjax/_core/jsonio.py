"""JSON that every reader accepts. RFC 8259 has no NaN or Infinity, and Python's `json.dumps` writes them as the bare
words `NaN` and `Infinity`, which JavaScript's `JSON.parse`, MATLAB's `jsondecode` (for Infinity inside objects), jq
and most other readers refuse. pamjax writes a non-finite number as the text "nan", "inf" or "-inf" (as its model
files always have) and reads those back as floats (`numbers`)."""

import json
import math
from collections.abc import Mapping
from typing import Any

NON_FINITE = ("nan", "inf", "-inf")


def plain(obj: Any) -> Any:
    """`obj` with dict keys as strings, tuples as lists, NumPy/JAX arrays and scalars as Python numbers and lists, and
    every non-finite float as "nan", "inf" or "-inf"."""
    if isinstance(obj, Mapping):  # a dict, or a read-only view of one (paper 001's tables)
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, (bool, int, str)) or obj is None:
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else repr(obj)
    if hasattr(obj, "tolist"):  # NumPy or JAX array or scalar
        return plain(obj.tolist())
    return obj


def dumps(obj: Any, **kwargs: Any) -> str:
    """`json.dumps` of `plain(obj)`: strict JSON (raises on anything `plain` cannot make plain)."""
    return json.dumps(plain(obj), allow_nan=False, **kwargs)


def numbers(obj: Any) -> Any:
    """The inverse of `plain` for numbers: every "nan", "inf" and "-inf" text in `obj` (nested dicts and lists) as a
    float; every other value as it is. Apply it to numeric fields only (a label may be any text)."""
    if isinstance(obj, dict):
        return {k: numbers(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [numbers(v) for v in obj]
    if isinstance(obj, str) and obj.strip().lower() in NON_FINITE:
        return float(obj)
    return obj


def json_text(obj: dict | list, indent: int | None = 1) -> str:
    """Strict JSON text of a result (a dict of numbers, lists, arrays, text): what `pamjax fit` and `FitResult.to_json`
    write. A non-finite number (a standard error the data do not determine: inf) is written as the text "inf", "-inf"
    or "nan", which every JSON reader accepts; NumPy/JAX arrays and scalars as lists and numbers."""
    return dumps(obj, indent=indent)
