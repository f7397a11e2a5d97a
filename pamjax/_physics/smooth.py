"""Smooth primitives for the non-smooth physics of pneumatic muscle systems.

Every non-smooth function the models need (sign, step, max, |·|, √ near zero, clip) lives here, each with an explicit
`width` in the units of its argument. As `width → 0` each primitive converges to its sharp counterpart (tested in
`tests/test_smooth.py`). All gradients are finite for every finite input (the "double where" trick, equinox
`docs/api/debug.md`), so they are safe inside ODE solves and least-squares fits.
"""

import contextlib
import contextvars
import math

import jax
import jax.numpy as jnp


def smooth_sign(x, width):
    """`tanh(x / width)`: a smooth sign of `x`; error below 1e-4 for `|x| > 5 width`."""
    return jnp.tanh(x / width)


def smooth_step(x, width):
    """Logistic step `1 / (1 + exp(-x / width))`: 0 for `x ≪ -width`, 1 for `x ≫ width`, ½ at 0."""
    return 0.5 * (1.0 + jnp.tanh(0.5 * x / width))


# 1/3, 1/5, ..., 1/25: log(1 + f) = 2 atanh(s) = 2 (s + s³/3 + s⁵/5 + ...), s = f / (2 + f) (Abramowitz & Stegun
# 4.5.62 with 4.6.22). With -1/4 <= f <= 1/2 (below), |s| <= 1/5, and twelve terms leave a truncation below 2^-53 s.
_ATANH_SERIES = tuple(1.0 / (2 * k + 1) for k in range(1, 13))
_LOG2 = math.log(2.0)


def log1p_exp(a):
    """`log(1 + exp(−a))` for `a` >= 0 (NaN in, NaN out; 0 at +inf), within 4 ulp of `numpy.log1p(numpy.exp(−a))`
    where that is a normal number (tests/test_smooth.py), as elementwise arithmetic that XLA vectorises and fuses:
    its CPU `log1p` of float64 costs ~5x an `exp` (3.8 vs 0.7 ns per value on the AVX-512 test machine), and a
    softplus pays it in every field evaluation. With e = exp(−a): for a >= log 2 (e <= 1/2) f = e, else
    log(1 + e) = log 2 + log(1 + f) with f = (e − 1)/2, exact, in [−1/4, 0]; then the atanh series. Written so that
    each costly operation (the exp, the one division) has one user: XLA fuses it with its neighbours instead of
    running it as a kernel of its own (with `s = f / (2 + f)` used twice, a RODAS5 step over 1,024 lanes took 49
    kernels instead of 28)."""
    small = a < _LOG2
    e = jnp.exp(-a)
    f = jnp.where(small, 0.5 * e - 0.5, e)
    s = f * (1.0 / (2.0 + f))
    q = s * s
    series = _ATANH_SERIES[-1]
    for c in reversed(_ATANH_SERIES[:-1]):
        series = series * q + c
    value = 2.0 * s * (1.0 + q * series)
    return jnp.where(small, value + _LOG2, value)


_LANES = contextvars.ContextVar("pamjax_batched_lanes", default=False)


@contextlib.contextmanager
def batched_lanes():
    """Trace the softplus with its log by `log1p_exp` (vectorised) instead of `jnp.logaddexp`, for programs whose
    field runs over many lanes side by side (`pamjax._sweep.lanes`). Single trajectories keep XLA's log: its scalar
    form is cheaper than the series (the averaged 25 s `simulate` ran 3-8 % slower with the series). A trace-time
    switch, as a `while_loop` under `vmap` traces its body unbatched: the function cannot see the lanes itself."""
    token = _LANES.set(True)
    try:
        yield
    finally:
        _LANES.reset(token)


def _softplus(z):
    """`log(1 + exp(z))` = max(z, 0) + log(1 + exp(−|z|)) (NaN in, NaN out; ±inf exact); see `batched_lanes`."""
    if _LANES.get():
        return jnp.maximum(z, 0.0) + log1p_exp(jnp.abs(z))
    return jnp.logaddexp(z, 0.0)


@jax.custom_jvp
def smooth_relu(x, width):
    """Softplus `width · log(1 + exp(x / width))`: ≈ max(x, 0); its error is at most `width · log 2` (at x = 0).

    Its derivatives are written out (∂/∂x = σ(x/w), ∂/∂w = log(1 + e^{x/w}) − (x/w) σ(x/w)) instead of
    differentiating `logaddexp`, whose rule costs more operations in every step of a batched sweep or a Jacobian
    (the same values; benchmarks/sweep.py 69 → 66 ms per 1,024-lane sweep, docs/performance.md), and in a sweep's
    lanes its log by `log1p_exp` (`batched_lanes`; within 4 ulp of `numpy.logaddexp(x / width, 0)`; a RODAS5 step
    over 1,024 lanes 15 % faster)."""
    return width * _softplus(x / width)


@smooth_relu.defjvp
def _smooth_relu_jvp(primals, tangents):
    x, width = primals
    dx, dwidth = tangents
    z = x / width
    soft = _softplus(z)
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
