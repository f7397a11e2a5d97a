"""Host values to JAX arrays without compiling anything.

JAX (0.10) compiles a small program for `jnp.asarray` of a NumPy array or a Python number, once per shape and dtype
(`jit(stage)`, `jit(convert_element_type)`: 5-30 ms each on a slow CPU); a fit's set-up makes dozens of such arrays
(the recordings, the parameter space, the decoded model), tenths of a second of a warm `pamjax fit`.
`jax.device_put` of the same NumPy array compiles nothing and gives the same array.
"""

import dataclasses
import difflib

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import DTypeLike

from .custom_types import Array, RealArray, RealArrayLike, RealScalar, RealScalarLike, Table, TableLike
from .errors import PamjaxInputError
from .private import jax_at_top_level


def as_scalar(x: RealScalarLike) -> RealScalar:
    """`jnp.asarray` of a component's scalar parameter: the field converter that gives its constructor the type of
    the argument (equinox annotates `__init__` with the converter's argument type). A Python float or int goes
    through `jax.device_put`: the same weakly typed array, without the small program `jnp.asarray` compiles for it
    (~50 ms the first time in a process: a preset's set-up in every `pamjax` command). An empty array is refused:
    it is no number nor a batch of them (a payload_mass of [] passed the positivity checks vacuously, and the solve
    failed deep inside JAX). Integers become floats, bools are refused (`_asarray`)."""
    if isinstance(x, (str, bytes)):  # jnp.asarray("0.1"): a raw TypeError from JAX, naming no parameter
        raise PamjaxInputError(f"a scalar parameter got the text {x!r}: give a number [SI] (0.1, not \"0.1\")")
    a = _asarray(x)
    if a.size == 0:
        raise PamjaxInputError(f"a scalar parameter got an empty array (shape {a.shape}): give one number [SI], or a "
                               "batch of them")
    return a


def _refuse_bool(x):
    what = "a bool" if isinstance(x, (bool, np.bool_)) else "bools"
    raise PamjaxInputError(f"a parameter must be a number, got {x!r:.80} ({what}): write the value itself (1.0, not "
                           "True)")


def _asarray(x):
    """`jnp.asarray(x)`, made on the host where `x` is a Python number or a list, tuple or NumPy array of numbers:
    the same dtype and weak type, without compiling; except that integers become floats (as if written 10.0) and
    bools are refused. A parameter is a real number: `payload_mass=10` stored as an int64 array failed the README's
    `jax.grad(loss)(system)` with JAX's "grad requires real-valued inputs ... got int64", naming no parameter, and
    `payload_mass=True` was 1 kg. (Counts and seeds have converters of their own, e.g. `LoopSensors.seed`.)"""
    if type(x) is float:  # not bool (`jnp.asarray(True)` is strongly typed), not subclasses
        return jax.device_put(x)  # weakly typed, as `jnp.asarray` makes it
    if type(x) is int:
        return jax.device_put(float(x))  # weakly typed float, as `jnp.asarray(10.0)`
    if isinstance(x, (bool, np.bool_)):
        _refuse_bool(x)
    if isinstance(x, (list, tuple, np.ndarray, np.generic)):
        try:
            a = np.asarray(x)
        except Exception:  # noqa: BLE001 - tracers or arrays of other shapes inside: JAX's own rules and errors
            return _floating(jnp.asarray(x), x)
        if a.dtype.kind == "b":
            _refuse_bool(x)
        if a.dtype.kind in "iu":  # strongly typed floats, as `jnp.asarray(np.asarray(x, float))`
            return device_array(a.astype(np.float64))
        if a.dtype.kind == "f":  # strongly typed as `jnp.asarray` makes them (an empty list: float64 both)
            return device_array(a)
    return _floating(jnp.asarray(x), x)


def _floating(a, x):
    """A JAX array or tracer `a` (made of `x`) of integers as floats; of bools refused (its dtype is known even
    traced)."""
    if a.dtype == jnp.bool_:
        _refuse_bool(x)
    if jnp.issubdtype(a.dtype, jnp.integer):
        return a.astype(jnp.result_type(float))
    return a


def check_overrides(cls: type, overrides: dict, caller: str) -> None:
    """Every key of `overrides` (a preset builder's keyword arguments, passed on to `cls`) is a field of `cls`'s
    constructor: else a `PamjaxInputError` naming the keyword, the closest field (one it begins, else difflib's) and
    all of them (a misspelt `switch_on_dely=3e-3` was Python's raw TypeError from `cls.__init__`, listing nothing)."""
    valid = [f.name for f in dataclasses.fields(cls) if f.init]
    for key in overrides:
        if key not in valid:
            close = [f for f in valid if f.startswith(str(key))] or difflib.get_close_matches(str(key), valid, n=1)
            raise PamjaxInputError(f"{caller} got the keyword {key}=, which is no {cls.__name__} field" + (
                f" (did you mean {close[0]}=?)" if close else "") + f"; the fields it overrides: {', '.join(valid)}")


def floats_as_arrays(tree):
    """`tree` with every Python `float` leaf as the array its component's constructor makes of it (`as_scalar`); the
    same object when it has none. A parameter set with `eqx.tree_at(lambda s: ..., system, 3.5e-3)` bypasses the
    constructor and stays a Python number, which `jax.jit` takes as a constant of the program: every value compiled
    a program of its own (~1.1 s each for the averaged MAS-10's `simulate`) and skipped the unit checks of
    concrete parameters. Python ints and bools are left alone (they may size or select things)."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    if not any(type(x) is float for x in leaves):
        return tree
    return jax.tree_util.tree_unflatten(treedef, [as_scalar(x) if type(x) is float else x for x in leaves])


def as_optional_scalar(x: RealScalarLike | None) -> RealScalar | None:
    """The converter of an optional scalar parameter: None stays None (not set), anything else a scalar array."""
    return None if x is None else as_scalar(x)


def as_array(x: RealArrayLike) -> RealArray:
    """`jnp.asarray` of a component's array parameter (a table, coefficients, a pair of time constants): a number,
    an array or a (nested) list or tuple of numbers."""
    return _asarray(x)


def as_table(x: TableLike) -> Table:
    """`jnp.asarray` of a column of a component's table (a calibration's voltages, tabulated conductances, a sampled
    signal's times): a vector with as many entries as the component's other columns (its constructor checks that
    they agree, through the shared dimension of `TableLike`)."""
    return _asarray(x)


def device_array(x: RealArrayLike, dtype: DTypeLike | None = None) -> Array:
    """`jnp.asarray(x, dtype)` for a concrete host value (a NumPy array, a list, a number with `dtype`): the same
    values, dtype and (strong) type, made without compiling; copied, never sharing `x`'s memory. A Python number
    without `dtype` (weakly typed in JAX), a JAX array or tracer, and float64 without JAX's x64 mode go through
    `jnp.asarray` as they are."""
    if isinstance(x, (jax.Array, jax.core.Tracer)) or (dtype is None and isinstance(x, (bool, int, float, complex))):
        return jnp.asarray(x, dtype=dtype)
    a = np.asarray(x, dtype=dtype)
    if a.dtype.itemsize == 8 and a.dtype.kind in "fiuc" and not jax.config.jax_enable_x64:
        return jnp.asarray(x, dtype=dtype)  # JAX narrows 64-bit values without x64: keep its rule
    return jax.device_put(a, may_alias=False)


def kept_on_device(key, make):
    """`make()` (a device array made from a host number, e.g. `jnp.asarray(0.0)`) kept under `key` and the default
    device, and returned as it is when asked again: a copy to the device costs 0.05-0.1 ms, a tenth of a 25 s
    averaged-valve `simulate` on a slow CPU, whose tolerances and start time are the same numbers at every call.
    JAX arrays are immutable, so one can be shared. Only outside any JAX transformation: inside one (a jit's trace)
    `make()` is called as it is (JAX may stage the copy as a tracer, which must neither be kept nor replaced by a
    kept concrete array). At most 64 are kept."""
    if not jax_at_top_level():
        return make()
    key = (key, jax.config.jax_default_device)
    kept = _KEPT.get(key)
    if kept is None:
        if len(_KEPT) >= 64:  # a few values in use: bounded memory
            _KEPT.clear()
        kept = _KEPT[key] = make()
    return kept


_KEPT = {}
