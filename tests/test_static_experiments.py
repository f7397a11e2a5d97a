"""Bench tests without a time axis (`pamjax/_fit/static_experiments.py`): their predictions against NumPy
transcriptions of paper 000's eq. 8-9 and 11, parameter recovery through `pamjax.fit` from oracle-made data, the
reductions of raw runs, and bad input named before any fit."""

import equinox as eqx
import numpy as np
import pytest
from helpers import P_ATM, np_ellipse_flow, np_eq7_force, np_friction

import pamjax as pj
from pamjax import presets
from pamjax._physics.friction import KarnoppFriction

# The laws under test jitted, one program each (eagerly, each of their operations compiles a program of its own); the
# velocities and pressures go in as arrays, not Python floats, which `filter_jit` would bake in as constants.
_steady_friction_force = eqx.filter_jit(pj.bench.steady_friction_force)
_flow_curve = eqx.filter_jit(pj.bench.flow_curve)
_mass_flow = eqx.filter_jit(lambda restriction, p_up, p_down, air: restriction.mass_flow(p_up, p_down, air))
_predict = eqx.filter_jit(lambda experiment, model: experiment.predict(model))
_residuals = eqx.filter_jit(lambda experiment, model: experiment.residuals(model))


@pytest.mark.parametrize("v", [-0.2, -0.01, 0.004, 0.15])
def test_steady_friction_force(v):
    """Eq. 9 at steady sliding: smooth sign (tanh), exact sign (Karnopp), and the bristle model's steady state
    z = F_c sign(v)/σ0 (its rate takes the exact |v|), where its force is F_c sign(v) + C_f v at any speed (the
    smoothed |v| it took before put 38.6 N at 10 µm/s for F_c = 16 N)."""
    smooth = pj.CoulombViscousFriction(16.0, 250.0)
    assert float(_steady_friction_force(smooth, np.asarray(v))) == pytest.approx(np_friction(v, 16.0, 250.0, 1e-3),
                                                                                 rel=1e-12)
    assert float(_steady_friction_force(KarnoppFriction(16.0, 250.0), np.asarray(v))) == pytest.approx(
        16.0 * np.sign(v) + 250.0 * v, rel=1e-12)
    bristle = pj.BristleFriction(16.0, velocity_width=1e-5)
    assert float(_steady_friction_force(bristle, np.asarray(v))) == pytest.approx(16.0 * np.sign(v) + 250.0 * v,
                                                                                  rel=1e-10)


def test_constant_velocity_point_reduces_a_run():
    t = np.linspace(0.0, 0.1, 101)
    v, f, se = pj.bench.constant_velocity_point(t, 0.01 + 0.05 * t, np.full(t.size, 28.5))
    assert v == pytest.approx(0.05, rel=1e-12) and f == pytest.approx(28.5) and se == 0.0
    with pytest.raises(pj.PamjaxInputError, match="force must be finite"):
        pj.bench.constant_velocity_point(t, t, np.where(t > 0.05, np.nan, 1.0))


def test_friction_curve_fit_recovers_eq9():
    """Points from eq. 9 (NumPy) with 0.5 N noise; F_c and C_f recovered within 3 standard errors."""
    rng = np.random.default_rng(1)
    v = np.concatenate([-np.geomspace(0.01, 0.2, 6), np.geomspace(0.01, 0.2, 6)])
    f = np_friction(v, 16.0, 250.0, 1e-3) + 0.5 * rng.standard_normal(v.size)
    exp = pj.bench.FrictionCurveExperiment(v, f, scale=0.5, friction="")
    res = pj.fit(pj.CoulombViscousFriction(10.0, 100.0), [exp], ["coulomb_force", "viscous_coefficient"],
                 progress=False)
    z = (np.asarray(res.values) - [16.0, 250.0]) / np.asarray(res.standard_errors)
    assert np.all(np.abs(z) < 3), (res.values, res.standard_errors)
    assert res.channel_errors["friction_curve"]["force"]["rmse"] < 1.0  # the fitter's report works without a time axis


def test_flow_curve_prediction_and_fit():
    """Eq. 11 through a valve path against the NumPy oracle; C_v, b_v of path 1→2 recovered from oracle points."""
    valve = presets.mas10_valve("exact")
    p_up = np.repeat([5e5, 6e5, 7e5], 10)
    p_down = np.concatenate([np.linspace(P_ATM, 0.98 * p, 10) for p in (5e5, 6e5, 7e5)])
    flow = np.array([np_ellipse_flow(a, b, 0.36, 0.28, 3.14e-6) for a, b in zip(p_up, p_down)])
    exp = pj.bench.FlowCurveExperiment(p_up, p_down, flow, scale=1e-5, restriction="inflate")
    np.testing.assert_allclose(np.asarray(_predict(exp, valve)["mass_flow"]), flow, rtol=1e-12)
    space = pj.ParameterSpace(valve, ["inflate.discharge_coefficient", "inflate.critical_ratio"])
    start = space.with_values([0.45, 0.2])
    res = pj.fit(start, [exp], ["inflate.discharge_coefficient", "inflate.critical_ratio"], progress=False)
    np.testing.assert_allclose(res.values, [0.36, 0.28], rtol=1e-6)  # noise-free: exact recovery
    assert np.allclose(_flow_curve(valve.inflate, np.asarray(6e5), np.asarray([0.1, 0.2]), pj.Air()),
                       _mass_flow(valve.inflate, np.asarray(6e5), np.asarray(0.0), pj.Air()))


def test_loop_force_map_prediction_slack_and_average():
    """Eq. 8-9: F = F_static − F_c sign(ẋ) − C_f ẋ (eq. 7 from NumPy); slack points only penalise a pulling model;
    `loop_average` gives the mean curve and the width 2 F_c + 2 C_f |ẋ|."""
    system = presets.mas10_system("pwm", friction=KarnoppFriction(16.0, 250.0))
    x = np.array([0.0, 0.02, 0.04, 0.0, 0.02, 0.04])
    p = np.full(6, P_ATM + 4e5)
    v = np.array([5e-3] * 3 + [-5e-3] * 3)
    law = system.muscle.force_law
    static = np_eq7_force(x, 4e5, np.asarray(law.max_force_coefficients), float(law.k0), float(law.k1),
                          float(law.k2))
    expected = static - (16.0 * np.sign(v) + 250.0 * v)
    exp = pj.bench.LoopForceMapExperiment(x, p, v, expected, scale=1.0)
    np.testing.assert_allclose(np.asarray(_predict(exp, system)["force"]), expected, rtol=1e-12)
    assert np.max(np.abs(np.asarray(_residuals(exp, system)))) < 1e-9
    slack = pj.bench.LoopForceMapExperiment(x, p, v, np.where(x > 0.03, 0.0, expected), scale=1.0)
    # 0 N measured: one-sided
    assert float(np.asarray(_residuals(slack, system))[2]) == pytest.approx(max(expected[2], 0.0))
    xa, pa, mean, width = pj.bench.loop_average(x, p, v, expected)
    np.testing.assert_allclose(width, 2 * (16.0 + 250.0 * 5e-3), rtol=1e-12)
    np.testing.assert_allclose(mean, static[:3], rtol=1e-12)


def test_bad_input_is_named_before_any_fit():
    with pytest.raises(pj.PamjaxInputError, match="velocities must be non-zero"):
        pj.bench.FrictionCurveExperiment([0.0, 0.1], [1.0, 2.0])
    with pytest.raises(pj.PamjaxInputError, match="one length"):
        pj.bench.FrictionCurveExperiment([0.1, 0.2], [1.0])
    with pytest.raises(pj.PamjaxInputError, match="upstream_pressures must be ABSOLUTE"):
        pj.bench.FlowCurveExperiment([5.0, 6.0], [1.0, 1.0], [1e-3, 1e-3])  # bar, not Pa
    with pytest.raises(pj.PamjaxInputError, match="scale must be > 0"):
        pj.bench.FlowCurveExperiment([5e5], [2e5], [1e-3], scale=0.0)
    with pytest.raises(pj.PamjaxInputError, match="has no 'friction'"):
        pj.bench.FrictionCurveExperiment([0.1, 0.2], [40.0, 66.0]).check(presets.mas10_valve())
    with pytest.raises(pj.PamjaxInputError, match="the model is OnOffValve; a AbstractFriction is needed"):
        pj.bench.FrictionCurveExperiment([0.1, 0.2], [40.0, 66.0], friction="").check(presets.mas10_valve())
    with pytest.raises(pj.PamjaxInputError, match="has no 'nozzle'"):
        pj.bench.FlowCurveExperiment([5e5], [2e5], [1e-3], scale=1e-5,
                                     restriction="nozzle").check(presets.mas10_valve())
    with pytest.raises(pj.PamjaxInputError, match="needs a 'muscle'"):
        pj.bench.LoopForceMapExperiment([0.0], [3e5], [1e-3], [10.0], scale=1.0).check(presets.mas10_valve())


def test_a_run_without_time_and_maps_in_mm_are_named():
    # A constant `t` gave NumPy's raw LinAlgError ("SVD did not converge"); positions in mm (0-70) were fitted as
    # metres. Both refused by name, before anything is computed.
    t = np.zeros(10)
    with pytest.raises(pj.PamjaxInputError, match=r"^t must span a time .* all are 0"):
        pj.bench.constant_velocity_point(t, np.linspace(0.0, 0.01, 10), np.full(10, 3.0))
    x, p, f = np.linspace(0.0, 70.0, 8), np.full(8, 4e5), np.linspace(500.0, 100.0, 8)
    v = np.where(np.arange(8) < 4, 1e-3, -1e-3)
    for build in (lambda: pj.bench.ForceMapExperiment(x, p, f), lambda: pj.bench.LoopForceMapExperiment(x, p, v, f),
                  lambda: pj.bench.HysteresisLoopExperiment(x, p, v, f)):
        with pytest.raises(pj.PamjaxInputError, match=r"positions reach 70 m, .* these look like mm"):
            build()
    pj.bench.ForceMapExperiment(x / 1e3, p, f)  # the same map in metres


def test_map_positions_outside_the_muscles_stroke_are_refused_by_name():
    # The data file's lengths L (0.222-0.296 m of a 300 mm muscle) passed for the contraction L0 - L were fitted to
    # nonsense (a0 = -3370 N) with only an identifiability warning: `check` (run by `fit` before anything is solved)
    # compares the positions with the muscle's stroke, 5 % of it admitted beyond either end (as simulate's start).
    system = presets.mas10_system("averaged")  # stroke [-0.02, 0.075] m
    lengths = np.linspace(0.222, 0.296, 6)
    p, f, v = np.full(6, 4e5), np.linspace(300.0, 0.0, 6), np.where(np.arange(6) < 3, 1e-3, -1e-3)
    for exp in (pj.bench.ForceMapExperiment(lengths, p, f, scale=1.0, name="bench_map"),
                pj.bench.LoopForceMapExperiment(lengths, p, v, f, scale=1.0, name="bench_map"),
                pj.bench.HysteresisLoopExperiment(lengths, p, v, f, scale=1.0, name="bench_map")):
        with pytest.raises(pj.PamjaxInputError, match=r"^bench_map: positions\[0\] = 0\.222 m .* outside the muscle's "
                                                      r"stroke \[-0\.02, 0\.075\] m .* contractions L0 − L \[m\]"):
            exp.check(system)
    with pytest.raises(pj.PamjaxInputError, match=r"bench_map: positions\[0\] = 0\.222 m"):  # a muscle alone
        pj.bench.ForceMapExperiment(lengths, p, f, scale=1.0, name="bench_map").check(system.muscle)
    with pytest.raises(pj.PamjaxInputError, match=r"bench_map: positions\[0\] = 0\.222 m"):  # before any solve
        pj.fit(system.muscle, [pj.bench.ForceMapExperiment(lengths, p, f, scale=1.0, name="bench_map")],
               ["force_law.k0"], progress=False)
    # within the margin (4 % of the 95 mm stroke beyond either end) the same map is accepted
    inside = np.linspace(-0.02 - 0.0038, 0.075 + 0.0038, 6)
    pj.bench.ForceMapExperiment(inside, p, f, scale=1.0).check(system)
    pj.bench.LoopForceMapExperiment(inside, p, v, f, scale=1.0).check(system)


def test_force_map_scale_and_slack_force_are_checked_as_the_loops_are():
    # scale=inf made every residual 0 (LoopForceMapExperiment refused it); slack_force=NaN turned every slack point
    # (0 N) into an ordinary 0 N point. Both refused by name, for each map.
    x, p, f, v = [0.0, 0.01, 0.02], np.full(3, 4e5), np.array([100.0, 50.0, 0.0]), [1e-3, 1e-3, -1e-3]
    builds = (lambda **k: pj.bench.ForceMapExperiment(x, p, f, **k),
              lambda **k: pj.bench.LoopForceMapExperiment(x, p, v, f, **k),
              lambda **k: pj.bench.HysteresisLoopExperiment(x, p, v, f, **k))
    for build in builds:
        for scale in (np.inf, np.nan, 0.0):
            with pytest.raises(pj.PamjaxInputError, match=r"^scale must be > 0 and finite \[N\]"):
                build(scale=scale)
        for slack in (np.nan, np.inf, [0.0, 1.0]):
            with pytest.raises(pj.PamjaxInputError, match=r"^slack_force must be one number \[N\]"):
                build(slack_force=slack)
        assert np.asarray(build(slack_force=0.0).slack).tolist() == [False, False, True]
        assert not np.any(np.asarray(build(slack_force=-np.inf).slack))  # -inf: no slack point


def test_force_map_errors_count_the_loaded_points_only():
    """A slack point (measured F ≤ 0) is an inequality, not a measurement of 0 N: its residual is 0 where the model is
    slack too, so counting it diluted the RMSE (the DMSP-20-300 map, 66 of 126 points slack: 3.1 N instead of the
    loaded points' 4.3 N). The statistics are over the loaded points; the slack ones are counted apart, with the
    model's largest push there."""
    from pamjax._fit.diagnostics import channel_errors

    forces = np.array([100.0, 200.0, 0.0, 300.0, 0.0, 0.0, 150.0, 250.0])
    x = np.linspace(0.0, 0.05, forces.size)
    exp = pj.bench.ForceMapExperiment(x, np.full(forces.size, 4e5), forces, scale=2.0)
    r = np.where(forces > 0, [1.0, -1.0, 0, 1.0, 0, 0, -1.0, 1.0], [0, 0, 0, 0, 1.5, 0, 0, 0])  # (model − F) / scale
    stats = channel_errors([exp], r)["force_map"]["force"]
    assert stats["rmse"] == pytest.approx(2.0) and stats["max_error"] == pytest.approx(2.0)  # loaded: |err| = 2 N
    assert stats["slack_points"] == 3 and stats["slack_max_violation"] == pytest.approx(3.0)
    assert stats["range"] == pytest.approx(300.0)  # the map's forces from 0 N up


def test_static_experiments_refuse_the_units_recordings_refuse():
    # Flows in g/s, velocities in mm/s and pressures of 5e7 Pa were accepted (a flow curve fitted C = 6.85e-6 for
    # 7.9e-9, a friction curve C_f = 0.25 for 250) where `Recording` refuses the same numbers: refused by name.
    x, f = np.linspace(0.005, 0.05, 6), np.linspace(300.0, 100.0, 6)
    p, v = np.full(6, 5e5), np.where(np.arange(6) < 3, 5.0, -5.0) * 5  # ±25 mm/s written as m/s
    with pytest.raises(pj.PamjaxInputError, match=r"^mass_flows reaches 5 kg/s.* look like g/s; pamjax takes SI"):
        pj.bench.FlowCurveExperiment(p, 0.5 * p, np.linspace(1.0, 5.0, 6))
    with pytest.raises(pj.PamjaxInputError, match=r"^velocities reaches 25 m/s; these look like mm/s"):
        pj.bench.FrictionCurveExperiment(v, f)
    for build in (lambda: pj.bench.LoopForceMapExperiment(x, p, v, f),
                  lambda: pj.bench.HysteresisLoopExperiment(x, p, v, f),
                  lambda: pj.bench.path_friction_force(KarnoppFriction(16.0, 250.0), x, v, np.arange(6) == 0)):
        with pytest.raises(pj.PamjaxInputError, match=r"^velocities reaches 25 m/s; these look like mm/s"):
            build()
    for build in (lambda: pj.bench.ForceMapExperiment(x, p * 100, f),
                  lambda: pj.bench.FlowCurveExperiment(p * 100, p, np.full(6, 1e-3))):
        with pytest.raises(pj.PamjaxInputError, match=r"pressures reaches 5e\+07 Pa = 500 bar"):
            build()
    pj.bench.FlowCurveExperiment(p, 0.5 * p, np.linspace(1.0, 5.0, 6) * 1e-3)  # the same in SI
    pj.bench.FrictionCurveExperiment(v / 1e3, f)


def test_a_force_map_with_loaded_points_at_atmospheric_pressure_is_gauge():
    # The Festo map's GAUGE pressures with its all-zero 35 kPa row dropped (65 kPa up) passed the half-atmosphere
    # check, and eq. 7 was fitted 264 N off at 6 bar: a muscle at or below one atmosphere pulls nothing.
    x = np.linspace(0.005, 0.05, 6)
    p, f = np.array([6.5e4, 8.5e4, 1.1e5, 2e5, 4e5, 6e5]), np.array([54.9, 113.4, 150.0, 300.0, 700.0, 1100.0])
    with pytest.raises(pj.PamjaxInputError, match=r"^pressures must be ABSOLUTE \[Pa\]: 2 loaded point\(s\) lie at "
                                                  r"or below one atmosphere .* GAUGE pressures \(add 101325 Pa\)"):
        pj.bench.ForceMapExperiment(x, p, f)
    pj.bench.ForceMapExperiment(x, p + P_ATM, f)  # absolute: accepted
    pj.bench.ForceMapExperiment(x, np.r_[P_ATM, P_ATM, p[2:] + P_ATM], np.r_[0.0, 0.0, f[2:]])  # vented and slack
    pj.bench.ForceMapExperiment(x, np.r_[P_ATM, p[1:] + P_ATM], np.r_[0.4, f[1:]], slack_force=0.5)  # noise at rest


def test_a_map_with_no_loaded_point_is_refused_and_sign_flipped_forces_named():
    # Tension read negative: every point slack (an inequality), the fit "converged" at cost 5e-25 to a pushing muscle.
    x, p, v = np.linspace(0.005, 0.05, 6), np.full(6, 5e5), np.where(np.arange(6) < 3, 5e-3, -5e-3)
    f = -np.array([0.0, 0.0, 150.0, 300.0, 700.0, 1100.0])
    for build in (lambda f, **k: pj.bench.ForceMapExperiment(x, p, f, **k),
                  lambda f, **k: pj.bench.LoopForceMapExperiment(x, p, v, f, **k),
                  lambda f, **k: pj.bench.HysteresisLoopExperiment(x, p, v, f, **k)):
        with pytest.raises(pj.PamjaxInputError, match=r"^forces: every point is at or below slack_force = 0 N .* no "
                                                      r"measured \(loaded\) force is left.* 4 of the 6 are negative .*"
                                                      r"sign-flipped .* pass -forces"):
            build(f)
        with pytest.raises(pj.PamjaxInputError, match=r"no measured \(loaded\) force is left to fit\.$"):
            build(-f, slack_force=2e3)  # all below a threshold, none negative: no sign said
        assert np.sum(~np.asarray(build(-f).slack)) == 4  # tension positive: the 4 loaded points measured


def test_the_diagnostics_of_a_map_do_not_read_its_row_order_as_time():
    # The same 126 points of the DMSP-20-300 map in file order gave lag-1 0.59, se_inflation 1.96 and "residuals
    # correlated in time"; sorted by pressure -0.24; shuffled -0.03. Without a time axis the order statistics are left
    # out (not NaN: two equal fits compare equal) and take no part in `mismatch`; the RMSE does not depend on the order.
    from pamjax._fit import diagnostics

    x = np.linspace(0.0, 0.05, 40)
    r = np.sin(np.linspace(0.0, 3.0, 40))  # a smooth residual in this order: lag-1 0.89 read as time
    order = np.random.default_rng(3).permutation(40)
    stats = []
    for idx in (np.arange(40), order):
        exp = pj.bench.ForceMapExperiment(x[idx], np.full(40, 4e5), np.linspace(100.0, 500.0, 40)[idx], scale=1.0)
        flow = pj.bench.FlowCurveExperiment(np.full(40, 6e5), np.linspace(2e5, 5e5, 40)[idx], np.full(40, 1e-3),
                                           scale=1e-5)
        errors = diagnostics.channel_errors([exp, flow], np.r_[r[idx], r[idx]])
        assert not diagnostics.mismatch(errors)[0] and diagnostics.understatement(errors) == 1.0
        for st in (errors["force_map"]["force"], errors["flow_curve"]["mass_flow"]):
            assert not st["ordered"] and not {"se_inflation", "noise_estimate", "autocorrelation"} & set(st)
        stats.append(errors["force_map"]["force"]["rmse"])
    assert stats[0] == pytest.approx(stats[1])
    # a loop read as the path travelled keeps them: its samples are in the order measured
    v = np.where(np.arange(40) < 20, 5e-3, -5e-3)
    loop = pj.bench.HysteresisLoopExperiment(x, np.full(40, 4e5), v, np.linspace(100.0, 500.0, 40), scale=1.0)
    st = diagnostics.channel_errors([loop], r)["hysteresis_loop"]["force"]
    assert st["ordered"] and st["autocorrelation"]["1"] > 0.8


def test_flow_curve_checks_its_arguments():
    # 6 (bar) for the upstream pressure gave flows 1e5 times too small, downstream pressures in Pa given as ratios
    # -1011 kg/s, a negative ratio was clipped to 0; all accepted without a word.
    inflate, air = presets.mas10_valve().inflate, pj.Air()
    with pytest.raises(pj.PamjaxInputError, match=r"^upstream_pressure is 6 Pa at most: that looks like bar"):
        pj.bench.flow_curve(inflate, 6.0, [0.3, 0.8], air)
    with pytest.raises(pj.PamjaxInputError, match=r"^ratios must be pressure ratios .* got 180000 \(these look like "
                                                  r"downstream pressures in Pa"):
        pj.bench.flow_curve(inflate, 6e5, [1.8e5, 4.8e5], air)
    with pytest.raises(pj.PamjaxInputError, match=r"^ratios must be pressure ratios p_down/p_up in \[0, 1\], "
                                                  r"got -0.5$"):
        pj.bench.flow_curve(inflate, 6e5, [-0.5], air)
    with pytest.raises(pj.PamjaxInputError, match=r"^air must be the air"):
        pj.bench.flow_curve(inflate, 6e5, [0.5], None)
    with pytest.raises(pj.PamjaxInputError, match=r"^restriction must be a restriction"):
        pj.bench.flow_curve(presets.mas10_valve(), 6e5, [0.5], air)


def test_the_bristle_friction_at_rest_is_0_n_with_a_finite_gradient():
    # Newton's step at v = 0 was 0/0: NaN force and NaN gradient, where the other frictions give 0 N.
    import jax

    v = np.array([-0.01, 0.0, 0.01])
    force = np.asarray(_steady_friction_force(pj.BristleFriction(16.0), v))
    np.testing.assert_allclose(force, [-18.5, 0.0, 18.5], rtol=1e-12)
    grad = jax.grad(lambda c: _steady_friction_force(pj.BristleFriction(coulomb_force=c), v)[1:].sum())(16.0)
    assert float(grad) == pytest.approx(1.0)


@pytest.mark.parametrize("call, match", [
    (lambda v, f: pj.bench.FrictionCurveExperiment(v, f, friction=None), r"^friction must be the component's path"),
    (lambda v, f: pj.bench.FlowCurveExperiment([5e5], [2e5], [1e-3], restriction=None),
     r"^restriction must be the component's path"),
    (lambda v, f: pj.bench.ForceMapExperiment(np.abs(v), np.full(6, 5e5), np.abs(f), scale=np.full(6, 2.0)),
     r"^scale must be one number \[N\]"),
    (lambda v, f: pj.bench.FlowCurveExperiment([5e5] * 2, [2e5] * 2, [1e-3] * 2, scale=np.full(2, 1e-5)),
     r"^scale must be one number \[kg/s\]"),
    (lambda v, f: pj.bench.ForceMapExperiment(["length_m"] + ["0.01"] * 5, np.full(6, 5e5), np.abs(f)),
     r"^positions must be numbers .*'length_m'"),
    (lambda v, f: pj.bench.constant_velocity_point(["t [s]", 0.1, 0.2], [0.0, 1e-3, 2e-3], [1.0, 2.0, 3.0]),
     r"^t must be numbers"),
    (lambda v, f: pj.bench.steady_friction_force("karnopp", 0.1), r"^friction must be a friction model"),
    (lambda v, f: pj.bench.loop_average(np.abs(v), np.full(6, 5e5), v, f, decimals="6"),
     r"^decimals must be an integer"),
])
def test_misuse_of_the_bench_tests_is_named(call, match):
    # each gave a raw AttributeError, TypeError or ValueError (friction=None only at the fit)
    v = np.r_[np.full(3, 0.01), np.full(3, -0.01)]
    with pytest.raises(pj.PamjaxInputError, match=match):
        call(v, 16 * np.sign(v) + 250 * v)
