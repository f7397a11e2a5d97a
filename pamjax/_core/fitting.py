"""How a component's parameter is fitted, declared where the parameter is: field metadata.

A component says, field by field, how `pamjax.fit` moves the parameter in its unconstrained space and how it reports
it; the fitter (`pamjax._fit.parameters`) reads these keys and knows no component:

    coulomb_force: RealScalar = positive(16.0, unit="N")
    critical_ratio: RealScalar = ratio(unit="-")
    polytropic_index: RealScalar = bounded(1.4, bounds=POLYTROPIC_RANGE, unit="-")
    max_force_coefficients: RealVector = eqx.field(converter=as_array, metadata=polynomial("a{i}", "stroke", "N/m^i"))
    pre_contraction: RealScalar = parameter(0.01, unit="m")

Each helper's `shape` says what the constructor takes (the converter's argument type, `_core/custom_types`):
"scalar" (the default: a number), "table" (a column of the component's table: every such column of one component
has the same length) or "array" (any shape: coefficients, a pair of time constants); the field's annotation gives the
exact shape.

- `transform`: "log" (a physically positive quantity, fitted as v₀ eᶿ so that a trial value is never ≤ 0; a start
  value ≤ 0 falls back to "linear"), "logistic" with `bounds` (lo, hi) (a bounded quantity: a ratio in (0, 1),
  `ratio`; any range outside which the component's check refuses a value, `bounded`, its bounds the check's own
  constant, so that no trial or fitted value leaves what the component accepts: a discharge coefficient fitted
  linearly or in log space converged at 1.105, outside the (0, 1] its restriction accepts), "nodes" (a polynomial's
  coefficients, fitted as its values at Chebyshev nodes over `domain`), or "linear" (the default: scaled by the
  start magnitude, or by `scale` where the field declares one: `signed`).
- `domain` ("nodes" only): the name of an attribute (lo, hi) of an enclosing component that bounds the polynomial's
  argument (a `Muscle`'s `stroke` for the force law's F_max(x)).
- `label`: how the entries of an array are reported, a format with `{i}` the flat index and `{n}` = i + 1 ("a{i}"
  gives a0…a4, "m{n}" m1…m9); a scalar, or an array without a label, is reported by its path.

- `unit`: the parameter's unit as model files write it (`pamjax.save_model`; "-" for a pure number). Every helper
  takes it (`positive(16.0, unit="N")`); `parameter(default, unit=...)` declares a parameter fitted linearly.

A `free` entry of `fit` may override the transform and bounds (`{"path": ..., "transform": ..., "bounds": ...}`).
"""

import dataclasses

import equinox as eqx

from .arrays import as_array, as_optional_scalar, as_scalar, as_table
from .custom_types import RealArray, RealArrayLike

TRANSFORMS = ("linear", "log", "logistic", "nodes")


def optional_array(x: RealArrayLike | None) -> RealArray | None:
    """Field converter of an optional array parameter: None stays None (not set), anything else an array."""
    return None if x is None else as_array(x)


# shape → (converter, converter of an optional parameter)
_CONVERTERS = {"scalar": (as_scalar, as_optional_scalar), "table": (as_table, None),
               "array": (as_array, optional_array)}


def _converter(default, shape):
    """The field's converter for `shape` ("scalar", "table" or "array"), optional (None stays None) where the default
    is None. The converter's argument type is the constructor's (equinox)."""
    if shape not in _CONVERTERS:
        raise ValueError(f"shape must be one of {sorted(_CONVERTERS)}, got {shape!r}")
    required, optional = _CONVERTERS[shape]
    return optional if default is None and optional is not None else required


def _with_unit(metadata, unit):
    return metadata if unit is None else {**metadata, "unit": unit}


def parameter(default=dataclasses.MISSING, *, unit=None, shape="scalar", **kwargs):
    """An array parameter fitted linearly (scaled by its start magnitude), in `unit`, of `shape` (module docstring)."""
    return eqx.field(converter=_converter(default, shape), default=default, metadata=_with_unit({}, unit), **kwargs)


def positive(default=dataclasses.MISSING, *, unit=None, shape="scalar", **kwargs):
    """An array parameter that is physically positive (an area, a mass, a friction force): fitted in log space, in
    `unit`, of `shape`. A default of None makes it optional (unset until given)."""
    return eqx.field(converter=_converter(default, shape), default=default,
                     metadata=_with_unit(dict(transform="log"), unit), **kwargs)


def ratio(default=dataclasses.MISSING, *, unit="-", shape="scalar", **kwargs):
    """An array parameter in the open interval (0, 1) (a critical pressure ratio): fitted through a logistic; of
    `shape`."""
    return eqx.field(converter=_converter(default, shape), default=default,
                     metadata=_with_unit(dict(transform="logistic", bounds=(0.0, 1.0)), unit), **kwargs)


def bounded(default=dataclasses.MISSING, *, bounds, unit=None, shape="scalar", **kwargs):
    """An array parameter its component accepts only inside `bounds` = (lo, hi) (a polytropic index in (0.99, 1.41),
    a discharge coefficient in (0, 1]): fitted through a logistic over (lo, hi), so that a fit's trial and fitted
    values stay in the range (one the data push to an end stops "at bound", never "converged" outside it), in
    `unit`, of `shape`. `bounds` is the constant the component's check uses (`bounded(1.4, bounds=POLYTROPIC_RANGE)`),
    never a copy of its numbers."""
    lo, hi = (float(b) for b in bounds)
    if not lo < hi:
        raise ValueError(f"bounds must be (lo, hi) with lo < hi, got {bounds!r}")
    return eqx.field(converter=_converter(default, shape), default=default,
                     metadata=_with_unit(dict(transform="logistic", bounds=(lo, hi)), unit), **kwargs)


def signed(default=dataclasses.MISSING, *, scale, unit=None, shape="scalar", **kwargs):
    """A signed array parameter (an offset, a delay) fitted linearly in units of `scale` (its natural size: a
    start value of 0 gives no magnitude of its own), in `unit`, of `shape`."""
    return eqx.field(converter=_converter(default, shape), default=default,
                     metadata=_with_unit(dict(transform="linear", scale=float(scale)), unit), **kwargs)


def polynomial(label, domain, unit=None):
    """Metadata of a polynomial's coefficients: fitted as its values at Chebyshev nodes over `domain` (an attribute
    (lo, hi) of an enclosing component), reported with `label` (e.g. "a{i}"), in `unit`."""
    return _with_unit(dict(transform="nodes", label=label, domain=domain), unit)


def labelled(label, unit=None):
    """Metadata of an array whose entries are reported with `label` (e.g. "m{n}" for m1…m9), fitted linearly."""
    return _with_unit(dict(label=label), unit)


def field_units(cls):
    """field name → unit of the equinox Module class `cls` (its own fields and those it inherits), from the fields'
    metadata; fields without a unit are left out."""
    return {f.name: f.metadata["unit"] for f in dataclasses.fields(cls) if "unit" in f.metadata}
