"""The host-side Levenberg-Marquardt of `pamjax.fit` (`pamjax._fit.lm`) on problems with known answers, its stopping
reasons, and the residual diagnostics (`pamjax._fit.diagnostics`)."""

import numpy as np
import pytest

from pamjax._fit import diagnostics as _diagnostics, lm as _lm


def _run(residuals, jacobian, theta, max_steps=200, **kw):
    r0, j0 = jacobian(theta)
    state = _lm.start(theta, r0, j0)
    opts = dict(ftol=1e-12, xtol=1e-12, gtol=1e-12, stall_steps=8) | kw
    while not state.done and state.step < max_steps:
        state = _lm.iterate(state, residuals, jacobian, **opts)
    return state


def _rosenbrock():
    def residuals(t):
        return np.array([10.0 * (t[1] - t[0] ** 2), 1.0 - t[0]])

    def jacobian(t):
        return residuals(t), np.array([[-20.0 * t[0], 10.0], [-1.0, 0.0]])

    return residuals, jacobian


@pytest.mark.parametrize("geodesic", [True, False])
def test_rosenbrock_valley_reaches_the_minimum(geodesic):
    residuals, jacobian = _rosenbrock()
    state = _run(residuals, jacobian, np.array([-1.2, 1.0]), geodesic=geodesic)
    assert state.done and state.reason.startswith("converged"), state.reason
    np.testing.assert_allclose(state.theta, [1.0, 1.0], atol=1e-8)


def test_geodesic_acceleration_follows_a_curved_valley_in_fewer_steps():
    # Transtrum & Sethna's point: on a narrow curved valley the accelerated steps need fewer iterations.
    residuals, jacobian = _rosenbrock()
    plain = _run(residuals, jacobian, np.array([-1.2, 1.0]), geodesic=False)
    geo = _run(residuals, jacobian, np.array([-1.2, 1.0]), geodesic=True)
    assert geo.accepted < plain.accepted


def test_linear_problem_converges_in_one_accepted_step_to_lstsq():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(40, 3)), rng.normal(size=40)

    def residuals(t):
        return a @ t - b

    def jacobian(t):
        return residuals(t), a

    state = _run(residuals, jacobian, np.zeros(3))
    np.testing.assert_allclose(state.theta, np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-6)
    assert state.reason.startswith("converged")


def test_failed_trials_are_rejected_not_fatal():
    # The residuals are undefined (None: a failed solve) beyond t = 2; the minimum at t = 3 lies beyond, so the
    # fit must end near the boundary without ever accepting an undefined point.
    def residuals(t):
        return None if t[0] > 2.0 else np.array([t[0] - 3.0])

    def jacobian(t):
        return residuals(t), np.array([[1.0]])

    state = _run(residuals, jacobian, np.array([0.0]), max_steps=60)
    assert 1.9 < state.theta[0] <= 2.0
    assert any(not accepted for *_, accepted in state.history)


def test_a_wrong_jacobian_stalls_and_the_check_says_so():
    # The Jacobian's sign is wrong: every step goes uphill. The fit must not claim convergence; it stalls, and the
    # Jacobian check measures a disagreement of order one.
    def residuals(t):
        return np.array([t[0] - 3.0, 2.0 * (t[1] + 1.0)])

    def jacobian(t):
        return residuals(t), -np.diag([1.0, 2.0])

    state = _run(residuals, jacobian, np.array([0.0, 0.0]), max_steps=1000)
    assert state.done and state.reason == "stalled", state.reason
    assert state.accepted == 0 and state.restarts == _lm.PROBE_RESTARTS  # probes found lower points; no step did
    assert _lm.jacobian_check(state, residuals) > 0.5


def test_a_minimum_where_the_cost_is_not_smooth_is_converged_not_stalled():
    # A noise-scaled problem (200 residuals, cost ≈ 100) whose cost jumps up where θ₀ crosses k, half a standard
    # error short of the smooth optimum (as a stick-slip phase appearing makes a bench cost jump). The Jacobian is
    # the smooth one, so it keeps promising a decrease beyond k that every step there refuses: the damped steps end
    # at the jump, with θ₁ (started 2 standard errors off) not yet at its optimum. The probe finds the lower point
    # along θ₁ and the iteration goes on from there; the next probe finds none: converged, not stalled.
    rng = np.random.default_rng(3)
    a = np.linalg.qr(rng.normal(size=(200, 2)))[0] * [8.0, 3.0]  # orthogonal columns: θ₁ is free of the jump
    e = rng.normal(size=200)
    smooth = np.linalg.lstsq(a, -e, rcond=None)[0]  # the minimum of ½‖a θ + e‖²
    se0 = np.sqrt(np.linalg.inv(a.T @ a)[0, 0])
    k = smooth[0] - 0.5 * se0
    rest = a @ smooth + e  # orthogonal to a's columns: beyond k the cost is higher by a constant (1.05² − 1)·½‖rest‖²

    def residuals(t):
        return a @ t + e + (0.05 * rest if t[0] > k else 0.0)

    def jacobian(t):
        return residuals(t), a

    state = _run(residuals, jacobian, np.array([smooth[0] - 3 * se0, smooth[1] + 2 / 3.0]), max_steps=300)
    assert state.done and state.reason == _lm.PROBED_MINIMUM, state.reason
    assert k - 0.01 * se0 < state.theta[0] <= k and state.restarts >= 1
    np.testing.assert_allclose(state.theta[1], smooth[1], atol=1e-3 / 3.0)
    assert _lm.probe(state, residuals)[0] <= 1e-6 * state.cost


def test_a_fit_crawling_at_a_minimum_is_probed_and_converged():
    # Tiny steps accepted between rejections never make `stall_steps` rejections in a row (two bench fits from the
    # presets ran to max_steps so, gaining 1e-9 of the cost per step). Where CRAWL_STEPS iterations together gained
    # less than POTENTIAL_TOL of the cost, the probe decides: here, at the minimum of a quadratic, converged.
    rng = np.random.default_rng(4)
    a, e = rng.normal(size=(50, 2)), rng.normal(size=50)

    def residuals(t):
        return a @ t + e

    def jacobian(t):
        return residuals(t), a

    best = np.linalg.lstsq(a, -e, rcond=None)[0]
    state = _lm.start(best, *jacobian(best))
    assert not _lm._crawling(state)
    state.history = [[k, state.cost * (1 + 1e-9 * (20 - k)), state.damping, k % 2 == 0] for k in range(20)]
    state.accepted, state.step = 10, 19
    assert _lm._crawling(state)
    state = _lm.iterate(state, residuals, jacobian, ftol=0.0, xtol=0.0, gtol=0.0, stall_steps=8)
    assert state.done and state.reason == _lm.PROBED_MINIMUM, state.reason
    state.history[-1 - _lm.CRAWL_STEPS][1] = state.cost * 1.01  # a real gain over the window: not crawling
    assert not _lm._crawling(state)


def test_state_round_trips_through_arrays():
    residuals, jacobian = _rosenbrock()
    state = _run(residuals, jacobian, np.array([-1.2, 1.0]), max_steps=5)
    again = _lm.LMState.from_arrays(state.arrays())
    for a, b in zip(_lm.LMState.__dataclass_fields__, _lm.LMState.__dataclass_fields__):
        va, vb = getattr(state, a), getattr(again, b)
        if isinstance(va, np.ndarray):
            np.testing.assert_array_equal(va, vb)
        else:
            assert va == vb, a


# --- residual diagnostics -------------------------------------------------------------------------------------
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
