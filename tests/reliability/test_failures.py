"""Failures are never silent: a named error with throw=True; under batching a per-point status with NaN outputs
that leaves the other points untouched."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._solve.simulate import result_message, solve

TS = jnp.linspace(0.0, 0.2, 11)


def test_max_steps_raises_named_error():
    with pytest.raises(pamjax.PamjaxSolveError, match="maximum number of solver steps"):
        pamjax.simulate(presets.mas10_system("averaged"), pamjax.Constant(0.5), TS, max_steps=5)


def test_max_steps_without_throw_returns_status_and_nan():
    traj = pamjax.simulate(presets.mas10_system("averaged"), pamjax.Constant(0.5), TS, max_steps=5, throw=False)
    assert int(traj.result) != 0 and not bool(traj.succeeded)
    assert np.all(np.isnan(np.asarray(traj.position))) and np.all(np.isnan(np.asarray(traj.pressure)))


def test_batched_failures_are_per_point():
    """A NaN payload mass (non-finite state) and an inf one fail alone; the other lanes equal their single runs to
    round-off and the failed lanes stop early instead of running to max_steps."""
    system = presets.mas10_system("averaged")

    def run(mass):
        return solve(eqx.tree_at(lambda s: s.payload_mass, system, mass), pamjax.Constant(0.5), TS, None, 0.0)

    masses = jnp.array([9.6, jnp.nan, 5.0, jnp.inf])
    batch = jax.jit(jax.vmap(run))(masses)
    result = np.asarray(batch.result)
    assert list(result == 0) == [True, False, True, False]
    for i in (1, 3):
        assert np.all(np.isnan(np.asarray(batch.position[i])))
        assert "non-finite" in result_message(int(result[i])) or "minimum step" in result_message(int(result[i]))
    assert np.max(np.asarray(batch.num_steps)) < 1000  # nobody ground on to max_steps (200,000)
    for i, m in ((0, 9.6), (2, 5.0)):
        single = jax.jit(run)(jnp.asarray(m))
        np.testing.assert_allclose(batch.position[i], single.position, rtol=1e-12, atol=1e-15)


def test_pwm_synchronous_instability_is_reported():
    """Too few RK4 substeps per PWM period for this stiff set-up → non-finite state → named error / status."""
    system = presets.mas10_tank_system("pwm", volume=1e-8)  # a tiny volume: pressure time constant ≪ substep
    with pytest.raises(pamjax.PamjaxSolveError):
        pamjax.simulate(system, pamjax.Constant(0.5), TS, stepping="pwm", substeps=2)
    traj = pamjax.simulate(system, pamjax.Constant(0.5), TS, stepping="pwm", substeps=2, throw=False)
    assert int(traj.result) != 0 and np.all(np.isnan(np.asarray(traj.pressure)))
