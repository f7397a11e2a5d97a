"""Friction: paper 000 eq. 8-9 (Coulomb through a smooth sign + viscous) and the bristle model."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import np_friction

import pamjax


def test_coulomb_viscous_matches_eq8_9():
    f = pamjax.CoulombViscousFriction(16.0, 250.0, 1e-3)
    for v in np.linspace(-0.1, 0.1, 41):
        assert float(f.force(jnp.asarray(v), None)) == pytest.approx(
            np_friction(v, 16.0, 250.0, 1e-3), rel=1e-13, abs=1e-15
        )
    # Far from v = 0 it is the sharp law F_c sign(v) + C_f v (paper 000 eq. 16's friction terms).
    for v in (-0.05, 0.02):
        assert float(f.force(v, None)) == pytest.approx(16 * np.sign(v) + 250 * v, rel=1e-12)
    assert float(f.force(0.0, None)) == 0.0
    assert np.isfinite(jax.grad(lambda v: f.force(v, None))(0.0))


def test_coulomb_sharpens_as_width_shrinks():
    v = 5e-3
    errors = [abs(float(pamjax.CoulombViscousFriction(16.0, 0.0, w).force(v, None)) - 16.0) for w in (5e-3, 1e-3, 5e-4)]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-6


def test_bristle_steady_sliding_equals_coulomb_plus_viscous():
    f = pamjax.BristleFriction()
    for v in (-0.02, 0.01):
        z_ss = 16.0 / 1e5 * np.sign(v)  # ż = 0 ⇒ z = F_c/σ0 sign(v) (|v| ≫ the 1e-5 m/s smoothing)
        # |v| is smoothed as sqrt(v² + w²) − w, so the residual rate is ≈ w sign(v) = 1e-5 m/s.
        assert abs(float(f.state_rate(v, z_ss))) < 1.01e-5
        assert float(f.force(v, z_ss)) == pytest.approx(16.0 * np.sign(v) + 250.0 * v, rel=1e-3)


def test_bristle_deflection_bounded_and_sticks():
    # Integrate ż = v − σ0|v| z/F_c for a constant v by small Euler steps: z approaches F_c/σ0 and never exceeds it.
    f = pamjax.BristleFriction()
    z, dt = 0.0, 1e-5
    for _ in range(3000):  # 30 ms ≈ 9 time constants F_c/(σ0 v) at v = 0.05 m/s
        z = z + dt * float(f.state_rate(0.05, z))
    z_max = 16.0 / 1e5 * 0.05 / (0.05 - 1e-5)  # steady state with the smoothed |v|
    assert 0 < z <= z_max * (1 + 1e-12) and z == pytest.approx(16.0 / 1e5, rel=1e-3)
    # At rest the bristles are a spring: force σ0 z, no creep term.
    assert float(f.state_rate(0.0, 1e-4)) == pytest.approx(0.0, abs=1e-12)
    assert float(f.force(0.0, 1e-4)) == pytest.approx(1e5 * 1e-4, rel=1e-9)


def test_a_coulomb_viscous_velocity_width_in_mm_per_s_is_named():
    # 1 (mm/s) typed for 1e-3 m/s smoothed the sign over 1 m/s: Coulomb's step gone at every speed of a run
    with pytest.raises(pamjax.PamjaxInputError, match=r"CoulombViscousFriction.velocity_width = 1 m/s.*mm/s"):
        pamjax.CoulombViscousFriction(velocity_width=1.0)
    assert float(pamjax.CoulombViscousFriction(velocity_width=1e-3).velocity_width) == 1e-3
