"""pamjax's least-squares solver: Levenberg-Marquardt as an optimistix `AbstractGaussNewton` with its own parts:

- `ScaledDampedDescent` (an `optimistix.AbstractDescent`): the damped Gauss-Newton step through an SVD of the
  Jacobian scaled by Moré's (1978) D, the running maximum of its column norms (the step is invariant to the units of
  θ), and Transtrum & Sethna's geodesic acceleration (2012, "Improvements to the Levenberg-Marquardt algorithm for
  nonlinear least-squares minimization"): the damped solution for the residuals' second directional derivative
  along the velocity v, r_vv ≈ (2/h)((r(θ + h v) − r)/h − J v), h = 0.1, one extra residual evaluation. It bends the
  step along a curved valley (force law, volume and friction trading off in a joint fit), where plain steps crawl;
  a step whose acceleration is large against its velocity (2‖a‖/‖v‖ > 0.75) is not trusted (rejected, more damping).
- `NielsenDamping` (an `optimistix.AbstractSearch`): Nielsen (1999) / Madsen, Nielsen & Tingleff, "Methods for
  non-linear least squares problems" (2004), alg. 3.16: λ₀ = τ max(1, diag DJᵀJD) = τ, λ ← λ max(1/3, 1 − (2ρ − 1)³)
  after an accepted step (ρ > 1e-4: actual over predicted decrease), λ ← λν, ν ← 2ν after a rejected one (a trial
  whose residuals are not finite, a failed solve, too; or whose Jacobian cannot be factored: not finite, or overflows).

A step evaluates the residuals at the trial point (and at θ + h v) and the Jacobian only where the trial is accepted
(optimistix's `LevenbergMarquardt` linearises at every trial: several residual evaluations through a fit's solves).
Stopping (`REASONS`): "converged" at a stationary point (an undamped step could gain at most `POTENTIAL_TOL` of the
cost) with the relative cost decrease, actual and predicted, below `ftol` or the scaled step below `xtol`, or every
column of J orthogonal to r within `gtol` (MINPACK's tests); "stalled" after `stall_steps` rejections in a row with
the predicted decrease above `ftol` and the step below `xtol` — unless probing the cost one parameter at a time
(`probe`) finds no decrease either: then the point is a minimum of a cost that is not smooth there (stick-slip events
move with θ), "converged"; where a probe finds a lower point the iteration goes on from it (`PROBE_RESTARTS` times at
most); where it finds none or only a crawl's gain, on the host, from a point along the least determined directions
lower by more than `ESCAPE_GAIN` of the cost (`pamjax._fit.escape`; `ESCAPES` tries). The probe also runs where
`CRAWL_STEPS` iterations together gained less than `POTENTIAL_TOL` of the cost. Rejections alone never stop an
iteration before its first accepted step.

**Two ways to run it**, one code: traced, as any optimistix solver (`optx.least_squares(fn, LevenbergMarquardt(),
y0)`; the Jacobian by `jax.jacfwd` in a `lax.cond` on acceptance); or from the host, as `pamjax.fit` does
(`pamjax._fit.drive`): `init`/`step`/`terminate` called from Python with a NumPy `y` and an `fn` returning NumPy
residuals (non-finite where the model fails) with `fn.jacobian(y, args)` → (residuals, Jacobian), a fit's two
compiled programs; the small linear algebra (an SVD of m × n, n ≤ ~50) runs in NumPy, no optimiser program compiled.
"""

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree

from .._core.custom_types import ArrayLike
from .._core.errors import PamjaxInputError, check_count
from .descent import Factors, ScaledDampedDescent, array_module, flatten, on_host
from .escape import ESCAPE_BELOW, ESCAPE_GAIN, ESCAPES, escape

# A fit counts as converged (by ftol or xtol) only where an undamped Gauss-Newton step could gain at most this
# fraction of the cost: a heavily damped step is small and gains little anywhere, which alone proves nothing (a start
# of the reliability benchmark stopped so at 8,800× its optimum cost).
POTENTIAL_TOL = 1e-6
ACCEPT_RATIO = 1e-4  # ρ above which a trial is accepted (Nielsen's alg. 3.16 accepts any ρ > 0; 1e-4 as MINPACK)
TAU = 1e-3  # λ₀ = τ max(1, diag DJᵀJD) (Madsen, Nielsen & Tingleff 2004, sec. 3.2: 1e-3 unless x₀ is known close)
GEODESIC_H = 0.1  # finite-difference step of r_vv along the velocity (Transtrum & Sethna 2012, sec. IV: h = 0.1)
# The probes, in conditional standard errors (the move of one parameter, the others fixed, that the local model says
# raises the cost by ½): small enough to see a descent the damped steps missed, large enough to step over the cost's
# jumps at stick-slip events (~1e-7 of the cost on the bench problems).
PROBE_STEPS = (0.1, 0.01)
PROBE_RESTARTS = 3  # moves to a lower probe point before a fit is called stalled
CRAWL_STEPS = 16  # iterations over which a fit that gains less than POTENTIAL_TOL of its cost is probed
PROBED_MINIMUM = ("converged: no parameter moved by ±0.1 or ±0.01 of its conditional standard error lowers the cost "
                  "by more than 1e-6 of it (a minimum where the cost is not smooth, e.g. where a stick-slip phase "
                  "begins or ends; the damped steps had stopped)")
REASONS = ("",  # still iterating (or stopped by the step budget)
           "converged: relative cost decrease below ftol", "converged: step below xtol",
           "converged: gradient orthogonal to the residuals (gtol)", "converged: no predicted decrease above ftol",
           PROBED_MINIMUM, "stalled", "converged: gradient orthogonal to the residuals at the start (gtol)",
           "failed: the residuals or their Jacobian are not finite at the start")
_FTOL, _XTOL, _GTOL, _NO_DECREASE, _PROBED, _STALLED, _GTOL_START, _NOT_FINITE_START = range(1, 9)
_FAILED = (_STALLED, _NOT_FINITE_START)  # the reasons that end a solve unsuccessfully


# --- running on the host (NumPy) or traced (jax.numpy) ---------------------------------------------------------------
def _cond(host, pred, true_fn, false_fn):
    """`lax.cond` when traced; a Python branch on the host (only the branch taken evaluates the model)."""
    if host:
        return true_fn() if bool(pred) else false_fn()
    return jax.lax.cond(pred, true_fn, false_fn)


def _residual(fn, y, args, host, unravel):
    """(residuals as one vector, aux) at y."""
    out, aux = fn(unravel(y), args)
    return flatten(out, host), aux


def _jacobian(fn, y, args, host, unravel):
    """(residuals, Jacobian (m × n), aux) at y: `fn.jacobian` on the host, forward mode when traced."""
    if host:
        if not callable(getattr(fn, "jacobian", None)):
            raise PamjaxInputError("fn: run on the host (a NumPy y), pamjax's LevenbergMarquardt needs "
                                   "fn.jacobian(y, args) -> (residuals, Jacobian)")
        r, jac = fn.jacobian(y, args)
        r = np.asarray(r, dtype=float).ravel()
        return r, np.asarray(jac, dtype=float).reshape(r.size, -1), None

    def f(t):
        r, aux = _residual(fn, t, args, False, unravel)
        return r, (r, aux)

    jac, (r, aux) = jax.jacfwd(f, has_aux=True)(y)
    return r, jac, aux


def _all_finite(xp, r):
    return xp.all(xp.isfinite(r))


def _cost(r):
    return 0.5 * (r @ r)


def gradient_cosine(jacobian, residual):
    """max over columns of |Jᵢ·r| / (‖Jᵢ‖ ‖r‖): 0 at a stationary point (MINPACK's gtol test); inf where a norm is
    not finite (NaN residuals are no stationary point: they read as 0, "orthogonal")."""
    xp = array_module(on_host(jacobian))
    norms = xp.linalg.norm(jacobian, axis=0) * xp.linalg.norm(residual)
    cos = xp.abs(jacobian.T @ residual) / xp.where(norms > 0, norms, 1.0)
    return xp.max(xp.where(xp.isfinite(norms), xp.where(norms > 0, cos, 0.0), xp.inf), initial=0.0)


# --- the search: Nielsen's damping update ----------------------------------------------------------------------------
class Damping(eqx.Module):
    """The search's state: the damping λ and its growth factor ν."""

    damping: ArrayLike
    growth: ArrayLike


class NielsenDamping(optx.AbstractSearch):
    """Accept a trial where ρ = actual / predicted decrease > `accept_ratio`; then λ ← λ max(1/3, 1 − (2ρ − 1)³),
    ν ← 2; else λ ← λν, ν ← 2ν (Nielsen 1999). As an optimistix search (`step`) it returns step_size = 1/λ and
    predicts the decrease of the trial step from the Jacobian (`optimistix.ClassicalTrustRegion`'s model); pamjax's
    `LevenbergMarquardt` calls `decide` with the velocity's prediction instead."""

    tau: float = TAU
    accept_ratio: float = ACCEPT_RATIO

    def init(self, y, f_info_struct):
        return Damping(jnp.array(jnp.nan), jnp.array(2.0))

    def start(self, scaled_jacobian):
        """λ₀ = τ max(1, largest diagonal entry of (JD⁻¹)ᵀ(JD⁻¹))."""
        xp = array_module(on_host(scaled_jacobian))
        largest = xp.max(xp.sum(scaled_jacobian * scaled_jacobian, axis=0), initial=1.0)
        return Damping(self.tau * largest, xp.asarray(2.0))

    def decide(self, ok, actual, predicted, state):
        """(accept, new state) for a trial whose cost fell by `actual` where the model predicted `predicted`."""
        xp = array_module(on_host((predicted, state.damping)))
        positive = predicted > 0
        rho = xp.where(positive, actual / xp.where(positive, predicted, 1.0), -xp.inf)
        accept = ok & (rho > self.accept_ratio)
        shrink = xp.maximum(1.0 / 3.0, 1.0 - (2.0 * xp.where(accept, rho, 0.0) - 1.0) ** 3)
        damping = xp.where(accept, state.damping * shrink, state.damping * state.growth)
        growth = xp.where(accept, 2.0, 2.0 * state.growth)
        return accept, Damping(damping, growth)

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        def fresh():
            jac = f_eval_info.jac.as_matrix()
            norms = jnp.linalg.norm(jac, axis=0)
            return self.start(jac / jnp.where(norms > 0, norms, 1.0))

        residual = flatten(f_info.residual, False)
        diff = jnp.ravel(y_eval - y)
        fitted = f_info.jac.as_matrix().reshape(residual.size, -1) @ diff + residual
        predicted = 0.5 * (residual @ residual - fitted @ fitted)
        actual = f_info.as_min() - f_eval_info.as_min()
        accept, new = self.decide(jnp.isfinite(actual), jnp.where(jnp.isfinite(actual), actual, -jnp.inf), predicted,
                                  state)
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(first_step, a, b), fresh(), new)
        return 1.0 / new.damping, accept | first_step, optx.RESULTS.successful, new


# --- the solver ----------------------------------------------------------------------------------------------------
class State(eqx.Module):
    """Everything `LevenbergMarquardt` carries between steps (a fit's checkpoint holds it, with θ and the history).
    `rows` counts the history rows, `recent` holds the cost of the last `CRAWL_STEPS` + 1 of them (the crawl rule),
    `last_rows` the rows this step added (one, or two where a probe moved the fit: [step, cost, damping, accepted])."""

    residual: ArrayLike
    jacobian: ArrayLike
    cost: ArrayLike
    initial_cost: ArrayLike
    factors: Factors
    search: Damping
    step: ArrayLike
    accepted: ArrayLike
    rejected_in_row: ArrayLike
    restarts: ArrayLike
    escapes: ArrayLike
    done: ArrayLike
    reason: ArrayLike
    rows: ArrayLike
    recent: ArrayLike
    last_rows: ArrayLike
    aux: object


def _noop_verbose(**kwargs):
    return None


class LevenbergMarquardt(optx.AbstractGaussNewton):
    """pamjax's Levenberg-Marquardt (the module docstring says what it does): an optimistix least-squares solver,
    the default of `pamjax.fit` (which runs it from the host around its two compiled programs), and usable in
    `optimistix.least_squares` like any other.

    **Arguments:**

    - `ftol`, `xtol`, `gtol`: convergence on the relative cost decrease (actual and predicted), on the scaled step
      (relative to the scaled θ), and on the gradient's cosine with the residuals (MINPACK's tests); optimistix's
      `rtol` and `atol` are `ftol` and `xtol`.
    - `stall_steps`: rejected trials in a row after which an iteration whose step has shrunk below `xtol` while
      the local model still promises a decrease is probed (then "converged" at a non-smooth minimum, or "stalled").
    - `geodesic`: the geodesic acceleration (default on; off: plain Levenberg-Marquardt, one residual evaluation
      fewer per step).

    With `optimistix.least_squares`, a stall, or residuals or a Jacobian not finite at the start (where optimistix's
    own solver fails too), ends the solve with `RESULTS.nonlinear_divergence` (`throw=True`: an error); `sol.stats`
    holds `reason` (an index into `pamjax._fit.solver.REASONS`) and `num_accepted_steps`.
    """

    rtol: float
    atol: float
    norm: Callable
    descent: ScaledDampedDescent
    search: NielsenDamping
    verbose: Callable
    gtol: float
    stall_steps: int = eqx.field(static=True)
    geodesic: bool = eqx.field(static=True)

    def __init__(self, ftol: float | int = 1e-10, xtol: float | int = 1e-10, gtol: float | int = 1e-10,
                 stall_steps: int = 8, geodesic: bool = True):
        for label, tol in (("ftol", ftol), ("xtol", xtol), ("gtol", gtol)):
            if isinstance(tol, bool) or not (isinstance(tol, (int, float)) and 0 <= tol < 1):
                raise PamjaxInputError(f"{label} must be a number in [0, 1), got {tol!r}")
        check_count(stall_steps, "stall_steps")
        if not isinstance(geodesic, bool):
            raise PamjaxInputError(f"geodesic must be True or False, got {geodesic!r}")
        self.rtol, self.atol, self.gtol = float(ftol), float(xtol), float(gtol)
        self.norm = optx.two_norm
        self.descent, self.search = ScaledDampedDescent(), NielsenDamping()
        self.verbose = _noop_verbose
        self.stall_steps, self.geodesic = int(stall_steps), geodesic

    def fingerprint(self):
        """What a checkpoint records of this solver (`pamjax._files.fingerprint`): whether the acceleration is on (the
        tolerances and `stall_steps` only decide where the same iterations stop). The text is the host
        Levenberg-Marquardt's that this solver replaced, which its checkpoints carry: they resume here."""
        print_ = {"class": "pamjax Levenberg-Marquardt (pamjax._fit.lm)"}
        return print_ if self.geodesic else {**print_, "geodesic": "False"}

    ftol = property(lambda self: self.rtol, doc="`ftol` (optimistix's `rtol`)")
    xtol = property(lambda self: self.atol, doc="`xtol` (optimistix's `atol`)")

    # -- optimistix's interface ----------------------------------------------------------------------------------
    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        host = on_host(y)
        xp = array_module(host)
        flat, unravel = _ravel(y, host)
        r, jac, aux = _jacobian(fn, flat, args, host, unravel)
        # a start whose residuals or Jacobian are not finite is a failure, not a stationary point: NaN norms made the
        # gradient's cosine 0 and the solve "converged" after 0 steps (optimistix's own solver fails there). It is
        # factored as zeros (NumPy's SVD raises on NaN) and ends at once.
        finite = _all_finite(xp, r) & _all_finite(xp, jac)
        factors = self.descent.factor(xp.where(finite, r, 0.0), xp.where(finite, jac, 0.0), xp.zeros(flat.size))
        search = self.search.start(xp.where(finite, jac, 0.0) / factors.scale)
        cost = _cost(r)
        reason = xp.where(finite, xp.where(gradient_cosine(jac, r) <= self.gtol, _GTOL_START, 0), _NOT_FINITE_START)
        first = xp.stack([xp.asarray(0.0), cost, search.damping, xp.asarray(1.0)])
        return State(
            residual=r, jacobian=jac, cost=cost, initial_cost=cost, factors=factors, search=search,
            step=_int(xp, 0), accepted=_int(xp, 0), rejected_in_row=_int(xp, 0), restarts=_int(xp, 0),
            escapes=_int(xp, 0), done=xp.asarray(reason != 0), reason=reason, rows=_int(xp, 1),
            recent=xp.concatenate([xp.full(CRAWL_STEPS, xp.nan), xp.reshape(cost, (1,))]),
            last_rows=xp.stack([first, xp.full(4, xp.nan)]), aux=aux)

    def step(self, fn, y, args, options, state, tags):
        host = on_host(y)
        xp = array_module(host)
        flat, unravel = _ravel(y, host)
        with np.errstate(all="ignore"):
            new_flat, state = self._iterate(fn, flat, args, state, host, xp, unravel)
        return unravel(new_flat), state, state.aux

    def terminate(self, fn, y, args, options, state, tags):
        if on_host(y):
            failed = int(state.reason) in _FAILED
            return bool(state.done), optx.RESULTS.nonlinear_divergence if failed else optx.RESULTS.successful
        failed = (state.reason == _STALLED) | (state.reason == _NOT_FINITE_START)
        return state.done, optx.RESULTS.where(failed, optx.RESULTS.nonlinear_divergence, optx.RESULTS.successful)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {"num_accepted_steps": state.accepted, "reason": state.reason}

    # -- one iteration -------------------------------------------------------------------------------------------
    def _iterate(self, fn, y, args, state, host, xp, unravel):
        f, lam = state.factors, state.search.damping
        r, jac, cost = state.residual, state.jacobian, state.cost
        velocity, coef, filt, predicted, size, potential = self.descent.damped(lam, f)
        step, trusted = velocity, xp.asarray(True)
        if self.geodesic:
            r_h, _ = _residual(fn, y + GEODESIC_H * velocity, args, host, unravel)
            rvv = (2.0 / GEODESIC_H) * ((r_h - r) / GEODESIC_H - jac @ velocity)
            accelerated, trusted_acc = self.descent.accelerate(coef, filt, rvv, f)
            finite = _all_finite(xp, r_h)  # a failed solve at θ + h v: the plain step, trusted
            step = xp.where(finite, accelerated, velocity)
            trusted = xp.where(finite, trusted_acc, True)
        trial = y + step
        r_trial, aux_trial = _cond(host, trusted, lambda: _residual(fn, trial, args, host, unravel),
                                   lambda: (xp.full_like(r, xp.nan), state.aux))
        ok = trusted & _all_finite(xp, r_trial)
        actual = cost - xp.where(ok, _cost(r_trial), xp.inf)
        accept, search = self.search.decide(ok, actual, predicted, state.search)
        refused = self.search.decide(xp.asarray(False), actual, predicted, state.search)[1]  # as a failed trial
        count = state.step + 1
        theta_norm = xp.linalg.norm(y * f.scale)
        # the tests below may only end a fit at a stationary point (or on a zero-residual problem, at its zero)
        stationary = (potential <= POTENTIAL_TOL * cost) | (cost <= 1e-20 * state.initial_cost)
        small = size <= self.xtol * (theta_norm + self.xtol)

        def accepted():
            r_new, j_new, aux_new = _jacobian(fn, trial, args, host, unravel)
            # a Jacobian that cannot be factored refuses the trial (a column norm not finite: an entry, or overflow)
            usable = _all_finite(xp, xp.linalg.norm(j_new, axis=0))
            def take():
                cost_new = _cost(r_new)
                reason = xp.where(
                    stationary & (xp.abs(actual) <= self.ftol * cost_new) & (predicted <= self.ftol * cost_new), _FTOL,
                    xp.where(stationary & small, _XTOL, xp.where(gradient_cosine(j_new, r_new) <= self.gtol, _GTOL, 0)))
                return (trial, r_new, j_new, cost_new, self.descent.factor(r_new, j_new, f.scale),
                        aux_trial if host else aux_new, state.accepted + 1, _int(xp, 0), reason, xp.asarray(False),
                        search)
            return _cond(host, usable, take, lambda: rejected(refused))

        def rejected(after=search):
            # the local model promises no decrease worth having: a minimum to the solver's precision
            reason = xp.where(stationary & (predicted <= self.ftol * cost) & (state.accepted > 0), _NO_DECREASE, 0)
            rejected_in_row = state.rejected_in_row + 1
            stall = (reason == 0) & (rejected_in_row >= self.stall_steps) & small
            return y, r, jac, cost, f, state.aux, state.accepted, rejected_in_row, reason, stall, after

        y_new, r, jac, cost, f, aux, n_accepted, rejected_in_row, reason, stall, search = _cond(host, accept, accepted,
                                                                                                 rejected)
        row = xp.stack([xp.asarray(count, dtype=float), cost, search.damping,
                        xp.asarray(n_accepted > state.accepted, dtype=float)])
        recent = xp.concatenate([state.recent[1:], xp.reshape(cost, (1,))])
        rows = state.rows + 1
        crawling = (reason == 0) & (n_accepted > 0) & (rows > CRAWL_STEPS) & (recent[0] - cost <= POTENTIAL_TOL * cost)
        base = State(residual=r, jacobian=jac, cost=cost, initial_cost=state.initial_cost, factors=f, search=search,
                     step=count, accepted=n_accepted, rejected_in_row=rejected_in_row, restarts=state.restarts,
                     escapes=state.escapes, done=reason != 0, reason=reason, rows=rows, recent=recent,
                     last_rows=xp.stack([row, xp.full(4, xp.nan)]), aux=aux)
        return _cond(host, stall | crawling, lambda: self._stalled_or_minimum(fn, y_new, args, base, host, xp, unravel),
                     lambda: (y_new, base))

    def _stalled_or_minimum(self, fn, y, args, state, host, xp, unravel):
        """Where the damped steps have stopped gaining: the Jacobian may describe the cost badly only because the
        cost is not smooth here (a stick-slip phase begins or ends as θ moves), at a minimum all the same. Probe the
        cost: a lower point → go on from it with the start's damping (`PROBE_RESTARTS` times at most). Where it
        finds none, only a crawl's gain (≤ `ESCAPE_BELOW` of the cost) or no restarts are left, on the host the least
        determined directions are probed too (`pamjax._fit.escape`, `ESCAPES` tries), and a point lower by more than
        `ESCAPE_GAIN` of the cost (and than the probe's) is gone on from; else a lower probe point, else stop:
        converged at a probed minimum, or "stalled"."""
        gain, point = probe(fn, y, args, state.jacobian, state.cost, host=host, unravel=unravel)
        minimum = gain <= POTENTIAL_TOL * state.cost

        def stop():
            reason = xp.where(minimum, _PROBED, _STALLED)
            return y, dataclasses.replace(state, done=xp.asarray(True), reason=reason)

        def restart(point=point, escaped=False):
            r, jac, aux = _jacobian(fn, point, args, host, unravel)
            fresh = xp.linalg.norm(jac, axis=0)
            search = self.search.start(jac / xp.where(fresh > 0, fresh, 1.0))
            cost = _cost(r)
            row = xp.stack([state.last_rows[0, 0], cost, search.damping, xp.asarray(1.0)])
            return point, dataclasses.replace(
                state, residual=r, jacobian=jac, cost=cost, factors=self.descent.factor(r, jac, state.factors.scale),
                search=search, rejected_in_row=_int(xp, 0), restarts=_int(xp, 0) if escaped else state.restarts + 1,
                rows=state.rows + 1,
                recent=xp.concatenate([state.recent[1:], xp.reshape(cost, (1,))]),
                last_rows=xp.stack([state.last_rows[0], row]), aux=state.aux if host else aux)

        if not host:
            return jax.lax.cond(minimum | (state.restarts >= PROBE_RESTARTS), stop, restart)
        spent = state.restarts >= PROBE_RESTARTS
        if (gain <= ESCAPE_BELOW * state.cost or spent) and state.escapes < ESCAPES:  # crawling on, or stopping
            lower, there = escape(y, float(state.cost), state.jacobian,
                                  lambda t: _residual(fn, t, args, True, unravel)[0],
                                  lambda t: _jacobian(fn, t, args, True, unravel)[:2])
            state = dataclasses.replace(state, escapes=state.escapes + 1)  # an attempt, found or not
            if lower > max(gain, ESCAPE_GAIN * state.cost):  # a valley worth the steps
                return restart(there, escaped=True)
        return stop() if minimum or spent else restart()


def _int(xp, value):
    return np.int64(value) if xp is np else jnp.asarray(value)


def _ravel(y, host):
    return (np.asarray(y, dtype=float).ravel(), lambda t: t) if host else ravel_pytree(y)


def probe(fn, y, args, jacobian, cost, *, host=True, unravel=lambda t: t):
    """(gain, θ): the largest cost decrease found by moving one parameter at a time by ± `PROBE_STEPS` conditional
    standard errors (1/‖Jᵢ‖ of the Jacobian's column), or at the vertex of the parabola through the cost at −0.1, 0,
    +0.1 of them along the best parameter; gain ≤ 0 at a minimum, smooth or not (4n + 1 residual evaluations, only
    where an iteration would otherwise stop as stalled). A failed solve counts as no decrease."""
    xp = array_module(host)
    norms = xp.linalg.norm(jacobian, axis=0)
    live = norms > 0
    safe = xp.where(live, norms, 1.0)
    signed = xp.asarray([f * s for f in PROBE_STEPS for s in (1.0, -1.0)])  # +0.1, −0.1, +0.01, −0.01
    n, k = y.size, signed.size
    deltas = (signed[None, :] / safe[:, None]).reshape(-1)  # parameter i, probe j at i k + j
    axis = xp.repeat(xp.arange(n), k)
    points = y[None, :] + deltas[:, None] * (axis[:, None] == xp.arange(n)[None, :])
    usable = xp.repeat(live, k)

    def gain_at(theta):
        r, _ = _residual(fn, theta, args, host, unravel)
        return xp.where(_all_finite(xp, r), cost - _cost(r), -xp.inf)

    if host:
        gains = np.array([gain_at(p) if use else -np.inf for p, use in zip(points, usable)])
    else:
        gains = xp.where(usable, jax.lax.map(gain_at, points), -xp.inf)
    best_at = xp.argmax(gains)
    best, where = gains[best_at], points[best_at]
    i = best_at // k
    up, down = -gains[i * k], -gains[i * k + 1]  # cost differences at ±0.1 from the current point
    curvature = up + down
    vertex = xp.isfinite(best) & xp.isfinite(curvature) & (curvature > 0)
    shift = 0.5 * PROBE_STEPS[0] * (down - up) / xp.where(vertex, curvature, 1.0) / safe[i]
    theta = y + xp.where(xp.arange(n) == i, shift, 0.0)
    g = _cond(host, vertex, lambda: gain_at(theta), lambda: xp.asarray(-xp.inf, dtype=float))
    better = g > best
    return xp.where(better, g, best), xp.where(better, theta, where)
