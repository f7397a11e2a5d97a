"""design: the objective's gradient (forward mode over the envelope, reverse mode per period) against central finite
differences and each other; a design raises the information over its start and keeps its constraints; the CSV
replays as the same signal; `pamjax design CONFIG.toml` writes it; bad input is named before any solve.

The system is paper 000's valve feeding the 5e-5 m³ test tank (pressure only, a few PWM periods): small programs.
"""

import json
import math
import pathlib
import textwrap
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets
from pamjax._cli.main import main
from pamjax._core.arrays import device_array
from pamjax._identifiability import design_objective as obj

FREE = ["valve.inflate.discharge_coefficient", "valve.inflate.critical_ratio", "valve.exhaust.discharge_coefficient"]
NOISE = {"pressure": 2e3}
TANK = dict(channels=("pressure",), start={"pressure": 101325.0}, rate=500.0, design_rate=250.0, knots=4,
            max_duty_step=0.3, initial=pj.Constant(0.6))  # from 0.6: the tank passes the inflow's critical ratio


def _tank():
    return presets.mas10_tank_system(valve="pwm")


@eqx.filter_jit
def _at(signal, t):
    """`signal` at times `t`, one compiled program (eagerly, each of its operations would compile on its own)."""
    return signal(t)


_clip01 = jax.jit(obj.clip01)  # one program per shape (eagerly, each of its operations compiles its own)


def test_bspline_basis_is_a_partition_of_unity_and_soft_clip_inverts():
    t = np.linspace(0.0, 3.0, 301)
    b = obj.bspline_basis(t, 0.0, 3.0, 7)
    assert b.shape == (301, 7) and np.all(b >= 0)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-12)
    assert b[0, 0] == pytest.approx(1.0) and b[-1, -1] == pytest.approx(1.0)  # clamped ends
    z = np.linspace(-0.5, 1.5, 41)
    d = np.asarray(_clip01(z))
    assert np.all((d > 0) & (d < 1)) and np.all(np.diff(d) > 0)
    # within width·log 2 of the sharp clip, as smooth_relu promises
    assert np.max(np.abs(d - np.clip(z, 0, 1))) <= obj.CLIP_WIDTH * math.log(2) + 1e-12
    inner = d[(z > 0.05) & (z < 0.95)]
    np.testing.assert_allclose(np.asarray(_clip01(obj.unclip01(inner))), inner, atol=1e-12)


def _problem(parametrisation):
    """The compiled objective's problem for the 0.4 s tank run (20 PWM periods) as `design` builds it: no pressure
    limit and no variance floor are infinite ones, as in `design`, so that this problem, the CLI test's and every
    design of this module on the tank share one compilation of the objective and of its gradient."""
    from pamjax._identifiability.design_setup import designed_experiment, start_coefficients

    model = pj.ParameterSpace(_tank(), FREE).base
    space = pj.ParameterSpace(model, FREE)
    times = np.arange(20) * 0.02
    carrier = obj.multilevel_carrier(20, 10, 0)
    c0, basis = start_coefficients(parametrisation, times, 0.4, 4, carrier, (0.1, 0.9), None)
    exp = designed_experiment(model, 0.4, 0.02, 250.0, ("pressure",), NOISE, {"pressure": 101325.0}, 4,
                              np.full(20, 0.5))
    # the arrays made from NumPy with `device_array` (jnp.asarray compiles a program per shape; the scalars stay
    # jnp.asarray's weakly typed ones, as `design` makes them)
    prob = obj.DesignProblem(space=space, theta=space.initial_theta(), experiment=exp,
                             basis=None if basis is None else device_array(basis), prior=device_array(np.zeros((3, 3))),
                             weight=jnp.asarray(2.0), band=device_array([0.1, 0.9]), windows=None, stroke=None,
                             max_pressure=jnp.asarray(np.inf), max_step=jnp.asarray(0.3), min_force=None,
                             floor=device_array(np.full(3, np.inf)), subset=(0, 1, 2), criterion="D")
    c = device_array(np.asarray(c0) + 0.5)  # level lifted off the band's bottom: every parameter is fixed there
    return c, prob


def test_forward_gradient_matches_central_differences():
    # The objective is piecewise smooth in the duty (edges move continuously inside a period); away from the band
    # ends and the 10 %/90 % dead bands a central difference of step 1e-5 agrees to its truncation error.
    c, prob = _problem("envelope")
    g = np.asarray(obj.forward_gradient(c, prob))
    h, host = 1e-5, np.asarray(c)
    for k in range(c.size):
        e = np.zeros(c.size)
        e[k] = h  # the steps on the host: eager JAX would compile each small operation on its own
        up, down = (float(obj.value(jnp.asarray(host + sign * e), prob)[0]) for sign in (1.0, -1.0))
        fd = (up - down) / (2 * h)
        assert g[k] == pytest.approx(fd, rel=1e-4, abs=1e-6 * np.max(np.abs(g)))


def test_reverse_gradient_per_period_equals_forward_mode():
    c, prob = _problem("periods")
    rev = np.asarray(obj.reverse_gradient(c, prob))
    fwd = np.asarray(obj.forward_gradient(c, prob))
    assert np.any(rev != 0)
    np.testing.assert_allclose(rev, fwd, rtol=1e-8, atol=1e-10 * np.max(np.abs(fwd)))


def test_targets_are_the_baselines_standard_errors_over_the_margin_where_a_transform_mixes_parameters():
    # A force law's a0…a4 share one transform (θ mixes them), so √floor × |∂a/∂θ| (the diagonal) is no standard error
    # of a: it once reported a target of 0.0012 N for a0 beside a baseline of 2.5 N and named a0 "576× short" of it
    # while the table's ratio column read 3.6× better. The target is the baseline's physical standard error over the
    # margin (no prior here), as that column reads, for mixed and unmixed parameters alike.
    from pamjax._identifiability import design as dmod

    free = ["muscle.force_law.max_force_coefficients", "muscle.force_law.k0"]
    space = pj.ParameterSpace(presets.mas10_system(), free)
    theta = np.asarray(space.initial_theta())
    a = np.random.default_rng(7).normal(size=(theta.size, theta.size))
    base = a @ a.T + theta.size * np.eye(theta.size)  # a baseline's information about θ
    prior = np.zeros_like(base)
    floor = dmod._floor(prior, base, 1.5)
    targets = dmod._targets(space, theta, floor, base)
    physical = np.asarray(dmod._physical_errors(space, theta, base))
    np.testing.assert_allclose(targets, physical / 1.5, rtol=1e-12)
    g = np.abs(np.diag(np.asarray(dmod.physical_and_jacobian(space, device_array(theta))[1])))
    assert not np.allclose(np.sqrt(floor) * g, physical / 1.5, rtol=1e-3)  # the diagonal's figure is another one
    floor[:2] = np.inf  # no target where the floor asks none
    assert all(math.isinf(t) for t in dmod._targets(space, theta, floor, base)[:2])


def test_design_raises_the_information_keeps_its_constraints_and_replays_from_csv(tmp_path):
    # Baseline: a constant-duty run of the same length; the design must match it on every parameter.
    base_rec = pj.synthetic_recording(_tank(), pj.Constant(0.3), np.arange(0.0, 0.4, 2e-3), name="base")
    base = pj.Experiment(base_rec, pj.Constant(0.3), channels=["pressure"], scales=NOISE,
                         initial={"pressure": 101325.0})
    res = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=6, baseline=[base], progress=False, **TANK)
    assert res.objective[1] < res.objective[0]  # D criterion: log det F⁻¹ went down
    assert len(res.duty) == 20 and all(0.125 <= d <= 0.875 for d in res.duty)  # 0.025 from the 10 %/90 % thresholds
    assert res.constraints["threshold_distance"] >= 0.025 - 1e-12
    assert res.constraints["feasible"] and res.constraints["largest_duty_step"] <= 0.3 + 1e-9
    ratio = np.asarray(res.standard_errors["baseline"]) / np.asarray(res.standard_errors["design"])
    assert np.all(ratio > 0.97), ratio  # the floor's penalty leaves a slack of ~1 %
    assert all(math.isinf(s) for s in res.standard_errors["prior"])  # no prior experiments: nothing known
    # no prior: the target is the baseline's standard error over the margin (1), and what falls short is named
    np.testing.assert_allclose(res.standard_errors["target"], res.standard_errors["baseline"], rtol=1e-9)
    short = {k: v for k, v in zip(res.labels, 1 / ratio) if v > 1 + 1e-9}
    assert res.baseline_shortfall == pytest.approx(short, rel=1e-12)
    # the start (steps=0) is the constant 0.6 of TANK: the design beats it
    start = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=0, baseline=[base], progress=False, **TANK)
    assert start.objective[1] == pytest.approx(res.objective[0], rel=1e-9)
    path = res.to_csv(tmp_path / "design.csv")
    rec = pj.Recording.load(path)
    # one row per period and a last one at the run's end (the last duty again: a replay runs to the end); the duty
    # column is read as the bench's "command"
    np.testing.assert_array_equal(rec["command"], [*res.duty, res.duty[-1]])
    np.testing.assert_allclose(rec.t, [*res.times, 0.4], rtol=0, atol=1e-12)
    replay = pj.Sampled(rec.t, rec["command"], period=0.02)
    t = np.arange(0.0, 0.4, 0.005)
    np.testing.assert_array_equal(np.asarray(_at(replay, t)), np.asarray(_at(res.signal(), t)))
    with pytest.raises(FileExistsError):
        res.to_csv(path)


def _standard_errors_at(values, experiment):
    """Standard errors [physical units] of FREE from `experiment`'s information at the tank whose FREE are `values`:
    the fit's Jacobian of the experiment there (not the design's objective)."""
    from pamjax._fit.problem import physical_and_jacobian
    from pamjax._identifiability.design import information, variances

    space = pj.ParameterSpace(pj.ParameterSpace(_tank(), FREE).with_values(np.asarray(values)), FREE)
    theta = space.initial_theta()
    g = np.asarray(physical_and_jacobian(space, theta)[1])
    return np.sqrt(variances(information(space, np.asarray(theta), [experiment]), g))


def test_a_spread_design_averages_its_points_each_with_its_own_target(tmp_path):
    # spread: the objective is the average over the model's point and `spread_points` drawn as a Latin hypercube
    # (at 2 points: one in each half of every parameter's ±20 %); each point reports its design's and its baseline's
    # standard errors, checked against the fit's Jacobian of the designed run and of the baseline at that point
    from pamjax._identifiability.design_points import design_thetas

    base_rec = pj.synthetic_recording(_tank(), pj.Constant(0.3), np.arange(0.0, 0.4, 2e-3), name="base")
    base = pj.Experiment(base_rec, pj.Constant(0.3), channels=["pressure"], scales=NOISE,
                         initial={"pressure": 101325.0})
    res = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=3, baseline=[base], progress=False, spread=0.2,
                               spread_points=2, **TANK)
    assert len(res.points) == 3 and res.points[0]["values"] == pytest.approx(res.values, rel=1e-12)
    rel = np.array([p["values"] for p in res.points[1:]]) / np.array(res.values) - 1.0
    assert np.all(np.abs(rel) <= 0.2) and np.all(rel[0] * rel[1] < 0), rel  # one point in each half of each spread
    assert res.objective[1] == pytest.approx(np.mean([p["criterion"] for p in res.points]), rel=1e-9)
    assert res.objective[1] < res.objective[0] and all(p["worst_violation"] == 0.0 for p in res.points)
    assert res.plot(tmp_path / "spread.png").stat().st_size > 0  # the points drawn over the design's bars
    t = np.arange(0.0, 0.4 + 1e-3, 2e-3)
    for point in res.points:
        model = pj.ParameterSpace(_tank(), FREE).with_values(np.asarray(point["values"]))
        run = pj.Experiment(pj.synthetic_recording(model, res.signal(), t, name="designed"), res.signal(),
                            channels=["pressure"], scales=NOISE, initial={"pressure": 101325.0})
        errors = point["standard_errors"]
        np.testing.assert_allclose(errors["design"], _standard_errors_at(point["values"], run), rtol=0.03)
        np.testing.assert_allclose(errors["baseline"], _standard_errors_at(point["values"], base), rtol=1e-6)
        np.testing.assert_allclose(errors["target"], errors["baseline"], rtol=1e-9)  # margin 1, no prior
    short = {}
    for point in res.points:
        for label, d, t_ in zip(res.labels, point["standard_errors"]["design"], point["standard_errors"]["target"]):
            if d > t_ * (1 + 1e-9):
                short[label] = max(short.get(label, 0.0), d / t_)
    assert res.points_shortfall == pytest.approx(short, rel=1e-12)
    # steps=0 scores a given duty over the spread (one value per period, no search, no gradient): the same points'
    # criteria for the designed duty
    scored = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=0, baseline=[base], progress=False,
                                  spread=0.2, spread_points=2, **{**TANK, "initial": res.duty},
                                  parametrisation="periods")
    assert scored.iterations == 0 and scored.duty == pytest.approx(res.duty, abs=1e-9)
    np.testing.assert_allclose([p["criterion"] for p in scored.points], [p["criterion"] for p in res.points],
                               rtol=1e-6)
    space = pj.ParameterSpace(_tank(), FREE)
    first, again, other = (design_thetas(space, 0.2, 2, seed)[0] for seed in (0, 0, 1))
    np.testing.assert_array_equal(first, again)  # seeded: the same points twice, others for another seed
    assert not np.allclose(first, other)
    np.testing.assert_allclose(first, np.array([p["values"] for p in res.points[1:]]), rtol=1e-12)
    one = design_thetas(space, {FREE[1]: 0.2}, 3, 0)[0]  # a table spreads only the labels it names
    np.testing.assert_array_equal(one[:, [0, 2]], np.tile(np.asarray(res.values)[[0, 2]], (3, 1)))
    assert np.ptp(one[:, 1]) > 0


def test_a_spread_point_whose_solve_fails_is_named_as_a_failed_solve(monkeypatch):
    # a design point whose run fails (predictions NaN) was reported as "the start signal does not determine every
    # free parameter", with the advice to change the signal
    from pamjax._identifiability import design_points

    def aux(position, criterion):
        return {"position": np.array([0.0, position]), "pressure": np.array([2e5, 2e5]), "criterion": criterion}

    def fake(points):
        return lambda c, problem: (0.0, {"points": points})

    monkeypatch.setattr(design_points, "value", fake([aux(0.0, -3.0), aux(np.nan, np.nan), aux(0.0, -2.0)]))
    with pytest.raises(PamjaxInputError, match=r"design point\(s\) \[1\] .*solve fails at the start signal"):
        design_points.points_start(None, None)
    monkeypatch.setattr(design_points, "value", fake([aux(0.0, -3.0), aux(0.0, np.inf), aux(0.0, -2.0)]))
    with pytest.raises(PamjaxInputError, match=r"design point\(s\) \[1\] .*does not determine every free parameter"):
        design_points.points_start(None, None)
    points = [aux(0.0, -3.0), aux(0.0, -2.0)]
    monkeypatch.setattr(design_points, "value", fake(points))
    assert design_points.points_start(None, None)["points"] is points


VALVE = [*FREE, "valve.exhaust.critical_ratio"]
TANK_BUILD = dict(channels=("pressure",), start={"pressure": 101325.0}, rate=500.0, knots=4,
                  initial=pj.Constant(0.6), build=pj.TankFromModel(5e-5))


def _tank_test(model, duty, pressure, duration=0.2):
    """A constant-duty test of `model`'s valve on the 5e-5 m³ tank from `pressure` (paper 000's E1/E2), at 500 Hz."""
    build = pj.TankFromModel(5e-5)
    t = np.arange(0.0, duration + 1e-6, 2e-3)
    name = f"u{duty}_p{pressure:.0f}"
    rec = pj.synthetic_recording(build(model), pj.Constant(duty), t, channels=["pressure"], name=name,
                                 y0=build(model).initial_state(pressure=pressure))
    return pj.Experiment(rec, pj.Constant(duty), channels=["pressure"], scales=NOISE, build=build,
                         initial={"pressure": pressure}, name=name)


@pytest.fixture(scope="module")
def tank_design():
    """A 0.4 s tank test designed for the muscle model's valve (`build=TankFromModel`), against the bench's kind
    of tank tests in the same time: a charge from atmospheric and a discharge from supply at duty 0.5, 0.2 s each."""
    model = presets.mas10_system(valve="pwm")
    base = [_tank_test(model, 0.5, 101325.0), _tank_test(model, 0.5, float(model.valve.supply_pressure))]
    res = pj.design_experiment(model, VALVE, 0.4, noise=NOISE, steps=6, baseline=base, progress=False, **TANK_BUILD)
    return model, res


def test_a_designed_tank_test_beats_constant_duty_tank_tests_of_the_same_time(tank_design):
    # `build` drives the valve's tank, not the muscle: no stroke limit, the muscle's parameters untouched; the
    # designed 0.4 s determines both flow scales at least as well as the constant-duty pair (predicted, 1 kHz-fit
    # resolution) and the D criterion went down.
    model, res = tank_design
    assert res.constraints["stroke_limits"] is None and res.constraints["position_range"] is None
    assert res.constraints["feasible"] and res.objective[1] < res.objective[0]
    design, base = (np.asarray(res.standard_errors[k]) for k in ("design", "baseline"))
    for label in ("valve.inflate.discharge_coefficient", "valve.exhaust.discharge_coefficient"):
        i = res.labels.index(label)
        assert design[i] <= base[i], (label, design[i], base[i])
    assert np.all(base / design > 0.97), base / design  # the floor's penalty: none worse (≈1 % slack)


def test_a_design_that_determines_nothing_says_so_and_still_draws(tank_design, tmp_path):
    # A design point far from any plant (a fit that did not converge: the muscle slack, every direction loose) gives
    # infinite predicted standard errors: they are named as undetermined (not "every parameter at or below the
    # baseline"), the figure is drawn without a log scale to put them on (it raised matplotlib's "Data cannot be
    # log-scaled"), and the floor of parameters nothing fixes is inf without a division warning.
    import dataclasses

    from pamjax._identifiability import design as dmod

    _, res = tank_design
    assert res.undetermined == []
    loose = dataclasses.replace(res, standard_errors={k: [math.inf] * len(v) for k, v in res.standard_errors.items()})
    assert loose.undetermined == list(res.subset) and loose.baseline_shortfall == {}
    assert loose.plot(tmp_path / "loose.png").stat().st_size > 10_000
    with pytest.warns(pj.PamjaxDesignWarning, match=r"leaves \['a'\] undetermined"):
        dmod._warn_undetermined(["a"])
    zero = np.zeros((2, 2))
    assert np.all(np.isinf(dmod._floor(zero, zero, 1.0)))  # warnings are errors in the suite


def _fit_result(labels, values, se, corr, **kw):
    """A `FitResult` holding only a covariance (what a design's prior reads of a fit)."""
    fields = dict(labels=list(labels), paths=list(labels), values=list(values), initial_values=list(values),
                  standard_errors=list(se), correlation=np.asarray(corr).tolist(), cost=1.0, initial_cost=1.0,
                  iterations=1, accepted_steps=1, status="converged", converged=True, message="", channel_errors={},
                  mismatch=False, non_identifiable=[], warnings=[], history=[], fit_s=0.0, compile_s=0.0,
                  num_residuals=100)
    return pj.FitResult(**(fields | kw))


def test_a_fits_covariance_over_parameters_of_every_scale_is_its_information():
    # v0 [m³] to the force law's a4: the physical variances span ~25 orders of magnitude, so the covariance is inverted
    # in its correlation's scale (inverted as it stands, every direction but a3's and a4's fell below the cut-off and
    # the prior said nothing about v0, k0 or the valve: rig3101 of benchmarks/design_rigs.py). The information maps
    # back to the fit's own standard errors, through the force law's mixed transform too.
    from pamjax._identifiability import design as dmod, prior_fit

    model = presets.mas10_system(valve="pwm", friction="karnopp")
    space = pj.ParameterSpace(model, ["muscle.volume_law.v0", "muscle.force_law.max_force_coefficients",
                                      "muscle.force_law.k0", "valve.inflate.discharge_coefficient"])
    theta, values = np.asarray(space.initial_theta()), np.asarray(space.initial_values())
    n = values.size
    se = np.abs(values) * np.linspace(0.002, 0.05, n)
    a = np.random.default_rng(1).normal(size=(n, n))
    cov = a @ a.T + n * np.eye(n)
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    information = prior_fit.fit_information(space, theta, [(_fit_result(space.labels, values, se, corr), "a fit")])
    np.testing.assert_allclose(dmod._physical_errors(space, theta, information), se, rtol=1e-8)


def test_a_fits_covariance_is_the_designs_prior_with_its_nuisances_marginalised(tank_design, tmp_path):
    # prior = a fit (its fit.json, or the FitResult): the design's prior standard errors are the fit's own, its
    # plant block (`plant.` labels of a rig's fit) with the nuisance marginalised, here a pressure gain correlated
    # with the flow terms. The experiments alone would hold the gain known and report them tighter (Session 58).
    model, res = tank_design
    labels, values = list(res.labels), np.asarray(res.values)
    se = np.array([*(0.01 * values), 0.004])
    a = np.random.default_rng(5).normal(size=(5, 5))
    cov = a @ a.T + 5 * np.eye(5)
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    fit = _fit_result([f"plant.{lbl}" for lbl in labels] + ["sensors[rig].pressure_gain"], [*values, 1.0], se, corr)
    path = fit.to_json(tmp_path / "fit.json")
    kwargs = dict(noise=NOISE, steps=0, progress=False, **TANK_BUILD)
    for prior in ([str(path)], fit):
        d = pj.design_experiment(model, VALVE, 0.4, prior=prior, **kwargs)
        np.testing.assert_allclose(d.standard_errors["prior"], se[:4], rtol=1e-9)
    # a fit that may not hold is named: not converged, and fitted at other values than the design point's
    moved = _fit_result(labels, values * 1.01, se[:4], corr[:4, :4], status="max_steps")
    with pytest.warns(pj.PamjaxDesignWarning) as caught:
        pj.design_experiment(model, VALVE, 0.4, prior=[moved], **kwargs)
    said = " ".join(str(w.message) for w in caught)
    assert "ended 'max_steps', not converged" in said and "differ from its fitted values" in said
    with pytest.raises(PamjaxInputError, match="is not a file"):
        pj.design_experiment(model, VALVE, 0.4, prior=[str(tmp_path / "none.json")], **kwargs)
    with pytest.raises(PamjaxInputError, match="determines none of the design's free parameters"):
        pj.design_experiment(model, VALVE, 0.4, prior=[_fit_result(["friction.coulomb_force"], [16.0], [1.0],
                                                                    [[1.0]])], **kwargs)
    with pytest.raises(PamjaxInputError, match="prior must be pamjax experiments"):
        pj.design_experiment(model, VALVE, 0.4, prior=[1.0], **kwargs)
    # two values rounded to a correlation of 1 in fit.json: no information along their difference, and no error
    rounded = _fit_result(labels[:2], values[:2], se[:2], [[1.0, 1.0], [1.0, 1.0]])
    d = pj.design_experiment(model, VALVE, 0.4, prior=[rounded], **kwargs)
    assert all(math.isinf(v) for v in d.standard_errors["prior"])  # one combination known: neither value alone


def test_a_designed_tank_tests_information_matches_the_fits_standard_errors(tank_design):
    # The design's predicted (Cramér-Rao) errors are the fit's linearised ones on a recording of the designed signal:
    # σ² (JᵀJ)⁻¹ at the fit, σ² the fit's residual variance (divided out here). The recording is the fit's own
    # prediction plus noise of 1/100 of the bench's, so that the fit lands where the design's linearisation holds (at
    # the bench's 2 kPa, 0.4 s leave b23 loose by tens of % and the Jacobian at the fit differs by up to 20 %).
    model, res = tank_design
    t = np.arange(0.0, 0.4 + 1e-6, 2e-3)

    def experiment(pressure):
        # named as design's own verification experiment of the same run: the name is a static field of the compiled
        # residuals, so the fit's Jacobian can be the one compiled there
        rec = pj.Recording(t, {"pressure": pressure}, name="design")
        return pj.Experiment(rec, res.signal(), channels=["pressure"], scales=NOISE, build=pj.TankFromModel(5e-5),
                             initial={"pressure": 101325.0})

    clean = pj.predictions(model, [experiment(np.full(t.shape, 101325.0))])[0]["pressure"]
    noisy = clean + NOISE["pressure"] / 100 * np.random.default_rng(3).standard_normal(t.shape)
    fit = pj.fit(model, [experiment(noisy)], VALVE, max_steps=20, progress=False)
    sigma = math.sqrt(2.0 * fit.cost / (t.size - len(VALVE)))
    assert fit.status == "converged" and sigma == pytest.approx(0.01, rel=0.2)
    np.testing.assert_allclose(np.asarray(fit.standard_errors) / sigma, res.standard_errors["design"], rtol=0.02)


def test_a_start_that_leaves_a_parameter_free_is_named():
    with pytest.raises(PamjaxInputError, match=r"does not determine \['valve.inflate.critical_ratio'\]"):
        pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=1, progress=False,
                             **{**TANK, "initial": pj.Constant(0.12)})


@pytest.mark.parametrize("kwargs, match", [
    (dict(noise={"position": 1e-4}), r"noise must give the noise standard deviation of every channel"),
    (dict(noise=NOISE, duty_band=(0.9, 0.1)), r"duty_band must be \(lo, hi\)"),
    (dict(noise=NOISE, subset=["k0"]), r"subset \['k0'\] must name free parameters"),
    (dict(noise=NOISE, criterion="E"), r"criterion must be 'D' or 'A'"),
    (dict(noise=NOISE, parametrisation="fourier"), r"parametrisation must be 'envelope' or 'periods'"),
    (dict(noise=NOISE, build="tank"), r"build must be a callable model → system"),
    (dict(noise=NOISE, build=lambda m: m.valve), r"build\(model\) must give a pamjax system"),
    (dict(noise=NOISE, build=lambda m: 1 / 0), r"build\(model\) failed: ZeroDivisionError"),
    (dict(noise={**NOISE, "position": 1e-4}, build=pj.TankFromModel(5e-5), channels=("pressure", "position")),
     r"channels \['position'\]: the designed system \(TankSystem, from build\) has no such output"),
    (dict(noise=NOISE, start={"position": 0.0}), r"start: bad keys \['position'\]"),
    (dict(noise=NOISE, start=101325.0), r"start must be a dict of keyword arguments"),
])
def test_bad_input_is_named_before_any_solve(kwargs, match, monkeypatch):
    monkeypatch.setattr(obj, "value", lambda *a: pytest.fail("solved before rejecting the input"))
    with pytest.raises(PamjaxInputError, match=match):
        pj.design_experiment(_tank(), FREE, 0.4, **{**TANK, **kwargs})


def test_design_needs_a_pwm_period():
    with pytest.raises(PamjaxInputError, match="period: the model's valve has no pwm_frequency"):
        pj.design_experiment(presets.mas10_tank_system(valve="averaged"), ["valve.coefficients[1,0]"], 0.4, noise=NOISE,
                             channels=("pressure",))


def test_cli_design_writes_csv_json_figure_and_refuses_to_overwrite(tmp_path, capsys):
    cfg = tmp_path / "design.toml"
    cfg.write_text(textwrap.dedent(f"""
        [model]
        preset = "mas10_tank_system"
        options = {{ valve = "pwm" }}
        [design]
        free = {FREE!r}
        duration = 0.4
        noise = {{ pressure = 2e3 }}
        channels = ["pressure"]
        start = {{ pressure = 101325.0 }}
        rate = 500.0
        knots = 4
        max_duty_step = 0.3
        initial = 0.6
        steps = 2
    """).replace("'", '"'))
    out = tmp_path / "out"
    assert main(["design", str(cfg), "--out", str(out), "--quiet"]) == 0
    rec = pj.Recording.load(out / "design.csv")
    assert rec.t.size == 21 and rec.t[-1] == pytest.approx(0.4) and "command" in rec.channels
    assert (out / "design.png").stat().st_size > 10_000
    capsys.readouterr()
    assert main(["design", str(cfg), "--out", str(out), "--quiet"]) == 2  # a user error: one line, status 2
    assert "design.csv exists; pass --overwrite" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text(cfg.read_text().replace("knots = 4", "knot = 4"))
    assert main(["design", str(bad), "--out", str(tmp_path / "o2"), "--quiet"]) == 2
    assert "[design]: unknown key(s) ['knot']" in capsys.readouterr().err
    assert not (tmp_path / "o2").exists()  # refused before the output folder was made
    # prior = a fit's fit.json that did not converge: the design runs, and says what its prior may not hold
    model = presets.mas10_tank_system(valve="pwm")
    values = np.asarray(pj.ParameterSpace(model, FREE).initial_values())
    _fit_result(FREE, values, 0.01 * values, np.eye(3), status="max_steps").to_json(tmp_path / "fit.json")
    (tmp_path / "prior.toml").write_text(cfg.read_text() + 'prior = "fit.json"\n')
    assert main(["design", str(tmp_path / "prior.toml"), "--out", str(tmp_path / "o3"), "--quiet"]) == 0
    assert "warning: prior " in (out_text := capsys.readouterr().out) and "ended 'max_steps', not converged" in out_text


def test_design_example_config_loads():
    # every key of examples/design_example.toml is checked and its model built (the design not run): five parameters
    # designed for, the valve's switching delays free beside them, E3 + E4 as the planned runs to beat
    from pamjax._cli.design import load

    model, free, duration, kwargs, out = load(pathlib.Path(__file__).resolve().parents[1] / "examples"
                                              / "design_example.toml")
    assert duration == 33.0 and len(free) == 7 and out == "results/design_example"
    assert kwargs["subset"] == free[:5] and free[5:] == ["valve.switch_on_delay", "valve.switch_off_delay"]
    assert [e.name for e in kwargs["baseline"]] == ["E3", "E4"] and kwargs["baseline_margin"] == 1.1
    assert [float(e.times[-1]) for e in kwargs["baseline"]] == pytest.approx([25.0, 8.0])
    assert kwargs["duty_band"] == (0.1, 0.9) and kwargs["criterion"] == "D"
    assert kwargs["duty_margin"] == "auto" and kwargs["min_force"] == 20.0
    assert "build" not in kwargs


def test_pilot_examples_chain_the_pilots_model_file_and_runs_into_the_design(tmp_path):
    # examples/pilot_fit.toml fits some of the shipped bench's runs ([bench] runs) and writes model.json, which
    # examples/pilot_design.toml designs at, with the same runs as its prior and the same 15 parameters free (the
    # chain's files laid out as in the repository; the pilot's model.json here the presets', nothing solved but E3)
    from pamjax._cli.design import load as load_design
    from pamjax._cli.fit import load as load_fit

    root = pathlib.Path(__file__).resolve().parents[1]
    (tmp_path / "examples").mkdir()
    for name in ("pilot_fit.toml", "pilot_design.toml"):
        (tmp_path / "examples" / name).write_text((root / "examples" / name).read_text())
    (tmp_path / "pamjax" / "data").mkdir(parents=True)
    (tmp_path / "pamjax" / "data" / "hybrid-reference-bench").symlink_to(root / "pamjax" / "data" /
                                                                        "hybrid-reference-bench")
    pj.save_model(tmp_path / "results" / "pilot_fit" / "model.json", presets.mas10_system(valve="pwm",
                                                                                         friction="karnopp"))
    _, experiments, free, _, out, bench, staged = load_fit(tmp_path / "examples" / "pilot_fit.toml")
    runs = ["E1_u0.25", "E1_u0.50", "E1_u0.75", "E2_u0.25", "E2_u0.50", "E2_u0.75", "E4"]
    assert [e.name for e in experiments] == runs and staged and out == "results/pilot_fit"
    assert "not in runs" in bench.skipped["E3"] and len(bench.fitted_keys) == 15
    model, design_free, duration, kwargs, out = load_design(tmp_path / "examples" / "pilot_design.toml")
    assert design_free == list(free) and duration == 25.0 and out == "results/pilot_design"
    assert [e.name for e in kwargs["prior"]] == runs and [e.name for e in kwargs["baseline"]] == ["E3"]
    assert float(model.valve.period) == 0.02 and kwargs["baseline_margin"] == 1.0
    # prior = the pilot's fit.json instead of its config: the fit's covariance (its rig's nuisances counted)
    text = (tmp_path / "examples" / "pilot_design.toml").read_text()
    (tmp_path / "examples" / "by_fit.toml").write_text(text.replace('prior = "pilot_fit.toml"',
                                                                    'prior = "../results/pilot_fit/fit.json"'))
    _, _, _, kwargs, _ = load_design(tmp_path / "examples" / "by_fit.toml")
    assert kwargs["prior"] == [str(tmp_path / "examples" / ".." / "results" / "pilot_fit" / "fit.json")]


def test_design_config_planned_runs_are_runs_of_the_model_and_bad_ones_are_named(tmp_path):
    # `baseline_runs` / `prior_runs`: a protocol not recorded yet (a signal and a duration) as experiments of the
    # model: the design's rate, channels and noise, a tank test where it says tank_volume, the model's prediction as
    # its data (a design's information never reads data: the same run with other data carries the same information).
    from pamjax._cli.design import baseline_line, load
    from pamjax._identifiability.design import information

    body = ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm" }\n[design]\n'
            'free = ["valve.inflate.discharge_coefficient"]\nduration = 1.0\nnoise = { pressure = 2e3 }\n'
            'channels = ["pressure"]\nrate = 500.0\nstart = { pressure = 101325.0 }\ntank_volume = 5e-5\n'
            'baseline_runs = %s\n')
    cfg = tmp_path / "planned.toml"
    cfg.write_text(body % '[{ name = "held", signal = { kind = "Constant", value = 0.6 }, duration = 0.2, '
                          'tank_volume = 5e-5 }]')
    model, free, _, kwargs, _ = load(cfg)
    [run] = kwargs["baseline"]
    assert run.name == "held" and isinstance(run.signal, pj.Constant) and tuple(run.channels) == ("pressure",)
    t = np.asarray(run.times)
    assert t[0] == 0.0 and t[-1] == pytest.approx(0.2) and np.allclose(np.diff(t), 1 / 500.0)
    assert isinstance(run.build(model), pj.TankSystem) and float(run.scales["pressure"]) == 2e3
    data = np.asarray(run.data["pressure"])
    assert data[-1] > data[0] + 1e4  # the tank fills at duty 0.6: the model's prediction, not a placeholder
    other = pj.Experiment(pj.Recording(t, {"pressure": data + 5e3}, name="held"), run.signal, channels=["pressure"],
                          scales={"pressure": 2e3}, build=run.build, name="held")
    space = pj.ParameterSpace(model, free)
    theta = space.initial_values()
    assert np.allclose(information(space, theta, [run]), information(space, theta, [other]), rtol=1e-12)
    # a tank test among the planned runs of a muscle design records the design's channels it has: its pressure
    muscle = body.replace("tank_volume = 5e-5\n", "").replace('channels = ["pressure"]\n', "").replace(
        "noise = { pressure = 2e3 }", "noise = { pressure = 2e3, position = 1e-4 }")
    cfg.write_text(muscle % '[{ signal = { kind = "Constant", value = 0.6 }, duration = 0.1, tank_volume = 5e-5 }]')
    [tank] = load(cfg)[3]["baseline"]
    assert tuple(tank.channels) == ("pressure",) and tank.name == "baseline_runs[0]"
    # what `pamjax design` prints of the baseline's goal: met, or short on the parameters it names
    assert baseline_line({}, 1.1).startswith("baseline: every parameter of subset at or below")
    assert "short of the baseline's standard errors / 1.1" in baseline_line({"k1": 1.0123}, 1.1)
    assert "k1 (1.012× its target)" in baseline_line({"k1": 1.0123}, 1.1)
    for bad, match in (("[]", r"baseline_runs must be a non-empty list"),
                       ('[{ signal = "recorded", duration = 1.0 }]', r"baseline_runs\[0\] signal: a planned run"),
                       ('[{ signal = { kind = "Constant", value = 0.6 } }]', r"baseline_runs\[0\] needs 'duration'"),
                       ('[{ signal = { kind = "Constant", value = 0.6 }, duration = -1.0 }]',
                        r"baseline_runs\[0\] duration"),
                       ('[{ signal = { kind = "Constant", value = 0.6 }, duration = 1.0, durtion = 2 }]',
                        r"baseline_runs\[0\]: unknown key\(s\) \['durtion'\]")):
        cfg.write_text(body % bad)
        with pytest.raises(PamjaxInputError, match=match):
            load(cfg)


def test_design_config_tank_volume_designs_a_tank_test(tmp_path):
    # `tank_volume` in [design]: the signal drives a constant-volume tank test of the model's valve (build=), as a fit
    # experiment's tank_volume; a bad volume is refused naming the key, before anything is built or solved.
    from pamjax._cli.design import load

    body = ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm" }\n[design]\n'
            'free = ["valve.inflate.discharge_coefficient"]\nduration = 2.0\nnoise = { pressure = 2e3 }\n'
            'channels = ["pressure"]\nstart = { pressure = 101325.0 }\ntank_volume = %s\n')
    cfg = tmp_path / "tank.toml"
    cfg.write_text(body % "5e-5")
    model, _, _, kwargs, _ = load(cfg)
    system = kwargs["build"](model)
    assert isinstance(system, pj.TankSystem) and float(system.volume) == pytest.approx(5e-5)
    assert system.valve is model.valve
    for bad in ("-5e-5", '"big"'):
        cfg.write_text(body % bad)
        with pytest.raises(PamjaxInputError, match=r"\[design\] tank_volume"):
            load(cfg)


def test_pressure_limit_is_penalised_and_kept():
    # The penalty: zero below the limit; above it, PENALTY·dt·Σ(excess/1 kPa)² and the worst excess reported.
    c, prob = _problem("envelope")
    free_value, free_aux = obj.value(c, prob)
    top = float(np.max(np.asarray(free_aux["pressure"])))
    for limit in (top + 1e3, top - 5e3):
        limited = eqx.tree_at(lambda p: p.max_pressure, prob, jnp.asarray(limit))
        value, aux = obj.value(c, limited)
        excess = np.maximum(np.asarray(aux["pressure"]) - limit, 0.0)
        assert float(aux["worst_pressure"]) == pytest.approx(float(np.max(excess)), abs=1e-9)
        times = np.asarray(limited.experiment.times)
        dt = float(times[1] - times[0])
        expected = obj.PENALTY * dt * np.sum((excess / obj.PRESSURE_UNIT) ** 2)
        assert float(value) - float(free_value) == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert (expected > 0) == (limit < top)
    # A design that starts within the limit stays within it (pressure predicted at the design samples).
    start = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=0, progress=False, **TANK)
    limit = start.constraints["pressure_range"][1] + 2e3
    res = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=4, progress=False, max_pressure=limit, **TANK)
    assert res.constraints["feasible"] and res.constraints["pressure_range"][1] <= limit
    assert res.objective[1] < res.objective[0]


def test_stroke_limits_are_the_stops_less_the_margin_or_the_rest_position():
    from pamjax._identifiability.design_setup import stroke_limits

    muscle = presets.mas10_system(valve="pwm")
    rest = float(muscle.initial_state().position)  # the payload's equilibrium at atmospheric pressure
    lo, hi = float(muscle.muscle.min_position), float(muscle.muscle.max_position)
    assert stroke_limits(muscle, None, 0.005) == pytest.approx((lo + 0.005, hi - 0.005))
    margin = rest - lo + 0.002  # the payload rests 2 mm inside the margin: the design may go as far as the rest
    assert stroke_limits(muscle, None, margin) == pytest.approx((rest, hi - margin))
    # strictly below the rest, by far less than any sensor resolves: a design's own solve that holds the payload at a
    # rest a few units in the last place lower (computed in another program) keeps the limit
    assert rest - 1e-8 < stroke_limits(muscle, None, margin)[0] < rest - 1e-12
    assert stroke_limits(_tank(), None, 0.005) is None


# --- designs a real rig can trust (issue 29 item 7): the valve's thresholds, the muscle in tension, named limits ---


def test_switching_thresholds_come_from_the_valve_contract():
    # Paper 000's valve at 50 Hz with 2 ms switching: a period's on-pulse opens it from u T = t_on (0.1), its
    # off-pulse closes it until (1 − u) T = t_off (0.9); slower switching moves both; an averaged valve has none.
    from pamjax._identifiability.design_setup import switching_thresholds

    assert switching_thresholds(presets.mas10_valve()) == pytest.approx((0.1, 0.9), abs=1e-11)
    slow = presets.mas10_valve(switch_on_delay=3e-3, switch_off_delay=2.5e-3)
    assert switching_thresholds(slow) == pytest.approx((0.15, 0.875), abs=1e-11)
    assert switching_thresholds(presets.mas10_averaged_valve()) == ()


def test_duty_limits_keep_the_margin_from_every_threshold():
    from pamjax._identifiability.design_setup import _skip, duty_limits

    lo, hi, windows = duty_limits((0.1, 0.9), (0.1, 0.9), 0.025)  # ends at the thresholds: they move in
    assert (lo, hi) == pytest.approx((0.125, 0.875)) and windows == ()
    lo, hi, windows = duty_limits((0.09, 0.95), (0.1, 0.9), 0.025)
    assert (lo, hi) == pytest.approx((0.125, 0.95)) and np.allclose(windows, [(0.875, 0.925)])
    assert duty_limits((0.3, 0.6), (0.1, 0.9), 0.025) == (0.3, 0.6, ())  # far from both: as given
    assert duty_limits((0.0, 1.0), (0.1, 0.9), 0.0) == (0.0, 1.0, ())  # duty_margin = 0: no limit
    lo, hi, windows = duty_limits((0.0, 1.0), (0.1, 0.9), 0.025)  # thresholds inside: windows no duty may enter
    assert (lo, hi) == (0.0, 1.0) and np.allclose(windows, [(0.075, 0.125), (0.875, 0.925)])
    duty = np.array([0.0, 0.08, 0.0999, 0.1001, 0.124, 0.5, 0.9, 0.93, 1.0])
    np.testing.assert_allclose(_skip(duty, windows), [0.0, 0.075, 0.075, 0.125, 0.125, 0.5, 0.925, 0.93, 1.0])
    skipped = np.asarray(jax.jit(obj.skip_windows)(device_array(duty), device_array(np.asarray(windows))))
    np.testing.assert_array_equal(skipped, _skip(duty, windows))  # the objective's (traced) and the host's agree
    with pytest.raises(PamjaxInputError, match=r"no duty is left"):
        duty_limits((0.09, 0.11), (0.1, 0.9), 0.025)


MUSCLE_NOISE = {"pressure": 2e3, "position": 1e-4}
MUSCLE_FREE = ["friction.coulomb_force", "muscle.force_law.k0"]


def _muscle():
    return presets.mas10_system(valve="pwm")


@pytest.mark.parametrize("model, kwargs, match", [
    (_tank, dict(duration=0.01), r"duration 0\.01 s is shorter than one PWM period \(0\.02 s\)"),
    (_tank, dict(max_pressure=5.0), r"max_pressure 5\.0 Pa abs is not above the run's start pressure"),
    (_tank, dict(duty_band=(0.09, 0.11)), r"duty_band \(0\.09, 0\.11\) lies within duty_margin 0\.025 of the valve's"),
    (_tank, dict(duty_margin=0.6), r"duty_margin must be 'auto'"),
    (_tank, dict(initial=pj.Constant(1.5)), r"initial: the start duty must lie in \[0, 1\]"),
    (_tank, dict(period=-0.02), r"period must be the PWM period"),
    (_tank, dict(noise={"pressure": 2e5}), r"noise\['pressure'\] = 200000\.0 Pa is 0\.36 of the valve's whole range"),
    (_tank, dict(spread=1.5), r"spread: the relative spread of valve\.inflate\.discharge_coefficient must be a "
                              r"number in \[0, 1\)"),
    (_tank, dict(spread={"k1": 0.2}), r"spread: unknown parameter label\(s\) \['k1'\]; the free parameters are"),
    (_tank, dict(spread=0.2, spread_points=0), r"spread_points must be a positive integer"),
    (_tank, dict(spread=0.0), r"spread: every fraction is 0"),
    (_muscle, dict(stroke_margin=5.0), r"stroke_margin 5\.0 m leaves no stroke"),
    (_muscle, dict(min_force=200.0), r"min_force 200 N: eq\. 7 gives 94\.2 N at the run's start"),
    (_muscle, dict(noise={"pressure": 2e3, "position": 0.1}), r"noise\['position'\] = 0\.1 m is 1\.1 of the"),
    (_muscle, dict(build=pj.TankFromModel(5e-5), channels=("pressure",), start={"pressure": 101325.0}),
     r"free: \['friction\.coulomb_force', 'muscle\.force_law\.k0'\] do not enter the designed system \(TankSystem"),
    # a period the switching valve does not latch with: half of a 10 ms design's duties would do nothing at 50 Hz
    (_tank, dict(period=0.01), r"period 0\.01 s differs from the PWM period of the model's switching valve "
                               r"\(0\.02 s, 50 Hz\)"),
    (_muscle, dict(build=pj.TankFromModel(5e-5), channels=("pressure",), start={"pressure": 101325.0},
                   free=["valve.inflate.discharge_coefficient"], period=0.01), r"period 0\.01 s differs"),
    (_tank, dict(design_rate=0.0), r"design_rate must be the objective's sample rate \[Hz\], a number > 0, got 0\.0"),
    (_tank, dict(design_rate=float("nan")), r"design_rate must be .* got nan"),
    (_tank, dict(design_rate=-250.0), r"design_rate must be .* got -250\.0"),
    (_tank, dict(baseline_margin=float("nan")), r"baseline_margin must be a positive number, e\.g\. 1\.0 .* got nan"),
    (_tank, dict(baseline_margin=-1.0), r"baseline_margin must be a positive number.* got -1\.0"),
    (_tank, dict(baseline_margin=math.inf), r"baseline_margin must be a positive number.* got inf"),
    (_tank, dict(baseline_margin="1.1"), r"baseline_margin must be a positive number.* got '1\.1'"),
    (_tank, dict(subset=[FREE[0], FREE[0]]), r"subset names \['valve\.inflate\.discharge_coefficient'\] more than "
                                             r"once"),
    (_tank, dict(duty_band=(0.1, 0.5, 0.9)), r"duty_band must be \(lo, hi\) .* got \(0\.1, 0\.5, 0\.9\)"),
    (_tank, dict(duty_band=0.5), r"duty_band must be \(lo, hi\) .* got 0\.5"),
    (_tank, dict(max_pressure="5e5"), r"max_pressure must be an absolute pressure > 0 \[Pa\], got '5e5'"),
    (_tank, dict(rate="abc"), r"rate must be the recording's sample rate \[Hz\], a number > 0, got 'abc'"),
    (_tank, dict(noise={"pressure": "abc"}), r"noise\['pressure'\] must be a number > 0 .* got 'abc'"),
    (_tank, dict(seed="a"), r"seed must be an integer >= 0 .* got 'a'"),
    # a noise in bar (0.02 bar = 2 kPa) would weight the pressure 1e5× (the position's mm is refused above)
    (_tank, dict(noise={"pressure": 0.02}), r"noise\['pressure'\] = 0\.02 Pa is below 1 Pa.* bar .* kPa"),
    (_muscle, dict(noise={**MUSCLE_NOISE, "force": 1.0}), r"noise: \['force'\] not among the design's channels "
                                                          r"\['pressure', 'position'\]"),
    (_tank, dict(noise={"pressure": 2e3, "position": 1e-4}), r"noise: \['position'\] not among the design's"),
    (_tank, dict(spread_points=7), r"spread_points = 7 is given without spread"),
    # 33 s written in ms ran out of memory after 18 s (an "internal error"), its output folder left empty
    (_tank, dict(duration=33000.0), r"duration = 33000 s is more than 3600 s .*looks like ms \(33 s\)"),
])
def test_limits_no_run_can_keep_are_named_before_any_solve(model, kwargs, match, monkeypatch):
    # the battery's cases (issue 33): a limit in the wrong unit, a run shorter than a period, a band across the valve's
    # threshold, a tank test asked about the muscle: each a PamjaxInputError naming the argument, before any solve
    from pamjax._identifiability.design import check_design

    monkeypatch.setattr(obj, "value", lambda *a: pytest.fail("solved before rejecting the input"))
    base = (dict(noise=NOISE, **TANK) if model is _tank else
            dict(noise=MUSCLE_NOISE, knots=4, rate=500.0))
    args = {**base, **kwargs}
    free = args.pop("free", FREE if model is _tank else MUSCLE_FREE)
    duration = args.pop("duration", 0.4)
    with pytest.raises(PamjaxInputError, match=match):
        pj.design_experiment(model(), free, duration, progress=False, **args)
    with pytest.raises(PamjaxInputError, match=match):  # the CLI's check before it makes the output folder
        check_design(model(), free, duration, **args)


def test_a_period_equal_to_the_switching_valves_own_is_accepted():
    # the refusal of another period (above) leaves the valve's own, given as a number, and None alone
    from pamjax._identifiability.design import check_design

    for period in (None, 0.02, 1.0 / 50.0 * (1.0 + 1e-12)):
        assert check_design(_tank(), FREE, 0.4, noise=NOISE, **{**TANK, "period": period}) is None


def test_an_averaged_valve_designs_with_the_period_given():
    # the fix the error names works: period=0.02 for a model whose valve has no PWM frequency; no switching
    # thresholds, so no duty margin
    res = pj.design_experiment(presets.mas10_tank_system(valve="averaged"), ["valve.coefficients[1,0]"], 0.2,
                               noise=NOISE, channels=("pressure",), start={"pressure": 101325.0}, rate=500.0, knots=4,
                               steps=1, period=0.02, initial=pj.Constant(0.6), progress=False)
    assert res.period == 0.02 and len(res.duty) == 10 and res.feasible
    assert res.constraints["switching_thresholds"] == [] and res.constraints["duty_margin"] == 0.0


@pytest.fixture(scope="module")
def muscle_design():
    """A 1 s design of the MAS-10's friction and k0 with its default limits (duty 0.025 from the valve's thresholds,
    eq. 7's force >= 20 N), from a constant 0.55 (the muscle lifts and holds: in tension)."""
    res = pj.design_experiment(_muscle(), MUSCLE_FREE, 1.0, noise=MUSCLE_NOISE, rate=500.0, knots=4, steps=3,
                               initial=pj.Constant(0.55), progress=False)
    return res


def test_a_muscle_design_keeps_the_force_margin_and_reports_eq7_independently(muscle_design):
    # The reported force is eq. 7 of the predicted run: against a NumPy transcription of the paper's eq. 7
    # (tests/helpers.np_eq7_force) at the same samples; it stays >= min_force at the objective's samples and within
    # the stated tolerance at the fit's resolution; every duty 0.025 from the thresholds.
    from helpers import np_eq7_force

    from pamjax._identifiability.design_result import VERIFY_TOLERANCE
    from pamjax._identifiability.design_setup import MIN_FORCE

    res = muscle_design
    c = res.constraints
    assert res.feasible and c["violations"] == [] and c["min_force"] == MIN_FORCE
    fl = _muscle().muscle.force_law
    pred = res.prediction
    numpy = np_eq7_force(pred["position"], pred["pressure"] - 101325.0, np.asarray(fl.max_force_coefficients),
                         float(fl.k0), float(fl.k1), float(fl.k2))
    np.testing.assert_allclose(pred["force"], numpy, rtol=1e-12, atol=1e-9)
    assert c["force_range"][0] >= MIN_FORCE and c["force_range"][0] == pytest.approx(float(numpy.min()))
    assert c["verified"]["force_range"][0] >= MIN_FORCE - VERIFY_TOLERANCE["force"]
    assert c["threshold_distance"] >= 0.025 - 1e-12 and c["duty_limits"] == pytest.approx([0.125, 0.875])


def test_the_force_penalty_acts_from_the_buffer_and_the_limit_from_min_force():
    # objective(min_force) − objective(no limit) = PENALTY·dt·Σ(max(min_force + FORCE_BUFFER − F, 0))² at the
    # objective's samples, and the worst violation is measured from min_force itself
    from pamjax._identifiability.design import _problem
    from pamjax._identifiability.design_setup import set_up

    setup = set_up(_muscle(), MUSCLE_FREE, 1.0, noise=MUSCLE_NOISE, channels=("pressure", "position"), start={},
                   build=None, rate=500.0, criterion="D", subset=None, duty_band=(0.1, 0.9), stroke_margin=0.005,
                   max_pressure=None, max_duty_step=None, parametrisation="envelope", knots=4, steps=3,
                   initial=pj.Constant(0.55), seed=0, period=None, design_rate=250.0, substeps=4, duty_margin="auto",
                   min_force=None, baseline_margin=1.0)
    space = setup["space"]
    theta = np.asarray(space.initial_theta())

    def problem(min_force):
        return _problem(space, theta, setup["experiment"], setup["basis"], 2.0, setup["band"], setup["windows"],
                        setup["limits"], None, None, True, min_force, (0, 1), "D", np.zeros((2, 2)), None)

    c = device_array(setup["c0"])
    free_value, aux = obj.value(c, problem(None))
    force = np.asarray(aux["force"])
    dt = float(np.diff(np.asarray(setup["experiment"].times))[0])
    for limit in (float(force.min()) + 2.0, float(force.min()) - 2.0):
        value, aux_l = obj.value(c, problem(limit))
        near = np.maximum(limit + obj.FORCE_BUFFER - force, 0.0)
        assert float(value) - float(free_value) == pytest.approx(obj.PENALTY * dt * np.sum(near**2), rel=1e-9)
        assert float(aux_l["worst_force"]) == pytest.approx(max(limit - force.min(), 0.0), abs=1e-12)


def test_an_infeasible_design_fails_clearly_and_is_not_written(tmp_path):
    # a limit the start breaks and a search too short to repair it: the result says which limit and by how much,
    # warns, and to_csv refuses it (a bench must not play it) unless told otherwise
    with pytest.warns(pj.PamjaxDesignWarning, match=r"max_pressure: predicted up to"):
        res = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=1, progress=False,
                                   **{**TANK, "max_pressure": 1.2e5})
    assert not res.feasible and res.constraints["violations"][0].startswith("max_pressure")
    with pytest.raises(PamjaxInputError, match=r"violates its limits \(max_pressure"):
        res.to_csv(tmp_path / "design.csv")
    assert not (tmp_path / "design.csv").exists()
    res.to_csv(tmp_path / "design.csv", infeasible_ok=True)


def test_cli_design_takes_period_and_fails_an_infeasible_design(tmp_path, capsys):
    body = textwrap.dedent("""
        [model]
        preset = "mas10_tank_system"
        options = {{ valve = "{valve}" }}
        [design]
        free = ["{free}"]
        duration = 0.2
        noise = {{ pressure = 2e3 }}
        channels = ["pressure"]
        start = {{ pressure = 101325.0 }}
        rate = 500.0
        knots = 4
        initial = 0.6
        steps = 1
        {extra}
    """)
    cfg = tmp_path / "d.toml"
    averaged = dict(valve="averaged", free="valve.coefficients[1,0]")
    cfg.write_text(body.format(**averaged, extra=""))
    assert main(["design", str(cfg), "--out", str(tmp_path / "a"), "--quiet", "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "period = 0.02" in err and not (tmp_path / "a").exists()  # refused before the folder was made
    cfg.write_text(body.format(**averaged, extra="period = 0.02"))  # the fix the message names
    assert main(["design", str(cfg), "--out", str(tmp_path / "b"), "--quiet", "--no-plot"]) == 0
    assert pj.Recording.load(tmp_path / "b" / "design.csv").t[-1] == pytest.approx(0.2)
    capsys.readouterr()
    cfg.write_text(body.format(valve="pwm", free="valve.inflate.discharge_coefficient", extra="max_pressure = 1.2e5"))
    assert main(["design", str(cfg), "--out", str(tmp_path / "c"), "--quiet", "--no-plot"]) == 1
    captured = capsys.readouterr()
    assert "FAILED" in captured.err and "max_pressure: predicted up to" in captured.err
    assert not (tmp_path / "c" / "design.csv").exists() and (tmp_path / "c" / "design.json").exists()


# A tank design's config up to its [design] table's last common key (two tests below add their own keys)
TANK_DESIGN_CONFIG = textwrap.dedent("""
        [model]
        preset = "mas10_tank_system"
        options = { valve = "pwm" }
        [design]
        free = ["valve.inflate.discharge_coefficient"]
        duration = 0.2
        noise = { pressure = 2e3 }
        channels = ["pressure"]
        start = { pressure = 101325.0 }
""").lstrip()


def test_an_infeasible_design_with_overwrite_removes_the_earlier_designs_csv(tmp_path, capsys):
    # `pamjax design --overwrite` that ended outside its limits said "no design.csv was written (a bench must not
    # play it)" and left the earlier run's design.csv beside its new design.json: a bench played the old design
    cfg = tmp_path / "d.toml"
    cfg.write_text(TANK_DESIGN_CONFIG + textwrap.dedent("""
        rate = 500.0
        knots = 4
        initial = 0.6
        steps = 1
        max_pressure = 1.2e5
    """).lstrip())  # the smallest infeasible design above (test_cli_design_takes_period_and_fails_an_infeasible_design)
    out = tmp_path / "out"
    out.mkdir()
    (out / "design.csv").write_text("t [s],duty [-]\n0.0,0.5\n")  # an earlier, feasible design's
    assert main(["design", str(cfg), "--out", str(out), "--quiet", "--no-plot", "--overwrite"]) == 1
    err = capsys.readouterr().err
    assert "no design.csv was written (a bench must not play it; the earlier run's " in err and "was removed" in err
    assert not (out / "design.csv").exists() and (out / "design.json").exists()


def test_a_designed_run_is_a_bench_experiment(muscle_design, tmp_path):
    # A designed run recorded on a rig (the recording's own duty column, no triangle parameters) is a bench
    # experiment: kind "muscle_run", or "muscle_triangle" without lo/hi/f_tri. `load_bench` drives it by the recorded
    # duty (each period's designed duty), from rest, and its prediction at the plant that made it is the recording.
    import json

    model = _muscle()
    res = muscle_design
    t = np.round(np.arange(0.0, 1.0 + 1e-9, 2e-3), 9)
    rec = pj.synthetic_recording(model, res.signal(), t, channels=["pressure", "position", "command"], name="run",
                                 stepping="pwm", substeps=16)
    for name in ("D1", "D2"):
        rec.to_csv(tmp_path / f"{name}.csv")
    meta = {"experiments": {"D1": {"kind": "muscle_run"}, "D2": {"kind": "muscle_triangle"}},
            "noise": {"p_std_Pa": 2e3, "x_std_m": 1e-4}, "fitted_keys": ["Fc", "k0"]}
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    bench = pj.bench.load_bench(tmp_path, model)
    assert [e.name for e in bench.experiments] == ["D1", "D2"] and not bench.skipped
    starts = np.arange(len(res.duty)) * res.period
    for e in bench.experiments:
        np.testing.assert_array_equal(np.asarray(_at(e.signal, starts)), res.duty)
    for e, pred in zip(bench.experiments, pj.predictions(model, bench.experiments)):
        assert np.max(np.abs(pred["pressure"] - rec["pressure"])) < 1.0  # Pa, of 2 kPa noise
        assert np.max(np.abs(pred["position"] - rec["position"])) < 1e-7  # m, of 0.1 mm noise
    # without its duty column a run cannot be driven: named
    rec_no_duty = pj.Recording(rec.t, {"pressure": rec["pressure"], "position": rec["position"]}, name="run")
    rec_no_duty.to_csv(tmp_path / "D1.csv", overwrite=True)
    with pytest.raises(PamjaxInputError, match=r"'D1' has no recorded duty column"):
        pj.bench.load_bench(tmp_path, model)


def _latching(model):
    """The MAS-10 preset with eq. 7's F_max raised by 300 N: at the upper stop it pulls ~190 N even at atmospheric
    pressure, above the 94 N payload, so a payload that reaches the stop stays there (the unseen rigs' case)."""
    a = model.muscle.force_law.max_force_coefficients
    return eqx.tree_at(lambda m: m.muscle.force_law.max_force_coefficients, model, a.at[0].add(300.0))


def test_design_config_payload_kg_designs_a_run_with_another_payload(tmp_path):
    # `payload_kg` in [design]: the signal drives the model lifting that payload (build = PayloadFromModel), "auto"
    # the one pamjax.PayloadFromModel.advised proposes; bad values and a tank test beside it are refused by key.
    from pamjax._cli.design import load

    body = ('[model]\npreset = "mas10_system"\noptions = { valve = "pwm" }\n[design]\n'
            'free = ["friction.coulomb_force"]\nduration = 2.0\nnoise = { pressure = 2e3, position = 1e-4 }\n%s\n')
    cfg = tmp_path / "payload.toml"
    for value in ("30.0", '"auto"'):
        cfg.write_text(body % f"payload_kg = {value}")
        model, _, _, kwargs, _ = load(cfg)
        system = kwargs["build"](model)
        expected = 30.0 if value == "30.0" else float(pj.PayloadFromModel.advised(model).mass)
        assert isinstance(system, pj.MuscleSystem) and float(system.payload_mass) == pytest.approx(expected)
        assert eqx.tree_equal(eqx.tree_at(lambda s: s.payload_mass, system, model.payload_mass), model)  # the rest
    for bad, match in (("-5.0", r"\[design\] payload_kg must be \"auto\" or a number > 0"),
                       ('"heavy"', r"\[design\] payload_kg must be \"auto\" or a number > 0"),
                       ("30000.0", r"payload_kg = 30000 kg: more than 1000 kg; that looks like g"),
                       ("30.0\ntank_volume = 5e-5", r"\[design\]: give tank_volume .* or payload_kg .*not both")):
        cfg.write_text(body % f"payload_kg = {bad}")
        with pytest.raises(PamjaxInputError, match=match):
            load(cfg)


def test_a_design_with_another_payload_says_so_and_its_csv_carries_it(tmp_path):
    # The designed run's payload, where build changed it, is part of the design (the bench must carry it and the fit
    # read it): DesignResult.payload_kg, a comment line of design.csv (which Recording.load still reads) and JSON.
    from pamjax._identifiability.design import designed_payload
    from pamjax._identifiability.design_result import DesignResult

    model = presets.mas10_system("pwm")
    assert designed_payload(model, pj.PayloadFromModel(26.5)(model)) == 26.5
    assert designed_payload(model, model) is None
    assert designed_payload(model, pj.TankFromModel(5e-5)(model)) is None
    res = DesignResult(times=[0.0, 0.02], duty=[0.3, 0.6], period=0.02, labels=["friction.coulomb_force"],
                       values=[16.0], subset=["friction.coulomb_force"], criterion="D",
                       standard_errors={"design": [0.1], "prior": [math.inf]}, objective=[0.0, -1.0], history=[],
                       constraints={"feasible": True}, parametrisation="envelope", iterations=1, message="",
                       design_s=1.0, compile_s=0.5, duration=0.04, payload_kg=26.5)
    text = res.to_csv(tmp_path / "design.csv").read_text()
    assert "# payload 26.5 kg (not the model's): load the rig with it and fit the recording with payload_kg = 26.5" \
        in text
    rec = pj.Recording.load(tmp_path / "design.csv")
    np.testing.assert_allclose(np.asarray(rec["command"]), [0.3, 0.6, 0.6])
    assert json.loads(res.to_json(tmp_path / "design.json").read_text())["payload_kg"] == 26.5


def test_a_failed_design_whose_payload_the_stop_holds_names_the_heavier_payload():
    # A design whose payload passes the upper stroke limit, where the model's muscle holds it on the stop even at
    # atmospheric pressure: the failure names payload_kg = "auto" and its mass; not where the muscle lets it down,
    # nor where the design already has a build of its own.
    from types import SimpleNamespace

    from pamjax._cli.design import _payload_hint

    model = presets.mas10_system("pwm")
    over = SimpleNamespace(constraints=dict(position_range=[-0.02, 0.075], stroke_limits=[-0.02, 0.07]))
    within = SimpleNamespace(constraints=dict(position_range=[-0.02, 0.05], stroke_limits=[-0.02, 0.07]))
    latching = _latching(model)
    mass = float(pj.PayloadFromModel.advised(latching).mass)
    hint = _payload_hint(latching, over, {})
    assert f'payload_kg = "auto" designs the run with {mass:.3g} kg' in hint and "no duty brings it down" in hint
    assert _payload_hint(model, over, {}) == ""  # the preset lets its payload down at low pressure
    assert _payload_hint(latching, within, {}) == ""
    assert _payload_hint(latching, over, {"build": pj.PayloadFromModel(40.0)}) == ""


def _rests_on_the_stop(force_at_stop):
    """The MAS-10 preset (PWM valve) with eq. 7 shifted so that it gives `force_at_stop` N at the lower stop and
    atmospheric pressure: below the 94 N payload, which therefore rests on that stop at the run's start."""
    model = presets.mas10_system("pwm")
    f = float(model.muscle.static_force(model.muscle.min_position, 101325.0, model.air))
    a = model.muscle.force_law.max_force_coefficients
    return eqx.tree_at(lambda m: m.muscle.force_law.max_force_coefficients, model, a.at[0].add(force_at_stop - f))


def test_the_force_margin_asks_only_tension_where_the_payload_rests_on_the_lower_stop():
    # On the lower stop the stop carries the payload: eq. 7 is not seen there, only the muscle's geometry (its volume,
    # which the volume law gives while the muscle is taut). So the floor is min_force where the payload hangs free and
    # 0 N on the stop (force_floor), in the objective, the start's check and the report alike.
    from pamjax._identifiability.design import check_design
    from pamjax._identifiability.design_result import constraints_report

    stop = -0.02
    x = np.array([stop, stop + 5e-7, stop + 1e-3])
    np.testing.assert_array_equal(obj.force_floor(x, stop, 20.0, xp=np), [0.0, 0.0, 20.0])
    np.testing.assert_array_equal(obj.force_floor(x, stop, -np.inf, xp=np), [-np.inf] * 3)
    np.testing.assert_array_equal(np.asarray(obj.force_floor(jnp.asarray(x), stop, -5.0)), [-5.0] * 3)
    free = ["friction.coulomb_force"]
    noise = {"pressure": 2e3, "position": 1e-4}
    taut = _rests_on_the_stop(10.0)
    assert float(taut.initial_state().position) == pytest.approx(stop)  # the start: on the lower stop
    check_design(taut, free, 2.0, noise=noise)  # 10 N on the stop: taut, accepted under the default 20 N
    with pytest.raises(PamjaxInputError, match=r"min_force: eq. 7 gives -5.0 N at the run's start, on the lower stop"):
        check_design(_rests_on_the_stop(-5.0), free, 2.0, noise=noise)
    setup = dict(thresholds=[], duty_band=(0.1, 0.9), duty_margin=0.0, band=(0.1, 0.9), windows=[],
                 max_duty_step=None, limits=None, max_pressure=None, min_force=20.0, system=taut)

    def report(force):
        worst = np.max(np.maximum(obj.force_floor(x, stop, 20.0, xp=np) - force, 0.0))
        aux = dict(duty=np.full(3, 0.5), position=x, pressure=np.full(3, 2e5), force=np.asarray(force),
                   worst_stroke=0.0, worst_pressure=0.0, worst_step=0.0, worst_force=worst)
        return constraints_report(aux, setup)

    ok = report([10.0, 12.0, 25.0])
    assert ok["feasible"] and ok["violations"] == [] and ok["free_force_min"] == 25.0 and ok["stop_force_min"] == 10.0
    slack = report([-3.0, 12.0, 25.0])
    assert not slack["feasible"] and len(slack["violations"]) == 1 and "on the lower stop" in slack["violations"][0]
    near = report([10.0, 12.0, 15.0])
    assert not near["feasible"] and "15.0 N where the payload hangs free" in near["violations"][0]


def test_a_limit_passed_within_the_check_tolerance_is_explained_where_it_is_printed():
    # The check at the fit's resolution sees the PWM ripple the objective's samples miss and allows VERIFY_TOLERANCE
    # for it; pamjax design printed "smallest 19.3 N" under ">= 20 N" beside "every limit kept", unexplained (the MAS-10
    # example design). The line now says by how much the limit was passed and that it is within the tolerance.
    from pamjax._cli.design import constraint_lines
    from pamjax._identifiability.design_result import VERIFY_TOLERANCE, constraints_report

    stop = -0.02
    x = np.array([stop + 1e-3, stop + 2e-3, stop + 3e-3])
    setup = dict(thresholds=[], duty_band=(0.1, 0.9), duty_margin=0.0, band=(0.1, 0.9), windows=[],
                 max_duty_step=None, limits=(stop, 0.07), max_pressure=6e5, min_force=20.0,
                 system=_rests_on_the_stop(10.0))
    aux = dict(duty=np.full(3, 0.5), position=x, pressure=np.full(3, 2e5), force=np.array([25.0, 30.0, 40.0]),
               worst_stroke=0.0, worst_pressure=0.0, worst_step=0.0, worst_force=0.0)

    def printed(force, pressure):
        verified = dict(position=x, pressure=np.asarray(pressure), force=np.asarray(force))
        c = constraints_report(aux, setup, verified)
        return c, constraint_lines(c)

    c, text = printed([19.3, 30.0, 40.0], [2e5, 6.02e5, 3e5])
    assert c["feasible"] and "every limit kept" in text
    force_line = next(line for line in text.splitlines() if "muscle force" in line)
    assert "smallest 19.3 N" in force_line and "past the limit by 0.7 N" in force_line
    assert f"within the {VERIFY_TOLERANCE['force']:.1f} N allowed" in force_line
    pressure_line = next(line for line in text.splitlines() if "pressure up to" in line)
    assert "past the limit by 2.0 kPa" in pressure_line and "within the 5.0 kPa allowed" in pressure_line
    c, text = printed([12.0, 30.0, 40.0], [2e5, 3e5, 3e5])  # 8 N short: beyond the tolerance, a violation
    assert not c["feasible"] and "beyond the 5.0 N allowed" in text and "VIOLATED" in text
    c, text = printed([25.0, 30.0, 40.0], [2e5, 3e5, 3e5])  # every limit held: no note
    assert c["feasible"] and "past the limit" not in text


def test_random_probes_carry_the_search_past_a_kink_the_gradient_cannot_see(monkeypatch):
    # A cost with jumps (a stick-slip phase or a stop contact appearing): along the gradient it jumps up at c0 = 0.1,
    # while a step across c1 = 0.03, which the gradient (0 along c1) never proposes, lowers it by 4. The line search
    # stalls at the first jump; the probes find the second (the search used to end there: "no descent").
    from pamjax._identifiability import design_search as search

    def fake_value(c, problem):
        c = np.asarray(c)
        v = (c[0] - 1.0) ** 2 + 3.0 * (c[0] > 0.1) - 4.0 * (c[1] > 0.03) + np.sum(c[1:] ** 2)
        zero = jnp.zeros(())
        return jnp.asarray(v), dict(criterion=jnp.asarray(v), worst_stroke=zero, worst_pressure=zero,
                                    worst_step=zero, worst_force=zero)

    def gradient(c, problem):
        c = np.asarray(c)
        return jnp.asarray(np.concatenate([[2.0 * (c[0] - 1.0)], 2.0 * c[1:]]))

    monkeypatch.setattr(obj, "value", fake_value)
    c0 = np.zeros(4)
    monkeypatch.setattr(search, "PROBES", 0)
    _, aux_without, _, message_without = search.optimise(c0, None, gradient, 30, None, seed=0)
    monkeypatch.setattr(search, "PROBES", 8)
    c, aux_with, history, message_with = search.optimise(c0, None, gradient, 30, None, seed=0)
    assert float(aux_without["criterion"]) > 0.8 and "no descent" in message_without
    assert float(aux_with["criterion"]) < float(aux_without["criterion"]) - 3.0 and c[1] > 0.03, (c, message_with)
    assert "random probes past kinks" in message_with
    assert all(b[1] <= a[1] for a, b in zip(history, history[1:]))  # never uphill
    again = search.optimise(c0, None, gradient, 30, None, seed=0)
    assert np.array_equal(again[0], c)  # seeded: the same search twice


def test_a_spread_designs_points_are_printed_with_their_ratios_and_targets():
    # `pamjax design` prints each design point: its criterion, whether its plant would pass a limit, and the
    # baseline's standard error over the design's per parameter of subset; then the targets (margin at the model's
    # point, 1 at the others) and what falls short
    import types

    from pamjax._cli.design import points_lines

    labels = ["muscle.volume_law.v1", "friction.coulomb_force", "valve.switch_on_delay"]
    # (each parameter by its label's last two parts: the valve's two paths' discharge_coefficient stay apart)

    def point(design, violation):
        return dict(values=[1.0, 2.0, 3.0], criterion=-80.0, worst_violation=violation,
                    standard_errors=dict(design=design, baseline=[1.0, 1.0, 1.0], target=[1 / 1.1, 1 / 1.1, math.inf]))

    res = types.SimpleNamespace(labels=labels, subset=labels[:2], points=[point([0.8, 0.9, 5.0], 0.0),
                                                                          point([0.95, 1.04, 5.0], 3.5)])
    res.points_shortfall = pj.DesignResult.points_shortfall.fget(res)
    text = points_lines(res, 1.1)
    assert ("point 0: criterion -80.0000, every limit kept; baseline/design volume_law.v1 1.250, "
            "friction.coulomb_force 1.111") in text
    assert "point 1: criterion -80.0000, a limit passed (worst 3.5" in text and "switch_on_delay" not in text
    assert "/ 1.1 at the model's point and the baseline's own at the others" in text
    assert "friction.coulomb_force (1.144× its target at worst)" in text and "v1 (" in text


# --- the design's repairs (design_repair): a start that breaks a limit, a run that passes one between the samples ---


def _start_only(duration, **limits):
    """The MAS-10's default start, scored (steps=0) under `limits`: its DesignResult."""
    kwargs = dict(noise=MUSCLE_NOISE, rate=500.0, knots=4, steps=0, progress=False, **limits)
    with warnings.catch_warnings():  # steps=0: nothing searched on for the ripple the fit's resolution may show
        warnings.simplefilter("ignore", pj.PamjaxDesignWarning)
        return pj.design_experiment(_muscle(), MUSCLE_FREE, duration, **kwargs)


def test_a_start_only_a_moved_level_keeps_within_the_limits_is_repaired_where_it_breaks_them():
    # MAS-10 over 4 s with the upper stroke limit at 28 mm: E3's rising triangle passes it with or without its carrier
    # (no calmer carrier keeps it: on a realistic rig's pilot, E3's top duty lifted the payload onto the upper stop,
    # and the search from the default start as it was ended on the stop). The start is repaired where it broke the
    # limit: the level lowered over the second before the samples that passed it and the carrier halved there. It
    # keeps the limit, its duty below the triangle where it passed it, and the carrier is still there (its steps,
    # every 10 periods, are far larger than the triangle's 0.003 per period).
    res = _start_only(4.0, min_force=None, stroke_margin=0.047)
    c = res.constraints
    assert "no calmer carrier kept it, so it was repaired where it did" in res.message, res.message
    assert c["feasible"]
    assert c["stroke_limits"][0] <= c["position_range"][0] and c["position_range"][1] <= c["stroke_limits"][1]
    times, duty = np.asarray(res.times), np.asarray(res.duty)
    level = np.clip(np.asarray(_at(pj.Triangle(0.05, 0.95, 0.08), device_array(times))), 0.125, 0.875)
    assert np.mean(duty[times > 3.0]) < np.mean(level[times > 3.0]) - 0.05  # the level moved down where it passed
    assert np.max(np.abs(np.diff(duty))) > 0.02  # a carrier left


def test_a_start_whose_carrier_breaks_a_limit_is_calmed_where_a_calmer_carrier_keeps_it():
    # MAS-10 over 2 s with eq. 7's force kept >= 60 N: the default start's carrier exhausts the muscle below it; a
    # calmer carrier everywhere keeps the limit, and the design starts there (before the repair: taken first, or
    # where it scored lower, the repaired start gave the MAS-10 example a weaker design), within every limit.
    import re

    res = _start_only(2.0, min_force=60.0)
    c = res.constraints
    assert c["free_force_min"] >= 60.0 and (c["stop_force_min"] is None or c["stop_force_min"] >= 0.0)
    taken = re.search(r"the default start broke a limit, so its carrier's amplitude was lowered to ([\d.]+)",
                      res.message)
    assert taken and 0 < float(taken.group(1)) < 0.25, res.message
    assert "repaired" not in res.message and "verified at the fit's resolution" not in res.message


def test_a_limit_the_run_passes_between_the_samples_is_tightened_and_searched_on(monkeypatch):
    # The objective samples a PWM period 5 times and keeps max_pressure there; at the fit's resolution the run passes
    # it between its samples (the ripple: ~2 kPa on the tank). With no tolerance for it, the search goes on with the
    # limit lowered by what the samples missed, and the design ends within the limit at the fit's resolution too;
    # the constraints are still reported against the user's limit. (On a realistic rig's pilot, eq. 7's force was
    # 10.6 N lower between the samples than at them: 14.2 N under a 20 N limit, no design.)
    from pamjax._identifiability.design_result import VERIFY_TOLERANCE

    start = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=0, progress=False, **TANK)
    limit = start.constraints["pressure_range"][1] + 2e3
    monkeypatch.setitem(VERIFY_TOLERANCE, "pressure", 0.0)
    lines = []
    res = pj.design_experiment(_tank(), FREE, 0.4, noise=NOISE, steps=4, max_pressure=limit,
                               progress=lambda *a, **k: lines.append(a[0]), **TANK)
    c = res.constraints
    assert "verified at the fit's resolution, the pressure" in res.message and "its limit lowered to" in res.message
    assert c["feasible"] and c["verified"]["pressure_range"][1] <= limit and c["max_pressure"] == limit
    assert lines == sorted(lines) and [h[0] for h in res.history] == list(range(len(res.history)))  # numbered on
    assert res.iterations == len(res.history) - 1 > 4


# --- slips named before any work (issue: an earlier design smoothed, one margin for both thresholds, rate in kHz,
# a start outside the stroke) ---


def _set_up(model, free, duration, **kwargs):
    """`design_setup.set_up` with `design_experiment`'s defaults (as `check_design` calls it): no solve."""
    import inspect

    from pamjax._identifiability.design_setup import SETUP_ARGS, set_up

    args = {k: v.default for k, v in inspect.signature(pj.design_experiment).parameters.items() if k in SETUP_ARGS}
    return set_up(model, free, duration, **{**args, **kwargs})


def test_an_earlier_design_given_as_initial_is_the_envelopes_start_as_it_is():
    # An earlier design's per-period duties under the default envelope were least-squares fitted to its 4-knot level,
    # the carrier dropped: the start (and a steps=0 score) was another signal, up to 0.17 off. The part the envelope
    # cannot represent is now its fixed offset: the start duty and the objective's duty at the start are the given
    # one; a constant (which the envelope represents) needs none, so its designs share one compilation as before.
    from pamjax._identifiability.design import _problem_of

    given = np.repeat([0.6, 0.8, 0.55, 0.75, 0.5], 4)  # 20 periods of 0.4 s, steps <= 0.25: TANK's max_duty_step
    setup = _set_up(_tank(), FREE, 0.4, noise=NOISE, **{**TANK, "initial": given})
    assert setup["basis"] is not None and setup["offset"] is not None  # the envelope, with an offset
    np.testing.assert_allclose(np.asarray(setup["experiment"].signal.values), given, atol=1e-9)
    n = len(FREE)
    problem = _problem_of(setup, np.asarray(setup["space"].initial_theta()), tuple(range(n)), 2.0, None, 0.3,
                          "D")(np.zeros((n, n)), None)
    duty = eqx.filter_jit(lambda p, c: p.duty(c))(problem, device_array(setup["c0"]))
    np.testing.assert_allclose(np.asarray(duty), given, atol=1e-9)
    assert _set_up(_tank(), FREE, 0.4, noise=NOISE, **TANK)["offset"] is None  # Constant(0.6)
    signal = pj.Sampled(np.arange(21) * 0.02, [*given, given[-1]])  # `pamjax design`'s initial = "design.csv"
    np.testing.assert_allclose(np.asarray(_set_up(_tank(), FREE, 0.4, noise=NOISE, **{**TANK, "initial": signal})
                                          ["experiment"].signal.values), given, atol=1e-9)


def test_auto_duty_margin_is_each_thresholds_own_quarter():
    # t_on 2 ms, t_off 4 ms at 50 Hz: thresholds 0.1 and 0.8, each kept a quarter of its own switching time (0.025,
    # 0.05); one margin, the smaller, left the 0.8 threshold only 0.025 (and with t_off 1 ms gave 0.1 just 0.0125)
    from pamjax._identifiability.design_setup import auto_margins, duty_limits

    slow_off = eqx.tree_at(lambda m: m.valve.switch_off_delay, _tank(), jnp.asarray(4e-3))
    setup = _set_up(slow_off, FREE, 0.4, noise=NOISE, **TANK)
    assert setup["thresholds"] == pytest.approx((0.1, 0.8), abs=1e-9)
    assert setup["duty_margin"] == pytest.approx([0.025, 0.05], abs=1e-9)
    assert setup["band"] == pytest.approx((0.125, 0.9)) and np.allclose(setup["windows"], [(0.75, 0.85)])
    fast_off = auto_margins((0.1, 0.95))
    assert fast_off == pytest.approx([0.025, 0.0125])
    lo, hi, windows = duty_limits((0.0, 1.0), (0.1, 0.95), fast_off)
    assert np.allclose(windows, [(0.075, 0.125), (0.9375, 0.9625)])
    assert _set_up(_tank(), FREE, 0.4, noise=NOISE, **TANK)["duty_margin"] == pytest.approx(0.025)  # one number
    from pamjax._cli.design import constraint_lines

    report = dict(duty_range=[0.2, 0.7], duty_limits=[0.125, 0.9], switching_thresholds=[0.1, 0.8],
                  duty_band=[0.1, 0.9], duty_margin=[0.025, 0.05], threshold_distance=0.1, min_force=None,
                  stroke_limits=None, max_pressure=None, max_duty_step=None, feasible=True)
    assert "kept 0.025, 0.05 (each its own) from the valve's switching thresholds 0.1, 0.8" in constraint_lines(report)


@pytest.mark.parametrize("model, kwargs, match", [
    (_tank, dict(rate=1.0), r"rate 1\.0 Hz is below the PWM frequency \(50 Hz\).* Hz \(1 kHz = 1000\.0\)"),  # kHz
    (_tank, dict(rate=1e-3), r"rate 0\.001 Hz is below the PWM frequency"),
    (_tank, dict(design_rate=10.0), r"design_rate 10\.0 Hz is below the PWM frequency"),
    (_muscle, dict(start={"position": 0.5}), r"start\.position = 0\.5 m lies outside the stroke"),
    (_tank, dict(start={"pressure": 1.01325}), r"start\.pressure"),  # bar
    (_tank, dict(subset=FREE[0]), r"subset must be a list of free parameter labels.* got the string"),
    (_tank, dict(channels="pressure"), r"channels must be a list of recorded channels.* got the string 'pressure'"),
    (_muscle, dict(noise={"pressure": 2e3, "position": 0.1}), r"noise\['position'\] = 0\.1 m is 1\.1 of the"),
])
def test_a_rate_below_the_pwm_frequency_a_start_outside_the_stroke_and_bare_strings_are_named(model, kwargs, match,
                                                                                              monkeypatch):
    # rate = 1.0 (meant in kHz) gave the standard errors of a 3-sample run (22-32× worse); 1e-3 failed in Recording,
    # unnamed; a start at 0.5 m was widened into the stroke limit and failed ~35 s later, misnamed; a bare string
    # was split into its letters. Each refused before any solve, by the design and by the CLI's check.
    from pamjax._identifiability.design import check_design

    monkeypatch.setattr(obj, "value", lambda *a: pytest.fail("solved before rejecting the input"))
    base = dict(noise=NOISE, **TANK) if model is _tank else dict(noise=MUSCLE_NOISE, knots=4, rate=500.0)
    args = {**base, **kwargs}
    free = FREE if model is _tank else MUSCLE_FREE
    with pytest.raises(PamjaxInputError, match=match):
        pj.design_experiment(model(), free, 0.4, progress=False, **args)
    with pytest.raises(PamjaxInputError, match=match):
        check_design(model(), free, 0.4, **args)


def test_a_numpy_duration_is_a_number_and_a_missing_initial_csv_names_the_key(tmp_path, capsys):
    from pamjax._identifiability.design import check_design

    assert check_design(_tank(), FREE, np.int64(1), noise=NOISE, **TANK) is None  # was "not a positive number"
    cfg = tmp_path / "d.toml"
    cfg.write_text(TANK_DESIGN_CONFIG + 'initial = "nope.csv"\n')
    assert main(["design", str(cfg), "--out", str(tmp_path / "o"), "--quiet", "--no-plot"]) == 2
    assert "[design] initial = 'nope.csv'" in capsys.readouterr().err and not (tmp_path / "o").exists()


# --- a failed solve is not information (issue: an 800 s baseline run ran out of its max_steps: its residuals NaN, its
# forward-mode Jacobian exact zeros, its standard errors inf, and the design was said to beat it) ---


def _out_of_steps(name="E3"):
    """A run of the averaged MAS-10 whose adaptive solve runs out of steps (2): fails at once, as a long run does."""
    rec = pj.Recording(np.linspace(0.0, 0.5, 11), {"pressure": np.full(11, 2e5)}, name=name)
    return pj.Experiment(rec, pj.Constant(0.5), channels=["pressure"], scales={"pressure": 2e3}, stepping="adaptive",
                         max_steps=2, name=name)


def test_a_baseline_or_prior_run_whose_solve_fails_is_named_not_counted_as_no_information():
    from pamjax._identifiability import design as dmod
    from pamjax._identifiability.prior_fit import split_prior

    model = presets.mas10_system(valve="averaged")
    space = pj.ParameterSpace(model, MUSCLE_FREE)
    theta = np.asarray(space.initial_theta())
    for role, prior, baseline in (("baseline", split_prior(()), [_out_of_steps()]),
                                  ("prior", split_prior([_out_of_steps()]), None)):
        with pytest.raises(PamjaxInputError, match=rf"^{role}: not counted as information, as its simulation at the "
                                                   r"design point fails: experiment 'E3': its solve fails: the maximum "
                                                   r"number of solver steps was reached: max_steps=2 .*raise its "
                                                   r"max_steps"):
            dmod._in_hand(space, theta, prior, baseline, (0, 1), 1.0)


def test_a_designed_run_whose_solve_fails_at_the_start_says_so_not_that_it_determines_nothing(monkeypatch):
    # an 800 s design ran out of the designed run's max_steps: it was reported as "the start signal ... does not
    # determine [...]"; here the designed run's budget is cut to 2 steps
    from pamjax._identifiability import design_setup

    made = design_setup.designed_experiment

    def out_of_steps(*args, **kwargs):
        exp = made(*args, **kwargs)
        object.__setattr__(exp, "max_steps", 2)  # a static field of the bound copy (as `Experiment.bind` sets one)
        return exp

    monkeypatch.setattr(design_setup, "designed_experiment", out_of_steps)
    with pytest.raises(PamjaxInputError, match=r"duration: the designed run's solve fails at the start signal: the "
                                               r"maximum number of solver steps was reached: max_steps=2 .*design a "
                                               r"shorter run \(duration\)"):
        pj.design_experiment(presets.mas10_tank_system(valve="averaged"), ["valve.coefficients[1,0]"], 0.2,
                             noise=NOISE, channels=("pressure",), start={"pressure": 101325.0}, rate=500.0, knots=4,
                             steps=0, period=0.02, initial=pj.Constant(0.6), progress=False)


def test_a_long_planned_run_gets_the_step_budget_of_its_horizon():
    # a planned run has no max_steps key: an 800 s triangle of the averaged valve needs ~253,000 steps at the
    # Experiment's rtol 1e-9, beyond its default 100,000; a short run keeps the default (its compiled program)
    from pamjax._cli.design import _step_budget

    model = presets.mas10_system(valve="averaged")
    assert _step_budget(model, 25.0) == {}
    assert _step_budget(model, 800.0)["max_steps"] >= 2 * 253_000


def test_a_long_designed_run_gets_the_step_budget_of_its_horizon():
    # the designed run of an 800 s design ran out of the Experiment's default 100,000 steps at 96 s (~1,040 steps/s
    # at rtol 1e-9 with a duty per period): it gets twice `simulate`'s budget for its horizon; a design of up to
    # 50 s keeps the default (its compiled program)
    import inspect

    from pamjax._identifiability.design_setup import designed_experiment

    model = _tank()
    short = designed_experiment(model, 0.4, 0.02, 250.0, ("pressure",), NOISE, {"pressure": 101325.0}, 4,
                                np.full(20, 0.5))
    long = designed_experiment(model, 800.0, 0.02, 50.0, ("pressure",), NOISE, {"pressure": 101325.0}, 4,
                               np.full(40_000, 0.5))
    assert short.max_steps == inspect.signature(pj.Experiment.__init__).parameters["max_steps"].default
    assert long.max_steps >= 2 * 1_040 * 800
