"""Levenberg-Marquardt on the host: the iteration of `pamjax.fit`, around two compiled device functions.

Each iteration needs the residuals r(θ) at a trial point and, once a trial is accepted, the Jacobian J(θ) (forward
mode through the solves). Both are compiled once per problem structure; the small linear algebra (an SVD of the
column-scaled Jacobian, n ≤ ~50 parameters) runs in NumPy. Keeping the loop on the host keeps the compiled programs
small (one residual and one Jacobian program, not an optimiser step containing both) and lets every decision be
seen and explained: why a fit stopped, whether the Jacobian agrees with the cost where steps keep failing.

The damping follows Nielsen (1999) / Madsen, Nielsen & Tingleff, "Methods for non-linear least squares problems"
(2004), alg. 3.16: λ₀ = τ max(diag JᵀJ), λ ← λ max(1/3, 1 − (2ρ − 1)³) after an accepted step, λ ← λν, ν ← 2ν after a
rejected one, with Moré's (1978) scaling D = running max of the Jacobian's column norms (the step is invariant to the
units of θ). A trial whose residuals are not finite (a failed solve) is rejected like any other. Each step carries
Transtrum & Sethna's geodesic acceleration (one extra residual evaluation, no extra Jacobian), which follows the
curved valleys of a joint fit (force law, volume and friction trading off) in a few steps where plain
Levenberg-Marquardt crawls (`_step`).

Stopping (the `reason` says which):
- "converged": at a stationary point (an undamped Gauss-Newton step could gain at most `POTENTIAL_TOL` of the
  cost), the relative cost decrease, actual and predicted, below `ftol`, or the scaled step below `xtol`; or every
  column of J orthogonal to r within `gtol` (the gradient test);
- "stalled": `stall_steps` rejections in a row with the predicted decrease still above `ftol` of the cost and the
  step already below `xtol`: the local model and the cost disagree (the Jacobian check then says by how much) —
  unless probing the cost one parameter at a time (`probe`) finds no decrease either: then the point is a minimum
  of a cost that is not smooth there (stick-slip events move with θ) and the fit is "converged"; where a probe
  finds a lower point, the iteration goes on from it (`PROBE_RESTARTS` times at most). The same probe runs where
  `CRAWL_STEPS` iterations together gained less than `POTENTIAL_TOL` of the cost (tiny steps accepted between
  rejections, so the rejections in a row never come);
- "max_steps": the iteration budget ran out.
No rule stops the fit before its first accepted step except `max_steps`: rejections only raise the damping.
"""

import dataclasses

import numpy as np

# A fit counts as converged (by ftol or xtol) only where an undamped Gauss-Newton step could gain at most this
# fraction of the cost: a heavily damped step is small and gains little anywhere, which alone proves nothing (a start
# of the reliability benchmark stopped so at 8,800× its optimum cost).
POTENTIAL_TOL = 1e-6


@dataclasses.dataclass
class LMState:
    """Everything the iteration carries (a checkpoint holds exactly this)."""

    theta: np.ndarray
    residual: np.ndarray
    jacobian: np.ndarray
    cost: float
    damping: float  # λ
    growth: float  # ν
    scale: np.ndarray  # D, Moré's running column-norm maximum
    step: int  # iterations done (trial evaluations)
    accepted: int
    rejected_in_row: int
    done: bool
    reason: str
    history: list  # [step, cost at the current point, damping, accepted]
    restarts: int = 0  # moves to a probe point after a stall (`probe`)

    def arrays(self):
        """The numeric fields as a flat dict of arrays (for checkpoints)."""
        return dict(theta=self.theta, residual=self.residual, jacobian=self.jacobian,
                    scalars=np.asarray([self.cost, self.damping, self.growth], dtype=float), scale=self.scale,
                    counters=np.asarray([self.step, self.accepted, self.rejected_in_row, int(self.done),
                                         self.restarts]),
                    reason=np.asarray(self.reason), history=np.asarray(self.history, dtype=float).reshape(-1, 4))

    @classmethod
    def from_arrays(cls, a):
        cost, damping, growth = (float(v) for v in a["scalars"])
        step, accepted, rejected, done, *rest = (int(v) for v in a["counters"])  # checkpoints before restarts: 4
        history = [[int(s), float(c), float(z), bool(acc)] for s, c, z, acc in np.asarray(a["history"])]
        return cls(np.asarray(a["theta"]), np.asarray(a["residual"]), np.asarray(a["jacobian"]), cost, damping,
                   growth, np.asarray(a["scale"]), step, accepted, rejected, bool(done), str(a["reason"]), history,
                   rest[0] if rest else 0)


def _cost(r):
    return 0.5 * float(r @ r)


def start(theta, residual, jacobian, tau=1e-3):
    """The state at the start point (its residuals and Jacobian evaluated)."""
    scale = np.linalg.norm(jacobian, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    scaled = jacobian / scale
    damping = tau * float(np.max(np.sum(scaled * scaled, axis=0), initial=1.0))
    cost = _cost(residual)
    return LMState(np.asarray(theta, float), residual, jacobian, cost, damping, 2.0, scale, 0, 0, 0, False, "",
                   [[0, cost, damping, True]])


def _step(state, residuals, geodesic):
    """The damped Gauss-Newton step from the current point, its predicted cost decrease and scaled size, and
    whether the geodesic acceleration was within its bound.

    With `geodesic`, the step is v + a/2 with the geodesic acceleration a of Transtrum & Sethna (2012,
    "Improvements to the Levenberg-Marquardt algorithm for nonlinear least-squares minimization"): the damped
    solution for the residuals' second directional derivative along v, r_vv ≈ (2/h)((r(θ + h v) − r)/h − J v),
    h = 0.1, one extra residual evaluation. It bends the step along a curved valley, where plain steps crawl; a
    step whose acceleration is large against its velocity (2‖a‖/‖v‖ > 0.75) is not trusted (rejected, more damping).
    """
    scaled = state.jacobian / state.scale
    u, s, vt = np.linalg.svd(scaled, full_matrices=False)
    c = u.T @ state.residual
    filt = s / (s * s + state.damping)
    coef = -filt * c  # the scaled velocity in the right singular basis
    velocity = (vt.T @ coef) / state.scale
    # The decrease the local linear model predicts for the velocity: the yardstick of the acceptance ratio and of
    # the convergence tests (the acceleration's own linear prediction can be negative on a curved valley).
    predicted = 0.5 * float(c @ c - (c + s * coef) @ (c + s * coef))
    size = float(np.linalg.norm(coef))
    potential = 0.5 * float(c @ c)  # what an undamped Gauss-Newton step could still gain: ~0 at a minimum
    step, ok = velocity, True
    if geodesic:
        h = 0.1
        probe = residuals(state.theta + h * velocity)
        if probe is not None:
            rvv = (2.0 / h) * ((probe - state.residual) / h - state.jacobian @ velocity)
            acc = -filt * (u.T @ rvv)
            ok = 2.0 * float(np.linalg.norm(acc)) <= 0.75 * float(np.linalg.norm(coef))
            step = (vt.T @ (coef + 0.5 * acc)) / state.scale
    return step, predicted, size, ok, potential


# The probes of `probe_gain`, in conditional standard errors (the move of one parameter, the others fixed, that the
# local model says raises the cost by ½): small enough to see a descent the damped steps missed, large enough to
# step over the cost's jumps at stick-slip events (~1e-7 of the cost on the bench problems).
PROBE_STEPS = (0.1, 0.01)
PROBE_RESTARTS = 3  # moves to a lower probe point before a fit is called stalled
CRAWL_STEPS = 16  # iterations over which a fit that gains less than POTENTIAL_TOL of its cost is probed
PROBED_MINIMUM = ("converged: no parameter moved by ±0.1 or ±0.01 of its conditional standard error lowers the cost "
                  "by more than 1e-6 of it (a minimum where the cost is not smooth, e.g. where a stick-slip phase "
                  "begins or ends; the damped steps had stopped)")


def probe(state, residuals):
    """(gain, θ): the largest cost decrease found by moving one parameter at a time by ± `PROBE_STEPS` conditional
    standard errors (1/‖Jᵢ‖ of the current Jacobian's column), or at the vertex of the parabola through the cost at
    −0.1, 0, +0.1 of them along the best parameter; gain ≤ 0 at a minimum, smooth or not (4n + 1 residual
    evaluations, only where a fit would otherwise stop as stalled). A failed solve counts as no decrease."""

    def gain(theta):
        r = residuals(theta)
        return state.cost - _cost(r) if r is not None and np.all(np.isfinite(r)) else -np.inf

    norms = np.linalg.norm(state.jacobian, axis=0)
    best, where, axis = -np.inf, state.theta, None
    for i in np.flatnonzero(norms > 0):
        gains = {}
        for frac in PROBE_STEPS:
            for sign in (1.0, -1.0):
                theta = state.theta.copy()
                theta[i] += sign * frac / norms[i]
                gains[sign * frac] = gain(theta)
                if gains[sign * frac] > best:
                    best, where, axis = gains[sign * frac], theta, (i, gains)
    if axis is not None:
        i, gains = axis
        h = PROBE_STEPS[0]
        up, down = -gains[h], -gains[-h]  # cost differences from the current point
        curvature = up + down
        if np.isfinite(curvature) and curvature > 0:
            theta = state.theta.copy()
            theta[i] += 0.5 * h * (down - up) / curvature / norms[i]
            g = gain(theta)
            if g > best:
                best, where = g, theta
    return best, where


def _gradient_cosine(state):
    """max over columns of |Jᵢ·r| / (‖Jᵢ‖ ‖r‖): 0 at a stationary point (MINPACK's gtol test)."""
    norms = np.linalg.norm(state.jacobian, axis=0) * np.linalg.norm(state.residual)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(state.jacobian.T @ state.residual) / norms
    return float(np.max(np.where(norms > 0, cos, 0.0), initial=0.0))


def iterate(state, residuals, jacobian, *, ftol, xtol, gtol, stall_steps, geodesic=True, report=None):
    """One trial step. `residuals(θ)` → r (or None where the solve failed); `jacobian(θ)` → (r, J).
    Returns the new state (`done` and `reason` set when it stops)."""
    step, predicted, scaled_norm, trusted, potential = _step(state, residuals, geodesic)
    trial = state.theta + step
    r_trial = residuals(trial) if trusted else None
    ok = r_trial is not None and np.all(np.isfinite(r_trial))
    cost_trial = _cost(r_trial) if ok else np.inf
    actual = state.cost - cost_trial
    rho = actual / predicted if predicted > 0 else -np.inf
    state = dataclasses.replace(state, step=state.step + 1)
    theta_norm = float(np.linalg.norm(state.theta * state.scale))
    # the tests below may only end a fit at a stationary point (or on a zero-residual problem, at its zero)
    stationary = potential <= POTENTIAL_TOL * state.cost or state.cost <= 1e-20 * state.history[0][1]
    if ok and rho > 1e-4:
        r_new, j_new = jacobian(trial)
        scale = np.maximum(state.scale, np.linalg.norm(j_new, axis=0))
        state = dataclasses.replace(
            state, theta=trial, residual=r_new, jacobian=j_new, cost=_cost(r_new), scale=scale,
            damping=state.damping * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), growth=2.0,
            accepted=state.accepted + 1, rejected_in_row=0)
        state.history.append([state.step, state.cost, state.damping, True])
        if stationary and abs(actual) <= ftol * state.cost and predicted <= ftol * state.cost:
            state.done, state.reason = True, "converged: relative cost decrease below ftol"
        elif stationary and scaled_norm <= xtol * (theta_norm + xtol):
            state.done, state.reason = True, "converged: step below xtol"
        elif _gradient_cosine(state) <= gtol:
            state.done, state.reason = True, "converged: gradient orthogonal to the residuals (gtol)"
    else:
        state = dataclasses.replace(state, damping=state.damping * state.growth, growth=2.0 * state.growth,
                                    rejected_in_row=state.rejected_in_row + 1)
        state.history.append([state.step, state.cost, state.damping, False])
        if stationary and predicted <= ftol * state.cost and state.accepted > 0:
            # The local model promises no decrease worth having: the point is a minimum to the solver's precision.
            state.done, state.reason = True, "converged: no predicted decrease above ftol"
        elif state.rejected_in_row >= stall_steps and scaled_norm <= xtol * (theta_norm + xtol):
            state = _stalled_or_minimum(state, residuals, jacobian)
    if not state.done and state.accepted > 0 and _crawling(state):
        state = _stalled_or_minimum(state, residuals, jacobian)
    if report is not None:
        report(state.step, state.cost, state.damping, state.history[-1][3])
    return state


def _crawling(state):
    """True where the last `CRAWL_STEPS` iterations together lowered the cost by less than `POTENTIAL_TOL` of it:
    steps accepted for gains of ~1e-9 of the cost, between rejections, as at a minimum where the cost is not
    smooth (the stall rule, which wants rejections in a row, never fires there)."""
    if len(state.history) <= CRAWL_STEPS:
        return False
    return state.history[-1 - CRAWL_STEPS][1] - state.cost <= POTENTIAL_TOL * state.cost


def _stalled_or_minimum(state, residuals, jacobian):
    """Where the damped steps have stopped gaining: the Jacobian may describe the cost badly only because the cost
    is not smooth here (a stick-slip phase begins or ends as θ moves), at a minimum all the same. Probe the cost:
    no lower point → converged; a lower point → go on from it with the start's damping (`PROBE_RESTARTS` times at
    most); then "stalled"."""
    gain, point = probe(state, residuals)
    if gain <= POTENTIAL_TOL * state.cost:
        state.done, state.reason = True, PROBED_MINIMUM
        return state
    if state.restarts >= PROBE_RESTARTS:
        state.done, state.reason = True, "stalled"
        return state
    r_new, j_new = jacobian(point)
    fresh = start(point, np.asarray(r_new), np.asarray(j_new))
    state = dataclasses.replace(
        state, theta=point, residual=fresh.residual, jacobian=fresh.jacobian, cost=fresh.cost, damping=fresh.damping,
        growth=2.0, scale=np.maximum(state.scale, fresh.scale), rejected_in_row=0, restarts=state.restarts + 1)
    state.history.append([state.step, state.cost, state.damping, True])
    return state


def jacobian_check(state, residuals, directions=3):
    """Relative disagreement between J·d and the central difference of r along the steepest-descent direction and
    the first right singular vectors: ~1e-6 for a correct Jacobian of a smooth cost; O(1) where the cost is not
    what the Jacobian describes (a discontinuity, or a wrong derivative)."""
    scaled = state.jacobian / state.scale
    _, _, vt = np.linalg.svd(scaled, full_matrices=False)
    grad = scaled.T @ state.residual
    ds = [grad / (np.linalg.norm(grad) or 1.0)] + list(vt[: directions - 1])
    worst = 0.0
    for d in ds:
        d = d / state.scale
        predicted = state.jacobian @ d
        size = float(np.linalg.norm(predicted))
        if size == 0:
            continue
        eps = 1e-6 * max(float(np.linalg.norm(state.theta * state.scale)), 1.0) / float(np.linalg.norm(d * state.scale))
        up, down = residuals(state.theta + eps * d), residuals(state.theta - eps * d)
        if up is None or down is None:
            return np.inf
        fd = (up - down) / (2.0 * eps)
        worst = max(worst, float(np.linalg.norm(fd - predicted)) / size)
    return worst


def levenberg_marquardt(residuals, jacobian, theta0, *, max_steps=100, ftol=1e-10, xtol=1e-10, gtol=1e-10,
                        stall_steps=8, geodesic=True):
    """Least squares min ½‖r(θ)‖² by the iteration `pamjax.fit` uses, for a problem of your own.

    **Arguments:** `residuals(θ)` → r (NumPy, or None / non-finite where the model fails: that trial is rejected);
    `jacobian(θ)` → (r, ∂r/∂θ) (e.g. a jitted `jax.jacfwd` with the residuals as aux); `theta0` the start; the
    stopping settings as in `pamjax.fit`.

    **Returns:** the final `LMState`: `theta`, `cost`, `residual`, `jacobian`, `done` and `reason` ("converged: …",
    "stalled", or "" after `max_steps`), `history`.
    """
    r0, j0 = jacobian(np.asarray(theta0, dtype=float))
    state = start(np.asarray(theta0, dtype=float), np.asarray(r0), np.asarray(j0))
    if _gradient_cosine(state) <= gtol:
        state.done, state.reason = True, "converged: gradient orthogonal to the residuals at the start (gtol)"
    while not state.done and state.step < max_steps:
        state = iterate(state, residuals, jacobian, ftol=ftol, xtol=xtol, gtol=gtol, stall_steps=stall_steps,
                        geodesic=geodesic)
    return state
