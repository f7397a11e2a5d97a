"""pamjax's least-squares solver (`pamjax._fit.solver`: an optimistix `AbstractGaussNewton` with its own descent and
search) on problems with known answers, run from the host as `pamjax.fit` runs it and traced in
`optimistix.least_squares`; its stopping reasons; `fit(solver=...)` with optimistix's own solver; and the residual
diagnostics (`pamjax._fit.diagnostics`)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import pamjax as pj
from pamjax import PamjaxInputError, presets
from pamjax._fit import diagnostics as _diagnostics, drive as D, escape as E, solver as S


def _run(residuals, jacobian, theta, max_steps=200, **kw):
    opts = dict(ftol=1e-12, xtol=1e-12, gtol=1e-12, stall_steps=8) | kw
    return D.levenberg_marquardt(residuals, jacobian, np.asarray(theta, dtype=float), max_steps=max_steps, **opts)


def _rosenbrock():
    def residuals(t):
        return np.array([10.0 * (t[1] - t[0] ** 2), 1.0 - t[0]])

    def jacobian(t):
        return residuals(t), np.array([[-20.0 * t[0], 10.0], [-1.0, 0.0]])

    return residuals, jacobian


def _rosenbrock_jax(y, args):
    return jnp.stack([10.0 * (y[1] - y[0] ** 2), 1.0 - y[0]])


@pytest.mark.parametrize("geodesic", [True, False])
def test_rosenbrock_valley_reaches_the_minimum(geodesic):
    residuals, jacobian = _rosenbrock()
    out = _run(residuals, jacobian, [-1.2, 1.0], geodesic=geodesic)
    assert out.done and out.reason.startswith("converged"), out.reason
    np.testing.assert_allclose(out.theta, [1.0, 1.0], atol=1e-8)


def test_geodesic_acceleration_follows_a_curved_valley_in_fewer_steps():
    # Transtrum & Sethna's point: on a narrow curved valley the accelerated steps need fewer iterations.
    residuals, jacobian = _rosenbrock()
    plain = _run(residuals, jacobian, [-1.2, 1.0], geodesic=False)
    geo = _run(residuals, jacobian, [-1.2, 1.0], geodesic=True)
    assert geo.accepted < plain.accepted


def test_linear_problem_converges_to_lstsq():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(40, 3)), rng.normal(size=40)
    out = _run(lambda t: a @ t - b, lambda t: (a @ t - b, a), np.zeros(3))
    np.testing.assert_allclose(out.theta, np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-6)
    assert out.reason.startswith("converged")


def test_failed_trials_are_rejected_not_fatal():
    # The residuals are undefined (None: a failed solve) beyond t = 2; the minimum at t = 3 lies beyond, so the
    # fit must end near the boundary without ever accepting an undefined point.
    def residuals(t):
        return None if t[0] > 2.0 else np.array([t[0] - 3.0])

    out = _run(residuals, lambda t: (residuals(t), np.array([[1.0]])), [0.0], max_steps=60)
    assert 1.9 < out.theta[0] <= 2.0
    assert any(not accepted for *_, accepted in out.history)


@pytest.mark.parametrize("bad", [np.nan, 1e300])
def test_a_trial_whose_jacobian_cannot_be_factored_is_rejected_not_fatal(bad):
    # The residuals are defined everywhere, but beyond t = 2 the Jacobian is not finite or so large that its column
    # norms overflow (a solve that only just held: unseen rig901's joint fit raised NumPy's "SVD did not converge"):
    # the trial is refused as a failed one, and the fit ends near the boundary without an error.
    def residuals(t):
        return np.array([t[0] - 3.0, 0.5 * (t[0] - 3.0)])

    def jacobian(t):
        return residuals(t), np.full((2, 1), bad) if t[0] > 2.0 else np.array([[1.0], [0.5]])

    out = _run(residuals, jacobian, [0.0], max_steps=60)
    assert 1.9 < out.theta[0] <= 2.0
    assert any(not accepted for *_, accepted in out.history)


def test_traced_trial_whose_jacobian_is_not_finite_is_rejected_as_on_the_host():
    @jax.custom_jvp
    def shifted(t):
        return t - 3.0

    @shifted.defjvp
    def _(primals, tangents):
        (t,), (dt,) = primals, tangents
        return shifted(t), jnp.where(t > 2.0, jnp.nan, 1.0) * dt

    sol = optx.least_squares(lambda y, args: jnp.stack([shifted(y[0]), 0.5 * shifted(y[0])]),
                             pj.LevenbergMarquardt(1e-12, 1e-12, 1e-12), jnp.zeros(1), max_steps=60, throw=False)
    assert 1.9 < float(sol.value[0]) <= 2.0


def _wrong_jacobian():
    # The Jacobian's sign is wrong: every step goes uphill.
    def residuals(t):
        return np.array([t[0] - 3.0, 2.0 * (t[1] + 1.0)])

    return residuals, lambda t: (residuals(t), -np.diag([1.0, 2.0]))


def test_a_wrong_jacobian_stalls_and_the_check_says_so():
    # The fit must not claim convergence; it stalls, and the Jacobian check measures a disagreement of order one.
    residuals, jacobian = _wrong_jacobian()
    out = _run(residuals, jacobian, [0.0, 0.0], max_steps=1000)
    assert out.done and out.reason == "stalled", out.reason
    assert out.accepted == 0 and out.restarts == S.PROBE_RESTARTS  # probes found lower points; no step did
    assert D.jacobian_check(out, residuals) > 0.5


def _sticky():
    # A noise-scaled problem (200 residuals, cost ≈ 100) whose cost jumps up where θ₀ crosses k, half a standard
    # error short of the smooth optimum (as a stick-slip phase appearing makes a bench cost jump). The Jacobian is
    # the smooth one, so it keeps promising a decrease beyond k that every step there refuses.
    rng = np.random.default_rng(3)
    a = np.linalg.qr(rng.normal(size=(200, 2)))[0] * [8.0, 3.0]  # orthogonal columns: θ₁ is free of the jump
    e = rng.normal(size=200)
    smooth = np.linalg.lstsq(a, -e, rcond=None)[0]  # the minimum of ½‖a θ + e‖²
    se0 = np.sqrt(np.linalg.inv(a.T @ a)[0, 0])
    k = smooth[0] - 0.5 * se0
    rest = a @ smooth + e  # orthogonal to a's columns: beyond k the cost is higher by a constant (1.05² − 1)·½‖rest‖²
    start = np.array([smooth[0] - 3 * se0, smooth[1] + 2 / 3.0])
    return a, e, rest, k, smooth, se0, start


def test_a_minimum_where_the_cost_is_not_smooth_is_converged_not_stalled():
    # The damped steps end at the jump, with θ₁ (started 2 standard errors off) not yet at its optimum. The probe
    # finds the lower point along θ₁ and the iteration goes on from there; the next probe finds none: converged.
    a, e, rest, k, smooth, se0, start = _sticky()

    def residuals(t):
        return a @ t + e + (0.05 * rest if t[0] > k else 0.0)

    out = _run(residuals, lambda t: (residuals(t), a), start, max_steps=300)
    assert out.done and out.reason == S.PROBED_MINIMUM, out.reason
    assert k - 0.01 * se0 < out.theta[0] <= k and out.restarts >= 1
    np.testing.assert_allclose(out.theta[1], smooth[1], atol=1e-3 / 3.0)
    assert S.probe(lambda t, args: (residuals(t), None), out.theta, None, out.jacobian, out.cost)[0] <= \
        1e-6 * out.cost
    # the probe's move is in the history: a second row of the same iteration, accepted, at a lower cost
    steps = [row[0] for row in out.history]
    assert len(steps) > len(set(steps))


def test_the_statistics_of_a_minimum_at_a_kink_come_from_a_hair_off_it():
    # At a kink a stick-slip event begins or ends exactly at the end point, and the Jacobian there can be that of the
    # event's edge (an unseen rig's force law: columns 1e5× their size a hair off, standard errors 100× too small).
    # The statistics then take the Jacobian a hair off the end point, where the cost is the same; elsewhere, or where
    # a hair's move changes the cost (a cliff's edge), the end point's.
    a, e, rest, k, smooth, se0, start = _sticky()

    def residuals(t):
        return a @ t + e + (0.05 * rest if t[0] > k else 0.0)

    out = _run(residuals, lambda t: (residuals(t), a), start, max_steps=300)
    assert out.reason == S.PROBED_MINIMUM, out.reason
    edge = a * np.array([1e5, 1.0])
    out = dataclasses.replace(out, jacobian=edge)  # the fit's last Jacobian, at the end point

    def jacobian(t):
        return residuals(t), (edge if np.array_equal(t, out.theta) else a)

    jac, r = D.statistics_jacobian(out, jacobian)
    np.testing.assert_array_equal(jac, a)
    assert abs(0.5 * float(r @ r) - out.cost) <= E.HAIR_COST * out.cost
    cov = _diagnostics.covariance(jac, out.cost, a.shape[0], 1e-10)
    np.testing.assert_allclose(np.sqrt(cov[0, 0]), se0 * np.sqrt(2 * out.cost / (a.shape[0] - 2)), rtol=1e-9)
    converged = dataclasses.replace(out, reason="converged: relative cost decrease below ftol")
    assert D.statistics_jacobian(converged, jacobian)[0] is edge
    assert D.statistics_jacobian(out, lambda t: (10 * residuals(t), a))[0] is edge  # a cliff both ways


def test_a_fit_crawling_at_a_minimum_is_probed_and_converged():
    # Tiny steps accepted between rejections never make `stall_steps` rejections in a row (two bench fits from the
    # presets ran to max_steps so, gaining 1e-9 of the cost per step). Where CRAWL_STEPS iterations together gained
    # less than POTENTIAL_TOL of the cost, the probe decides: here, at the minimum of a quadratic, converged.
    rng = np.random.default_rng(4)
    a, e = rng.normal(size=(50, 2)), rng.normal(size=50)
    fn = D._Callables(lambda t: a @ t + e, lambda t: (a @ t + e, a))
    solver = S.LevenbergMarquardt(ftol=0.0, xtol=0.0, gtol=0.0)
    best = np.linalg.lstsq(a, -e, rcond=None)[0]
    state = solver.init(fn, best, None, {}, None, None, frozenset())
    crawled = state.cost * (1 + 1e-9 * np.arange(S.CRAWL_STEPS + 1)[::-1])  # the last 17 rows' costs, ~flat
    state = dataclasses.replace(state, recent=crawled, rows=np.int64(20), accepted=np.int64(10), step=np.int64(19))
    _, after, _ = solver.step(fn, best, None, {}, state, frozenset())
    assert after.done and S.REASONS[int(after.reason)] == S.PROBED_MINIMUM
    # a real gain over the window (its oldest row once this step's is added): not crawling, not probed
    gained = dataclasses.replace(state, recent=np.concatenate([crawled[:1], [state.cost * 1.01], crawled[2:]]))
    _, after, _ = solver.step(fn, best, None, {}, gained, frozenset())
    assert S.REASONS[int(after.reason)] != S.PROBED_MINIMUM


def test_state_round_trips_through_arrays_and_resumes_bitwise():
    residuals, jacobian = _rosenbrock()
    fn, solver = D._Callables(residuals, jacobian), S.LevenbergMarquardt(1e-12, 1e-12, 1e-12)
    whole = D.run_on_host(solver, fn, np.array([-1.2, 1.0]), max_steps=200)
    part = D.run_on_host(solver, fn, np.array([-1.2, 1.0]), max_steps=5)
    y, state, history = D.state_from_arrays(solver, D.state_arrays(*part))
    for name in ("residual", "jacobian", "recent", "cost", "step", "rows"):
        np.testing.assert_array_equal(getattr(state, name), getattr(part[1], name))
    np.testing.assert_array_equal(state.factors.u, part[1].factors.u)  # recomputed from J and D: the same bits
    resumed = D.run_on_host(solver, fn, y, state, history, max_steps=200)
    assert resumed[2] == whole[2] and np.array_equal(resumed[0], whole[0])


def test_a_checkpoint_of_the_host_levenberg_marquardt_resumes():
    # format 2 (pamjax until 2026-11): the reason as text, no crawl buffer; the same iteration continues from it
    residuals, jacobian = _rosenbrock()
    fn, solver = D._Callables(residuals, jacobian), S.LevenbergMarquardt(1e-12, 1e-12, 1e-12)
    whole = D.run_on_host(solver, fn, np.array([-1.2, 1.0]), max_steps=200)
    y, state, history = D.run_on_host(solver, fn, np.array([-1.2, 1.0]), max_steps=6)
    old = dict(theta=y, residual=state.residual, jacobian=state.jacobian,
               scalars=np.asarray([state.cost, state.search.damping, state.search.growth]), scale=state.factors.scale,
               counters=np.asarray([state.step, state.accepted, state.rejected_in_row, 0, 0]), reason=np.asarray(""),
               history=np.asarray(history, dtype=float))
    resumed = D.run_on_host(solver, fn, *D.state_from_arrays(solver, old), max_steps=200)
    assert resumed[2] == whole[2]


# --- the same solver traced, and its parts in optimistix ------------------------------------------------------------
@pytest.mark.parametrize("geodesic", [True, False])
def test_traced_in_optimistix_least_squares_as_on_the_host(geodesic):
    solver = pj.LevenbergMarquardt(1e-12, 1e-12, 1e-12, geodesic=geodesic)
    sol = optx.least_squares(_rosenbrock_jax, solver, jnp.array([-1.2, 1.0]), max_steps=200, throw=False)
    host = _run(*_rosenbrock(), [-1.2, 1.0], geodesic=geodesic)
    assert sol.result == optx.RESULTS.successful
    np.testing.assert_allclose(sol.value, [1.0, 1.0], atol=1e-8)
    assert int(sol.stats["num_steps"]) == host.step and int(sol.stats["num_accepted_steps"]) == host.accepted
    assert S.REASONS[int(sol.stats["reason"])] == host.reason


def test_traced_probe_finds_the_non_smooth_minimum_as_on_the_host():
    a, e, rest, k, smooth, se0, start = _sticky()

    def fn(t, args):
        return a @ t + e + jnp.where(t[0] > k, 0.05, 0.0) * rest

    sol = optx.least_squares(fn, pj.LevenbergMarquardt(1e-12, 1e-12, 1e-12), jnp.asarray(start), max_steps=300,
                             throw=False)
    host = _run(lambda t: np.asarray(fn(t, None)), lambda t: (np.asarray(fn(t, None)), a), start, max_steps=300)
    assert S.REASONS[int(sol.stats["reason"])] == S.PROBED_MINIMUM == host.reason
    np.testing.assert_allclose(np.asarray(sol.value), host.theta, rtol=1e-9)  # XLA's SVD, not LAPACK's: last bits


def test_traced_wrong_jacobian_ends_as_divergence():
    @jax.custom_jvp
    def f(t):
        return jnp.stack([t[0] - 3.0, 2.0 * (t[1] + 1.0)])

    @f.defjvp
    def _(primals, tangents):
        return f(primals[0]), -jnp.array([1.0, 2.0]) * tangents[0]

    sol = optx.least_squares(lambda t, args: f(t), pj.LevenbergMarquardt(1e-12, 1e-12, 1e-12), jnp.zeros(2),
                             max_steps=1000, throw=False)
    assert sol.result == optx.RESULTS.nonlinear_divergence and S.REASONS[int(sol.stats["reason"])] == "stalled"


def test_a_start_whose_residuals_are_not_finite_fails_traced_and_on_the_host():
    # NaN residuals at y0 read as a gradient orthogonal to them (NaN norms → cosine 0): RESULTS.successful after 0
    # steps, "converged"; optimistix's own LevenbergMarquardt fails there. On the host NumPy's SVD raised LinAlgError.
    t = jnp.linspace(0.0, 3.0, 40)

    def fn(p, args):
        return p[0] * jnp.exp(-p[1] * t) - 2.0 * jnp.exp(-0.7 * t) + jnp.sqrt(p[0] - 5.0)  # NaN for p[0] < 5

    sol = optx.least_squares(fn, pj.LevenbergMarquardt(), jnp.array([1.0, 1.0]), max_steps=50, throw=False)
    assert sol.result != optx.RESULTS.successful
    assert S.REASONS[int(sol.stats["reason"])].startswith("failed: the residuals or their Jacobian are not finite")
    with pytest.raises(Exception, match=r"diverged"):
        optx.least_squares(fn, pj.LevenbergMarquardt(), jnp.array([1.0, 1.0]), max_steps=50)
    host = _run(lambda p: np.asarray(fn(p, None)), lambda p: (np.asarray(fn(p, None)), np.full((40, 2), np.nan)),
                [1.0, 1.0])
    assert host.done and host.step == 0 and host.reason.startswith("failed:"), host.reason
    assert np.isinf(S.gradient_cosine(np.full((3, 2), np.nan), np.ones(3)))  # never "orthogonal"


def test_descent_and_search_serve_optimistix_gauss_newton():
    # pamjax's descent (Moré-scaled damped step) and search (Nielsen's damping) in optimistix's own Gauss-Newton loop
    class GN(optx.AbstractGaussNewton):
        rtol: float = 1e-10
        atol: float = 1e-10
        norm: object = optx.max_norm
        descent: S.ScaledDampedDescent = S.ScaledDampedDescent()
        search: S.NielsenDamping = S.NielsenDamping()
        verbose: object = S._noop_verbose

    sol = optx.least_squares(_rosenbrock_jax, GN(), jnp.array([-1.2, 1.0]), max_steps=500, throw=False)
    assert sol.result == optx.RESULTS.successful
    np.testing.assert_allclose(sol.value, [1.0, 1.0], atol=1e-6)


def test_bad_settings_are_named():
    with pytest.raises(PamjaxInputError, match="ftol"):
        pj.LevenbergMarquardt(ftol=2.0)
    with pytest.raises(PamjaxInputError, match="stall_steps"):
        pj.LevenbergMarquardt(stall_steps=0)
    with pytest.raises(PamjaxInputError, match="fn.jacobian"):
        pj.LevenbergMarquardt().init(lambda y, args: (y, None), np.zeros(2), None, {}, None, None, frozenset())


# --- fit(solver=...) ------------------------------------------------------------------------------------------------
FREE = ["force_law.max_force_coefficients", "force_law.k0", "force_law.k1"]


@pytest.fixture(scope="module")
def force_map():
    """The synthetic MAS-10 static force map of tests/reliability/test_fit_determinism.py, 30 % low."""
    muscle = presets.mas10_muscle()
    x, p = np.meshgrid(np.linspace(-0.01, 0.07, 9), 101325.0 + np.linspace(0.5e5, 6e5, 7), indexing="ij")
    x, p = x.ravel(), p.ravel()
    f = np.asarray(muscle.static_force(jnp.asarray(x), jnp.asarray(p), pj.Air()))
    f = f + 2.0 * np.random.default_rng(0).standard_normal(f.shape)
    space = pj.ParameterSpace(muscle, FREE)
    experiment = pj.bench.ForceMapExperiment(x, p, np.maximum(f, 0), scale=2.0)
    return space.with_values(np.asarray(space.initial_values()) * 0.7), experiment


def test_fit_with_optimistix_levenberg_marquardt_converges_to_pamjax_optimum(force_map):
    start, exp = force_map
    ours = pj.fit(start, [exp], FREE, max_steps=60, progress=False)
    lines = []
    theirs = pj.fit(start, [exp], FREE, max_steps=200, progress=lambda *row: lines.append(row),
                    solver=optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10))
    assert ours.converged and theirs.converged, theirs.message
    assert "optimistix LevenbergMarquardt" in theirs.message
    assert theirs.cost == pytest.approx(ours.cost, rel=1e-8)
    np.testing.assert_allclose(theirs.values, ours.values, rtol=1e-5)
    assert len(lines) >= theirs.iterations and lines[0][0] == 0  # one progress line per evaluation


def test_fit_with_an_explicit_pamjax_solver_is_the_default_fit(force_map):
    start, exp = force_map
    default = pj.fit(start, [exp], FREE, max_steps=60, progress=False)
    explicit = pj.fit(start, [exp], FREE, max_steps=60, progress=False, solver=pj.LevenbergMarquardt())
    assert explicit.history == default.history and explicit.values == default.values


def test_fit_refuses_what_a_solver_cannot_do(force_map, tmp_path):
    start, exp = force_map
    with pytest.raises(PamjaxInputError, match="solver must be"):
        pj.fit(start, [exp], FREE, solver="lm")
    with pytest.raises(PamjaxInputError, match="ftol"):
        pj.fit(start, [exp], FREE, solver=pj.LevenbergMarquardt(), ftol=1e-6)
    with pytest.raises(PamjaxInputError, match="checkpoint"):
        pj.fit(start, [exp], FREE, solver=optx.LevenbergMarquardt(1e-8, 1e-8), checkpoint=tmp_path / "c.npz")
    assert not (tmp_path / "c.npz").exists()


# --- residual diagnostics -------------------------------------------------------------------------------------------
def test_white_residuals_of_the_stated_noise_are_not_mismatch():
    rng = np.random.default_rng(1)
    err = 2e3 * rng.standard_normal(20000)
    stats = _diagnostics._residual_stats(err, 2e3)
    assert abs(stats["rmse_over_noise"] - 1) < 0.02
    assert abs(stats["noise_estimate"] / 2e3 - 1) < 0.05
    assert abs(stats["autocorrelation"]["1"]) < 0.03
    assert stats["se_inflation"] < 1.1


def test_smooth_model_error_is_flagged_as_mismatch():
    rng = np.random.default_rng(2)
    t = np.linspace(0, 25, 25001)
    err = 1e-4 * rng.standard_normal(t.size) + 1e-4 * np.sin(2 * np.pi * 0.3 * t)  # a slow error as large as noise
    stats = _diagnostics._residual_stats(err, None)  # noise estimated from differences: the slow part cancels
    assert abs(stats["noise_estimate"] / 1e-4 - 1) < 0.05
    assert stats["autocorrelation"]["1"] > 0.2 and stats["se_inflation"] > 1.2
    flagged, note = _diagnostics.mismatch({"E3": {"position": stats}})
    assert flagged and "E3/position" in note and "understate" in note


def test_a_kink_in_a_valley_is_left_for_the_lower_point_beyond_it(monkeypatch):
    # A valley whose weak combination w = (θ₀ − θ₁)/√2 the data determine 40× worse than θ₀ + θ₁, with a wall across
    # it (the cost 10 higher for w in (−1.5, 0.3) standard errors of w, as a stick-slip event appearing raises a rig's
    # cost): from w = −4 the damped steps and the one-parameter probes stop at the wall's near edge, 1.125 above the
    # smooth minimum, a probed minimum; the least determined direction probed 1–3 standard errors out finds the lower
    # point beyond the wall, and the fit ends at the far edge, 0.045 above it (unseen rig901: a stall 105 above).
    # Without the escapes (`ESCAPES` = 0 tries) the same fit stays at the near edge.
    rng = np.random.default_rng(5)
    q = np.linalg.qr(rng.normal(size=(200, 2)))[0]
    e = rng.normal(size=200)
    rest = e - q @ (q.T @ e)
    rot = np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2.0)  # θ → (strong, weak) coordinates
    a = q * [40.0, 1.0] @ rot
    smooth = np.linalg.lstsq(a, -e, rcond=None)[0]
    floor = 0.5 * float(np.sum((a @ smooth + e) ** 2))

    def weak(t):
        return (rot @ (t - smooth))[1]  # in w's standard errors

    def residuals(t):
        return a @ t + e + (0.05 * rest if -1.5 < weak(t) < 0.3 else 0.0)

    start = smooth + rot.T @ np.array([0.3, -4.0])
    monkeypatch.setattr(S, "ESCAPES", 0)
    stuck = _run(residuals, lambda t: (residuals(t), a), start, max_steps=300)
    assert stuck.reason == S.PROBED_MINIMUM and stuck.escapes == 0
    assert weak(stuck.theta) == pytest.approx(-1.5, abs=1e-3) and stuck.cost - floor == pytest.approx(1.125, abs=2e-3)
    monkeypatch.undo()
    out = _run(residuals, lambda t: (residuals(t), a), start, max_steps=300)
    assert out.reason == S.PROBED_MINIMUM and 1 <= out.escapes <= E.ESCAPES  # tries: the one that moved, and more
    assert weak(out.theta) == pytest.approx(0.3, abs=1e-3) and out.cost - floor == pytest.approx(0.045, abs=2e-3)
    # the escape's move is a row of its own in the history, accepted, at a lower cost than the kink's
    assert min(row[1] for row in out.history) == out.cost < stuck.cost


def test_an_escape_probes_the_least_determined_directions_a_hair_off_a_kink():
    # escape() takes its directions and standard errors from the Jacobian a hair off the point (the point's own is
    # that of an event's edge: here 1e5× in one column, which would make that parameter's standard error 1e5× too
    # small and its probes no move at all), probes ±1, ±2, ±3 standard errors along each, and returns the lowest
    # point found; at a smooth minimum none is lower.
    a = np.diag([10.0, 0.1])  # standard errors 0.1 and 10

    def residuals(t):
        return a @ (t - [0.0, 25.0])  # θ₁ 2.5 standard errors from its best value

    def jacobian_at(t):
        return residuals(t), a

    cost = 0.5 * 2.5**2
    gain, point = E.escape(np.zeros(2), cost, a * [1.0, 1e5], residuals, jacobian_at)
    np.testing.assert_allclose(point, [0.0, 20.0])  # +2 standard errors: the lowest of the probes
    assert gain == pytest.approx(cost - 0.5 * 0.5**2)
    gain, _ = E.escape(np.array([0.0, 25.0]), 0.0, a, residuals, jacobian_at)
    assert gain == pytest.approx(-0.5)  # the best probe: one standard error out, the cost ½ higher
