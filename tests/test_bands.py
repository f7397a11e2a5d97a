"""Bands on predictions (`pamjax.prediction_band`, the map bands, `--band`), checked against what they claim:

- the linear band's standard deviation against the spread of REFITS over noise seeds (40 synthetic recordings of
  one tank → 40 fits → the scatter of their predictions of another run), and its coverage of the truth;
- the delta method against an independent one (central differences in the PHYSICAL parameters with the covariance
  rebuilt from the fit's standard errors and correlations), so the unconstrained-space algebra is checked;
- the steady-state map's band against a NumPy oracle: a tank with eq. 13's valve settles where the flow is zero, the
  root of a quadratic in the gauge pressure;
- the flow surface's band against central differences of `pamjax.flow_surface`;
- samples against linear where the problem is linear at the scale of its uncertainty; a rig's nuisances
  marginalised; every refusal named.

The problem: paper 000's averaged (eq. 13) valve charging its 5e-5 m³ tank along a 1 Hz triangle, 2 kPa noise,
three free parameters (m4, m5 and the volume); each fit < 0.1 s after the first.
"""

import json
import pathlib
import re
import textwrap
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax import presets
from pamjax._cli.main import main
from pamjax._core.errors import PamjaxInputError

FREE = ["valve.coefficients[1,0]", "valve.coefficients[1,1]", "volume"]
NOISE = 2e3  # Pa, the hybrid bench's pressure noise
SIGNAL = pj.Triangle(0.1, 0.9, 1.0)
T_FIT = np.linspace(0.0, 2.0, 101)
# The prediction banded: another run than the one fitted (a 0.7 Hz sine), on the fixed RK4 grid (1 ms): smooth in
# every parameter, so the ±1 σ points see the model's curvature and not an adaptive solver's step pattern.
PREDICT_SIGNAL = pj.Sine(0.5, 0.3, 0.7)
T_PREDICT = np.linspace(0.0, 3.0, 31)
REFITS = 40


def predict(model):
    return pj.simulate(model, PREDICT_SIGNAL, T_PREDICT, stepping="grid", throw=False).channel("pressure")


def _fit(truth, seed):
    rec = pj.synthetic_recording(truth, SIGNAL, T_FIT, noise=dict(pressure=NOISE), seed=seed, name="tank")
    exp = pj.Experiment(rec, SIGNAL, channels=["pressure"], scales=dict(pressure=NOISE))
    return pj.fit(truth, [exp], FREE, progress=False)


@pytest.fixture(scope="module")
def truth():
    return presets.mas10_tank_system("averaged")


@pytest.fixture(scope="module")
def refits(truth):
    """40 fits of 40 noise seeds, each with its linear band of `predict`. (A seed's residuals may pass the mismatch
    threshold by chance, at most ~1 % of fits since the threshold reads the sample count: its band's warning is
    expected.)"""
    fits, bands = [], []
    for seed in range(REFITS):
        res = _fit(truth, seed)
        assert res.converged, res.message
        fits.append(res)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pj.PamjaxBandWarning)
            bands.append(pj.prediction_band(res, predict, check_linearity=False))
    return fits, bands


def test_linear_band_matches_the_spread_of_refits_and_covers_the_truth(truth, refits):
    """The band's σ against the empirical σ of 40 refits' predictions: an empirical σ of N draws scatters by
    1/√(2(N−1)) = 11 % relative, so every time's ratio must lie within ±3 of that (0.66…1.34) and their median within
    ±2 (0.77…1.23); the truth must be inside the 95 % band in at least 85 % of fits × times (3 binomial σ of 40
    effectively independent fits below 0.95). A band off by the σ² estimate, the transform's Jacobian or a factor z
    fails this."""
    _, bands = refits
    predictions = np.array([b.prediction for b in bands])
    stds = np.array([b.std for b in bands])
    later = T_PREDICT > 0.15  # the start (atmosphere at t = 0) is known exactly: no spread to compare
    ratio = predictions.std(axis=0, ddof=1)[later] / stds.mean(axis=0)[later]
    assert np.all((ratio > 0.66) & (ratio < 1.34)), ratio
    assert 0.77 < np.median(ratio) < 1.23, ratio
    y_true = np.asarray(predict(truth))
    inside = (y_true >= np.array([b.lower for b in bands])) & (y_true <= np.array([b.upper for b in bands]))
    assert inside[:, later].mean() > 0.85, inside[:, later].mean()
    assert bands[0].method == "linear" and "forward-mode Jacobian" in bands[0].how
    assert bands[0].parameters == [*FREE[:2], "volume"] and bands[0].marginalised == []


def test_delta_method_equals_central_differences_in_the_physical_parameters(refits):
    """σ² = diag(J Σ Jᵀ) with J by central differences of the prediction in the PHYSICAL values (steps of 1e-4 of
    each value) and Σ = diag(SE) R diag(SE) from the result's stored numbers: the band's forward-mode Jacobian in the
    unconstrained space must give the same σ (to 1e-4: the differences' truncation and round-off)."""
    fits, bands = refits
    res, band = fits[0], bands[0]
    se = np.asarray(res.standard_errors)
    cov = np.asarray(res.correlation) * np.outer(se, se)
    reference = _delta_std(predict, pj.ParameterSpace(res.model, FREE), np.asarray(res.values), cov, 1e-4)
    later = T_PREDICT > 0.15
    np.testing.assert_allclose(band.std[later], reference[later], rtol=1e-4)
    np.testing.assert_allclose(band.upper - band.prediction, 1.959964 * band.std, rtol=1e-6)


def test_samples_agree_with_linear_and_the_linearity_index_is_small(refits):
    """Where the uncertainty is small (0.4 % in m4), the prediction is linear over it: the nonlinearity index is
    far below 0.1, and 200 draws give the linear σ within 15 % (a σ of 200 draws scatters by 5 %)."""
    fits, _ = refits
    linear = pj.prediction_band(fits[1], predict)
    assert linear.nonlinearity < 0.02, linear.nonlinearity
    samples = pj.prediction_band(fits[1], predict, method="samples", samples=200, seed=1)
    later = T_PREDICT > 0.15
    ratio = samples.std[later] / linear.std[later]
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    assert samples.method == "samples" and "200 draws" in samples.how and samples.failed == 0
    assert np.all(samples.lower <= samples.upper)
    assert samples.nonlinearity is None


def _settled_pressure(coefficients, u, p_atm):
    """NumPy oracle: the tank pressure [Pa abs] where eq. 13's flow Σ m_ij uⁱ p_gʲ is zero, in (0, 6 bar) gauge."""
    c = np.array([1.0, u, u * u]) @ coefficients  # c0, c1, c2 of the gauge pressure
    roots = np.roots([c[2], c[1], c[0]])
    real = roots[np.isreal(roots)].real
    return p_atm + real[(real > 0) & (real < 6e5)][0]


def test_steady_state_band_against_the_settled_pressure_oracle(refits):
    """The steady-state map's band (±1 σ points as one more sweep axis) against the delta method on the NumPy
    oracle's root (its Jacobian by central differences in m4, m5; the volume does not move a settled tank): σ
    within 2 %, the band's centre within 20 Pa of the root (the map averages a settled 0.5 s window)."""
    fits, _ = refits
    res = fits[0]
    duties = np.array([0.3, 0.5, 0.7])
    band = pj.steady_state_band(res, duties, horizon=2.0, window=0.5, progress=False)
    assert "central differences at ±1 σ" in band.how
    m = np.asarray(res.model.valve.coefficients)
    p_atm = float(res.model.air.atmospheric_pressure)
    se = np.asarray(res.standard_errors)[:2]
    cov = np.asarray(res.correlation)[:2, :2] * np.outer(se, se)
    for k, u in enumerate(duties):
        grad = []
        for index in ((1, 0), (1, 1)):
            h = 1e-5 * abs(m[index])
            up, down = m.copy(), m.copy()
            up[index] += h
            down[index] -= h
            grad.append((_settled_pressure(up, u, p_atm) - _settled_pressure(down, u, p_atm)) / (2 * h))
        grad = np.array(grad)
        assert abs(band.prediction["pressure"][k] - _settled_pressure(m, u, p_atm)) < 20.0
        assert band.std["pressure"][k] == pytest.approx(np.sqrt(grad @ cov @ grad), rel=0.02)


@pytest.mark.slow  # ~15 s: two frequency-response sweeps of 14 and 202 lanes (compiled once each)
def test_frequency_response_band_linear_and_samples_agree(refits):
    """Gain and phase of the tank pressure at 0.5 and 2 Hz: the ±1 σ linear band and 200 draws agree within 20 %
    (Monte-Carlo scatter 5 %, and the lanes' error control 1e-5); phases differenced modulo 360°."""
    res = refits[0][2]
    f = np.array([0.5, 2.0])
    kwargs = dict(channels=("pressure",), settle_periods=2, periods=2, samples_per_period=40, progress=False)
    linear = pj.frequency_response_band(res, f, **kwargs)
    samples = pj.frequency_response_band(res, f, method="samples", samples=200, **kwargs)
    for name in ("pressure_gain", "pressure_phase"):
        assert np.all(linear.std[name] > 0)
        np.testing.assert_allclose(samples.std[name], linear.std[name], rtol=0.2)
    assert linear.prediction["pressure_phase"][1] < linear.prediction["pressure_phase"][0] < 0  # a lag, growing
    direct = pj.frequency_response(res.model, f, channels=("pressure",), settle_periods=2, periods=2,
                                   samples_per_period=40, progress=False)
    np.testing.assert_allclose(linear.prediction["pressure_gain"], direct["pressure"]["gain"], rtol=1e-4)


def test_flow_surface_band_against_central_differences():
    """A switching valve's cycle-averaged flow surface with a stated covariance of two inflate-path parameters
    (2 % and 3 %, correlation 0.4; a `FitUncertainty` from its JSON document, as a model file carries it): σ from
    the forward-mode Jacobian equals the delta method with central differences of `pamjax.flow_surface` (1e-5)."""
    model = presets.mas10_tank_system("pwm")
    paths = ["valve.inflate.discharge_coefficient", "valve.inflate.critical_ratio"]
    values = np.array([float(model.valve.inflate.discharge_coefficient), float(model.valve.inflate.critical_ratio)])
    se = values * np.array([0.02, 0.03])
    document = dict(labels=paths, paths=paths, values=values.tolist(), standard_errors=se.tolist(),
                    correlation=[[1.0, 0.4], [0.4, 1.0]], status="converged", mismatch=False)
    uncertainty = pj.FitUncertainty.from_document(json.loads(json.dumps(document)), "a stated covariance")
    u, p = np.array([0.3, 0.6]), np.array([2e5, 4e5])
    band = pj.flow_surface_band(uncertainty, u, p, model=model)
    cov = np.array([[1.0, 0.4], [0.4, 1.0]]) * np.outer(se, se)
    reference = _delta_std(lambda m: pj.flow_surface(m.valve, u, p, model.air), pj.ParameterSpace(model, paths), values,
                           cov, 1e-6)
    np.testing.assert_allclose(band.std["mass_flow"], reference, rtol=1e-5)
    np.testing.assert_allclose(band.prediction["mass_flow"], pj.flow_surface(model.valve, u, p, model.air),
                               rtol=1e-12)


def test_a_linearity_check_point_that_fails_is_counted_and_warned():
    """A prediction that fails (NaN) at +1 σ of the volume, finite at the fitted value: the linear band's σ is the
    delta method's, but its linearity check lost an axis; it said "index 0, the linear band holds", failed 0."""
    model = presets.mas10_tank_system("averaged")
    volume = float(model.volume)
    document = dict(labels=["volume"], paths=["volume"], values=[volume], standard_errors=[0.01 * volume],
                    correlation=[[1.0]], status="converged", mismatch=False)
    uncertainty = pj.FitUncertainty.from_document(document, "a stated covariance")

    def fragile(m):
        return jnp.where(m.volume > 1.005 * volume, jnp.nan, 1e6 * m.volume) * jnp.ones(3)

    with pytest.warns(pj.PamjaxBandWarning, match="1 of the 2 linearity-check predictions at ±1 σ failed"):
        band = pj.prediction_band(uncertainty, fragile, model=model)
    text = band.describe()
    assert band.failed == 1 and "1 of 3 predictions failed" in text and "the linear band holds" not in text
    np.testing.assert_allclose(band.std, 1e6 * 0.01 * volume, rtol=1e-6)


def _stated(model, paths, relative):
    """A `FitUncertainty` of `paths` of `model` at their values, uncorrelated, `relative` standard errors, read back
    from its JSON document (as a fit.json or a model file carries it): no fit needed."""
    space = pj.ParameterSpace(model, paths)
    values = [float(v) for v in np.asarray(space.initial_values())]
    document = dict(labels=list(space.labels), paths=paths, values=values,
                    standard_errors=[relative * v for v in values], correlation=np.eye(len(paths)).tolist(),
                    status="converged", mismatch=False)
    return document, pj.FitUncertainty.from_document(json.loads(json.dumps(document)), "a stated covariance")


@pytest.mark.parametrize("kwargs, match", [
    (dict(pressures=[-2e5, 3e5]), r"pressures \(absolute\) \[Pa\] must be > 0"),
    (dict(commands=[-0.5, 0.5, 1.5]), r"commands must lie in \[0\.0, 1\.0\]"),
    (dict(phases=0), r"phases must be a positive integer"),
    (dict(phases=2.5), r"phases must be a positive integer"),
    (dict(averaged=True), r"valve: the flow surface is a switching valve.s flow .* AveragedValve does not switch"),
])
def test_flow_surface_band_refuses_what_flow_surface_refuses_before_anything_is_traced(kwargs, match, monkeypatch):
    # the same checks as pamjax.flow_surface (and an averaged valve, which has no PWM period to average over, and
    # phases, flow_surface's samples): named, before the band is traced (not numbers, not JAX's TypeError)
    import pamjax._bands.maps as band_maps

    monkeypatch.setattr(band_maps, "propagated_band", lambda *a: pytest.fail("traced before refusing the input"),
                        raising=False)
    averaged = kwargs.pop("averaged", False)
    model = presets.mas10_tank_system("averaged" if averaged else "pwm")
    paths = ["valve.coefficients[1,0]"] if averaged else ["valve.inflate.discharge_coefficient"]
    args = {**dict(commands=[0.5], pressures=[3e5], phases=400), **kwargs}
    with pytest.raises(PamjaxInputError, match=match):
        pj.flow_surface_band(_stated(model, paths, 0.01)[1], args.pop("commands"), args.pop("pressures"),
                             model=model, **args)
    if "pressures" in kwargs or "commands" in kwargs:  # flow_surface's own refusal, the same words
        with pytest.raises(PamjaxInputError, match=match):
            pj.flow_surface(model.valve, kwargs.get("commands", [0.5]), kwargs.get("pressures", [3e5]), model.air)


def test_a_fit_json_without_model_asks_for_the_model(tmp_path):
    # a fit.json holds the covariance but no model: the band asks for model= (not "not a pamjax model file")
    document, _ = _stated(presets.mas10_tank_system("averaged"), FREE, 0.01)
    (tmp_path / "fit.json").write_text(json.dumps(document))
    with pytest.raises(PamjaxInputError, match=r"model: this fit result holds no model \(read from JSON\?\): pass "
                                               r"model="):
        pj.prediction_band(tmp_path / "fit.json", predict)
    with pytest.raises(PamjaxInputError, match=r"pass model="):
        pj.prediction_band(str(tmp_path / "fit.json"), predict)


@pytest.mark.slow  # ~30 s: compiles the PWM grid's solve with tangents and vmapped
def test_band_of_a_switching_valve_and_stick_slip_on_the_pwm_grid():
    """The bench's model (switching valve on the PWM-synchronous grid, exact stick-slip): the grid's size needs the
    PWM frequency concrete, which a band must not trace (only the free parameters are). σ from the forward-mode
    Jacobian equals the delta method with central differences in the physical values (1e-4)."""
    model = presets.mas10_system(valve="pwm", friction="karnopp")
    paths = ["friction.coulomb_force", "valve.inflate.discharge_coefficient"]
    values = np.array([float(model.friction.coulomb_force), float(model.valve.inflate.discharge_coefficient)])
    se, corr = 0.02 * values, np.array([[1.0, 0.3], [0.3, 1.0]])
    uncertainty = pj.FitUncertainty.from_document(
        dict(labels=paths, paths=paths, values=values.tolist(), standard_errors=se.tolist(),
             correlation=corr.tolist()), "a stated covariance")
    ts = np.linspace(0.0, 0.6, 31)

    def position(m):
        return pj.simulate(m, pj.Triangle(0.1, 0.9, 1.0), ts, throw=False).channel("position")

    band = pj.prediction_band(uncertainty, position, model=model, check_linearity=False)
    reference = _delta_std(position, pj.ParameterSpace(model, paths), values, corr * np.outer(se, se), 1e-5)
    moving = reference > 1e-3 * reference.max()
    assert np.count_nonzero(moving) > 20
    np.testing.assert_allclose(band.std[moving], reference[moving], rtol=1e-4)


def test_a_rig_fit_gives_the_plants_band_with_its_nuisances_marginalised(refits):
    """A rig's fit (the plant's labels `plant.…` and a sensor delay correlated with them): the band is the plant's,
    from the plant block of the covariance (the marginal), the delay named as marginalised; equal to the plain
    fit's band with that block."""
    res, band = refits[0][0], refits[1][0]
    se = np.asarray(res.standard_errors)
    corr = np.eye(4)
    corr[:3, :3] = np.asarray(res.correlation)
    corr[3, :3] = corr[:3, 3] = [0.5, -0.3, 0.2]
    labels = [f"plant.{p}" for p in FREE] + ["sensors[rig].delay"]
    document = dict(labels=labels, paths=labels, values=[*res.values, 1e-3], correlation=corr.tolist(),
                    standard_errors=[*se, 2e-4], status="converged", mismatch=False)
    rig = pj.Rig(res.model)
    plant_band = pj.prediction_band(pj.FitUncertainty.from_document(document, "a rig"), predict, model=rig,
                                    check_linearity=False)
    assert plant_band.marginalised == ["sensors[rig].delay"]
    assert plant_band.parameters == FREE
    assert any("nuisances (sensors[rig].delay) marginalised" in n for n in plant_band.notes)
    np.testing.assert_allclose(plant_band.std, band.std, rtol=1e-10)


def test_refusals_are_named(refits, tmp_path):
    res = refits[0][0]
    with pytest.raises(PamjaxInputError, match="level must be a confidence level"):
        pj.prediction_band(res, predict, level=95)
    with pytest.raises(PamjaxInputError, match="method must be one of"):
        pj.prediction_band(res, predict, method="bootstrap")
    with pytest.raises(PamjaxInputError, match="samples must be an integer >= 20"):
        pj.prediction_band(res, predict, method="samples", samples=5)
    unidentified = res.to_dict() | {"standard_errors": [float("inf"), *res.standard_errors[1:]]}
    with pytest.raises(PamjaxInputError, match=r"does not determine valve.coefficients\[1,0\]"):
        pj.prediction_band(pj.FitUncertainty.from_document(unidentified, "x"), predict, model=res.model)
    pj.save_model(tmp_path / "model.json", res.model)  # a model file that no fit wrote
    with pytest.raises(PamjaxInputError, match="this model was not fitted"):
        pj.prediction_band(tmp_path / "model.json", predict)
    loaded = pj.FitResult.from_json(res.to_json(tmp_path / "fit.json"))
    with pytest.raises(PamjaxInputError, match="pass model="):
        pj.prediction_band(loaded, predict)
    adaptive = lambda m: pj.simulate(m, PREDICT_SIGNAL, T_PREDICT[:4], throw=False).pressure  # noqa: E731
    with pytest.raises(PamjaxInputError, match='needs adjoint="forward"'):  # reverse mode only: named, not JAX's
        pj.prediction_band(res, adaptive)
    with warnings.catch_warnings():
        warnings.simplefilter("error", pj.PamjaxBandWarning)
        mismatched = res.to_dict() | {"mismatch": True}
        with pytest.raises(pj.PamjaxBandWarning, match="understates the uncertainty"):
            pj.prediction_band(pj.FitUncertainty.from_document(mismatched, "x"), predict, model=res.model)
        # a fit that warned that its payload barely moved (pamjax._fit.force_balance.weak_motion): its standard
        # errors, and so the band, may understate the uncertainty; a model file's covariance entry keeps the caution
        barely = res.to_dict() | {"warnings": ["E3, E4: the payload slides in only 10 % of the muscle runs' samples "
                                               "(605 of 6286 samples; ...)", "an unrelated warning"]}
        unc = pj.FitUncertainty.from_document(barely, "x")
        assert len(unc.cautions) == 1 and pj.FitUncertainty.from_document(unc.document(), "m").cautions == unc.cautions
        with pytest.raises(pj.PamjaxBandWarning, match="E3, E4's payload barely moved"):
            pj.prediction_band(unc, predict, model=res.model)
    assert pj.FitUncertainty.from_document(res.to_dict(), "x").cautions == ()


# -- the command line -------------------------------------------------------------------------------------------
FIT_CONFIG = """
    [model]
    preset = "mas10_tank_system"
    options = { valve = "averaged" }
    [fit]
    free = ["valve.coefficients[1,0]", "valve.coefficients[1,1]", "volume"]
    max_steps = 30
    [[experiment]]
    name = "tank"
    file = "tank.csv"
    signal = { kind = "Triangle", low = 0.1, high = 0.9, frequency = 1.0 }
    channels = ["pressure"]
    scales = { pressure = 2e3 }
"""
SIMULATE_CONFIG = """
    [model]
    file = "fit/model.json"{extra}
    [input]
    signal = {{ kind = "Sine", offset = 0.5, amplitude = 0.3, frequency = 0.7 }}
    [simulate]
    t_end = 3.0
    dt = 0.1
    rtol = 1e-8
    atol = 1e-8
"""


@pytest.fixture(scope="module")
def fitted(truth, tmp_path_factory):
    """`pamjax fit` of the tank (model.json carries the covariance)."""
    root = tmp_path_factory.mktemp("bands")
    pj.synthetic_recording(truth, SIGNAL, T_FIT, noise=dict(pressure=NOISE), seed=0, name="tank").to_csv(
        root / "tank.csv")
    (root / "fit.toml").write_text(textwrap.dedent(FIT_CONFIG))
    assert main(["fit", str(root / "fit.toml"), "--out", str(root / "fit"), "--quiet", "--no-plot"]) == 0
    (root / "sim.toml").write_text(textwrap.dedent(SIMULATE_CONFIG.format(extra="")))
    return root


@pytest.mark.slow  # ~25 s: compiles the CLI's solve, its band and the Python API's band of it
def test_cli_simulate_band_columns_figure_and_unchanged_without(fitted, refits):
    root = fitted
    document = json.loads((root / "fit" / "model.json").read_text())
    assert document["provenance"]["covariance"]["labels"] == FREE
    assert main(["simulate", str(root / "sim.toml"), "--out", str(root / "plain")]) == 0
    assert main(["simulate", str(root / "sim.toml"), "--out", str(root / "band"), "--band"]) == 0
    plain = pj.Recording.load(root / "plain" / "trajectory.csv")
    band = pj.Recording.load(root / "band" / "trajectory.csv")
    assert "pressure_lower" not in plain.channels
    assert set(band.channels) == set(plain.channels) | {f"{c}_{e}" for c in ("pressure", "mass_flow")
                                                       for e in ("lower", "upper")}
    np.testing.assert_array_equal(band["pressure"], plain["pressure"])
    assert np.all(band["pressure_lower"] <= band["pressure"]) and np.all(band["pressure"] <= band["pressure_upper"])
    text = (root / "band" / "trajectory.csv").read_text()
    assert "# 95 % confidence band (linear): delta method" in text and "model.json" in text
    assert (root / "band" / "trajectory.png").stat().st_size > 10_000
    # the same band as the Python API's of the same fit (fit.json's values), to the CSV's exact floats
    python = pj.prediction_band(root / "fit" / "fit.json", lambda m: pj.simulate(
        m, PREDICT_SIGNAL, band.t, rtol=1e-8, atol=1e-8, adjoint="forward", throw=False).channel("pressure"),
        model=pj.load_model(root / "fit" / "model.json"), check_linearity=False)
    np.testing.assert_allclose(band["pressure_upper"], python.upper, rtol=1e-12)


def test_cli_band_refusals_and_an_older_model_file(fitted, capsys):
    root = fitted
    preset = root / "preset.toml"
    preset.write_text(textwrap.dedent(SIMULATE_CONFIG.format(extra="").replace('file = "fit/model.json"',
                                                                               'preset = "mas10_tank_system"')))
    assert main(["simulate", str(preset), "--out", str(root / "x"), "--band"]) == 2
    assert "is not a fitted model; --band needs [model] file" in capsys.readouterr().err
    changed = root / "changed.toml"
    changed.write_text(textwrap.dedent(SIMULATE_CONFIG.format(extra='\n    set = { "volume" = 6e-5 }')))
    assert main(["simulate", str(changed), "--out", str(root / "y"), "--band"]) == 2
    assert "changes 'volume', a parameter the fit determined" in capsys.readouterr().err
    assert not (root / "x").exists() and not (root / "y").exists()  # refused before the output folder
    # a model.json written before the covariance entry: the fit.json its provenance names, beside it
    old = json.loads((root / "fit" / "model.json").read_text())
    del old["provenance"]["covariance"]
    (root / "old").mkdir()
    (root / "old" / "model.json").write_text(json.dumps(old))
    (root / "old" / "fit.json").write_text((root / "fit" / "fit.json").read_text())
    (root / "old.toml").write_text(textwrap.dedent(SIMULATE_CONFIG.format(extra="")).replace("fit/model", "old/model"))
    assert main(["simulate", str(root / "old.toml"), "--out", str(root / "z"), "--band", "--no-plot"]) == 0
    assert "covariance of" in capsys.readouterr().out
    (root / "old" / "fit.json").unlink()
    assert main(["simulate", str(root / "old.toml"), "--out", str(root / "w"), "--band"]) == 2
    assert "this model was not fitted" in capsys.readouterr().err


def _delta_std(predict, space, values, cov, rel_step):
    """The delta method's standard deviation of `predict(model)` (an independent reference for a band): each
    gradient a central difference at ±`rel_step` of each physical value, σ² = gᵀ Σ g per output."""
    grads = []
    for i in range(values.size):
        h = rel_step * values[i]
        up, down = values.copy(), values.copy()
        up[i] += h
        down[i] -= h
        grads.append((np.asarray(predict(space.with_values(up))) - np.asarray(predict(space.with_values(down))))
                     / (2 * h))
    grads = np.stack(grads, axis=-1)
    return np.sqrt(np.einsum("...i,ij,...j->...", grads, cov, grads))


def _steady_state_config(model_file, commands, horizon):
    """A `pamjax sweep` config of the steady-state map of a model file, its last 0.5 s averaged."""
    return (f'kind = "steady_state"\n[model]\nfile = "{model_file}"\n[sweep]\ncommands = {commands}\n'
            f"horizon = {horizon}\nwindow = 0.5\n")


def test_cli_sweep_steady_state_band(fitted):
    root = fitted
    (root / "ss.toml").write_text(_steady_state_config("fit/model.json", [0.3, 0.5, 0.7], 2.0))
    assert main(["sweep", str(root / "ss.toml"), "--out", str(root / "ss"), "--band", "--cpu-devices", "1"]) == 0
    with np.load(root / "ss" / "sweep.npz") as f:
        columns = {k: f[k] for k in f.files}
    assert list(columns)[-2:] == ["pressure_pa_abs_lower", "pressure_pa_abs_upper"]
    assert np.all(columns["pressure_pa_abs_lower"] < columns["pressure_pa_abs"])
    assert np.all(columns["pressure_pa_abs"] < columns["pressure_pa_abs_upper"])
    assert (root / "ss" / "sweep.png").stat().st_size > 10_000


def test_cli_band_notes_give_the_commands_option_not_the_apis_keyword(capsys):
    # A band's note advises `method='samples'` (the API's keyword); the command line prints its own option instead.
    from pamjax._cli.bands import report

    class Band:
        def describe(self):
            return "95 % confidence band (linear)\nnote: nonlinear in position (index 0.4); use method='samples'"

    text = report(Band(), "results/fit/model.json", "pamjax simulate")
    out = capsys.readouterr().out
    assert "use --band-method samples" in out and "use --band-method samples" in text
    assert "method='samples'" not in out


def test_a_stick_slip_models_steady_state_band_is_the_delta_method_over_its_maps():
    """A hybrid model (exact stick-slip, `KarnoppFriction`): the map's lanes locate the mode switches as `simulate`
    does, so its band is a band like any other. Its prediction is `steady_state_map` of the model, and its standard
    deviation the delta method with each gradient from central differences of two more `steady_state_map`s (the band
    takes its differences at ±1 σ along the covariance's axes, the reference at ±1e-3 of each value: they agree to
    the band's own nonlinearity, a few per cent)."""
    model = presets.mas10_system(valve="averaged", friction="karnopp")
    paths = ["friction.coulomb_force", "muscle.force_law.k0"]
    values = np.array([float(model.friction.coulomb_force), float(model.muscle.force_law.k0)])
    se, corr = np.array([1.0, 2.0]), np.array([[1.0, 0.3], [0.3, 1.0]])
    uncertainty = pj.FitUncertainty.from_document(dict(labels=paths, paths=paths, values=values.tolist(),
                                                       standard_errors=se.tolist(), correlation=corr.tolist()), "x")
    u, kwargs = np.linspace(0.1, 0.9, 5), dict(horizon=3.0, window=0.5)
    band = pj.steady_state_band(uncertainty, u, model=model, progress=False, **kwargs)
    np.testing.assert_array_equal(band.prediction["position"], pj.steady_state_map(model, u, **kwargs)["position"])
    reference = _delta_std(lambda m: pj.steady_state_map(m, u, **kwargs)["position"], pj.ParameterSpace(model, paths),
                           values, corr * np.outer(se, se), 1e-3)
    assert np.all(reference > 1e-4)  # the payload moves with the parameters at every duty
    np.testing.assert_allclose(band.std["position"], reference, rtol=0.05)
    assert band.nonlinearity["position"] < 0.1


def test_cli_sweep_band_of_a_stick_slip_model_file(tmp_path):
    # `pamjax sweep --band` of a fitted stick-slip model (its model.json carrying the covariance): was refused as
    # "hybrid"; now its band's map is the plain map and brackets it
    model = presets.mas10_system(valve="averaged", friction="karnopp")
    paths = ["friction.coulomb_force", "muscle.force_law.k0"]
    covariance = dict(labels=paths, paths=paths, values=[float(model.friction.coulomb_force),
                                                         float(model.muscle.force_law.k0)],
                      standard_errors=[1.0, 2.0], correlation=[[1.0, 0.3], [0.3, 1.0]], status="converged",
                      mismatch=False)
    pj.save_model(tmp_path / "model.json", model, provenance=dict(covariance=covariance))
    (tmp_path / "ss.toml").write_text(_steady_state_config("model.json", [0.1, 0.5, 0.9], 3.0))
    assert main(["sweep", str(tmp_path / "ss.toml"), "--out", str(tmp_path / "b"), "--band", "--cpu-devices", "1",
                 "--no-plot"]) == 0
    assert main(["sweep", str(tmp_path / "ss.toml"), "--out", str(tmp_path / "p"), "--cpu-devices", "1",
                 "--no-plot"]) == 0
    with np.load(tmp_path / "b" / "sweep.npz") as band, np.load(tmp_path / "p" / "sweep.npz") as plain:
        np.testing.assert_array_equal(band["position_m"], plain["position_m"])
        assert np.all(band["position_m_lower"] < band["position_m"])
        assert np.all(band["position_m"] < band["position_m_upper"])


def test_a_samples_band_of_a_phase_near_180_degrees_is_differenced_modulo_a_turn():
    # draws of a phase at -179.96° fall on both sides of the ±180° cut: their raw quantiles spanned [-179.99,
    # 179.99] (σ 149°) where the linear band gave ±0.12°; unwrapped about ŷ, as the linear method differences them
    from pamjax._bands.maps import band_of_points

    rng = np.random.default_rng(0)
    phase = -179.96 + 0.06 * rng.standard_normal((201, 1))
    phase[0] = -179.96
    wrapped = (phase + 180.0) % 360.0 - 180.0  # what the frequency response gives: within [-180, 180)
    assert np.any(wrapped > 0)
    gain = 1.0 + 0.01 * rng.standard_normal((201, 1))
    outputs = {"position_gain": gain, "position_phase": wrapped}
    pred, lower, upper, std, _, failed = band_of_points(outputs, "samples", 0.95, 3, {"position_phase": 360.0})
    assert failed == 0 and pred["position_phase"] == pytest.approx(-179.96)
    assert std["position_phase"][0] == pytest.approx(0.06, rel=0.2)
    assert lower["position_phase"][0] < -179.96 < upper["position_phase"][0]
    assert upper["position_phase"][0] - lower["position_phase"][0] < 1.0
    np.testing.assert_allclose(std["position_gain"], np.std(gain[1:], ddof=1))  # no period: as it was


def test_seed_channels_and_over_are_refused_by_name_before_any_work(tmp_path, capsys):
    # raw NumPy errors for the seed (on the command line after the simulation ran), "unknown channel 'p'" for a bare
    # string, a raw "multiple values for keyword argument 'over'" TypeError; a result that does not exist would be
    # refused otherwise, so each is checked before the fit is read
    missing = tmp_path / "missing.json"
    for seed in (-1, 1.5, True, "0"):
        with pytest.raises(PamjaxInputError, match=r"seed must be an integer >= 0"):
            pj.prediction_band(missing, predict, method="samples", seed=seed)
        with pytest.raises(PamjaxInputError, match=r"seed must be an integer >= 0"):
            pj.steady_state_band(missing, [0.5], method="samples", seed=seed)
    with pytest.raises(PamjaxInputError, match=r"channels must be .* such as \('position',\), got 'position'"):
        pj.frequency_response_band(missing, [1.0], channels="position")
    with pytest.raises(PamjaxInputError, match=r"over: steady_state_band sweeps the fitted parameters' points"):
        pj.steady_state_band(missing, [0.5], over={"payload_mass": np.array([5.0, 9.6])})
    with pytest.raises(PamjaxInputError, match=r"over: frequency_response_band sweeps"):
        pj.frequency_response_band(missing, [1.0], over={"payload_mass": np.array([5.0, 9.6])})
    for command in ("simulate", "sweep"):
        for seed in ("-1", "1.5"):
            with pytest.raises(SystemExit) as exit_:
                main([command, str(tmp_path / "x.toml"), "--band", "--band-method", "samples", "--band-seed", seed])
            assert exit_.value.code == 2
            assert f"--band-seed must be an integer >= 0, got '{seed}'" in capsys.readouterr().err


# -- a covariance that is not one, any pytree, real-scalar levels, the map's keywords, a misjudged noise level -----
def test_a_covariance_that_is_not_one_is_refused_by_name(refits, tmp_path):
    # A variance of -1e-14 gave a band of std 0 everywhere, a correlation of 3 edited into a model file half-widths
    # of 0 Pa at 11 of 31 rows (J Σ Jᵀ < 0, clipped), a (2, 2) covariance for one label a raw NumPy ValueError.
    res = refits[0][0]
    one = dict(labels=("volume",), paths=("volume",), values=np.array([5e-5]))
    three = dict(labels=tuple(res.labels), paths=tuple(FREE), values=np.asarray(res.values))
    se = np.asarray(res.standard_errors)
    corr = np.array([[1.0, 0.9, 0.9], [0.9, 1.0, -0.9], [0.9, -0.9, 1.0]])  # each in [-1, 1], together impossible
    cases = [
        (dict(one, covariance=[[-1e-14]]), r"the covariance of a FitUncertainty gives volume a negative variance"),
        (dict(one, covariance=np.eye(2) * 1e-14), r"need 1 values and a \(1, 1\) covariance, got .* of shape \(2, 2\)"),
        (dict(one, covariance=[[np.nan]]), "must be finite"),
        (dict(three, covariance=np.array([[1.0, 3.0, 0], [3.0, 1.0, 0], [0, 0, 1.0]]) * np.outer(se, se)),
         r"correlates valve.coefficients\[1,0\] and valve.coefficients\[1,1\] by 3: a correlation lies in \[-1, 1\]"),
        (dict(three, covariance=np.triu(np.full((3, 3), 0.5)) + 0.5 * np.eye(3)), "is not symmetric"),
        (dict(three, covariance=corr * np.outer(se, se)), "is not positive semi-definite: its correlation matrix"),
    ]
    for kwargs, match in cases:
        with pytest.raises(PamjaxInputError, match=match):
            pj.FitUncertainty(**kwargs)
    # a fit's own covariance passes, rounding and all; a file's edited correlation is refused naming the file
    assert pj.FitUncertainty.of(res).labels == tuple(res.labels)
    document = json.loads(json.dumps(res.to_dict(), default=str))  # a copy: to_dict shares the result's lists
    document["correlation"][0][1] = document["correlation"][1][0] = 3.0
    (tmp_path / "fit.json").write_text(json.dumps(document))
    with pytest.raises(PamjaxInputError, match=r"the covariance of .*fit.json correlates .* by 3"):
        pj.prediction_band(tmp_path / "fit.json", predict, model=res.model)
    # a FitUncertainty built in Python is named as one, not as "a FitResult"
    built = pj.FitUncertainty(("vol",), ("volume",), np.array([5e-5]), np.array([[1e-14]]))
    with pytest.raises(PamjaxInputError, match=r"do not match this model's \['volume'\] \(a FitUncertainty\)"):
        pj.prediction_band(built, predict, model=presets.mas10_tank_system("averaged"))


def test_any_pytree_prediction_gets_its_nonlinearity_and_description(refits):
    # A tuple, list or nested dict broke describe() ("'>' not supported between 'tuple' and 'float'"), and a nested
    # dict above the 0.1 index killed prediction_band itself after every solve ("bad operand type for unary -").
    res = refits[0][0]
    volume, sd = res.values[2], res.standard_errors[2]
    shapes = {"tuple": lambda m: (m.volume * jnp.ones(2), 2.0 * m.volume), "list": lambda m: [m.volume * jnp.ones(3)],
              "nested": lambda m: {"tank": {"v": m.volume * jnp.ones(2)}}}
    for name, f in shapes.items():
        band = pj.prediction_band(res, f)
        leaves = jax.tree_util.tree_leaves(band.nonlinearity)
        assert leaves and all(v < 0.1 for v in leaves), (name, band.nonlinearity)
        assert "the linear band holds" in band.describe(), name
    with pytest.warns(pj.PamjaxBandWarning, match=r"nonlinear in the parameters .* in tank.x \("):
        band = pj.prediction_band(res, lambda m: {"tank": {"x": jnp.exp((m.volume - volume) / sd) * jnp.ones(2)},
                                                  "y": (m.volume,)})
    assert band.nonlinearity["tank"]["x"] > 0.1 and "tank.x" in band.describe() and "y[0]" in band.describe()


def test_a_level_may_be_any_real_scalar_and_a_maps_unknown_keyword_names_the_band(refits, tmp_path):
    res = refits[0][0]
    for level in (np.float32(0.95), jnp.asarray(0.9), np.float64(0.5)):
        band = pj.prediction_band(res, lambda m: m.volume * jnp.ones(2), level=level, check_linearity=False)
        assert band.level == pytest.approx(float(level))
    for level in (np.bool_(True), "0.95", np.array([0.95]), np.float32(1.0)):
        with pytest.raises(PamjaxInputError, match="level must be a confidence level in"):
            pj.prediction_band(res, predict, level=level)
    # a misspelt keyword of a map's band: named with the band, and what it takes, before the fit is read
    with pytest.raises(PamjaxInputError, match=r"steady_state_band got the keyword horizn=, which it does not take; "
                                               r"its own: model, level, .*passed on to steady_state_map: horizon"):
        pj.steady_state_band(tmp_path / "missing.json", [0.5], horizn=3.0)
    with pytest.raises(PamjaxInputError, match=r"frequency_response_band got the keyword rtol=.*solve_options"):
        pj.frequency_response_band(tmp_path / "missing.json", [1.0], rtol=1e-9)


def test_residuals_above_a_misjudged_noise_level_do_not_claim_understated_standard_errors(truth):
    # 2 kPa white noise stated as 1 kPa: the covariance is scaled by the residuals' own variance (the refits' spread
    # over their standard errors 0.88, 1.01, 0.74 over 10 seeds), yet every fit said "standard errors understated by
    # up to ~2x": se_inflation multiplied the RMSE ratio, which σ² had already absorbed, by the correlation factor.
    rec = pj.synthetic_recording(truth, SIGNAL, T_FIT, noise=dict(pressure=NOISE), seed=0, name="tank")
    res = pj.fit(truth, [pj.Experiment(rec, SIGNAL, channels=["pressure"], scales=dict(pressure=NOISE / 2))], FREE,
                 progress=False)
    stats = res.channel_errors["tank"]["pressure"]
    assert stats["rmse_over_noise"] > 1.5 and stats["se_inflation"] < 1.2, stats
    assert res.mismatch  # reported: not noise at the stated level
    [note] = [w for w in res.warnings if "stated noise" in w]
    assert "the noise level stated in the experiment's scales is too low, or the model misfits" in note, note
    assert "not understated by this ratio" in note and "standard errors understate" not in note, note
    unc = pj.FitUncertainty.of(res)
    assert unc.se_inflation == 1.0 and not any("understated by" in n for n in unc.notes()), unc.notes()


def test_no_page_runs_simulate_or_sweep_on_a_model_file():
    # README said `pamjax simulate MODEL.json --band`, which the command refuses (it reads a TOML config naming the
    # model file: docs/cli.md).
    root = pathlib.Path(__file__).resolve().parents[1]
    for page in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        for line in page.read_text(encoding="utf-8").splitlines():
            if "refused" not in line:  # docs/cli.md: "`pamjax simulate model.json` is refused with ..."
                assert not re.findall(r"pamjax (?:simulate|sweep) \S+\.json", line), (page.name, line)


def test_a_free_entry_of_several_labels_makes_a_fit_uncertainty():
    # `paths` is the fit's free spec: "force_law.F_max" gives five labels (a0…a4); a check of one path per label
    # refused every fit of the bench (fits/joint.py: "the fit result: 15 labels but 11 paths")
    labels = ("a0", "a1", "payload_mass")
    unc = pj.FitUncertainty(labels, ("force_law.F_max", "payload_mass"), np.ones(3), np.diag([1e-2, 1e-4, 1e-6]))
    assert unc.labels == labels and unc.covariance.shape == (3, 3)


def _covariance_file(tmp_path, edit=None):
    """A model file whose provenance holds a two-parameter covariance (correlation -0.62), its document `edit`ed."""
    paths = ("friction.viscous_coefficient", "friction.coulomb_force")
    se, corr = np.array([3.0, 0.09]), np.array([[1.0, -0.62], [-0.62, 1.0]])
    doc = pj.FitUncertainty(paths, paths, np.array([250.0, 16.0]), corr * np.outer(se, se)).document()
    if edit is not None:
        edit(doc)
    return pj.save_model(tmp_path / "model.json", presets.mas10_system("averaged"), overwrite=True,
                         provenance={"covariance": doc})


def _set(doc, key, i, j, value):
    doc[key][i][j] = value
    if i != j:
        doc[key][j][i] = value


@pytest.mark.parametrize("edit, match", [
    (lambda d: _set(d, "correlation", 0, 1, "nan"),  # read as correlation 0
     r"correlation of friction.viscous_coefficient and friction.coulomb_force is nan"),
    (lambda d: _set(d, "correlation", 1, 1, 0.3),  # accepted
     r"correlation of friction.coulomb_force with itself is 0.3"),
])
def test_a_damaged_correlation_is_refused_naming_the_pair(tmp_path, edit, match):
    path = _covariance_file(tmp_path, edit)
    with pytest.raises(PamjaxInputError, match=match):
        pj.read_uncertainty(path)


def test_an_undetermined_parameters_nan_correlations_read_as_zero(tmp_path):
    def undetermined(d):
        d["standard_errors"][1] = "inf"
        _set(d, "correlation", 0, 1, "nan")

    unc = pj.read_uncertainty(_covariance_file(tmp_path, undetermined))
    assert np.isinf(unc.covariance[1, 1]) and unc.covariance[0, 1] == 0.0


def test_read_uncertainty_skips_a_byte_order_mark(tmp_path):
    path = _covariance_file(tmp_path)
    path.write_text("\ufeff" + path.read_text(encoding="utf-8"), encoding="utf-8")  # Notepad's "UTF-8 with BOM"
    unc = pj.read_uncertainty(path)
    np.testing.assert_allclose(unc.covariance[0, 1], -0.62 * 3.0 * 0.09, rtol=1e-12)
