"""The walk of one side of one parameter's profile (`Branch`) and what its points say (`crossing`, `verdict`), for
`pamjax.profile_likelihood` (`pamjax._identifiability.profile`).

A fit that ended "at bound" left some parameters at a bound of their range (a logistic transform saturated, a log
one pushed towards 0: `ParameterSpace.at_bound`), where the data pull them beyond it. Their θ coordinates are held
at the fit's values while another parameter is profiled: re-fitted, they would stay on the bound anyway (the data
pull them there), but the transform is flat there (its derivative ~1e-7 of the range at |θ| = 15), so the
predictor's least squares divided by a vanishing Jacobian column and the first point jumped to Δχ² ≈ 1.5e4 (a tank's
volume beside a supply pressure held by a logistic range below its true value; the walk also stopped at once, the
bound being "reached" where it started). A parameter at its bound is itself profiled inwards only, the bound closing
the other side: its interval is one-sided, from the bound (`bound_verdict`).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

FLAT = 1e-3  # Δχ²: a profile within this of its minimum over its whole span on both sides is flat (structural)
BISECTIONS = 3  # re-fits bisecting the step across the threshold (the interval's end to ~1/8 of a step, then
# interpolated)
REFINES = 6  # shorter retakes of a step that jumps across the threshold (locates a steep crossing to ~4⁻⁶ of it)


class Branch:
    """One side of one parameter's profile: θ = τ u + N φ + θ_held with ψ a monotone function of τ alone; walks τ
    away from the fit, re-fitting φ at each point. `held` (per θ entry) are the coordinates kept at the fit's values
    (parameters at a bound of their range); `closed`: a bound ends this side at the fit (no walk)."""

    def __init__(self, evaluator, index, u, side, theta, jac, se_tau, settings, held, closed=False):
        self.evaluator, self.index, self.u, self.side, self.closed = evaluator, index, u, side, closed
        held = np.asarray(held, dtype=bool)
        # (I − u uᵀ) with the held coordinates' columns zeroed (u has none of them): its range is ⟂ u and ⟂ the held
        projector = (np.eye(u.size) - np.outer(u, u)) * ~held
        self.null = np.linalg.svd(projector)[0][:, : int(np.count_nonzero(~held)) - 1]  # orthonormal, ⟂ u
        self.fixed = np.where(held, np.asarray(theta, dtype=float), 0.0)
        self.tau0 = float(u @ theta)
        self.phi = self.null.T @ theta
        self.start_bound = evaluator.space.at_bound(theta)  # the walk stops where another parameter reaches a bound
        self.jac = jac  # full Jacobian at the current point
        self.settings = settings
        span = settings["span"]
        finite = math.isfinite(se_tau) and se_tau > 0
        self.step = min(settings["first_step"] * se_tau, 0.25 * span) if finite else 0.05 * span
        self.points = []  # (tau, delta, theta, converged)

    def theta(self, tau, phi):
        return tau * self.u + self.null @ phi + self.fixed

    def refit(self, tau, phi):
        """Re-fit φ with τ held: Levenberg-Marquardt from `phi`."""
        ev, s = self.evaluator, self.settings

        def residuals(p):
            return ev.residuals(self.theta(tau, p))

        def jacobian(p):
            r, j = ev.jacobian(self.theta(tau, p))
            self.jac = j
            return r, j @ self.null

        r0 = residuals(phi)
        if r0 is None:
            return None
        from .._fit.drive import levenberg_marquardt

        state = levenberg_marquardt(residuals, jacobian, phi, max_steps=s["max_steps"], ftol=s["ftol"],
                                    xtol=s["xtol"], gtol=s["gtol"], stall_steps=8)
        self.jac = ev.jacobian(self.theta(tau, state.theta))[1]
        return state

    def walk(self):
        """Step away from the fit until Δχ² passes the threshold by `overshoot`, the span is reached or another
        parameter newly reaches a bound of its range, or `max_points` points are taken. A step that jumps across the
        threshold by more than the threshold itself is retaken a quarter as long (at most `REFINES` times), so that
        the crossing is located where the profile is steep or has a kink (a physical limit)."""
        s, ev = self.settings, self.evaluator
        tau, phi, last_delta, refines = self.tau0, self.phi, 0.0, 0
        while not self.closed and len(self.points) < s["max_points"]:
            step = self.side * self.step
            if abs(tau + step - self.tau0) > s["span"]:
                step = self.side * max(s["span"] - abs(tau - self.tau0), 0.0)
                if abs(step) < 1e-12:
                    break
            # Predictor: the others' linearised change along τ, −(J_φᵀJ_φ)⁺ J_φᵀ J_τ.
            j_phi, j_tau = self.jac @ self.null, self.jac @ self.u
            slope = -np.linalg.lstsq(j_phi, j_tau, rcond=None)[0]
            state = self.refit(tau + step, phi + slope * step)
            delta = math.inf if state is None else 2.0 * (state.cost - ev.cost) / ev.sigma2
            if delta > s["threshold"] and delta - last_delta > s["threshold"] and refines < REFINES:
                refines += 1  # jumped across: retake a shorter step from the last point
                self.step *= 0.25
                self.jac = ev.jacobian(self.theta(tau, phi))[1]
                continue
            if state is None:  # the solve fails here: the physical range ends
                break
            tau, phi = tau + step, state.theta
            theta = self.theta(tau, phi)
            self.points.append((tau, delta, theta, state.reason.startswith("converged")))
            if delta > s["threshold"] * s["overshoot"] or (ev.space.at_bound(theta) & ~self.start_bound).any():
                break
            growth = delta - last_delta
            if growth < s["threshold"] / 8:
                self.step *= 2.0
            elif growth > s["threshold"] / 2:
                self.step *= 0.5
            last_delta = delta
        self._refine()
        return self

    def _refine(self):
        """Bisect the last step across the threshold `BISECTIONS` times (re-fits warm-started from the point
        below), so that interpolating √Δχ² places the interval's end to a small fraction of a step even where the
        profile is far from quadratic."""
        s, ev = self.settings, self.evaluator
        below = [(t, d, th) for t, d, th, _ in self.points if d < s["threshold"]]
        above = [(t, d, th) for t, d, th, _ in self.points if d >= s["threshold"]]
        if not above:
            return
        lo = max(below, key=lambda p: abs(p[0] - self.tau0), default=(self.tau0, 0.0, self.theta(self.tau0,
                                                                                                   self.phi)))
        hi = min(above, key=lambda p: abs(p[0] - self.tau0))
        for _ in range(BISECTIONS):
            tau = 0.5 * (lo[0] + hi[0])
            self.jac = ev.jacobian(lo[2])[1]
            state = self.refit(tau, self.null.T @ lo[2])
            if state is None:
                break
            theta = self.theta(tau, state.theta)
            point = (tau, 2.0 * (state.cost - ev.cost) / ev.sigma2, theta)
            self.points.append(point + (state.reason.startswith("converged"),))
            lo, hi = (point, hi) if point[1] < s["threshold"] else (lo, point)
        self.points.sort(key=lambda p: abs(p[0] - self.tau0))


def direction(space, theta, index):
    """Unit vector u in θ along which the physical value of parameter `index` moves, the others held: for a
    per-entry transform its own coordinate (also where its transform is flat: a logistic saturated at its bound,
    whose gradient is 0); for the F_max nodes (a0…a4 linear in the five node values) the row of the linear map."""
    grad = np.asarray(jax.grad(lambda t: space.physical(t)[index])(jnp.asarray(theta)))
    if np.count_nonzero(grad) <= 1:
        return np.eye(grad.size)[index] if not grad.any() else (grad != 0).astype(float)
    return grad / np.linalg.norm(grad)


def crossing(points, threshold, x0, coordinate=lambda p: p[0]):
    """Where Δχ² crosses `threshold` on this side, or None: linear interpolation of √Δχ² in `coordinate` of a point
    (τ: exact for a profile quadratic in τ, whose √Δχ² = |τ − τ̂|/se is linear), from x0 (the fit's) on."""
    last_x, last_root = x0, 0.0
    for point in points:
        x, delta = coordinate(point), point[1]
        root = math.sqrt(max(delta, 0.0))
        if delta >= threshold:
            w = (math.sqrt(threshold) - last_root) / (root - last_root) if root > last_root else 1.0
            return last_x + w * (x - last_x)
        last_x, last_root = x, root
    return None


def physical_at(space, theta, index, u, tau):
    t = np.asarray(theta) + (tau - float(u @ theta)) * u
    return float(space.physical(jnp.asarray(t))[index])


def verdict(lower, upper, branches):
    deltas = [d for b in branches for _, d, _, _ in b.points]
    if deltas and max(deltas) < FLAT and all(len(b.points) > 0 for b in branches):
        return "structurally non-identifiable"
    if lower is not None and upper is not None:
        return "identifiable"
    sides = [name for name, hit in (("lower", lower), ("upper", upper)) if hit is None]
    return "practically non-identifiable (" + (" and ".join(sides) if len(sides) == 1 else "both") + " side" + \
        ("s" if len(sides) == 2 else "") + ")"


def bound_side(theta_i):
    """The bound a parameter at a bound of its range sits on, from its θ: a logistic's upper end at θ → +∞, its
    lower one at −∞; a log transform's 0 at θ → −∞ (both transforms increase with θ)."""
    return "upper" if theta_i > 0 else "lower"


def bound_verdict(side, inward_end):
    """The verdict on a parameter the fit left at its `side` bound: not "structurally non-identifiable" (its
    transform is flat there; the data still see it), but the bound, and whether the profile inwards crosses the
    threshold (`inward_end` not None: a one-sided interval from the bound)."""
    inward = "lower" if side == "upper" else "upper"
    said = f"at the {side} bound of its range (the data pull it beyond)"
    if inward_end is not None:
        return said + ": one-sided interval from the bound"
    return said + f"; practically non-identifiable ({inward} side)"
