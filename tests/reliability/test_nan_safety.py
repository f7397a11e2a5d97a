"""No NaN/inf in the vector field, its Jacobian, trajectories, a loss or its gradient, for seeded inputs including
exact zero pressure difference, zero velocity, duty exactly 0 and 1 and states far outside the physical range.
CI runs ~1,000 inputs; `benchmarks/reliability.py` runs 10,000."""

import jax
import numpy as np

from pamjax._physics import smooth as sm
from pamjax._physics.gas import ellipse_flow_fraction

from .nan_safety import trajectory_counts, vector_field_counts

_ellipse_flow_fraction = jax.jit(ellipse_flow_fraction)  # one program per shape, not one per operation


def _host(f):
    """`f` jitted (one program; eagerly, each of its operations compiles its own), its value a Python float (so that
    the arithmetic on it runs on the host, not as more eager programs)."""
    jitted = jax.jit(f)
    return lambda *args: float(jitted(*args))


def test_vector_field_and_jacobian_are_finite():
    counts = vector_field_counts(250, seed=1)
    assert counts["inputs"] == 1000
    assert counts["nonfinite"] == 0


def test_trajectory_loss_and_gradient_are_finite():
    counts = trajectory_counts(16, seed=2)
    assert counts["nonfinite"] == 0


def test_smoothing_errors_at_ten_widths():
    """Stated smoothing errors (docs): at ten widths from the kink each primitive is within these bounds of its
    sharp counterpart: sign 1e-8, step 5e-5, relu 5e-5·width; |·| ≈ sqrt(x² + w²) − w is off by at most one width
    everywhere."""
    w = 0.7
    x = 10 * w
    smooth_sign, smooth_step, smooth_relu, smooth_abs = (
        _host(f) for f in (sm.smooth_sign, sm.smooth_step, sm.smooth_relu, sm.smooth_abs))
    assert abs(smooth_sign(x, w) - 1) < 1e-8 and abs(smooth_sign(-x, w) + 1) < 1e-8
    assert abs(smooth_step(x, w) - 1) < 5e-5 and abs(smooth_step(-x, w)) < 5e-5
    assert abs(smooth_relu(x, w) - x) < 5e-5 * w and abs(smooth_relu(-x, w)) < 5e-5 * w
    assert abs(smooth_abs(x, w) - x) <= w and smooth_abs(0.0, w) == 0.0


def test_flow_law_smoothing_is_confined_to_the_laminar_zone():
    """The laminar branch changes the quarter-ellipse law only for p_down/p_up > 0.999: below it the two agree to
    round-off; inside it the flow is linear and its deviation is bounded by the ellipse value at the zone's start."""
    b = 0.28
    r = np.linspace(0.0, 0.999, 5001)
    exact = np.where(r <= b, 1.0, np.sqrt(np.clip(1 - ((np.asarray(r) - b) / (1 - b)) ** 2, 0, None)))
    np.testing.assert_allclose(_ellipse_flow_fraction(r, b), exact, atol=1e-12)
    zone = np.linspace(0.999, 1.0, 101)
    phi = np.asarray(_ellipse_flow_fraction(zone, b))
    assert phi[-1] == 0.0 and np.all(np.diff(phi) < 0)
    assert np.all(phi <= exact[-1] + 1e-12)
