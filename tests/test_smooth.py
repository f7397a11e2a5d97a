"""Smooth primitives: converge to their sharp counterparts as width → 0; finite values and gradients everywhere."""

import equinox as eqx
import jax
import numpy as np
import pytest

from pamjax._physics import smooth as sm

X = np.concatenate([np.linspace(-3.0, 3.0, 601), [0.0, 1e-300, -1e-300]])

# A primitive and its pointwise gradient jitted once per primitive and shape, the widths as array arguments: called
# eagerly, every operation would compile a program of its own.
_call = eqx.filter_jit(lambda fn, *args: fn(*args))
_gradient = eqx.filter_jit(lambda fn, x, width: jax.vmap(jax.grad(lambda x: fn(x, width)))(x))


@pytest.mark.parametrize(
    "fn, sharp",
    [
        (sm.smooth_sign, np.sign),
        (sm.smooth_step, lambda x: (x > 0).astype(float)),
        (sm.smooth_relu, lambda x: np.maximum(x, 0.0)),
        (sm.smooth_abs, np.abs),
    ],
)
def test_smooth_to_sharp_as_width_shrinks(fn, sharp):
    # Error away from the kink (|x| > 0.1) falls monotonically to ~0; near it the bound is the width itself.
    far = np.abs(X) > 0.1
    errors = []
    for width in (1e-1, 1e-2, 1e-3, 1e-4):
        err = np.abs(np.asarray(_call(fn, X, np.asarray(width))) - sharp(X))
        errors.append(err[far].max())
        assert err.max() <= max(width, 1.0 if fn in (sm.smooth_sign, sm.smooth_step) else width)
    assert all(a > b for a, b in zip(errors, errors[1:]) if a > 1e-15)
    assert errors[-1] <= 1.001e-4  # ≤ width (smooth_abs is off by ≈ width far out; the others by ~e^(-x/w))


def test_smooth_relu_error_bound_and_max_min():
    for w in (1.0, 0.1):
        err = np.asarray(_call(sm.smooth_relu, X, np.asarray(w))) - np.maximum(X, 0)
        assert np.all(err >= 0) and err.max() <= w * np.log(2) + 1e-15
    a, b, w = np.asarray(2.0), np.asarray(-1.0), np.asarray(1e-3)
    assert np.isclose(_call(sm.smooth_max, a, b, w), 2.0) and np.isclose(_call(sm.smooth_min, a, b, w), -1.0)


@pytest.mark.parametrize("fn", [sm.smooth_sign, sm.smooth_step, sm.smooth_relu, sm.smooth_abs])
def test_gradients_finite_and_match_finite_differences(fn):
    width = np.asarray(0.5)
    g = _gradient(fn, X, width)
    assert np.all(np.isfinite(g))
    x = np.linspace(-2, 2, 9)
    h = 1e-6
    fd = (np.asarray(_call(fn, x + h, width)) - np.asarray(_call(fn, x - h, width))) / (2 * h)
    np.testing.assert_allclose(_gradient(fn, x, width), fd, rtol=1e-7, atol=1e-9)


def test_safe_sqrt_and_divide():
    x = np.asarray([-1.0, 0.0, 4.0])
    np.testing.assert_array_equal(_call(sm.safe_sqrt, x), [0.0, 0.0, 2.0])
    g = jax.jit(jax.vmap(jax.grad(sm.safe_sqrt)))(x)  # one program (eagerly: one per operation)
    np.testing.assert_array_equal(g, [0.0, 0.0, 0.25])
    one, zero = np.asarray(1.0), np.asarray(0.0)
    assert (np.isfinite(_call(sm.safe_divide, one, zero))
            and np.isfinite(jax.jit(jax.grad(sm.safe_divide, argnums=1))(one, zero)))
    assert float(_call(sm.safe_divide, np.asarray(6.0), np.asarray(3.0))) == 2.0


def test_softplus_log_matches_numpy_to_a_few_ulp():
    # `log1p_exp` replaces XLA's costly float64 log1p in every softplus: against NumPy's log1p/logaddexp (an
    # independent implementation) within 4 ulp over the whole range, both branches and the switch between them
    # (a = log 2), the tails (exp underflowing to 0; never negative), and NaN/inf passed through.
    a = np.concatenate([np.linspace(0.0, 40.0, 400_001), np.geomspace(1e-300, 745.0, 20_001),
                        [np.log(2.0), np.nextafter(np.log(2.0), 0.0), np.nextafter(np.log(2.0), 1.0), 0.0]])
    got, ref = np.asarray(_call(sm.log1p_exp, a)), np.log1p(np.exp(-a))
    normal = ref >= np.finfo(float).tiny  # below, XLA's CPU code may flush a subnormal result to 0
    assert np.max(np.abs(got - ref)[normal] / np.spacing(ref[normal])) <= 4.0
    assert np.all(np.abs(got - ref)[~normal] <= np.finfo(float).tiny) and np.all(got >= 0.0)
    # the softplus traced for a sweep's lanes (`batched_lanes`: with `log1p_exp`) and as for one trajectory (with
    # jnp.logaddexp): both against NumPy; smooth_relu's value and derivatives (its custom rule) alike both ways
    z = np.concatenate([np.linspace(-60.0, 60.0, 240_001), [0.0, 1e-300, -1e-300, 700.0, -700.0]])
    with sm.batched_lanes():
        batched = np.asarray(jax.jit(jax.vmap(sm._softplus))(z))
        special = np.asarray(jax.jit(jax.vmap(sm._softplus))(np.asarray([np.inf, -np.inf, np.nan])))
    for got in (batched, np.asarray(jax.jit(jax.vmap(sm._softplus))(z))):  # outside: traced with XLA's log
        ref = np.logaddexp(z, 0.0)
        assert np.max(np.abs(got - ref) / np.spacing(ref)) <= 4.0
    assert special[0] == np.inf and special[1] == 0.0 and np.isnan(special[2])
    x, width = np.linspace(-3.0, 3.0, 7), np.linspace(0.5, 2.0, 7)
    for fn in (sm.smooth_relu, jax.grad(sm.smooth_relu, argnums=(0, 1))):
        with sm.batched_lanes():
            vec = jax.jit(jax.vmap(fn))(x, width)
        one = jax.jit(jax.vmap(fn))(x, width)
        np.testing.assert_allclose(np.asarray(vec), np.asarray(one), rtol=1e-15)
