"""Input validation shared by all components.

Checks on concrete values raise `PamjaxInputError` (a `ValueError`) naming the offending argument, at construction
time, before any solve. Inside `jit`/`vmap`/`grad` values are tracers and cannot be inspected in Python; there the
entry points (`simulate`, `fit`, `sweep`) validate concrete inputs before tracing.
"""

import contextlib

import jax
import numpy as np
from jax.core import Tracer


class PamjaxInputError(ValueError):
    """A bad input, named in the message (argument, expected, got)."""


class PamjaxSolveError(RuntimeError):
    """The ODE solve failed (too many steps, non-finite state, ...); the message names the cause."""


def require_float64(caller):
    """pamjax's physics is float64 (pressures ~1e5 Pa next to flows ~1e-3 kg/s): refuse to run in float32."""
    if not jax.config.jax_enable_x64:
        raise PamjaxInputError(
            f"{caller} needs float64: call jax.config.update('jax_enable_x64', True) at the start of your program "
            "(before any array is made). Without it JAX computes in float32, which loses the pressure and flow "
            "resolution the models and their gradients need."
        )


def concrete_values(x):
    """The value as a NumPy array, or None when it is traced (no concrete value to check)."""
    if isinstance(x, Tracer):
        return None
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        return None


_TRACED = []  # the open `traced_checks` collections (innermost last)


@contextlib.contextmanager
def traced_checks():
    """Collect the checks that meet traced values (inside jit, vmap or grad they cannot be decided in Python): the
    context yields a list that fills with (tracer, failed, message), `failed` a traced boolean. `simulate` attaches
    them to the solve as run-time errors (`equinox.error_if`), so that a bad parameter inside `jax.jit`/`jax.vmap`
    is named ("MuscleSystem.payload_mass must be > 0 and finite") instead of surfacing as a solver failure."""
    found = []
    _TRACED.append(found)
    try:
        yield found
    finally:
        _TRACED.pop()


def _traced(x, failed, name, expected):
    """Record a check on traced `x` (`failed(x)`: traced bool) when `traced_checks` is collecting."""
    if _TRACED and isinstance(x, Tracer):
        import jax.numpy as jnp

        _TRACED[-1].append((x, jnp.any(failed(x)), f"{name} must be {expected} (checked at run time: the value is "
                                                   "traced by jit/vmap/grad)"))


def _fail(name, expected, value):
    raise PamjaxInputError(f"{name} must be {expected}, got {np.array2string(np.asarray(value), threshold=6)}")


def check_finite(x, name):
    v = concrete_values(x)
    if v is not None and not np.all(np.isfinite(v)):
        _fail(name, "finite (no NaN or inf)", v)
    _traced(x, lambda a: ~jax.numpy.isfinite(a), name, "finite (no NaN or inf)")


def check_positive(x, name):
    v = concrete_values(x)
    if v is not None and not np.all(v > 0):
        _fail(name, "> 0 and finite", v)
    _traced(x, lambda a: ~(a > 0), name, "> 0 and finite")
    check_finite(x, name)


def check_nonnegative(x, name):
    v = concrete_values(x)
    if v is not None and not np.all(v >= 0):
        _fail(name, ">= 0 and finite", v)
    _traced(x, lambda a: ~(a >= 0), name, ">= 0 and finite")
    check_finite(x, name)


def check_in_open_interval(x, lo, hi, name):
    v = concrete_values(x)
    if v is not None and not np.all((v > lo) & (v < hi)):
        _fail(name, f"in the open interval ({lo}, {hi})", v)
    _traced(x, lambda a: ~((a > lo) & (a < hi)), name, f"in the open interval ({lo}, {hi})")


def check_in_closed_interval(x, lo, hi, name):
    v = concrete_values(x)
    if v is not None and not np.all((v >= lo) & (v <= hi)):
        _fail(name, f"in [{lo}, {hi}]", v)
    _traced(x, lambda a: ~((a >= lo) & (a <= hi)), name, f"in [{lo}, {hi}]")


def check_progress(progress):
    """A `progress` argument: True, False (or None) or a callable taking each line, else `PamjaxInputError` before
    any work (`progress="yes"` failed with a raw TypeError after the first chunk or fit had run)."""
    if not (isinstance(progress, bool) or progress is None or callable(progress)):
        raise PamjaxInputError(f"progress must be True, False or a callable taking each progress line, got "
                               f"{progress!r}")


def check_count(x, name, what="a positive int"):
    """`x` a whole count >= 1 (a Python or NumPy integer, not a bool), e.g. a step budget (`max_steps`)."""
    if not (isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_)) and x >= 1):
        raise PamjaxInputError(f"{name} must be {what}, got {x!r}")


def check_time_grid(ts, name="ts"):
    """A 1-D, finite, strictly increasing time grid with at least one point."""
    v = concrete_values(ts)
    if v is None:
        return
    if v.ndim != 1 or v.size < 1:
        raise PamjaxInputError(f"{name} must be a 1-D array of times [s] with at least one entry, got shape {v.shape}")
    check_finite(v, name)
    if v.size > 1 and not np.all(np.diff(v) > 0):
        bad = int(np.argmin(np.diff(v) > 0))
        raise PamjaxInputError(
            f"{name} must be strictly increasing; {name}[{bad + 1}] = {v[bad + 1]} does not exceed "
            f"{name}[{bad}] = {v[bad]}"
        )
