"""Input signals (`pamjax._physics.signals`): constant, step, triangle (paper 000's 0.05-0.95 duty), sine, sampled (held
per PWM period)."""

import equinox as eqx
import jax
import numpy as np
import pytest

import pamjax

# One program per signal type and number of times (eagerly, each of the signal's operations compiles its own).
_values = eqx.filter_jit(lambda signal, ts: jax.vmap(signal)(ts))


def _eval(signal, ts):
    return np.asarray(_values(signal, np.asarray(ts, dtype=float)))


def test_constant_and_step():
    np.testing.assert_array_equal(_eval(pamjax.Constant(0.3), [0.0, 1.0, 7.5]), 0.3)
    np.testing.assert_array_equal(_eval(pamjax.Step(0.2, 0.7, 1.0), [0.0, 0.999, 1.0, 2.0]), [0.2, 0.2, 0.7, 0.7])
    assert pamjax.Step(0.7, 0.2, 1.0).bounds() == (0.2, 0.7)


def test_triangle_matches_paper_shape():
    tri = pamjax.Triangle(0.05, 0.95, 0.08)  # period 12.5 s
    ts = np.linspace(0, 25, 1001)
    phase = (ts * 0.08) % 1.0
    expected = 0.05 + 0.9 * (1 - np.abs(2 * phase - 1))
    np.testing.assert_allclose(_eval(tri, ts), expected, atol=1e-12)
    assert _eval(tri, [0.0, 6.25, 12.5]).tolist() == pytest.approx([0.05, 0.95, 0.05])
    assert tri.bounds() == (0.05, 0.95)


def test_sine():
    s = pamjax.Sine(0.5, 0.2, 2.0, 0.3)
    ts = np.linspace(0, 1, 50)
    np.testing.assert_allclose(_eval(s, ts), 0.5 + 0.2 * np.sin(2 * np.pi * 2 * ts + 0.3), atol=1e-14)
    assert s.bounds() == pytest.approx((0.3, 0.7))


def test_sampled_zero_order_hold_and_pwm_latch():
    times, values = np.array([0.0, 0.015, 0.03]), np.array([0.2, 0.6, 0.8])
    s = pamjax.Sampled(times, values)
    np.testing.assert_array_equal(_eval(s, [0.0, 0.014, 0.015, 0.029, 0.04]), [0.2, 0.2, 0.6, 0.6, 0.8])
    latched = pamjax.Sampled(times, values, period=0.02)  # value at the start of each 20 ms PWM period
    np.testing.assert_array_equal(_eval(latched, [0.005, 0.019, 0.021, 0.035, 0.041]), [0.2, 0.2, 0.6, 0.6, 0.8])
    assert latched.bounds() == (0.2, 0.8)


def test_a_held_sample_at_its_period_start_counts_whatever_the_rounding():
    # A logger's times 1234.507 + k ms moved by -7 ms land a few ulp beside the periods' starts k·20 ms: a sample at
    # 1234.5000000000002 (after 61725 · 0.02 = 1234.5) was not "in force" at its period's start, and the period took
    # the previous period's duty.
    import numpy as np

    import pamjax

    t = np.nextafter(1234.5 + 1e-3 * np.arange(60), np.inf)  # each logged time one ulp after its grid time
    u = np.repeat([0.2, 0.5, 0.8], 20)
    signal = pamjax.Sampled(t, u, period=0.02)
    for k, expected in enumerate((0.2, 0.5, 0.8)):
        start = 1234.5 + 0.02 * k
        assert float(signal(start + 0.005)) == expected and float(signal(start)) == expected


def test_a_square_wave_edge_too_wide_for_its_period_is_refused():
    # 1 ms edges at 100 Hz (10 % of the period) peaked at 2.55 of 3 and jumped at each period start, silently. As
    # OnOffValve's: an edge is at most 5 % of the period; paper 001's 1.5 Hz wave and 1 ms at 50 Hz (5 %) pass.
    for frequency, width in [(100.0, 1e-3), (10.0, 1e-2)]:
        with pytest.raises(pamjax.PamjaxInputError, match=r"SquareWave\.edge_width \(.* s\) must not exceed 5% of the "
                                                          r"period 1/SquareWave\.frequency"):
            pamjax.SquareWave(0.0, 3.0, frequency, edge_width=width)
    pamjax.SquareWave(0.0, 3.0, 1.5)
    pamjax.SquareWave(0.0, 3.0, 50.0, edge_width=1e-3)


def test_a_sampled_period_that_is_not_finite_is_refused():
    # period=inf was accepted and read the last sample at every time (the latch time (0 + 1e-9) · inf is inf)
    with pytest.raises(pamjax.PamjaxInputError, match=r"Sampled\.period must be a finite number > 0"):
        pamjax.Sampled([0.0, 0.1, 0.2], [0.2, 0.5, 0.9], period=float("inf"))
