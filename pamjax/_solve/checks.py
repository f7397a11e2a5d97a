"""A system's parameters checked before a solve, however the system was made (a constructor, a model file,
`eqx.tree_at`, a transformation):

- `check_parameters`: every component's own checks (`__check_init__`: `payload_mass must be > 0`), which a model
  changed with `eqx.tree_at` skipped, and the magnitudes that betray another unit (`check_setting`: 9600 kg looks like
  grams); on concrete values, in Python, before anything is traced;
- `runtime_checks`: the same checks on values that are traced (inside `jax.jit`, `jax.vmap`, `jax.grad`), attached
  to those values as run-time errors naming the parameter (`equinox.error_if`), and the command's range at the
  output times;
- `batched_parameters`: parameters that hold several values where a system takes one (`payload_mass = [9.6, 9.6]`
  in a model file, or a batch built with `eqx.tree_at`).

A system's state leaves hold one value each (a pressure, a position, ...). A parameter array with a leading axis too
many broadcasts into the state's rate (the accelerations of two payloads are two), and the solve then fails deep
inside JAX ("scan body function carry input and carry output must have equal types"). Shapes alone tell (one
`jax.eval_shape` of the vector field at the system's `state_scale`, a state of constants: ~20 ms, nothing compiled
or run): the rate has the state's shape, or it does not, and then the parameter whose first entry alone restores it
is the one. Batches of models are what `jax.vmap` and `pamjax.sweep` are for.
"""

import contextlib
import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import floats_as_arrays
from .._core.custom_types import RealScalar
from .._core.errors import PamjaxInputError, concrete_values, traced_checks
from .._core.private import jax_at_top_level
from .._core.units import MIN_ABSOLUTE_PA, check_absolute_pressure, check_setting, checks_setting
from .._systems.base import AbstractSystem
from .hints import negative_inflow
from .trajectory import RESULT_NONPHYSICAL


def _components(obj, path=""):
    """(path, component) for `obj` and every component inside it, depth first."""
    if isinstance(obj, eqx.Module):
        yield path, obj
        for f in dataclasses.fields(obj):
            yield from _components(getattr(obj, f.name), f"{path}.{f.name}" if path else f.name)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            yield from _components(v, f"{path}.{i}" if path else str(i))
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _components(v, f"{path}.{k}" if path else str(k))


def _own_checks(component):
    """Run `component`'s `__check_init__`s (each class of its MRO that defines one, base classes first), as its
    constructor did."""
    for klass in reversed(type(component).__mro__):
        check = klass.__dict__.get("__check_init__")
        if check is not None:
            check(component)


_CHECKED = []  # the last systems `check_parameters` passed (kept alive, so that their ids stay theirs)
_REMEMBERED = 8


def prepared(system):
    """(`floats_as_arrays(system)`, whether it holds a tracer). Outside any JAX transformation, a system given to one
    of the last few calls is not walked again: modules are immutable, so the same object gives the same answer (two
    walks of the MAS-10's leaves cost ~60 µs of a 1 ms `simulate`), and a system with a Python float set by
    `eqx.tree_at` becomes the same array-holding system at every call, which `check_parameters` then knows. (Inside a
    transformation the floats' arrays may be staged as tracers: walked at every call, as they were without it.)"""
    top = jax_at_top_level()
    for given, ready in _PREPARED if top else ():
        if given is system:
            return ready, False
    ready = floats_as_arrays(system)
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(ready))
    if top and not traced:
        _PREPARED.append((system, ready))  # both kept alive, so that their ids stay theirs
        del _PREPARED[:-_REMEMBERED]
    return ready, traced


_PREPARED = []


def check_parameters(system, where="system"):
    """Every component's own checks and the unit-magnitude checks of every concrete parameter of `system`; a
    `PamjaxInputError` names the parameter. Traced values are left to `runtime_checks`. The last few systems that
    passed are remembered (immutable: the same object passes again), so that a loop simulating one system with
    many signals pays the ~2 ms once."""
    if any(s is system for s in _CHECKED):
        return
    for path, component in _components(system):
        _own_checks(component)
        for f in dataclasses.fields(component):
            value = getattr(component, f.name)
            if checks_setting(f.name) and eqx.is_array(value) and not isinstance(value, jax.core.Tracer):
                check_setting(f"{path}.{f.name}" if path else f.name, np.asarray(value), f"{where} parameter")
    if not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(system)):
        _CHECKED.append(system)
        del _CHECKED[:-_REMEMBERED]


def check_finite_state(state, name):
    """Refuse a state (a start state, an operating point, a guess) with a concrete leaf that is not finite, naming
    the leaf (`y0.pressure must be finite (no NaN or inf), got nan`). Traced leaves have no value to check."""
    for path, leaf in jax.tree_util.tree_flatten_with_path(state)[0]:
        if isinstance(leaf, jax.core.Tracer):
            continue
        value = np.asarray(leaf, dtype=float)
        if not np.all(np.isfinite(value)):
            where = f"{name}.{_name(path)}" if path else name
            raise PamjaxInputError(f"{where} must be finite (no NaN or inf), got "
                                   f"{np.array2string(value, threshold=6)}")


# The farthest a start position may lie outside the stroke its system names, as a fraction of that stroke: the end
# stops let the payload press in by ~0.6 mm (the MAS-10's 630 N on the stops' 1e6 N/m), and a position read off a
# bench's sensor may sit a little past a stop; 5 % of the stroke (4.75 mm of the MAS-10's 95 mm) admits both and
# refuses a start the stops would fling the payload from (0.5 m for the MAS-10: was "minimum step size reached").
START_STROKE_MARGIN = 0.05


def check_positive_number(value, name):
    """A solver setting (a tolerance, a step [s]) one finite number > 0: a Python or NumPy number or a 0-d array, not
    a bool, else `PamjaxInputError` naming it. Returns it as a NumPy float; a traced value unchecked, as None.
    `simulate`'s check of rtol, atol, dt0, grid_step, and `simulate_closed_loop`'s."""
    if isinstance(value, jax.core.Tracer):
        return None
    number = (isinstance(value, (int, float, np.ndarray, np.generic, jax.Array))
              and not isinstance(value, (bool, np.bool_)))
    v = np.asarray(value, dtype=float) if number else None
    if v is None or v.ndim != 0 or not np.isfinite(v) or v <= 0:
        raise PamjaxInputError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def check_start_pressure(pressure, name, lanes=False):
    """A start pressure ABSOLUTE pascal: > 0, and not bar or gauge by its magnitude (1.01325 or 0 refused, the likely
    unit named); concrete values only. `lanes`: one value per point of a sweep, the first bad one named by its index.
    `simulate`'s check of `y0` and `sweep`'s of its start values."""
    v = concrete_values(pressure)
    if v is not None and not np.all(v > 0):
        if not lanes:
            raise PamjaxInputError(f"{name} must be an ABSOLUTE pressure > 0 [Pa], got {pressure}")
        v = v.reshape(-1)
        bad = int(np.argmin(v > 0))
        raise PamjaxInputError(f"{name} must be an ABSOLUTE pressure > 0 [Pa], point {bad} is {v[bad]}")
    check_absolute_pressure(pressure, name)


def check_start_state(system, y0, name="y0"):
    """`simulate`'s checks of a start state `y0` (None: nothing to check): a state of the system's own structure
    (`check_state_structure`), its leaves the shapes of the system's state (`check_state_shapes`: one start state,
    not a batch); concrete leaves only: every leaf finite;
    the pressures the system names (`start_pressures`) ABSOLUTE pascal, > 0 and not bar or gauge by magnitude; the
    displacements it names (`start_positions`) metres (not mm by magnitude) and inside their stroke, give or take
    `START_STROKE_MARGIN`. `name`: what the errors call the state (a linearisation's "state" or "guess", a closed
    loop's "y0.plant")."""
    if y0 is None:
        return
    check_state_structure(system, y0, name)
    check_state_shapes(system, y0, name)
    check_finite_state(y0, name)
    for path, pressure in type(system).start_pressures(system, y0).items():  # y0.pressure, y0.regulator.pressure
        check_start_pressure(pressure, f"{name}.{path}")
    for path, (position, stroke) in type(system).start_positions(system, y0).items():
        check_start_position(position, stroke, f"{name}.{path}")


def resolve_stepping(system, stepping):
    """The stepping for `system`: "auto" is "adaptive" for smooth systems, and for hybrid ones (stick-slip
    friction) the fixed grid: "pwm" with a switching valve, "grid" with a continuous one. "grid" is refused for a
    switching valve: its uniform steps read the command as one duty at each RK4 stage, so the duty was not latched
    per PWM period nor the valve's state carried from the period before, and the result was silently off (MAS-10,
    Triangle(0.05, 0.95, 1.0) over 2 s: 27-30 kPa and 2.6-3.3 mm from the exact-edge solve, not converging as the
    step shrank: 29.6, 27.7, 27.6 kPa at 1e-3, 1e-4, 1e-5 s), where "pwm" puts its edges on the grid (18 Pa)."""
    if stepping not in ("auto", "adaptive", "pwm", "grid"):
        raise PamjaxInputError(f"stepping must be 'auto', 'adaptive', 'pwm' or 'grid', got {stepping!r}")
    switches = system.valve.switches
    if stepping == "auto":
        return ("pwm" if switches else "grid") if system.hybrid else "adaptive"
    if stepping == "adaptive" and system.hybrid:
        raise PamjaxInputError(
            "this system is hybrid (stick-slip friction, e.g. KarnoppFriction): its modes switch at events, which "
            "the fixed-grid integrator locates; use stepping='auto' (or 'pwm' for a switching valve, 'grid' "
            "otherwise), or CoulombViscousFriction for an adaptive solve"
        )
    if stepping == "pwm" and not switches:
        raise PamjaxInputError(
            f"stepping='pwm' needs a switching valve (its PWM edges define the grid), got {type(system.valve).__name__}"
            "; use stepping='grid' (uniform fixed steps) or 'adaptive'"
        )
    if stepping == "grid" and switches:
        other = "stepping='auto'" if system.hybrid else "stepping='adaptive'"
        raise PamjaxInputError(
            f"stepping='grid' is for continuous valves (averaged, proportional); {type(system.valve).__name__} "
            "switches on PWM edges, which uniform steps straddle without latching the duty per period (tens of kPa "
            f"off); use stepping='pwm' (its edges on the grid, the exact-edge model) or {other}"
        )
    return stepping


_STRUCTURES = []  # (system, its state's pytree structure) of the last few systems at the top level (kept alive)


def check_state_structure(system, y0, name="y0"):
    """Refuse a start state `y0` that is no state of `system`: its pytree structure not that of the system's state
    (its `state_scale()`'s, shape-inferred: ~0.7 ms, nothing compiled, once per system object). Another plant's state
    (the identified plant's, with a stick-slip friction leaf, given to a smooth plant) failed inside the solve with a
    raw pytree ValueError."""
    if not isinstance(system, AbstractSystem):
        return
    found = [structure for known, structure in _STRUCTURES if known is system]
    template = None
    if not found:
        template = jax.eval_shape(system.state_scale)
        found = [jax.tree_util.tree_structure(template)]
        if jax_at_top_level():
            _STRUCTURES.append((system, found[0]))
            del _STRUCTURES[:-_REMEMBERED]
    if jax.tree_util.tree_structure(y0) == found[0]:
        return
    template = jax.eval_shape(system.state_scale) if template is None else template

    def described(state):
        paths = [_name(path) for path, _ in jax.tree_util.tree_flatten_with_path(state)[0]]
        return f"a {type(state).__name__} with leaves ({', '.join(paths)})"

    raise PamjaxInputError(
        f"{name} must be a state of the system ({type(system).__name__}): {described(template)}, as its "
        f"initial_state() gives; got {described(y0)}: the state of another system (another friction model, "
        "regulator or valve) does not fit it")


def check_state_shapes(system, y0, name="y0"):
    """Refuse a start state `y0` whose leaves do not have the shapes of the system's own state (`initial_state()`):
    one with several values in a leaf (`initial_state(pressure=jnp.array([2e5, 3e5]))`, a batch) failed in the
    solve with JAX's raw carry-type `TypeError` (a muscle), or came back as a trajectory of shape (n, 2) (a tank).
    Cheap where it matters (`simulate` costs ~1 ms): nothing is done for a state whose every leaf is 0-d (no leaf
    to hold a batch in), and the system's state is shape-inferred (`jax.eval_shape` of `initial_state`, ~1.5 ms)
    only where a leaf's shape differs from its `state_scale()`'s (~0.2 ms)."""
    leaves = jax.tree_util.tree_leaves(y0)
    if not isinstance(system, AbstractSystem) or all(np.ndim(leaf) == 0 for leaf in leaves):
        return
    mismatch = _shape_mismatch(system.state_scale(), y0)
    if mismatch is None:
        return
    try:
        mismatch = _shape_mismatch(jax.eval_shape(system.initial_state), y0)
    except Exception:  # noqa: BLE001 - a system whose initial_state needs arguments: the scale's shapes decide
        pass
    if mismatch is not None:
        path, shape, wanted = mismatch
        raise PamjaxInputError(
            f"{name}.{path} has shape {shape} where the system's state (system.initial_state()) holds "
            f"{'one number' if not wanted else f'shape {wanted}'}: simulate takes one start state; several are a "
            "sweep (pamjax.sweep over 'y0.pressure', ...) or jax.vmap over simulate")


def _shape_mismatch(template, y0):
    """(path, y0's shape, the template's) of the first leaf of `y0` whose shape is not `template`'s; None where
    every leaf's is, or where the two are not states of one structure (left to the solve's own errors)."""
    found, structure = jax.tree_util.tree_flatten_with_path(y0)
    wanted = jax.tree_util.tree_leaves(template)
    if structure != jax.tree_util.tree_structure(template):
        return None
    for (path, leaf), want in zip(found, wanted):
        if np.shape(leaf) != tuple(np.shape(want)):
            return _name(path), tuple(np.shape(leaf)), tuple(np.shape(want))
    return None


def check_start_position(position, stroke, name, lanes=False, path=None):
    """A start displacement [m] (concrete values only): metres (30 for 30 mm refused, "looks like mm") and inside
    `stroke` (lowest, highest) [m] (None: unchecked), give or take `START_STROKE_MARGIN`. `lanes`: one value per point
    of a sweep, the first bad one named by its index; `path` the state's own path ("y0.position") where `name` is
    another ("over['y0.position']"). `simulate`'s check of `y0` and `sweep`'s of its start values."""
    x = concrete_values(position)
    if x is None:
        return
    check_setting(path or name, x, "start state")
    lo, hi = (None, None) if stroke is None else (concrete_values(b) for b in stroke)
    if lo is None or hi is None:
        return
    margin = START_STROKE_MARGIN * (hi - lo)
    outside = (x < lo - margin) | (x > hi + margin)
    if np.any(outside):
        shown = np.array2string(x, threshold=6)
        if lanes:
            bad = int(np.argmax(np.reshape(outside, -1)))
            shown = f"{float(np.reshape(x, -1)[bad]):.6g} at point {bad}"
        raise PamjaxInputError(
            f"{name} = {shown} m lies outside the stroke its system allows, "
            f"[{float(np.min(lo)):.6g}, {float(np.max(hi)):.6g}] m (the muscle's min_position, max_position; "
            f"{START_STROKE_MARGIN:.0%} of it beyond either end is admitted, for the end stops' give): start "
            "inside it (position in metres, positive = contraction)"
        )


def runtime_checks(system, signal, ts, command_range):
    """`(system, signal)` with the checks that meet traced values attached as run-time errors (`equinox.error_if`
    on those values): the components' own checks, and the command within `command_range` at the times `ts` (when
    the signal is traced). Unchanged when nothing is traced. Under `jax.vmap` alone the checks run at once: a
    failed one is raised as a `PamjaxInputError` here."""
    try:
        return _runtime_checks(system, signal, ts, command_range)
    except Exception as err:
        named = [line.strip() for line in str(err).splitlines() if "(checked at run time" in line]
        if not named:
            raise
        raise PamjaxInputError(named[0].split("EquinoxRuntimeError: ")[-1]) from None


@contextlib.contextmanager
def naming_batched(system):
    """A parameter with an axis too many fails while the solve is traced (JAX's carry-type `TypeError`): named."""
    try:
        yield
    except (TypeError, ValueError):
        found = batched_parameters(system, quiet=True)
        if found:
            raise PamjaxInputError(describe_batched(found)) from None
        raise


def _runtime_checks(system, signal, ts, command_range):
    with traced_checks() as found:
        for _, component in _components(system):
            _own_checks(component)
    if found:
        system = _attach(system, found)
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(signal)):
        lo, hi = command_range
        u = jax.vmap(signal)(jnp.asarray(ts, dtype=float))
        failed = jnp.any((u < lo - 1e-12) | (u > hi + 1e-12) | ~jnp.isfinite(u))
        message = (f"signal (the valve command, e.g. duty ratio) must stay within [{lo}, {hi}] (checked at run time, "
                   "at the output times: the signal is traced by jit/vmap/grad)")
        signal = jax.tree_util.tree_map(
            lambda x: eqx.error_if(x, failed, message) if isinstance(x, jax.core.Tracer) else x, signal)
    return system, signal


def _attach(tree, found):
    """`tree` with each traced leaf of `found` (tracer, failed, message) carrying its run-time errors."""
    checks = {}
    for tracer, failed, message in found:
        checks.setdefault(id(tracer), []).append((failed, message))

    def attach(x):
        for failed, message in checks.get(id(x), ()):
            x = eqx.error_if(x, failed, message)
        return x

    return jax.tree_util.tree_map(attach, tree)


_SCALAR_TYPES = (RealScalar, RealScalar | None)  # the annotations of a one-number parameter (after its converter)


def _name(path):
    return ".".join(str(getattr(k, "name", getattr(k, "key", getattr(k, "idx", k)))) for k in path)


def _fine(system, command):
    """Whether `system`'s vector field keeps the shape of its state (its `state_scale`, a state of constants), by
    shape inference only (~20 ms)."""
    scale = system.state_scale()
    rate = jax.eval_shape(lambda s, y: s.vector_field(jnp.zeros(()), y, command), system, scale)
    return [np.shape(x) for x in jax.tree_util.tree_leaves(scale)] == [x.shape for x in jax.tree_util.tree_leaves(rate)]


def batched_parameters(system, quiet=False):
    """[(path, shape, the shape it fits with)] of the array parameters of `system` with axes too many (several
    values where the system takes one): with each one's first entry alone (along one leading axis, or more) the
    vector field keeps the state's shape. Empty for a system whose vector field keeps it (the usual case: one shape
    inference), and for anything that is not a system."""
    if quiet:  # the diagnosis of a failure: it must not replace the failure it explains
        try:
            return batched_parameters(system)
        except Exception:  # noqa: BLE001
            return []
    if not isinstance(system, AbstractSystem):
        return _wrapped_batched(system, "") if isinstance(system, eqx.Module) else []
    lo, hi = (float(np.min(b)) for b in system.command_range)
    middle = 0.5 * (lo + hi) if np.isfinite(lo + hi) else 0.0
    # the system's own command: one number, or a (flexor, extensor) pair for a joint, whose range is one regulator's
    # (a scalar command failed the joint's own shape check, and every trial below with it: nothing was found)
    commands = [jnp.asarray(middle), jnp.full((2,), middle)]

    def fine(candidate):
        for command in commands:
            try:
                if _fine(candidate, command):
                    return True
            except Exception:  # noqa: BLE001, PERF203 - the shapes do not even combine (any error of shape inference)
                continue
        return False

    if fine(system):
        return []
    dynamic, static = eqx.partition(system, eqx.is_array)
    flat, treedef = jax.tree_util.tree_flatten_with_path(dynamic)
    leaves = [leaf for _, leaf in flat]
    found = []
    for k, leaf in enumerate(leaves):
        for axes in range(1, np.ndim(leaf) + 1):  # the first entry along one, two, ... leading axes
            if 0 in np.shape(leaf)[:axes]:
                break
            trial = list(leaves)
            trial[k] = leaf[(0,) * axes]
            if fine(eqx.combine(jax.tree_util.tree_unflatten(treedef, trial), static)):
                found.append((_name(flat[k][0]), tuple(np.shape(leaf)), tuple(np.shape(trial[k]))))
                break
    return found


def _wrapped_batched(node, path):
    """`batched_parameters` of a model that wraps systems (a `Rig`: its plant, sensors and runs): each system's, its
    path prefixed, and every array with axes where its field is declared `RealScalar` (a sensor's gain, a run's
    supply pressure), which no shape inference of the plant sees (they reached the solve as raw TypeErrors)."""
    prefix = f"{path}." if path else ""
    if isinstance(node, AbstractSystem):
        return [(prefix + p, shape, wanted) for p, shape, wanted in batched_parameters(node)]
    if isinstance(node, dict):
        return [f for k, v in node.items() for f in _wrapped_batched(v, f"{prefix}{k}")]
    if isinstance(node, list | tuple):
        return [f for i, v in enumerate(node) for f in _wrapped_batched(v, f"{prefix}{i}")]
    if not isinstance(node, eqx.Module):
        return []
    found = []
    for f in dataclasses.fields(node):
        value = getattr(node, f.name, None)
        if eqx.is_array(value) and f.type in _SCALAR_TYPES and np.ndim(value) > 0:
            found.append((prefix + f.name, tuple(np.shape(value)), ()))
        elif not eqx.is_array(value):
            found += _wrapped_batched(value, prefix + f.name)
    return found


def describe_batched(found):
    """The sentence naming `batched_parameters`' findings."""
    def one(path, shape, wanted):
        wanted = "one number" if not wanted else f"shape {wanted}"
        return f"parameter {path!r} has shape {shape} where the model takes {wanted}"

    return ("; ".join(one(*f) for f in found) + ": it would make the state hold several values too, and the solve "
            "fail; give the value the model takes (a batch of models is simulated with jax.vmap over simulate, or "
            "pamjax.sweep)")


def vacuum(traj, system, signal, t0, y0):
    """A solve that succeeded with the chamber drawn below half an atmosphere, by a valve that empties a chamber at
    atmospheric pressure (negative inflow: a flow coefficient's sign flipped), is a failure: RESULT_NONPHYSICAL, NaN
    outputs. (A run over 2 s of such a model turned non-finite; over 0.5 s it "succeeded" at 6,600 Pa abs.) The
    diagnosis runs only when the pressure is that low."""
    pressure = traj.outputs.get("pressure") if isinstance(traj.outputs, dict) else None
    if pressure is None or int(traj.result) != 0:
        return traj
    low = np.asarray(pressure)
    if not (low.size and np.nanmin(low) < MIN_ABSOLUTE_PA) or negative_inflow(system, signal, t0, y0) is None:
        return traj
    outputs = jax.tree_util.tree_map(lambda a: jnp.full_like(a, jnp.nan), traj.outputs)
    return eqx.tree_at(lambda tr: (tr.outputs, tr.result), traj,
                       (outputs, jnp.asarray(RESULT_NONPHYSICAL, dtype=jnp.asarray(traj.result).dtype)))
