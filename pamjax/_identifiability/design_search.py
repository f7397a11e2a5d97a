"""The search of `design_experiment`: a BFGS on the host over the signal's coefficients, with a backtracking line
search on the objective's value (one forward-mode Jacobian per trial), a gradient only at accepted points, and seeded
random probes past the kinks of the cost where the gradient sees no descent. The objective is one `DesignProblem`'s
or the average over the design points' (`design_points`)."""

import math

import jax.numpy as jnp
import numpy as np

from . import design_points as pts
from .design_result import worst_violation

# Where the line search along the gradient fails (a kink: the cost jumps where a stick-slip phase or a stop contact
# appears), the search probes PROBES seeded random directions, both signs, of max-norm PROBE_SCALES in turn (in the
# coefficients' units: the duty band is z ∈ [0, 1]). Measured on the fitted models of three stop-resting rigs
# (benchmarks/RESULTS.md, design, Session 55): the D criterion 0–4.1 lower than without (never higher: a probe is
# taken only where it lowers the objective); the searches with probes took 5–32 s.
PROBES = 8
PROBE_SCALES = (0.05, 0.02, 0.005)


def feasible(aux_trial, aux):
    """Whether a trial keeps the feasible set (or, from an infeasible point, does not increase the worst violation)."""
    return worst_violation(aux_trial) <= max(worst_violation(aux), 0.0) + 1e-9


def probe(c, v, aux, problem, rng):
    """The best of `PROBES` seeded random directions (both signs, max-norm `PROBE_SCALES` in turn) that lowers the
    objective by more than 1e-3 and keeps feasibility: (trial, value, aux, scale), or None."""
    best = None
    for k in range(PROBES):
        scale = PROBE_SCALES[k % len(PROBE_SCALES)]
        e = rng.standard_normal(c.size)
        e *= scale / np.max(np.abs(e))
        for trial in (c + e, c - e):
            v_trial, aux_trial = pts.value(jnp.asarray(trial), problem)
            v_trial = float(v_trial)
            if (math.isfinite(v_trial) and v_trial < v - 1e-3 and feasible(aux_trial, aux)
                    and (best is None or v_trial < best[1])):
                best = (trial, v_trial, aux_trial, scale)
    return best


def optimise(c, problem, gradient, steps, report, seed=0):
    """BFGS on the host: a backtracking line search on the value (cheap), a gradient at each accepted point; a
    trial may not leave the feasible set (or, from an infeasible start, increase the worst violation). The cost
    jumps where a stick-slip phase or a stop contact appears or vanishes, and the gradient does not see a jump: where
    the line search fails, seeded random probes around the point (`probe`) look for a lower value past it, and the
    search goes on from the best one with steepest descent; two failures of both in a row end the search."""
    rng = np.random.default_rng(seed)
    probed = 0
    v, aux = pts.value(jnp.asarray(c), problem)
    v = float(v)
    history = [[0, v, float(aux["criterion"]), 0.0, True]]
    if steps == 0:  # the start scored, no search (no gradient: in reverse mode, ~50 Jacobians)
        return c, aux, history, "0 iterations"
    g = np.asarray(pts.gradient(gradient, jnp.asarray(c), problem))
    eye = np.eye(c.size)
    h0 = 0.5 / max(float(np.max(np.abs(g))), 1e-12)  # first step moves z by at most 0.5 (the band is z ∈ [0, 1])
    inverse = eye * h0
    failures, message = 0, f"{steps} iterations"
    for it in range(1, steps + 1):
        direction = -inverse @ g
        slope = float(g @ direction)
        if not slope < 0:
            inverse, direction = eye * h0, -h0 * g
            slope = float(g @ direction)
        step, accepted = 1.0, False
        for _ in range(8):
            trial = c + step * direction
            v_trial, aux_trial = pts.value(jnp.asarray(trial), problem)
            v_trial = float(v_trial)
            if math.isfinite(v_trial) and v_trial <= v + 1e-4 * step * slope and feasible(aux_trial, aux):
                accepted = True
                break
            step *= 0.3
        found = None if accepted else probe(c, v, aux, problem, rng)
        if found is not None:  # past a kink: go on from there by steepest descent (no curvature across a jump)
            trial, v_trial, aux_trial, step = found
            accepted, probed, inverse = True, probed + 1, eye * h0
        history.append([it, v_trial if accepted else v, float((aux_trial if accepted else aux)["criterion"]), step,
                         accepted])
        if report is not None:  # the printer also says which steps were probes (a callable gets the five values)
            report(it, history[-1][1], history[-1][2], step, accepted,
                   **({"probe": found is not None} if getattr(report, "says_probes", False) else {}))
        if not accepted:
            failures += 1
            inverse = eye * h0 * 0.1
            if failures >= 2:
                message = (f"stopped after {it} iterations: no descent along the gradient nor in {2 * PROBES} random "
                           "probes around the point (kinks of the cost)")
                break
            continue
        failures = 0
        g_new = np.asarray(pts.gradient(gradient, jnp.asarray(trial), problem))
        s, y = trial - c, g_new - g
        if found is None and s @ y > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
            rho = 1.0 / (s @ y)
            left = eye - rho * np.outer(s, y)
            inverse = left @ inverse @ left.T + rho * np.outer(s, s)
        decrease = v - v_trial
        c, g, v, aux = trial, g_new, v_trial, aux_trial
        if decrease < 1e-6 * max(abs(v), 1.0) and step == 1.0:
            message = f"converged after {it} iterations (objective decrease below 1e-6)"
            break
    if probed:
        message += f"; {probed} of the steps by random probes past kinks of the cost, where the gradient saw no descent"
    return c, aux, history, message
