"""`filter_jit`: `equinox.filter_jit`'s semantics (arrays traced, every other leaf static) with a cheaper call.

A call of `equinox.filter_jit` partitions its arguments in Python (`eqx.partition` over every module of the system,
the signal and the solver: ~0.11 ms) and wraps the call with its run-time error reporting: about 0.1 ms per call on
this project's 2-core CPU, a tenth of a 25 s averaged-valve solve (the same compiled program 1.07 ms through
`jax.jit`, 1.10 ms through this, 1.19 ms through `equinox.filter_jit`, medians of 101; docs/performance.md). Here the
arguments are flattened once by JAX's C++ pytree code, the non-array leaves (with their types) and the tree
structure (its static fields included) key a `jax.jit` of the arrays alone, and the outputs' non-array leaves are
kept from the trace, as `equinox.filter_jit` does.

What it leaves out: equinox's run-time error messages (`eqx.error_if` fired inside the program surfaces as JAX's
own runtime error). It is used only where the program traces those checks as NaN (`simulate`'s concrete calls,
`pamjax._core.private.equinox_errors_as_nan`) and the result is checked on the host. A static leaf that cannot be
hashed goes to `equinox.filter_jit`, which refuses it with its own error.
"""

import functools
import types

import equinox as eqx
import jax

_ARRAY = object()  # marks a traced leaf's place among the static ones


def _static_key(leaf):
    return (type(leaf), leaf)  # 1, 1.0 and True are equal and hash alike: the type keeps them apart


def filter_jit(fn, **jit_kwargs):
    """`fn` compiled as `equinox.filter_jit(fn, **jit_kwargs)` would compile it (arrays of the arguments traced,
    every other leaf static; any outputs), dispatched through `jax.jit` (see the module docstring)."""
    slow = eqx.filter_jit(fn, **jit_kwargs)
    programs = {}  # (tree structure, static leaves) → (jitted function of the arrays, the outputs' static part)

    def program(treedef, statics):
        out_static = []

        def arrays_only(arrays):
            it = iter(arrays)
            leaves = [next(it) if s is _ARRAY else s[1] for s in statics]
            args, kwargs = jax.tree_util.tree_unflatten(treedef, leaves)
            dynamic, static = eqx.partition(fn(*args, **kwargs), eqx.is_array)
            # None: every output leaf is an array (the usual case), and the call returns JAX's output as it is
            out_static[:] = [static if jax.tree_util.tree_leaves(static) else None]
            return dynamic

        arrays_only.__name__ = arrays_only.__qualname__ = getattr(fn, "__name__", "fn")  # the program's name
        return jax.jit(arrays_only, **jit_kwargs), out_static

    @functools.wraps(fn)
    def call(*args, **kwargs):
        leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
        arrays, statics = [], []
        for x in leaves:
            if eqx.is_array(x):
                arrays.append(x)
                statics.append(_ARRAY)
            else:
                statics.append(_static_key(x))
        statics = tuple(statics)
        key = (treedef, statics)
        try:
            entry = programs.get(key)
        except TypeError:  # an unhashable static leaf
            return slow(*args, **kwargs)
        if entry is None:
            entry = programs[key] = program(treedef, statics)
        jitted, out_static = entry
        dynamic = jitted(arrays)
        return dynamic if out_static[0] is None else eqx.combine(dynamic, out_static[0])

    call.lower = slow.lower  # the same program, for ahead-of-time use
    return call


class SameCode:
    """A user's function as a static argument of a compiled program, equal to another function of the same code with
    the same defaults and closure values, so that a lambda written inline (`sweep(system, lambda v: Constant(v["duty"]),
    ...)` in a loop, a script run cell by cell) reuses the program its first call compiled instead of compiling one per
    call (a function is otherwise keyed by its identity: a 1,024-point sweep's ~3 s of compilation at every call).
    Two such functions compute the same thing: the same instructions, the same constants, the same global namespace
    (its names are read when the program is traced, as for any jitted function) and equal closure values. A closure
    value that cannot be compared by value (an array, a list, a dict, an object without value equality) keys the
    function by its identity, as before."""

    __slots__ = ("fn", "_key")

    def __init__(self, fn):
        self.fn = fn
        self._key = _code_key(fn)

    def __call__(self, *args, **kwargs):
        return self.fn(*args, **kwargs)

    def __hash__(self):
        return hash(self._key)

    def __eq__(self, other):
        return isinstance(other, SameCode) and self._key == other._key

    def __repr__(self):
        return f"SameCode({self.fn!r})"


class _Identity:
    """Keys an object by its identity (kept alive with the key)."""

    __slots__ = ("obj",)

    def __init__(self, obj):
        self.obj = obj

    def __hash__(self):
        return id(self.obj)

    def __eq__(self, other):
        return isinstance(other, _Identity) and other.obj is self.obj


_VALUE_TYPES = (bool, int, float, complex, str, bytes, type(None))


def _value_key(value, depth=0):
    """A key equal for equal values: numbers and strings (with their type: 1, 1.0 and True differ), tuples and
    frozensets of them, functions by `_code_key`; None where the value has no such key."""
    if isinstance(value, float):
        return (float, value.hex())  # -0.0 and 0.0 apart, every NaN alike
    if isinstance(value, complex):
        return (complex, value.real.hex(), value.imag.hex())
    if isinstance(value, _VALUE_TYPES):
        return (type(value), value)
    if depth < 4 and isinstance(value, (tuple, frozenset)):
        keys = [_value_key(v, depth + 1) for v in value]
        return None if any(k is None for k in keys) else (type(value), tuple(keys))
    if depth < 4 and isinstance(value, types.FunctionType):
        key = _code_key(value, depth + 1)
        return None if isinstance(key, _Identity) else key
    if isinstance(value, (types.ModuleType, type)):
        return _Identity(value)  # a module or a class: the same object is the same namespace
    return None


def _code_key(fn, depth=0):
    if not isinstance(fn, types.FunctionType):
        return _Identity(fn)
    parts = [fn.__code__, _Identity(fn.__globals__)]
    for value in (fn.__defaults__ or ()) + tuple(sorted((fn.__kwdefaults__ or {}).items())):
        parts.append(_value_key(value, depth))
    for cell in fn.__closure__ or ():
        try:
            parts.append(_value_key(cell.cell_contents, depth))
        except ValueError:  # an empty cell (a name assigned after the function was made)
            parts.append(None)
    if any(p is None for p in parts):
        return _Identity(fn)
    return ("code", tuple(parts))
