"""profile: likelihood-ratio intervals equal the linearised ones for a model linear in its parameters; a nonlinear
two-parameter profile agrees with a brute-force grid of an independent NumPy transcription; eq. 7's k0, k1, k2 come
out structurally non-identifiable; `pamjax fit --profile` writes the profile and its figure; bad input is named, also
`fits/joint_profile.py --names` before its joint fit."""

import dataclasses
import json
import math
import textwrap
import warnings

import equinox as eqx
import numpy as np
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets
from pamjax._cli.main import main

# the muscle's force law jitted: eagerly, each of its operations compiles a program of its own
_static_force = eqx.filter_jit(lambda muscle, x, p, air: muscle.static_force(x, p, air))


def _force_map(noise, pressures_bar, positions, seed=0):
    """Synthetic isometric map of the MAS-10 preset with Gaussian noise [N]."""
    muscle = presets.mas10_muscle()
    x, p = np.meshgrid(positions, 101325.0 + 1e5 * np.asarray(pressures_bar), indexing="ij")
    x, p = x.ravel(), p.ravel()
    f = np.asarray(_static_force(muscle, x, p, pj.Air()))
    f = f + noise * np.random.default_rng(seed).standard_normal(f.shape)
    return muscle, x, p, f, pj.bench.ForceMapExperiment(x, p, f, scale=noise)


def _fit(model, exps, free):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pj.PamjaxIdentifiabilityWarning)
        return pj.fit(model, exps, free, progress=False)


def test_linear_model_profile_intervals_equal_the_linearised_ones():
    # Eq. 7 is linear in a0…a4, k0, k1 (k2 held): the profile is exactly quadratic, its interval ψ̂ ± 1.96 se.
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.max_force_coefficients", "force_law.k0", "force_law.k1"])
    prof = pj.profile_likelihood(res, ["a2", "force_law.k0", "force_law.k1"], progress=False)
    assert prof.threshold == pytest.approx(3.841459, abs=1e-5)
    for p in prof.profiles:
        assert p.verdict == "identifiable"
        width = p.linearised[1] - p.linearised[0]
        # crossing located by interpolating √Δχ² (exact for a quadratic) between re-fitted points: 1e-4 of the width
        np.testing.assert_allclose(p.interval, p.linearised, atol=1e-4 * width)
        assert all(p.converged)
        i = p.values.index(p.value)
        assert p.delta[i] == 0.0 and min(p.delta) > -1e-6  # the fit is the profile's minimum


def test_two_parameter_profile_matches_a_brute_force_grid():
    # k0 and k2 free (k1 held): F = F_max(x) − (p_max − p_g)(k0 − k1 x)/k2 is nonlinear in k2. The noise is large
    # so that the interval is wide and the profile visibly not quadratic. Oracle: the same equation in NumPy,
    # minimised over a fine grid of w = 1/k2 (w → 0: k2 → ∞, where this profile levels off) for each k0.
    muscle, x, p, f, exp = _force_map(60.0, [3.0, 4.0, 5.0, 6.0], np.linspace(-0.01, 0.03, 6), seed=3)
    assert np.all(f > 0)  # no slack points: every residual is (F_model − F)/scale
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k2"])
    prof = pj.profile_likelihood(res, ["force_law.k0"], progress=False)
    law = muscle.force_law
    fmax = np.polyval(np.asarray(law.max_force_coefficients)[::-1], x)
    gauge_gap = float(law.max_pressure) - (p - 101325.0)
    k1 = float(law.k1)

    def cost(k0, w):
        model = fmax[:, None] - gauge_gap[:, None] * (k0 - k1 * x[:, None]) * w[None, :]
        return 0.5 * np.sum(((model - f[:, None]) / 60.0) ** 2, axis=0)

    w_hat = 1.0 / res.values[1]
    grid = np.linspace(0.0, 10.0 * w_hat, 200_001)[1:]
    cost_min = cost(res.values[0], np.asarray([w_hat]))[0]
    sigma2 = 2.0 * cost_min / (x.size - 2)
    assert prof.sigma2 == pytest.approx(sigma2, rel=1e-9)
    pr = prof.profiles[0]
    assert pr.verdict == "identifiable"
    brute = np.asarray([2.0 * (cost(k0, grid).min() - cost_min) / sigma2 for k0 in pr.values])
    # a grid step of 5e-5 ŵ costs at most ~1e-6 in Δχ² at the profile's curvature; the profile's re-fits converge
    np.testing.assert_allclose(pr.delta, brute, atol=2e-3)
    # the profile is not quadratic here (else this test would not check more than the linear one)
    se = (pr.linearised[1] - pr.linearised[0]) / (2 * math.sqrt(prof.threshold))
    quad = ((np.asarray(pr.values) - pr.value) / se) ** 2
    assert np.max(np.abs(quad - np.asarray(pr.delta))) > 0.05
    # the interval ends: where the brute-force profile crosses the threshold (bisection on k0)
    for end, side in zip(pr.interval, (-1, 1)):
        lo, hi = pr.value, pr.value + side * 20 * se
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            below = 2.0 * (cost(mid, grid).min() - cost_min) / sigma2 < prof.threshold
            lo, hi = (mid, hi) if below else (lo, mid)
        assert end == pytest.approx(0.5 * (lo + hi), abs=0.01 * se)


def test_k0_k1_k2_together_are_structurally_non_identifiable():
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k1", "force_law.k2"])
    prof = pj.profile_likelihood(res, ["force_law.k0", "force_law.k2"], progress=False)
    for p in prof.profiles:
        assert p.verdict == "structurally non-identifiable", p.label
        assert p.interval == [-math.inf, math.inf]
        assert max(p.values) / min(p.values) > 10  # walked far (the span) on both sides, flat all the way
        assert max(abs(d) for d in p.delta) < 1e-3


def test_a_fit_at_a_bound_holds_the_pinned_parameter_there_and_profiles_it_inwards():
    # A fit that ended "at bound" (k1's logistic range below its true value): every walk stopped at its first point
    # (the bound "reached" where it started), the predictor divided by the pinned parameter's vanishing Jacobian
    # column (on a tank a first point at Δχ² ≈ 1.5e4), and the pinned parameter read "structurally non-identifiable".
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    k1 = float(muscle.force_law.k1)
    start = eqx.tree_at(lambda m: m.force_law.k1, muscle, np.asarray(0.7 * k1))
    res = _fit(start, [exp], ["force_law.k0", {"path": "force_law.k1", "transform": "logistic",
                                               "bounds": (0.5 * k1, 0.9 * k1)}])
    assert res.status == "at bound"
    prof = pj.profile_likelihood(res, progress=False)
    k0, pinned = prof["force_law.k0"], prof["force_law.k1"]
    # k0 with k1 held on its bound: the model is linear in k0, so its profile interval is the linearised one
    assert k0.verdict == "identifiable" and len(k0.values) > 4
    np.testing.assert_allclose(k0.interval, k0.linearised, atol=1e-3 * (k0.linearised[1] - k0.linearised[0]))
    np.testing.assert_allclose(k0.others["force_law.k1"], 0.9 * k1, rtol=1e-6)  # held on its bound
    # k1 at its upper bound: profiled inwards, its interval one-sided from the bound, Δχ² at its lower end the
    # threshold (a re-fit of k0 by hand with k1 held there)
    assert pinned.verdict.startswith("at the upper bound of its range") and "structurally" not in pinned.verdict
    assert pinned.interval[1] == pytest.approx(0.9 * k1) and 0.5 * k1 < pinned.interval[0] < 0.9 * k1
    again = _fit(eqx.tree_at(lambda m: m.force_law.k1, res.model, np.asarray(pinned.interval[0])), [exp],
                 ["force_law.k0"])
    assert 2.0 * (again.cost - res.cost) / prof.sigma2 == pytest.approx(prof.threshold, abs=0.05)


def test_bad_input_is_named_before_any_solve():
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k1"])
    with pytest.raises(PamjaxInputError, match=r"names \['k0'\] must be fitted parameters"):
        pj.profile_likelihood(res, ["k0"])
    with pytest.raises(PamjaxInputError, match="level must be in"):
        pj.profile_likelihood(res, level=95)
    loaded = pj.FitResult.from_dict(json.loads(json.dumps(res.to_dict())))
    with pytest.raises(PamjaxInputError, match="experiments: this FitResult does not carry"):
        pj.profile_likelihood(loaded)


def test_repeated_names_no_experiments_and_a_level_not_a_number_are_named_before_any_work(monkeypatch):
    # each was a raw ValueError / TypeError, the repeated name's only after every branch had been walked
    from pamjax._identifiability import profile as profile_module

    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k1"])
    monkeypatch.setattr(profile_module, "_Evaluator", lambda *a: pytest.fail("worked before refusing the input"))
    with pytest.raises(PamjaxInputError, match=r"names \['force_law\.k0'\] given more than once"):
        pj.profile_likelihood(res, ["force_law.k0", "force_law.k1", "force_law.k0"], progress=False)
    with pytest.raises(PamjaxInputError, match=r"experiments must hold the experiments the fit was made of, got none"):
        pj.profile_likelihood(res, experiments=[], progress=False)
    for level in ("0.95", True, float("nan"), [0.95]):
        with pytest.raises(PamjaxInputError, match=r"level must be in \(0, 1\), a number"):
            pj.profile_likelihood(res, level=level, progress=False)


def test_joint_profile_script_checks_names_against_the_bench_before_fitting(tmp_path, monkeypatch, capsys):
    # fits/joint_profile.py --names: a held key (k2) or a pamjax label is refused by the parser, listing the bench's
    # fitted keys, before the joint fit (minutes); it was a raw KeyError after it
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "fits" / "joint_profile.py"
    spec = importlib.util.spec_from_file_location("joint_profile", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    monkeypatch.setattr(pj, "fit", lambda *a, **k: pytest.fail("fitted before checking --names"))
    for names in (["k2"], ["friction.coulomb_force"], ["Fc", "Fc"]):
        with pytest.raises(SystemExit) as exit_info:
            script.main(["--names", *names, "--out", str(tmp_path)])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        assert f"--names {sorted(set(names))}" in err and "fitted ones (meta.json's fitted_keys) are: " in err, err
        assert " Fc " in err and " k2 " not in err
    assert not list(tmp_path.iterdir())


def test_fit_cli_profile_writes_json_and_figure(tmp_path, capsys, monkeypatch):
    # A 0.6 s constant-volume charge through the averaged valve, eq. 13 terms u and u·p free.
    system = presets.mas10_tank_system(valve="averaged")
    ts = np.arange(0.0, 0.6, 2e-3)
    rec = pj.synthetic_recording(system, pj.Constant(0.5), ts, noise={"pressure": 2e3}, seed=1, name="charge")
    rec.to_csv(tmp_path / "charge.csv")
    cfg = tmp_path / "tank.toml"
    cfg.write_text(textwrap.dedent("""
        [model]
        preset = "mas10_tank_system"
        options = { valve = "averaged" }
        [fit]
        free = ["valve.coefficients[1,0]", "valve.coefficients[1,1]"]
        [[experiment]]
        file = "charge.csv"
        signal = { kind = "Constant", value = 0.5 }
        channels = ["pressure"]
        scales = { pressure = 2e3 }
    """))
    assert main(["fit", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--profile"]) == 0
    data = json.loads((tmp_path / "out" / "profile.json").read_text())
    assert [p["label"] for p in data["profiles"]] == ["valve.coefficients[1,0]", "valve.coefficients[1,1]"]
    assert all(p["verdict"] == "identifiable" for p in data["profiles"])
    assert (tmp_path / "out" / "profile.png").stat().st_size > 10_000
    assert (tmp_path / "out" / "fit.png").is_file()
    # --profile NAMES: those only (a rig's fit frees dozens; each profile is minutes there), names checked first
    one = "valve.coefficients[1,1]"
    assert main(["fit", str(cfg), "--out", str(tmp_path / "one"), "--quiet", "--no-plot", "--profile", one]) == 0
    data = json.loads((tmp_path / "one" / "profile.json").read_text())
    assert data["labels"] == [one] and data["profiles"][0]["verdict"] == "identifiable"
    # a fit the profile finds is not at its minimum (here: moved off it before profiling): the refit's results
    # replace the fit's files, profile.json lists the refit, and the verdicts stand
    real = pj.profile_to_minimum

    def from_a_moved_fit(res, names, **kwargs):
        c = res.model.valve.coefficients
        off = eqx.tree_at(lambda m: m.valve.coefficients, res.model, c.at[1, 1].multiply(1.05))
        moved = dataclasses.replace(res, model=off, values=[res.values[0], res.values[1] * 1.05])
        return real(moved, names, **kwargs)

    monkeypatch.setattr(pj, "profile_to_minimum", from_a_moved_fit)
    assert main(["fit", str(cfg), "--out", str(tmp_path / "moved"), "--no-plot", "--profile", one]) == 0
    monkeypatch.undo()
    text = capsys.readouterr().out
    assert "1 refit(s) from the lowest point" in text, text[-2000:]
    data = json.loads((tmp_path / "moved" / "profile.json").read_text())
    assert len(data["refits"]) == 1 and data["profiles"][0]["verdict"] == "identifiable"
    written = json.loads((tmp_path / "moved" / "fit.json").read_text())
    assert written["cost"] == pytest.approx(data["refits"][0]["cost"], rel=1e-12)
    assert main(["fit", str(cfg), "--out", str(tmp_path / "bad"), "--quiet", "--profile", "valve.mass"]) == 2
    err = capsys.readouterr().err
    assert "--profile: 'valve.mass' is not a fitted parameter; give the fit's labels" in err and one in err
    assert not (tmp_path / "bad").exists()  # named before the fit: nothing written


# -- a start that is not a minimum (issue 33) ------------------------------------------------------------------
def test_a_fit_stopped_at_max_steps_is_refused_before_any_work():
    # the regression: after a fit stopped at max_steps every parameter read "structurally non-identifiable",
    # interval (-inf, inf), because every re-fit fell below the unconverged start (Δχ² < 0 all along)
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    start = eqx.tree_at(lambda m: m.force_law.k0, muscle, muscle.force_law.k0 * 1.5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pj.PamjaxIdentifiabilityWarning)
        res = pj.fit(start, [exp], ["force_law.k0", "force_law.k1"], max_steps=1, progress=False)
    assert res.status == "max_steps"
    with pytest.raises(PamjaxInputError, match=r"status 'max_steps'.*not a minimum.*--resume --profile"):
        pj.profile_likelihood(res, progress=False)


def test_a_start_below_which_the_profile_finds_a_lower_cost_voids_every_verdict():
    # a "converged" result whose model is not the best fit (here: moved off it by hand; in practice a fit stopped
    # by a loose tolerance): the re-fits find a lower cost, and no verdict claims anything
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k1"])
    off = eqx.tree_at(lambda m: m.force_law.k1, res.model, res.model.force_law.k1 * 1.05)
    moved = dataclasses.replace(res, model=off, values=[res.values[0], res.values[1] * 1.05])
    prof = pj.profile_likelihood(moved, progress=False)
    assert prof.warnings and "not at a minimum" in prof.warnings[0]
    assert all(p.verdict.startswith("not a minimum") for p in prof.profiles)
    assert "WARNING: the fit is not at a minimum" in prof.table()
    # the lowest re-fitted point: every parameter's value there, a start to fit again from, which reaches the fit
    delta, point = prof.lowest()
    assert delta < -1.0 and set(point) == set(res.labels)
    again = _fit(prof.lower_start(moved), [exp], ["force_law.k0", "force_law.k1"])
    assert again.cost == pytest.approx(res.cost, rel=1e-6)
    np.testing.assert_allclose(again.values, res.values, rtol=1e-4)
    other = _fit(muscle, [exp], ["force_law.k0"])
    with pytest.raises(PamjaxInputError, match="result: this profile is of a fit of"):
        prof.lower_start(other)
    control = pj.profile_likelihood(res, progress=False)  # the fit itself: no warning, the verdicts stand
    assert not control.warnings and all(p.verdict == "identifiable" for p in control.profiles)
    assert control.lowest() is None and control.lower_start(res) is None
    # profile_to_minimum: the refit from the lowest point, then a profile of it whose verdicts stand
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pj.PamjaxIdentifiabilityWarning)
        done = pj.profile_to_minimum(moved, progress=False)
    assert len(done.refits) == 1 and done.refits[0]["delta_chi2"] < -1.0
    assert done.refits[0]["cost"] < done.refits[0]["from_cost"] and done.refits[0]["status"] == "converged"
    assert done.result.cost == pytest.approx(res.cost, rel=1e-6) and not done.profile.warnings
    assert [p.verdict for p in done.profile.profiles] == ["identifiable"] * 2
    assert done.profile_s > done.profile.profile_s > 0
    with pytest.raises(PamjaxInputError, match="rounds must be an int >= 1"):
        pj.profile_to_minimum(res, rounds=0)


def test_a_progress_callable_gets_the_lines_and_nothing_is_printed(capsys):
    # the callable was never called, and the lines were printed instead
    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k1"])
    capsys.readouterr()
    lines = []
    prof = pj.profile_likelihood(res, ["force_law.k0"], max_points=4, progress=lines.append)
    assert capsys.readouterr().out == ""
    assert all(isinstance(line, str) for line in lines)
    assert lines[0].startswith("profiling 1 parameter(s)") and any(line.startswith("profiled force_law.k0")
                                                                    for line in lines)
    assert lines[-1].startswith(f"force_law.k0: {prof.profiles[0].verdict}")


def test_a_result_read_from_json_is_told_what_works_and_bad_counts_or_spans_are_named(monkeypatch):
    # read from JSON, the advice "pass the experiments" only led to a second refusal ("no fitted model"); span="4"
    # was a raw TypeError, max_points=np.int64(5) refused as "must be an int"
    from pamjax._identifiability import profile as profile_module

    muscle, *_, exp = _force_map(2.0, np.linspace(0.5, 6.0, 7), np.linspace(-0.01, 0.07, 9))
    res = _fit(muscle, [exp], ["force_law.k0", "force_law.k1"])
    loaded = pj.FitResult.from_dict(json.loads(json.dumps(res.to_dict())))
    rebuild = r"set its fitted model from the model the fit started from: result\.model = result\.apply\(start_model\)"
    with pytest.raises(PamjaxInputError, match=rf"pass the experiments it was fitted to, and {rebuild}$"):
        pj.profile_likelihood(loaded, progress=False)
    with pytest.raises(PamjaxInputError, match=rf"result has no fitted model \(read from JSON\): {rebuild}"):
        pj.profile_likelihood(loaded, experiments=[exp], progress=False)
    loaded.model = loaded.apply(muscle)  # as the advice says: then it profiles
    prof = pj.profile_likelihood(loaded, ["force_law.k0"], experiments=[exp], max_points=np.int64(2),
                                 max_steps=np.int64(30), workers=np.int64(1), progress=False)
    assert prof.profiles[0].label == "force_law.k0" and len(prof.profiles[0].values) >= 3
    monkeypatch.setattr(profile_module, "_Evaluator", lambda *a: pytest.fail("worked before refusing the input"))
    for kwargs, match in ((dict(span="4"), r"span must be a finite number > 0 .*got '4'"),
                          (dict(span=float("inf")), "span must be a finite number > 0"),
                          (dict(span=0.0), "span must be a finite number > 0"),
                          (dict(max_points=1), "max_points must be an int >= 2, got 1"),
                          (dict(max_points=True), "max_points must be an int >= 2, got True"),
                          (dict(max_steps=0), "max_steps must be an int >= 1, got 0"),
                          (dict(max_steps="5"), "max_steps must be an int >= 1, got '5'"),
                          (dict(workers=2.0), "workers must be an int >= 1, got 2.0")):
        with pytest.raises(PamjaxInputError, match=match):
            pj.profile_likelihood(res, progress=False, **kwargs)
