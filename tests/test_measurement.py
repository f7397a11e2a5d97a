"""`pamjax.Measurement` (`pamjax/_fit/measurement.py`): one parameter's independent measurement with its uncertainty,
fitted beside the data. Checked against the closed form of a linear Gaussian problem (eq. 9's steady friction is
linear in F_c and C_f): the fit with the measurement is the data's estimate and the measurement combined by their
inverse variances, with the combined standard error; a contradiction is named; bad input is named before any solve."""

import numpy as np
import pytest
from helpers import np_friction

import pamjax as pj
from pamjax import presets

FREE = ["coulomb_force", "viscous_coefficient"]


@pytest.fixture(scope="module")
def curve():
    """Eq. 9 friction points (NumPy) with 0.5 N noise, and the data-only fit: (experiment, F_c, its variance in the
    residuals' own units (JᵀJ)⁻¹, unscaled by the residual variance)."""
    rng = np.random.default_rng(3)
    v = np.concatenate([-np.geomspace(0.01, 0.2, 10), np.geomspace(0.01, 0.2, 10)])
    f = np_friction(v, 16.0, 250.0, 1e-3) + 0.5 * rng.standard_normal(v.size)
    exp = pj.bench.FrictionCurveExperiment(v, f, scale=0.5, friction="")
    res = pj.fit(pj.CoulombViscousFriction(10.0, 100.0), [exp], FREE, progress=False)
    s2 = 2 * res.cost / (res.num_residuals - 2)  # the fit scales its covariance by the residual variance
    return exp, res.values[0], res.standard_errors[0] ** 2 / s2


@pytest.mark.parametrize("offset_sd, ratio", [(2.0, 1.0), (1.0, 0.25), (-3.0, 4.0)])
def test_the_fit_combines_data_and_measurement_by_their_inverse_variances(curve, offset_sd, ratio):
    exp, theta_d, var_d = curve
    sd = np.sqrt(ratio * var_d)  # the measurement's variance, `ratio` × the data's
    value = theta_d + offset_sd * np.sqrt(var_d)
    m = pj.Measurement("coulomb_force", value, sd, name="load cell")
    res = pj.fit(pj.CoulombViscousFriction(10.0, 100.0), [exp, m], FREE, progress=False)
    assert res.converged, res.message
    w = (1 / var_d) / (1 / var_d + 1 / sd**2)
    expected = w * theta_d + (1 - w) * value  # the linear Gaussian posterior mean
    assert res.values[0] == pytest.approx(expected, abs=1e-6 * np.sqrt(var_d))
    s2 = 2 * res.cost / (res.num_residuals - 2)
    assert res.standard_errors[0] ** 2 / s2 == pytest.approx(1 / (1 / var_d + 1 / sd**2), rel=1e-5)
    st = res.channel_errors["load cell"]["value"]
    assert st["measured"] == pytest.approx(value) and st["sd"] == pytest.approx(sd)
    assert st["fitted"] == pytest.approx(res.values[0], rel=1e-12)
    assert st["z"] == pytest.approx((res.values[0] - value) / sd, rel=1e-9)
    assert not any("load cell" in w for w in res.warnings)  # one datum is not a noise sample, nor contradicted
    assert "load cell" not in pj.bench.bench_rmse(res)


def test_a_measurement_the_data_contradict_is_named(curve):
    exp, theta_d, var_d = curve
    value = theta_d + 12 * np.sqrt(var_d)  # as certain as the data, 12 of their standard errors away: z = −6
    m = pj.Measurement("coulomb_force", value, np.sqrt(var_d))
    res = pj.fit(pj.CoulombViscousFriction(10.0, 100.0), [exp, m], FREE, progress=False)
    z = res.channel_errors["measured coulomb_force"]["value"]["z"]
    assert z == pytest.approx(-6.0, rel=1e-4)
    assert any(w.startswith("measured coulomb_force: measured") and "-6.0 uncertainties" in w
               and "the measurement and the recordings disagree" in w for w in res.warnings), res.warnings


def test_bad_measurements_are_named_before_any_solve():
    model = presets.mas10_system()
    for sd in (0.0, -1.0, float("nan"), "a"):
        with pytest.raises(pj.PamjaxInputError, match=r"Measurement\('friction.coulomb_force'\) sd must"):
            pj.Measurement("friction.coulomb_force", 14.0, sd)
    with pytest.raises(pj.PamjaxInputError, match="value must be finite"):
        pj.Measurement("friction.coulomb_force", float("inf"), 1.0)
    with pytest.raises(pj.PamjaxInputError, match="malformed"):
        pj.Measurement("friction..coulomb_force", 14.0, 1.0)
    with pytest.raises(pj.PamjaxInputError, match="no parameter 'friction.coulomb'"):
        pj.Measurement("friction.coulomb", 14.0, 1.0).check(model)
    law = "muscle.force_law.max_force_coefficients"
    with pytest.raises(pj.PamjaxInputError, match=r"is an array of shape \(5,\); measure one element"):
        pj.Measurement(law, 1.0, 1.0).check(model)
    with pytest.raises(pj.PamjaxInputError, match=r"index \[7\] is outside"):
        pj.Measurement(f"{law}[7]", 1.0, 1.0).check(model)
    a0 = float(model.muscle.force_law.max_force_coefficients[0])
    np.testing.assert_allclose(np.asarray(pj.Measurement(f"{law}[0]", a0, 1.0).residuals(model)), [0.0], atol=1e-12)
    # a measurement of a parameter the fit holds only adds a constant: refused, naming it
    exp = pj.bench.FrictionCurveExperiment([0.05, 0.1, 0.2], [30.0, 40.0, 66.0], friction="")
    with pytest.raises(pj.PamjaxInputError, match="measured viscous_coefficient: measures 'viscous_coefficient', "
                                                  "which `free` does not free"):
        pj.fit(pj.CoulombViscousFriction(10.0, 100.0), [exp, pj.Measurement("viscous_coefficient", 250.0, 10.0)],
               ["coulomb_force"], progress=False)


def test_a_measurement_adds_its_information_to_an_experiment_design():
    """`design_experiment`'s prior experiments may hold a calibration: its Fisher information about the parameter is
    (∂F_c/∂θ)²/sd², θ = log F_c (the fit's transform of a positive parameter): F_c²/sd²."""
    from pamjax._identifiability.design import information

    friction = pj.CoulombViscousFriction(14.0, 250.0)
    space = pj.ParameterSpace(friction, FREE)
    info = information(space, np.asarray(space.initial_theta()), [pj.Measurement("coulomb_force", 15.0, 0.5)])
    np.testing.assert_allclose(info, [[14.0**2 / 0.5**2, 0.0], [0.0, 0.0]], rtol=1e-12, atol=1e-12)
