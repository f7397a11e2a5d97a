"""`_solve/gradcheck.py`'s `gradient_check` on small losses (no solve): a wrong gradient is caught at θ = 0 too, a
parameter on the edge of its valid range is differenced one-sidedly into it, and what cannot be differenced is named.
The solves' own gradients against finite differences: `tests/reliability/test_gradients.py`."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax


@jax.custom_jvp
def _g(b):
    return jnp.sin(b) + b


@_g.defjvp
def _g_jvp(primals, tangents):  # deliberately wrong: 10 × the true slope cos b + 1
    (b,), (db,) = primals, tangents
    return _g(b), 10.0 * (jnp.cos(b) + 1.0) * db


@pytest.mark.parametrize("b", [0.5, 0.0])
def test_a_wrong_gradient_fails_at_zero_as_elsewhere(b):
    # At b = 0 the step was 1e-12·h (the difference measured nothing: 0) and the errors were scaled by θ = 0, so the
    # tenfold slope passed with error_fd = 0. A parameter at 0 is now stepped and scaled by `zero_scale` (1).
    report = pamjax.gradient_check(lambda tree, adjoint: tree["a"] ** 2 + _g(tree["b"]),
                                   {"a": jnp.asarray(1.5), "b": jnp.asarray(b)})
    assert list(report["names"]) == ["['a']", "['b']"]
    assert report["finite_difference"][1] == pytest.approx(np.cos(b) + 1.0, rel=1e-6)
    assert report["error_fd"][0] < 1e-8
    assert report["error_fd"][1] == pytest.approx(9.0, rel=1e-5)  # |s_rev − s_fd| / |s_fd| = (20 − 2) / 2 at b = 0


def _refusing(calibration, adjoint):
    """A loss that refuses a calibration outside 0-10 V at run time, as `simulate` does a traced parameter."""
    del adjoint
    outside = (calibration.voltage[0] < 0.0) | (calibration.voltage[-1] > 10.0)
    return eqx.error_if(calibration(3.0) / 1e5, outside, "VoltageCalibration.voltage [V] must be in [0.0, 10.0]")


def test_a_parameter_on_its_bound_is_differenced_one_sidedly():
    # The calibration's voltages sit on 0 and 10 V: ±h pushed one past its bound and the check raised a raw
    # JaxRuntimeError (every regulator: internal_volume 0, a tank volume 0, its calibration's 10 V). Each is now
    # differenced into its valid range, the others centrally.
    calibration = pamjax.VoltageCalibration()
    report = pamjax.gradient_check(_refusing, calibration)
    assert list(report["names"]) == ["voltage[0]", "voltage[1]", "gauge_pressure[0]", "gauge_pressure[1]"]
    assert list(report["difference"]) == ["forward", "backward", "central", "central"]
    # a straight line through (0, 0) and (10 V, g): L = g (3 − v0) / (v1 − v0) / 1e5
    g = float(calibration.gauge_pressure[1]) / 1e5
    np.testing.assert_allclose(report["reverse"], [-0.7 * g / 10, -0.3 * g / 10, 0.7e-5, 0.3e-5], rtol=1e-12)
    assert report["error_fd"].max() < 1e-6, report["error_fd"]


def test_what_cannot_be_differenced_is_named_before_any_evaluation():
    # voltage[2] = 5 V lies 1e-9 V from both neighbours: no step of the ladder keeps the table increasing (its
    # neighbours move away from it: one-sided)
    tight = pamjax.VoltageCalibration(voltage=(0.0, 5.0 - 1e-9, 5.0, 5.0 + 1e-9, 10.0),
                                      gauge_pressure=(0.0, 4e5, 5e5, 6e5, 1e6))
    with pytest.raises(pamjax.PamjaxInputError, match=r"gradient_check: voltage\[2\] cannot be perturbed either way"):
        pamjax.gradient_check(_refusing, tight)
    with pytest.raises(pamjax.PamjaxInputError, match="zero_scale must be > 0 and finite"):
        pamjax.gradient_check(_refusing, pamjax.VoltageCalibration(), zero_scale=-1.0)


def test_a_refusal_by_the_loss_itself_is_named():
    # no component bounds `a`: the loss' own run-time refusal at a perturbed tree is named, not a raw JaxRuntimeError
    def loss(tree, adjoint):
        return eqx.error_if(tree["a"] ** 2, tree["a"] > 1.0, "a must be at most 1")

    with pytest.raises(pamjax.PamjaxInputError, match=r"the loss failed at a tree perturbed by relative step 0.01: "
                                                      r"a must be at most 1"):
        pamjax.gradient_check(loss, {"a": jnp.asarray(1.0)})


def test_bad_arguments_and_a_loss_that_is_not_finite_are_named():
    # Each was a silent NaN report, RuntimeWarnings of 0/0, a wrong cause ("cannot be perturbed either way" for no
    # steps at all), or a raw ValueError / TypeError.
    tree = {"a": jnp.asarray(2.0), "b": jnp.asarray(3.0)}

    def loss(t, adjoint):
        return t["a"] ** 2 * t["b"]

    refusals = [
        (dict(relative_steps=[0.0, 1e-4]), "relative_steps must be one or more finite numbers in"),
        (dict(relative_steps=[]), "relative_steps must be one or more"),
        (dict(relative_steps=[1e-3, float("nan")]), "relative_steps must be"),
        (dict(floor=float("nan")), "floor must be a finite number >= 0"),
        (dict(floor=-1.0), "floor must be a finite number >= 0"),
    ]
    for kwargs, match in refusals:
        with pytest.raises(pamjax.PamjaxInputError, match=match):
            pamjax.gradient_check(loss, tree, **kwargs)
    with pytest.raises(pamjax.PamjaxInputError, match="tree has no parameter to check"):
        pamjax.gradient_check(lambda t, adjoint: 1.0, {"n": 3})
    with pytest.raises(pamjax.PamjaxInputError, match=r"loss must take two arguments, loss\(tree, adjoint\)"):
        pamjax.gradient_check(lambda t: loss(t, None), tree)
    with pytest.raises(pamjax.PamjaxInputError, match="the loss is not finite at `tree`"):
        pamjax.gradient_check(lambda t, adjoint: loss(t, adjoint) * jnp.nan, tree)
    # finite at the tree, its gradient not (√ at 0): named with the parameter
    with pytest.raises(pamjax.PamjaxInputError, match=r"reverse-mode gradient is not finite at `tree` for \['b'\]"):
        pamjax.gradient_check(lambda t, adjoint: t["a"] + jnp.sqrt(t["b"]), {"a": jnp.asarray(1.0),
                                                                            "b": jnp.asarray(0.0)})
