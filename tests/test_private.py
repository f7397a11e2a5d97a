"""The private internals of JAX, equinox and diffrax that pamjax reads (all in `pamjax._core.private`, each where no
public route exists) are still where pamjax looks: an upgrade that moves one fails here, not in a user's run."""

import diffrax as dfx
import jax.numpy as jnp

from pamjax._core import private


def test_equinox_error_switch_exists_and_is_restored():
    import equinox._errors as eqx_errors

    before = eqx_errors.EQX_ON_ERROR
    with private.equinox_errors_as_nan():
        assert eqx_errors.EQX_ON_ERROR == "nan"
    assert eqx_errors.EQX_ON_ERROR == before


def test_jax_backend_and_coordinator_queries_exist():
    from jax._src import distributed, xla_bridge

    assert callable(xla_bridge.backends_are_initialized)
    assert hasattr(distributed.global_state, "coordinator_address")
    assert isinstance(private.jax_backends_initialized(), bool)
    assert private.jax_coordinator_address() is None  # this process never called jax.distributed.initialize


def test_diffrax_result_code_and_message():
    sol = dfx.diffeqsolve(dfx.ODETerm(lambda t, y, args: -y), dfx.Tsit5(), 0.0, 1.0, 0.1, jnp.ones(()))
    assert int(private.diffrax_result_code(sol.result)) == 0
    assert isinstance(getattr(dfx.RESULTS, "_index_to_message", None), (list, tuple))
    failed = dfx.diffeqsolve(dfx.ODETerm(lambda t, y, args: -y), dfx.Tsit5(), 0.0, 1.0, 0.1,
                             jnp.ones(()), max_steps=2, throw=False)
    code = int(private.diffrax_result_code(failed.result))
    assert code != 0
    message = private.diffrax_result_message(code)
    assert message and "steps" in message.lower()
    assert private.diffrax_result_message(10_000) is None
