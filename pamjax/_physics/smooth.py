"""Smooth primitives for the non-smooth physics of pneumatic muscle systems.

Every non-smooth function the models need (sign, step, max, |·|, √ near zero, clip) lives here, each with an explicit
`width` in the units of its argument. As `width → 0` each primitive converges to its sharp counterpart (tested in
`tests/test_smooth.py`). All gradients are finite for every finite input (the "double where" trick, equinox
`docs/api/debug.md`), so they are safe inside ODE solves and least-squares fits.
"""

import jax
import jax.numpy as jnp


def smooth_sign(x, width):
    """`tanh(x / width)`: a smooth sign of `x`; error below 1e-4 for `|x| > 5 width`."""
    return jnp.tanh(x / width)


def smooth_step(x, width):
    """Logistic step `1 / (1 + exp(-x / width))`: 0 for `x ≪ -width`, 1 for `x ≫ width`, ½ at 0."""
    return 0.5 * (1.0 + jnp.tanh(0.5 * x / width))


@jax.custom_jvp
def smooth_relu(x, width):
    """Softplus `width · log(1 + exp(x / width))`: ≈ max(x, 0); its error is at most `width · log 2` (at x = 0).

    Its derivatives are written out (∂/∂x = σ(x/w), ∂/∂w = log(1 + e^{x/w}) − (x/w) σ(x/w)) instead of
    differentiating `logaddexp`, whose rule costs more operations in every step of a batched sweep or a Jacobian
    (the same values; benchmarks/sweep.py 69 → 66 ms per 1,024-lane sweep, docs/performance.md)."""
    return width * jnp.logaddexp(x / width, 0.0)


@smooth_relu.defjvp
def _smooth_relu_jvp(primals, tangents):
    x, width = primals
    dx, dwidth = tangents
    z = x / width
    soft = jnp.logaddexp(z, 0.0)
    slope = jax.nn.sigmoid(z)
    return width * soft, slope * dx + (soft - z * slope) * dwidth


def smooth_abs(x, width):
    """`sqrt(x² + width²) - width`: ≈ |x| with zero value and slope at 0."""
    return jnp.sqrt(x * x + width * width) - width


def smooth_max(a, b, width):
    """≈ max(a, b) via `b + smooth_relu(a - b, width)`."""
    return b + smooth_relu(a - b, width)


def smooth_min(a, b, width):
    """≈ min(a, b) via `a - smooth_relu(a - b, width)`."""
    return a - smooth_relu(a - b, width)


def safe_sqrt(x):
    """`sqrt(max(x, 0))` whose gradient is 0 (not inf or NaN) at and below 0."""
    positive = x > 0
    safe_x = jnp.where(positive, x, 1.0)
    return jnp.where(positive, jnp.sqrt(safe_x), 0.0)


def safe_divide(num, den, tiny=1e-300):
    """`num / den` with `den` kept away from 0 by `tiny` (sign preserved), so neither value nor gradient is inf."""
    den = jnp.where(jnp.abs(den) < tiny, jnp.where(den < 0, -tiny, tiny), den)
    return num / den
