"""Leaving a kink for a lower valley: where pamjax's Levenberg-Marquardt stops at a kink of its cost (a probed
minimum, or stalled: `pamjax._fit.solver`), or crawls along one (its one-parameter probes gain less than
`ESCAPE_BELOW` of the cost), the cost is probed along the directions the data determine worst, one to three standard
errors out; where that finds a point lower by more than `ESCAPE_GAIN` of the cost (and than the one-parameter
probes), the iteration goes on from it (`ESCAPES` tries per fit at most).

Why: with stick-slip friction the cost has kinks (an event appears or vanishes as θ moves), and across a valley of
poorly determined combinations a kink can hold a fit whose damped steps and one-parameter probes (±0.01 and ±0.1
conditional standard errors) cannot cross it, while a lower point lies a few marginal standard errors along the
valley (tests/test_solver.py: a wall across a valley, the fit held 1.125 above the minimum, 0.045 with the escape).
On the unseen rigs whose payload rests on a stroke limit (benchmarks/RESULTS.md, identify, Session 48) the probes
find such points, but mostly small ones: taking every gain moved rig901 from a stall at cost 38,825 to convergence
at 38,749, and held rig1001 in a crawl past its step budget (109 steps for 6.7 of 39,011); `ESCAPE_GAIN` takes only
a valley worth its steps, which leaves both rigs where they were.

The directions and their standard errors are those of the Jacobian a hair off the end point (`hair_off`: at a kink a
stick-slip event begins or ends exactly at the point, and the Jacobian there can be that of the event's edge, 1e5×
too large), as the fit's statistics take them (`pamjax._fit.drive.statistics_jacobian`). Host (NumPy) only: the
traced solver (`optimistix.least_squares`) probes one parameter at a time as before.
"""

import numpy as np

HAIR = 1e-6  # θ units (the logarithm of a positive value: 1e-6 of it): "a hair off" a kink
HAIR_COST = 1e-4  # of the cost: the most a hair's move may change it (else the point is on a cliff's edge)
ESCAPES = 3  # probes along the least determined directions per fit (each 6 × 6 residual evaluations)
ESCAPE_BELOW = 1e-5  # of the cost: a kink's one-parameter probes gaining less than this (a crawl) try them too
# of the cost: the least gain an escape must find to be taken (a noise-scaled fit of 80,000 samples: 7.8 in χ², a
# lower valley; smaller gains along a kink prolonged rig1001's crawl from 40 to 109 steps for 6.7 of its 39,011)
ESCAPE_GAIN = 1e-4
ESCAPE_DIRECTIONS = 6  # the least determined directions probed (6 × 6 residual evaluations per probe)
ESCAPE_STEPS = (1.0, -1.0, 2.0, -2.0, 3.0, -3.0)  # standard errors along each (the local model: a cost rise of c²/2)
RANK_TOL = 1e-6  # directions whose singular value is below this × the largest are not determined: not probed


def hair_off(theta, cost, jacobian_at):
    """(r, J) a hair off θ (every component + `HAIR`, else − `HAIR`) where the cost is θ's to within `HAIR_COST` of
    it; None where neither is (a cliff's edge) or the model fails there. `jacobian_at(θ)` → (r, J)."""
    for sign in (1.0, -1.0):
        r, jac = (np.asarray(a, dtype=float) for a in jacobian_at(theta + sign * HAIR))
        r = r.ravel()
        if (np.all(np.isfinite(r)) and np.all(np.isfinite(jac))
                and abs(0.5 * float(r @ r) - cost) <= HAIR_COST * cost):
            return r, jac.reshape(r.size, -1)
    return None


def escape(theta, cost, jacobian, residual_at, jacobian_at):
    """(gain, θ'): the largest cost decrease found by moving θ `ESCAPE_STEPS` standard errors along each of the
    `ESCAPE_DIRECTIONS` least determined directions of the Jacobian a hair off θ (`hair_off`; `jacobian`, θ's own,
    where there is none), and the point where it was found; gain ≤ 0 where none is lower. A direction's unit move is
    V ᵢ / (D sᵢ) of the SVD of the column-scaled Jacobian J D⁻¹ = U S Vᵀ (its local cost rise is ½). A failed model
    counts as no decrease. `residual_at(θ)` → r (non-finite where the model fails), `jacobian_at(θ)` → (r, J)."""
    theta = np.asarray(theta, dtype=float)
    off = hair_off(theta, cost, jacobian_at)
    jac = np.asarray(jacobian if off is None else off[1], dtype=float)
    norms = np.linalg.norm(jac, axis=0)
    if not np.all(np.isfinite(norms)) or not np.any(norms > 0):
        return -np.inf, theta
    scale = np.where(norms > 0, norms, 1.0)
    _, s, vt = np.linalg.svd(jac / scale, full_matrices=False)
    live = np.flatnonzero(s > RANK_TOL * s[0])  # s descending: the least determined last
    best, point = -np.inf, theta
    for i in live[::-1][:ESCAPE_DIRECTIONS]:
        move = vt[i] / scale / s[i]
        for c in ESCAPE_STEPS:
            trial = theta + c * move
            with np.errstate(all="ignore"):
                r = np.asarray(residual_at(trial), dtype=float).ravel()
                gain = cost - 0.5 * float(r @ r) if np.all(np.isfinite(r)) else -np.inf
            if gain > best:
                best, point = gain, trial
    return best, point
