"""Canonical, process-independent descriptions of pytrees and their digests: the keys of fit fingerprints
(`pamjax._files.fingerprint`) and of the traced-program cache (`pamjax._core.cache`)."""

import dataclasses
import hashlib

import equinox as eqx
import numpy as np


def digest(*parts):
    """A 16-hex-digit SHA-256 digest of `parts` (bytes as they are, anything else by its repr)."""
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else repr(part).encode())
    return h.hexdigest()[:16]


def describe(obj, values=True):
    """A canonical, process-independent description of a pytree: arrays by digest, modules by class and fields.

    With `values=False` arrays are described by shape, dtype (and JAX's weak type) only: the structure a traced
    program depends on when its arrays are its arguments (the traced-program cache's key); every other field
    (Python numbers, strings, static fields) by value, since tracing bakes those in."""
    if eqx.is_array(obj) or isinstance(obj, np.ndarray):
        if not values:
            return ("array", tuple(obj.shape), str(obj.dtype), bool(getattr(obj, "weak_type", False)))
        a = np.asarray(obj)
        return ("array", a.shape, str(a.dtype), digest(np.ascontiguousarray(a).tobytes()))
    if isinstance(obj, eqx.Module) or dataclasses.is_dataclass(obj):
        # a module's static fields, and a plain dataclass (a pytree leaf, not a node), are baked in by value
        module = isinstance(obj, eqx.Module)
        return (type(obj).__qualname__, tuple(
            (f.name, describe(getattr(obj, f.name, None), values or not module or bool(f.metadata.get("static"))))
            for f in dataclasses.fields(obj)))
    if isinstance(obj, dict):
        return ("dict", tuple((str(k), describe(v, values))
                              for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))))
    if isinstance(obj, (list, tuple)):
        return (type(obj).__name__, tuple(describe(v, values) for v in obj))
    if callable(obj):
        return ("callable", getattr(obj, "__qualname__", type(obj).__qualname__))
    return ("value", repr(obj))
