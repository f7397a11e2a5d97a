"""The one place pamjax reads private internals of its dependencies, each where no public route exists.

`tests/test_private.py` fails when any of these names moves, so an upgrade of JAX, equinox or diffrax
that breaks one is caught by the test suite, not by a user. Everything else in pamjax uses public APIs only.
"""

import contextlib
import threading


@contextlib.contextmanager
def equinox_errors_as_nan():
    """Trace with equinox's run-time checks returning NaN instead of raising through a host callback.

    diffrax checks its save times with `eqx.error_if` inside every solve, and equinox raises such errors from a host
    callback; JAX refuses to write a program with a host callback to its persistent compilation cache, so every fit
    with an adaptive solve would compile again in every run. A fit treats non-finite residuals as a failed trial step,
    so NaN is the right failure there. equinox reads `EQX_ON_ERROR` from the environment once, at import: the only
    switch afterwards is its private module-level name `equinox._errors.EQX_ON_ERROR`."""
    import equinox._errors as eqx_errors

    # Counted: a fit's two programs are traced in two threads whose uses overlap; the setting is restored when the
    # last one ends (a plain save/restore per use could leave "nan" set, or restore "raise" under a tracing thread).
    with _ERRORS_AS_NAN["lock"]:
        if _ERRORS_AS_NAN["depth"] == 0:
            _ERRORS_AS_NAN["old"] = eqx_errors.EQX_ON_ERROR
            eqx_errors.EQX_ON_ERROR = "nan"
        _ERRORS_AS_NAN["depth"] += 1
    try:
        yield
    finally:
        with _ERRORS_AS_NAN["lock"]:
            _ERRORS_AS_NAN["depth"] -= 1
            if _ERRORS_AS_NAN["depth"] == 0:
                eqx_errors.EQX_ON_ERROR = _ERRORS_AS_NAN["old"]


_ERRORS_AS_NAN = {"lock": threading.Lock(), "depth": 0, "old": None}


def jax_backends_initialized() -> bool:
    """Whether JAX has started its backends (after which XLA flags and device counts no longer apply). JAX has no
    public query that does not itself start them; False when the private name has moved."""
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except Exception:
        return False


def jax_at_top_level() -> bool:
    """Whether no JAX transformation (jit, vmap, grad, ...) is tracing right now: only then may a `jax.jit` carry its
    own `compiler_options` (JAX refuses them on a nested jit). False when the private name has moved (the caller then
    takes the plain program)."""
    try:
        from jax._src import core

        return bool(core.trace_state_clean())
    except Exception:
        return False


def jax_coordinator_address():
    """The coordinator address `jax.distributed.initialize` connected to, or None (JAX keeps it in a private global
    state only; None too when that name has moved)."""
    try:
        from jax._src import distributed

        return distributed.global_state.coordinator_address
    except (ImportError, AttributeError):
        return None


def diffrax_result_code(result):
    """The integer code of a diffrax result (`sol.result`): the one array leaf of its pytree (an equinox
    enumeration item, whose integer is a private field)."""
    import jax

    (code,) = jax.tree_util.tree_leaves(result)
    return code


def diffrax_result_message(code):
    """The message of diffrax result `code` (first line), or None for a code diffrax does not have (its table of
    messages is private)."""
    import diffrax as dfx

    messages = getattr(dfx.RESULTS, "_index_to_message", None)
    if messages is not None and 0 <= code < len(messages):
        return messages[code].split("\n")[0]
    return None
