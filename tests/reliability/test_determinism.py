"""Determinism: a vmapped batch equals a Python loop over the same points, bitwise on CPU, and a repeated run
equals the first. (Fit determinism and bitwise resume: `test_fit_determinism.py`.)

The batch engine is `pamjax.sweep` (fixed steps in lockstep): its arithmetic per point does not depend on the batch.
An adaptive diffrax solve under `vmap` agrees with the unbatched solve only to round-off (~1e-16 relative for the
averaged valve); with PWM edges the step-size controller can amplify that ULP difference into a different step
pattern (~1e-7 m), which `test_adaptive_vmap_agrees_to_round_off` bounds.
"""

import jax
import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets
from pamjax._solve.simulate import solve

TS = np.linspace(0.0, 0.5, 11)


def test_sweep_batch_equals_python_loop_bitwise():
    system = presets.mas10_system("averaged")
    duties = np.array([0.1, 0.35, 0.5, 0.65, 0.9])
    batch = pamjax.sweep(system, pamjax.Constant(0.5), TS, {"signal.value": duties}, progress=False)
    for i, u in enumerate(duties):
        alone = pamjax.sweep(system, pamjax.Constant(0.5), TS, {"signal.value": np.array([u])}, progress=False)
        for channel in batch.channels:
            np.testing.assert_array_equal(batch[channel][i], alone[channel][0])
    again = pamjax.sweep(system, pamjax.Constant(0.5), TS, {"signal.value": duties}, progress=False)
    for channel in batch.channels:
        np.testing.assert_array_equal(batch[channel], again[channel])


def test_adaptive_vmap_agrees_to_round_off():
    system = presets.mas10_system("averaged")

    def run(u):
        return solve(system, pamjax.Constant(u), jnp.asarray(TS), None, 0.0).position

    duties = jnp.array([0.3, 0.5, 0.7])
    batch = np.asarray(jax.jit(jax.vmap(run))(duties))
    for i, u in enumerate(duties):
        np.testing.assert_allclose(batch[i], np.asarray(jax.jit(run)(u)), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(batch, np.asarray(jax.jit(jax.vmap(run))(duties)))  # repeat: bitwise
