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
        z_ss = 16.0 / 1e5 * np.sign(v)  # ż = 0 ⇒ z = F_c/σ0 sign(v) (|v| exact)
        assert abs(float(f.state_rate(v, z_ss))) < 1e-15
        assert float(f.force(v, z_ss)) == pytest.approx(16.0 * np.sign(v) + 250.0 * v, rel=1e-12)


def test_bristle_deflection_bounded_and_sticks():
    # Integrate ż = v − σ0|v| z/F_c for a constant v by small Euler steps: z approaches F_c/σ0 and never exceeds it.
    f = pamjax.BristleFriction()
    z, dt = 0.0, 1e-5
    for _ in range(3000):  # 30 ms ≈ 9 time constants F_c/(σ0 v) at v = 0.05 m/s
        z = z + dt * float(f.state_rate(0.05, z))
    assert 0 < z <= 16.0 / 1e5 * (1 + 1e-12) and z == pytest.approx(16.0 / 1e5, rel=1e-3)
    # At rest the bristles are a spring: force σ0 z, no creep term.
    assert float(f.state_rate(0.0, 1e-4)) == pytest.approx(0.0, abs=1e-12)
    assert float(f.force(0.0, 1e-4)) == pytest.approx(1e5 * 1e-4, rel=1e-9)


def test_bristle_steady_sliding_holds_the_coulomb_level_at_a_creep():
    # |v| smoothed as sqrt(v² + w²) − w (w = 1e-5 m/s) made the steady force blow up at slow speed: 17.7 N at
    # 0.1 mm/s, 38.6 N at 10 µm/s, 320.8 N at 1 µm/s against F_c = 16 N, the deflection 20 F_c/σ0; the quasi-static
    # path model gave 67.8 N at 5 µm/s. With the exact |v|: F_c sign(v) + C_f v, the deflection within F_c/σ0.
    f = pamjax.BristleFriction()
    for v in (1e-4, -1e-5, 1e-6):
        assert float(pamjax.bench.steady_friction_force(f, v)) == pytest.approx(16.0 * np.sign(v) + 250.0 * v,
                                                                                 rel=1e-12)
    rate, z = jax.jit(lambda v, z: f.state_rate(v, z)), 0.0
    for _ in range(400):  # 4000 s at 1 µm/s: 4 mm, 25 deflections F_c/σ0 (Euler steps of 10 s: z does not overshoot)
        z = z + 10.0 * float(rate(1e-6, z))
    assert 0.99 * 16.0 / 1e5 < z <= 16.0 / 1e5
    x = np.linspace(0.0, 2e-4, 41)  # 0.2 mm at 5 µm/s, the loop fitter's path model
    starts = np.zeros(x.size, bool)
    starts[0] = True
    path = np.asarray(pamjax.bench.path_friction_force(f, x, np.full(x.size, 5e-6), starts))
    assert np.all(path <= 16.0 + 250.0 * 5e-6 + 1e-9) and path[-1] == pytest.approx(16.0, rel=1e-3)
    # at rest the slope in v is the mean of its two sides (v·sign v: 0), the bristle spring without a branch
    assert float(jax.grad(f.state_rate)(0.0, 1e-4)) == pytest.approx(1.0, rel=1e-12)
    assert f.smoothing_width() is None  # nothing smoothed: no stiff rate F_c/(w M) for a hint to name


def test_a_bristle_velocity_width_in_mm_per_s_is_named():
    # accepted before, where CoulombViscousFriction and BoucWenFriction refused it
    with pytest.raises(pamjax.PamjaxInputError, match=r"BristleFriction.velocity_width = 1 m/s.*mm/s"):
        pamjax.BristleFriction(velocity_width=1.0)


def test_a_coulomb_viscous_velocity_width_in_mm_per_s_is_named():
    # 1 (mm/s) typed for 1e-3 m/s smoothed the sign over 1 m/s: Coulomb's step gone at every speed of a run
    with pytest.raises(pamjax.PamjaxInputError, match=r"CoulombViscousFriction.velocity_width = 1 m/s.*mm/s"):
        pamjax.CoulombViscousFriction(velocity_width=1.0)
    assert float(pamjax.CoulombViscousFriction(velocity_width=1e-3).velocity_width) == 1e-3
