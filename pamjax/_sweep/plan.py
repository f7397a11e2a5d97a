"""A sweep's plan: which path each swept key names (system, signal, initial state or a signal factory), the lane
built from one point's values, and the checks of every point's values against the components' own constraints,
before any solve."""

import difflib
import inspect
import re

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.errors import PamjaxInputError
from .._physics.signals import AbstractSignal
from .._solve.checks import check_parameters, check_start_position, check_start_pressure


def get(obj, parts):
    for p in parts:
        obj = getattr(obj, p)
    return obj


def _split(key):
    parts = key.split(".")
    if parts[0] in ("signal", "y0"):
        return parts[0], parts[1:]
    return "system", parts


class Plan(eqx.Module):
    """Static description of a sweep: which key goes where, and each swept leaf's own shape."""

    keys: tuple = eqx.field(static=True)
    targets: tuple = eqx.field(static=True)  # ("system" | "signal" | "y0" | "factory", parts)
    leaf_shapes: tuple = eqx.field(static=True)


def make_signal(signal, plan, values):
    """The lane's signal: the base signal with its swept leaves replaced, or the factory's signal."""
    if not isinstance(signal, AbstractSignal):
        return signal(dict(values))
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if where == "signal":
            signal = eqx.tree_at(lambda s, parts=parts: get(s, parts), signal, values[key])
    return signal


def lane_system(system, plan, values):
    """The lane's system: the base system with its swept leaves replaced by `values` (a dict key -> array)."""
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if where == "system":
            system = eqx.tree_at(lambda s, parts=parts: get(s, parts), system, values[key])
    return system


def make_lane(system, signal, y0, plan, values):
    """The lane's (system, signal, y0) for one set of swept `values` (a dict key -> array)."""
    system = lane_system(system, plan, values)
    signal = make_signal(signal, plan, values)
    y0_keys = [(key, parts) for key, (where, parts) in zip(plan.keys, plan.targets) if where == "y0"]
    if y0 is None:  # "y0.pressure" etc. are arguments of `initial_state` (position then in equilibrium with them)
        return system, signal, system.initial_state(**{parts[0]: values[key] for key, parts in y0_keys})
    for key, parts in y0_keys:
        y0 = eqx.tree_at(lambda s, parts=parts: get(s, parts), y0, values[key])
    return system, signal, y0


def _check_module(module, name):
    """Re-run the `__check_init__` of every class of `module` (equinox skips them under `tree_at`)."""
    for cls in type(module).__mro__:
        check = cls.__dict__.get("__check_init__")
        if check is not None:
            try:
                check(module)
            except PamjaxInputError as err:
                raise PamjaxInputError(f"over[{name!r}]: {err}") from None


def validate_values(system, signal, y0, plan, values, batch_size):
    """Checks of the swept values against each component's own constraints, batched where the checks allow it
    (they are elementwise `np.all`); per point otherwise."""
    flat = {k: v.reshape((batch_size,) + shape) for (k, v), shape in zip(values.items(), plan.leaf_shapes)}
    for key, v in flat.items():
        if not np.all(np.isfinite(v)):
            bad = int(np.argmin(np.all(np.isfinite(v.reshape(batch_size, -1)), axis=1)))
            raise PamjaxInputError(f"over[{key!r}] must be finite, point {bad} is {v[bad]}")
    check_start(system, y0, plan, flat)

    def check_lanes(vals, n, leaves="scalar"):
        for key, (where, parts), shape in zip(plan.keys, plan.targets, plan.leaf_shapes):
            if where != "system" or (bool(shape) if leaves == "scalar" else key != leaves):
                continue
            lane_system = eqx.tree_at(lambda s, parts=parts: get(s, parts), system, jnp.asarray(vals[key]))
            for i in range(len(parts)):
                sub = get(lane_system, parts[:i])
                if isinstance(sub, eqx.Module):
                    _check_module(sub, key)

    # A non-scalar leaf (a valve's coefficient matrix) is checked one distinct value at a time: its component checks
    # its shape, which a batch of values fails.
    for key, shape in zip(plan.keys, plan.leaf_shapes):
        if shape:
            for value in np.unique(flat[key].reshape(batch_size, -1), axis=0):
                check_lanes({key: value.reshape(shape)}, 1, leaves=key)
    try:
        check_lanes(flat, batch_size)
        batched_ok = True
    except PamjaxInputError:
        raise
    except Exception:  # a check that cannot take an array (e.g. `bool(hi > lo)`): check point by point
        batched_ok = False
    if not batched_ok:
        for i in range(batch_size):
            check_lanes({k: v[i] for k, v in flat.items()}, 1)
    check_magnitudes(system, plan, flat, batch_size)
    # The command must stay in the valve's range at every point: all points at once where the signal's `bounds()`
    # takes arrays (Constant), point by point otherwise.
    signal_keys = [k for k, (w, _) in zip(plan.keys, plan.targets) if w in ("signal", "factory")]
    if not signal_keys and isinstance(signal, AbstractSignal):
        check_bounds(system, signal, None)
        return
    try:
        if not isinstance(signal, AbstractSignal):
            raise TypeError
        check_bounds(system, make_signal(signal, plan, {k: jnp.asarray(v) for k, v in flat.items()}), None)
    except PamjaxInputError:
        pass  # find and name the offending point below
    except Exception:
        pass
    else:
        return
    for i in range(batch_size):
        check_bounds(system, make_signal(signal, plan, {k: jnp.asarray(v[i]) for k, v in flat.items()}),
                      {k: np.asarray(v[i]).tolist() for k, v in flat.items()} | {"index": i})


def check_magnitudes(system, plan, flat, batch_size):
    """`simulate`'s check of a system's parameters (`check_parameters`: the magnitudes that betray another unit,
    9600 kg for 9.6 kg looks like grams, 75 m for a 75 mm stroke like mm) on every lane's system, before any solve;
    a failure named by its swept key and the first point that fails (`over['payload_mass'] at point 1: ...`). The
    components' own checks have passed at every point (`check_lanes`), and the magnitude checks refuse a value beyond
    a bound (a peak above, a low below, `pamjax._core.units.check_setting`), so a set of points passes where the
    points holding each swept entry's lowest and highest value pass: those few systems are checked (~1 ms each), not
    every point's, and the first failing point is found by bisecting the points (one with an own check that takes no
    batch of values, `muscle.max_position`'s `bool(hi > lo)`, cannot be checked with its values batched)."""
    keys = [(key, parts) for key, (where, parts) in zip(plan.keys, plan.targets) if where == "system"]
    if not keys:  # the base system alone, as `simulate` checks it (then remembered: a loop of sweeps pays once)
        check_parameters(system)
        return

    def point(i):
        return lane_system(system, plan, {key: np.asarray(flat[key][i]) for key, _ in keys})

    def fails(stop):  # whether any of the points [0, stop) fails: those at each entry's extremes decide
        extremes = set()
        for key, _ in keys:
            entries = flat[key][:stop].reshape(stop, -1)
            extremes.update(np.argmin(entries, axis=0).tolist() + np.argmax(entries, axis=0).tolist())
        try:
            for i in sorted(extremes):
                check_parameters(point(i))
        except PamjaxInputError:
            return True
        return False

    if not fails(batch_size):
        return
    lo, hi = 0, batch_size  # the first `lo` points pass, the first `hi` fail
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if fails(mid) else (mid, hi)
    try:
        check_parameters(point(hi - 1))
    except PamjaxInputError as err:
        named = [key for key, parts in keys if f"parameter {'.'.join(parts)} " in str(err)]
        if not named:  # a component's own check names its field, not the path: "PolynomialForce: max_pressure = 6"
            named = [key for key, parts in keys if re.search(rf"\b{re.escape(parts[-1])} = ", str(err))][:1]
        if not named:
            raise  # a parameter no point sweeps: named as `simulate` names it
        raise PamjaxInputError(f"over[{named[0]!r}] at point {hi - 1}: {err}") from None


def _names_pressure(parts, pressures=None):
    """Whether a start value's path names a pressure: with a `y0` given, one of its `pressures` (the system's
    `start_pressures(y0)`: "pressure", "regulator.pressure"); without, an `initial_state` keyword such as `pressure`
    or `flexor_pressure` (the contract: `AbstractSystem.initial_state` takes ABSOLUTE pressures)."""
    if pressures is not None:
        return ".".join(parts) in pressures
    return bool(parts) and (parts[-1] == "pressure" or parts[-1].endswith("_pressure"))


def check_start(system, y0, plan, flat):
    """The checks `simulate` applies to a start state, on a sweep's, before any solve: every swept start value that is
    a pressure ("y0.pressure", "y0.flexor_pressure", a pressure of the `y0` given by the system's `start_pressures`:
    "y0.regulator.pressure") an ABSOLUTE pressure > 0 [Pa] at every point, named by its key; every swept start value
    that is a displacement the system names (`start_positions`: "y0.position") metres and inside its stroke; the `y0`
    given finite, its pressures and displacements that are not swept likewise."""
    pressures = None if y0 is None else type(system).start_pressures(system, y0)
    starts = {".".join(parts): key for key, (where, parts) in zip(plan.keys, plan.targets) if where == "y0"}
    # the displacements the system names (`start_positions`: "position", with its stroke) in the start given, or
    # without one among the `initial_state` keywords swept
    state = y0 if y0 is not None else {name: flat[key] for name, key in starts.items()}
    positions = type(system).start_positions(system, state)
    swept = set(starts)
    for name, key in starts.items():
        if _names_pressure(name.split("."), pressures):
            check_start_pressure(flat[key], f"over[{key!r}]", lanes=True)
        if name in positions:
            check_start_position(flat[key], positions[name][1], f"over[{key!r}]", lanes=True, path=f"y0.{name}")
    if y0 is None:
        return
    for path, leaf in jtu.tree_flatten_with_path(y0)[0]:
        name = jtu.keystr(path).lstrip(".")
        if name in swept or isinstance(leaf, jax.core.Tracer):
            continue
        if not np.all(np.isfinite(np.asarray(leaf, dtype=float))):
            raise PamjaxInputError(f"y0 must be finite (no NaN or inf), y0.{name} is {leaf}")
    for name, leaf in pressures.items():
        if name not in swept and not isinstance(leaf, jax.core.Tracer):
            check_start_pressure(leaf, f"y0.{name}", lanes=True)
    for name, (leaf, stroke) in positions.items():
        if name not in swept and not isinstance(leaf, jax.core.Tracer):
            check_start_position(leaf, stroke, f"y0.{name}")


def check_bounds(system, sig, point):
    if not isinstance(sig, AbstractSignal):
        raise PamjaxInputError(f"the signal factory must return a pamjax signal, got {type(sig)}")
    clo, chi = system.command_range
    lo, hi = sig.bounds()
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < clo - 1e-12 or hi > chi + 1e-12:
        where = "" if point is None else f" at sweep point {point}"
        raise PamjaxInputError(
            f"signal (the valve command) must stay within [{clo}, {chi}], its range is [{lo}, {hi}]{where}"
        )


def host_lanes(system, signal, plan, flat, batch_size):
    """(system, signal) pairs that hold every lane's swept values, for checks on the host before any solve (nothing
    traced or solved): one pair with all values batched in its swept leaves, or, where a signal factory does not take
    a batch of values, one pair per lane."""
    values = {k: np.asarray(v) for k, v in flat.items()}
    system = lane_system(system, plan, values)
    try:
        return [(system, make_signal(signal, plan, values))]
    except PamjaxInputError:
        raise
    except Exception:  # a factory that needs one lane's numbers (e.g. `float(v["duty"])`)
        return [(system, make_signal(signal, plan, {k: v[i] for k, v in values.items()})) for i in range(batch_size)]


_STRUCTURES = {}


def structure(system, y0):
    """(initial-state shapes, output channel names) of a system: its state traced once per system structure (not
    solved), its channels its `output_names` and "command"."""
    if y0 is not None:
        return y0, [*system.output_names, "command"]
    key = jtu.tree_structure(system)
    if key not in _STRUCTURES:
        _STRUCTURES[key] = jax.eval_shape(system.initial_state)
    return _STRUCTURES[key], [*system.output_names, "command"]


def make_plan(system, signal, base_state, over, y0_given=True):
    """The `Plan` of `over` ({path: values}), the values broadcast to the batch shape (plus each leaf's own shape),
    and the batch shape. Paths name a leaf of the system, the signal ("signal.…") or the initial state ("y0.…": a
    leaf of the `y0` given, or without one a number `system.initial_state` takes, e.g. "y0.pressure"); with a signal
    factory, any other name goes to the factory, which must read it (`check_factory_keys`)."""
    factory = not isinstance(signal, AbstractSignal)
    keys, targets, leaf_shapes, arrays = [], [], [], []
    for key, value in over.items():
        if not y0_given and isinstance(key, str) and _split(key)[0] == "y0":
            where, parts, leaf = "y0", _initial_state_keyword(system, key), 0.0
        else:
            where, parts, leaf = _resolve(system, signal, base_state, factory, key)
        shape = () if leaf is None else tuple(np.shape(leaf))
        try:
            v = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise PamjaxInputError(f"over[{key!r}] must be numbers, got {value!r}") from None
        if v.ndim < len(shape) or v.shape[v.ndim - len(shape):] != shape:
            raise PamjaxInputError(f"over[{key!r}] must end in the leaf's shape {shape}, got shape {v.shape}")
        keys.append(key)
        targets.append((where, tuple(parts)))
        leaf_shapes.append(shape)
        arrays.append(v)
    try:
        batch_shape = np.broadcast_shapes(*[a.shape[: a.ndim - len(s)] for a, s in zip(arrays, leaf_shapes)])
    except ValueError:
        raise PamjaxInputError(
            "over values must broadcast together, got shapes "
            + ", ".join(f"{k}: {a.shape}" for k, a in zip(keys, arrays))
        ) from None
    for k, a, s in zip(keys, arrays, leaf_shapes):  # no point to sweep: refused by name, not an IndexError later
        if int(np.prod(a.shape[: a.ndim - len(s)])) == 0:
            raise PamjaxInputError(f"over[{k!r}] holds no values (shape {a.shape}): give at least one")
    values = {k: np.broadcast_to(a, batch_shape + s) for k, a, s in zip(keys, arrays, leaf_shapes)}
    plan = Plan(tuple(keys), tuple(targets), tuple(leaf_shapes))
    check_factory_keys(system, signal, plan, values)
    return plan, values, batch_shape


def _initial_state_keyword(system, key):
    """The one keyword of `system.initial_state` a swept "y0.<name>" names (the sweep's start is built from it)."""
    parts = _split(key)[1]
    names = [n for n, p in inspect.signature(system.initial_state).parameters.items()
             if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    if len(parts) != 1 or parts[0] not in names:
        raise PamjaxInputError(
            f"over[{key!r}]: without a y0, a swept start names a number {type(system).__name__}.initial_state takes "
            f"({', '.join(f'y0.{n}' for n in names) or 'none'}); to sweep another leaf of the start, pass y0")
    return parts


def _resolve(system, signal, base_state, factory, key):
    """(where, parts, leaf) of one swept key; the leaf is None for a factory's key."""
    if not isinstance(key, str) or not key:
        raise PamjaxInputError(f"over keys must be path strings like 'valve.supply_pressure', got {key!r}")
    where, parts = _split(key)
    root = {"system": system, "signal": signal, "y0": base_state}[where]
    try:
        leaf = get(root, parts) if not (where == "signal" and factory) else None
    except AttributeError:
        leaf = None
        if not factory:
            raise PamjaxInputError(no_leaf(key, where, root, parts)) from None
        where, parts = "factory", [key]
    if where == "signal" and factory:
        where = "factory"
    if where != "factory" and not isinstance(leaf, (jax.Array, np.ndarray, float, int, jax.ShapeDtypeStruct)):
        raise PamjaxInputError(f"over[{key!r}] must name an array parameter, it names a {type(leaf).__name__}")
    return where, parts, leaf


def no_leaf(key, where, root, parts, also=""):
    """The message for a swept path that names no leaf of the system, signal or start (`also`: what follows), with
    the nearest leaf's path ("payload_mas": did you mean 'payload_mass'?)."""
    names = [jtu.keystr(path).lstrip(".") for path, _ in jtu.tree_flatten_with_path(root)[0]]
    prefix = "" if where == "system" else f"{where}."
    close = difflib.get_close_matches(".".join(parts), names, n=1)
    hint = f"; did you mean {prefix + close[0]!r}?" if close else ""
    return f"over[{key!r}]: the {where} ({type(root).__name__}) has no leaf {'.'.join(parts)!r}{also}{hint}"


class _ReadKeys(dict):
    """A point's values handed to a signal factory, recording the keys it reads (by item, `get` or `in`); one that
    iterates over them (`dict(v)`, `**v`, `v.items()`) reads them all."""

    def __init__(self, values):
        super().__init__(values)
        self.read = set()

    def __getitem__(self, key):
        self.read.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.read.add(key)
        return super().get(key, default)

    def __contains__(self, key):
        self.read.add(key)
        return super().__contains__(key)

    def __iter__(self):
        self.read.update(super().keys())
        return super().__iter__()

    def keys(self):
        self.read.update(super().keys())
        return super().keys()

    def values(self):
        self.read.update(super().keys())
        return super().values()

    def items(self):
        self.read.update(super().keys())
        return super().items()


def check_factory_keys(system, signal, plan, values):
    """`PamjaxInputError` for a swept key a signal factory never reads that names no leaf of the system (a typo:
    `{"payload_mas": [5, 15]}` went to the factory, which ignored it: every point ran the base payload, status 0),
    named with the nearest leaf's path, as without a factory. The factory is called once on the host with the first
    point's values (the lanes call it with each point's)."""
    keys = [key for key, (where, _) in zip(plan.keys, plan.targets) if where == "factory"]
    if isinstance(signal, AbstractSignal) or not keys:
        return
    point = _ReadKeys({k: np.asarray(v).reshape((-1,) + shape)[0]
                       for (k, v), shape in zip(values.items(), plan.leaf_shapes)})
    signal(point)
    for key in keys:
        if key in point.read:
            continue
        where, parts = _split(key)
        unread = (f" and the signal factory never reads it (a key that names no leaf of the system goes to the "
                  f"factory; it reads {sorted(point.read)})")
        if where == "system":
            raise PamjaxInputError(no_leaf(key, where, system, parts, unread))
        raise PamjaxInputError(f"over[{key!r}]: with a signal factory every signal.* key goes to the factory, which "
                               f"never reads this one (it reads {sorted(point.read)}): have the factory read it, or "
                               "drop it")
