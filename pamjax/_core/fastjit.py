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
    """A user's function as a static argument of a compiled program, equal to another function that computes the same
    thing, so that a lambda written inline (`sweep(system, lambda v: Constant(v["duty"]), ...)` in a loop, a script
    run cell by cell) reuses the program its first call compiled instead of compiling one per call (a function is
    otherwise keyed by its identity: a 1,024-point sweep's ~3 s of compilation at every call).

    Two functions are equal when they have the same code (instructions, constants, names), the same global namespace,
    and equal values for everything the code reads from outside: defaults, closure cells and the globals it names
    (a loop at a module's top level rebinds a global that an inline lambda reads: each value is another program).
    Numbers, strings, and tuples of them compare by value (1, 1.0 and True apart; -0.0 and 0.0 apart); functions by
    this same rule; what cannot change in place (a module, a class, a JAX array, an equinox module such as a system)
    by its identity. A function that reads anything else (a dict, a list, a NumPy array, an arbitrary object: it may
    have changed since) is keyed by its own identity: another function object is traced afresh, but the SAME function
    object reuses the program traced at its first call, whatever that dict holds now, as `jax.jit` itself does (a
    `def` reading a global dict that changed between two sweeps gave the first sweep's results again). A factory
    must be a pure function of its arguments; globals are read when it is traced (docs/sweeps.md).

    A callable object (not a function, nor an equinox module: that stays a pytree) is keyed by its type and the
    values of its attributes, by the same rule, so an attribute changed between two calls is another program (a
    bound method by its function and its object's attributes; a `functools.partial` by its function and
    arguments); an object whose attributes may change in place (a dict, a list, ...) or that has none to compare
    (`__slots__`, a C type) is not shared with any other `SameCode`, so it is traced afresh at every call."""

    __slots__ = ("fn", "_key")

    def __init__(self, fn):
        self.fn = fn
        if isinstance(fn, types.FunctionType):
            key = _code_key(fn)
            self._key = _Identity(fn) if key is None else key
        else:  # a callable object: by its state now; else this instance only (a changed attribute is traced afresh)
            key = _value_key(fn)
            self._key = _Identity(self) if key is None else key

    def __call__(self, *args, **kwargs):
        return self.fn(*args, **kwargs)

    def __hash__(self):
        return hash(self._key)

    def __eq__(self, other):
        return isinstance(other, SameCode) and self._key == other._key

    def __repr__(self):
        return f"SameCode({self.fn!r})"


def keyed_by_code(fn):
    """`SameCode(fn)` for a plain Python function (a `def` or a `lambda`) or another callable object (by its type and
    attributes' values, see `SameCode`); an equinox module as it is (a callable module, e.g. a system builder with
    parameters, stays a pytree whose arrays are traced and whose static fields key the program by value)."""
    return fn if isinstance(fn, eqx.Module) else SameCode(fn)


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
_MAX_DEPTH = 4  # nested tuples and functions compared by value this deep; deeper, by identity


def _value_key(value, depth=0):
    """A key equal for equal values (see `SameCode`); None for a value that may change in place."""
    if isinstance(value, float):
        return (float, value.hex())  # -0.0 and 0.0 apart, every NaN alike
    if isinstance(value, complex):
        return (complex, value.real.hex(), value.imag.hex())
    if isinstance(value, _VALUE_TYPES):
        return (type(value), value)
    if depth < _MAX_DEPTH and isinstance(value, (tuple, frozenset)):
        keys = tuple(_value_key(v, depth + 1) for v in value)
        return None if any(k is None for k in keys) else (type(value), keys)
    if depth < _MAX_DEPTH and isinstance(value, types.FunctionType):
        return _code_key(value, depth + 1)
    if isinstance(value, (types.ModuleType, type, types.BuiltinFunctionType, jax.Array, eqx.Module)):
        return _Identity(value)  # cannot change in place: the same object reads the same
    if depth < _MAX_DEPTH and callable(value):
        return _object_key(value, depth + 1)
    return None


_HEAP_TYPE = 1 << 9  # Py_TPFLAGS_HEAPTYPE: a class written in Python


def _plain_python_class(cls):
    """Whether an instance's whole state is its `__dict__`: every class of its MRO written in Python (no C state,
    no `__slots__`)."""
    return all(c is object or (c.__flags__ & _HEAP_TYPE and "__slots__" not in vars(c)) for c in cls.__mro__)


def _object_key(obj, depth):
    """A callable object's key: its type and its state by value (`_value_key`), or None where that may change in
    place or cannot be read (no `__dict__`)."""
    if isinstance(obj, types.MethodType):
        owner = _value_key(obj.__self__, depth)  # a class's method: the class, by identity
        parts = (_value_key(obj.__func__, depth), _object_key(obj.__self__, depth) if owner is None else owner)
    elif isinstance(obj, functools.partial):
        parts = (_value_key(obj.func, depth), _value_key(obj.args, depth),
                 _value_key(tuple(sorted(obj.keywords.items())), depth))
    elif _plain_python_class(type(obj)) and isinstance(getattr(obj, "__dict__", None), dict):
        state = sorted(vars(obj).items())
        parts = (tuple(name for name, _ in state), *(_value_key(v, depth) for _, v in state))
    else:
        return None
    if any(p is None for p in parts):
        return None
    return ("object", _Identity(type(obj)), parts)


def _global_names(code):
    """The names `code` (and the functions and comprehensions defined in it) may read as globals."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _global_names(const)
    return names


def _code_key(fn, depth=0):
    """`fn`'s key (see `SameCode`), or None where it reads a value that may change in place."""
    parts = [fn.__code__, _Identity(fn.__globals__)]
    parts += [_value_key(v, depth) for v in fn.__defaults__ or ()]
    parts += [_value_key(v, depth) for _, v in sorted((fn.__kwdefaults__ or {}).items())]
    try:
        parts += [_value_key(cell.cell_contents, depth) for cell in fn.__closure__ or ()]
    except ValueError:  # an empty cell (a name assigned after the function was made)
        return None
    # the globals it reads, by value (an attribute name that is no global is skipped: `pj.Constant` reads `pj`)
    names = sorted(n for n in _global_names(fn.__code__) if n in fn.__globals__)
    parts += [_value_key(fn.__globals__[n], depth) for n in names]
    if any(p is None for p in parts):
        return None
    return ("code", tuple(names), tuple(parts))
