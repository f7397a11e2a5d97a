"""The design's repairs where its limits and its runs disagree (`design_experiment`):

- `start_within_limits`: the default start (paper 000's E3 triangle with the carrier on top) breaks a limit on the
  model at hand (a pilot fit whose payload reaches the upper stop at E3's top duty, or whose muscle goes slack in the
  carrier's fast exhausts). The carrier's amplitude is lowered everywhere until the start keeps every limit (as
  before); where no amplitude does, the start is repaired where it breaks one (`repaired_start`): the carrier's
  amplitude halved and the level moved away from the limit over the second before each sample that passes it.
  Before, the search then went on from the default start as it was, and on one of three unseen realistic rigs (its
  pilot's payload lifted onto the upper stop by E3's top duty, which no calmer carrier avoids: only a lower level
  does) it ended on the stop: no design. The repaired start taken before a calmer carrier (or whichever scores
  lower) gave the MAS-10 example a weaker design (benchmarks/RESULTS.md, Session 59).
- `search`: the search, and the design verified at the fit's resolution; where the run passes a
  limit there that the objective's samples keep (the PWM ripple between them: eq. 7's force 10.6 N lower on one
  rig, 24.8 N at the samples and 14.2 N between them), the objective's limit is tightened by what its samples missed
  and the search goes on from where it stopped, `TIGHTEN_ROUNDS` times at most.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from . import design_objective as obj, design_points as pts
from .design_result import VERIFY_TOLERANCE, constraints_report, worst_violation
from .design_setup import CARRIER_HOLD, START_AMPLITUDE, start_coefficients

REPAIRS = 10  # evaluations of the objective the start's repair may take (one forward-mode Jacobian each)
REPAIR_WINDOW = 1.0  # s: a limit passed at t is blamed on the duties of the second before it (assumed: longer than
# the muscle's response to a duty step; the coefficients acting there are found from their basis functions)
REPAIR_BIN = 0.05  # s: the samples passing a limit are taken 50 ms at a time (one window each)
REPAIR_LEVEL = 0.1  # of the duty band: how far one repair moves the level away from the limit passed (assumed; ten
# repairs can move it across the whole band)
REPAIR_AMPLITUDE = 0.02  # of the band: a carrier amplitude halved below it is set to 0 (assumed: 1.5 % duty; on
# rig3102's pilot, E3's triangle with a carrier of 0.05 of the band scored no better than without one (D criterion
# -234.1 against -234.7), with 0.25 of it -241.1: the carrier's information is in its large swings)
CALMER = (0.8, 0.6, 0.4, 0.2, 0.0)  # factors on START_AMPLITUDE tried, in turn, for a calmer carrier everywhere
TIGHTEN_ROUNDS = 2  # searches after the first, each with the limits tightened by what the verification found
TIGHTEN_SPARE = 1.0  # in each limit's penalty unit (mm, kPa, N): kept beyond the gap the verification found


def _knots_of(times, start, end, basis):
    """The coefficients (indices) whose basis functions act on the periods from `start` to `end` [s]."""
    rows = (times >= start - 1e-12) & (times <= end + 1e-12)
    if not np.any(rows):
        rows = np.argmin(np.abs(times - end)) == np.arange(times.size)
    return np.flatnonzero(np.max(basis[rows], axis=0) > 0.05)


def _blamed(aux, problem, sample_times, period_times, basis):
    """The coefficients acting over the `REPAIR_WINDOW` before each sample that passes a limit, as three sets: where
    the run passes the upper stroke limit or the pressure limit (the level to be lowered), the lower stroke limit (to
    be raised), eq. 7's force limit (the fast exhausts of the carrier: raised, more pressure and more force, only
    once no carrier is left there; `repaired_start`). The carrier is calmed on all three."""
    x, p, f = (None if aux.get(k) is None else np.asarray(aux[k]) for k in ("position", "pressure", "force"))
    passed = dict(lower=[], raise_=[], force=[])
    if problem.stroke is not None and x is not None:
        lo, hi = (float(s) for s in problem.stroke)
        passed["lower"].append(x > hi)
        passed["raise_"].append(x < lo)
    if p is not None and math.isfinite(float(problem.max_pressure)):
        passed["lower"].append(p > float(problem.max_pressure))
    if problem.min_force is not None and f is not None and x is not None:
        floor = obj.force_floor(x, float(problem.space.model(problem.theta).muscle.min_position),
                                float(problem.min_force), xp=np)
        passed["force"].append(f < floor)
    out = {key: set() for key in passed}
    for key, masks in passed.items():
        for mask in masks:
            for t in np.unique(np.floor(sample_times[mask] / REPAIR_BIN) * REPAIR_BIN):
                out[key].update(_knots_of(period_times, t - REPAIR_WINDOW, t + REPAIR_BIN, basis).tolist())
    return out["lower"], out["raise_"], out["force"]


def repaired_start(problem, setup, envelope, duration, knots, carrier, flat, aux0=None):
    """The default start (E3's triangle, the carrier at `START_AMPLITUDE`) repaired where it breaks a limit (module
    docstring), and the note for the design's message; the least violating start found if none of `REPAIRS` keeps
    every limit. `problem`: the search's (one `DesignProblem`, or the design points' tuple, the model's first);
    `carrier`, `flat`: the start's multilevel carrier and its coefficients without it (`start_within_limits`);
    `aux0`: the objective's aux at the default start, if known."""
    nominal = _model_point(problem)  # the limits are the model's
    times = np.asarray(setup["times"])
    sample_times = np.asarray(setup["experiment"].times)
    level = np.array(flat[:knots] if envelope else flat)
    amplitude = np.full(level.size, START_AMPLITUDE)
    basis = obj.bspline_basis(times, 0.0, duration, knots) if envelope else np.eye(times.size)

    best, repairs, aux = None, 0, aux0
    while True:
        c = np.concatenate([level, amplitude]) if envelope else level + amplitude * carrier
        if aux is None:
            aux = pts.value(jnp.asarray(c), problem)[1]
        violation = worst_violation(aux)
        if best is None or violation < best[1]:
            best = (c, violation)
        lower, raise_, force = _blamed(aux, nominal, sample_times, times, basis)
        calm = sorted(lower | raise_ | force)
        if violation <= 0 or repairs == REPAIRS or not calm:  # kept; or out of repairs; or nothing a sample shows
            break
        bare = [k for k in force if amplitude[k] == 0.0]  # no carrier left there: more pressure
        amplitude[calm] *= 0.5
        amplitude[np.abs(amplitude) < REPAIR_AMPLITUDE] = 0.0
        lower, raise_ = sorted(lower - raise_), sorted((raise_ | set(bare)) - lower)
        level[lower] = np.minimum(level[lower], 1.0) - REPAIR_LEVEL
        level[raise_] = np.maximum(level[raise_], 0.0) + REPAIR_LEVEL
        repairs, aux = repairs + 1, None
    c, violation = best
    if violation > 0:
        return c, (f"; neither the default start, nor a calmer carrier, nor {_repairs(repairs)} (the carrier calmed "
                   f"and the level moved off the limit where it was passed) kept every limit (worst violation "
                   f"{violation:.3g} in the limit's unit: mm, kPa, N)")
    return c, (f"; the default start broke a limit and no calmer carrier kept it, so it was repaired where it did "
               f"({_repairs(repairs)}: the carrier's amplitude halved and the level moved off the limit over the "
               "second before each sample that passed it)")


def start_within_limits(problem, setup, parametrisation, duration, knots, seed, aux0):
    """Where the default start breaks a limit: the carrier's amplitude lowered everywhere (`CALMER`, in turn) until
    the start keeps every limit; else the start repaired where it breaks one (`repaired_start`). (coefficients,
    note for the design's message)."""
    carrier = obj.multilevel_carrier(setup["count"], CARRIER_HOLD, seed)
    flat, _ = start_coefficients(parametrisation, np.asarray(setup["times"]), duration, knots, carrier,
                                 setup["band"], None, 0.0)
    envelope = parametrisation == "envelope"
    calmer = _calmer(problem, flat, knots, envelope, carrier)
    if calmer is not None:
        return calmer[0], f"; the default start broke a limit, so its carrier's amplitude was lowered to {calmer[1]:g}"
    return repaired_start(problem, setup, envelope, duration, knots, carrier, flat, aux0)


def _calmer(problem, flat, knots, envelope, carrier):
    """The default start with its carrier's amplitude lowered everywhere (`CALMER`, in turn) until it keeps every
    limit: (coefficients, amplitude), or None if none does."""
    for factor in CALMER:
        amplitude = factor * START_AMPLITUDE
        c = np.concatenate([flat[:knots], np.full(knots, amplitude)]) if envelope else flat + amplitude * carrier
        if worst_violation(pts.value(jnp.asarray(c), problem)[1]) <= 0:
            return c, amplitude
    return None


def _repairs(count):
    return f"{count} repair" + "s" * (count != 1)


def _tightened(current, original, report):
    """`current` (the search's `DesignProblem`) with each limit that the run at the fit's resolution passes by more
    than the tolerance, while the objective's samples keep it, tightened to the user's (`original`'s) less the gap
    between the two and `TIGHTEN_SPARE` (never loosened from `current`'s); and the note on what was tightened.
    (None, "") where no limit needs it."""
    verified = report.get("verified")
    if verified is None or verified["feasible"]:
        return None, ""
    excess, notes, problem, tolerance = verified["excess"], [], current, VERIFY_TOLERANCE
    if excess.get("force") is not None and excess["force"] > tolerance["force"] and \
            report.get("free_force_min") is not None and verified.get("free_force_min") is not None:
        gap = report["free_force_min"] - verified["free_force_min"]
        if gap > 0:
            limit = max(float(current.min_force), float(original.min_force) + gap + TIGHTEN_SPARE * obj.FORCE_UNIT)
            problem = eqx.tree_at(lambda p: p.min_force, problem, jnp.asarray(limit))
            notes.append(f"eq. 7's force {verified['free_force_min']:.1f} N between the samples, {gap:.1f} N below "
                         f"them: its limit raised to {limit:.1f} N")
    if excess.get("stroke") is not None and excess["stroke"] > tolerance["stroke"] and current.stroke is not None:
        (x_lo, x_hi), (v_lo, v_hi) = report["position_range"], verified["position_range"]
        (lo, hi), (now_lo, now_hi) = ([float(s) for s in q.stroke] for q in (original, current))
        spare = TIGHTEN_SPARE * obj.STROKE_UNIT
        new = (max(now_lo, lo + max(x_lo - v_lo, 0.0) + spare * (v_lo < x_lo)),
               min(now_hi, hi - max(v_hi - x_hi, 0.0) - spare * (v_hi > x_hi)))
        problem = eqx.tree_at(lambda p: p.stroke, problem, jnp.asarray(new))
        notes.append(f"the stroke {1e3 * v_lo:.2f} … {1e3 * v_hi:.2f} mm between the samples: its limits moved to "
                     f"{1e3 * new[0]:.2f} … {1e3 * new[1]:.2f} mm")
    if excess.get("pressure") is not None and excess["pressure"] > tolerance["pressure"]:
        gap = verified["pressure_range"][1] - report["pressure_range"][1]
        if gap > 0:
            limit = min(float(current.max_pressure),
                        float(original.max_pressure) - gap - TIGHTEN_SPARE * obj.PRESSURE_UNIT)
            problem = eqx.tree_at(lambda p: p.max_pressure, problem, jnp.asarray(limit))
            notes.append(f"the pressure {gap / 1e3:.1f} kPa higher between the samples: its limit lowered to "
                         f"{limit / 1e5:.3f} bar abs")
    return (problem, "; ".join(notes)) if notes else (None, "")


def _model_point(problem):
    """The model's `DesignProblem` of the search's (one, or the design points' tuple, the model's first)."""
    return problem[0] if isinstance(problem, tuple) else problem


def _numbered_on(report, offset):
    """`report` with the iterations numbered on from `offset` (None stays None)."""
    if report is None:
        return None

    def numbered(it, *args, **kwargs):
        return report(it + offset, *args, **kwargs)

    numbered.says_probes = getattr(report, "says_probes", False)
    return numbered


def search(c0, problem, gradient, steps, report, seed, setup, optimise, verify):
    """The search (`optimise`) from `c0`, the design verified at the fit's resolution (`verify`: aux → (standard
    errors, the verified channels or None)) and, where the run there passes a limit its samples keep, searched on
    with the limit tightened (module docstring). Returns (c, aux at the original limits, history, message, errors,
    verified, note)."""
    c, aux, history, message = optimise(c0, problem, gradient, steps, report, seed)
    errors, verified = verify(aux)
    searched, notes = problem, []
    for round_ in range(1, TIGHTEN_ROUNDS + 1):
        if steps == 0 or verified is None or worst_violation(aux) > 1e-9:  # no search asked, nothing verified, or
            # the samples themselves pass a limit (no ripple to make up for)
            break
        limits = constraints_report(aux, setup, verified)
        tight, note = _tightened(_model_point(searched), _model_point(problem), limits)
        if tight is None:
            break
        searched = (tight, *searched[1:]) if isinstance(searched, tuple) else tight
        more = max(steps // 2, 5)
        if getattr(report, "says_probes", False):  # the command's printer: say why the search goes on
            print(f"  verified at the fit's resolution: {note}; {more} more iterations", flush=True)
        offset = history[-1][0]
        c, _, more_history, more_message = optimise(c, searched, gradient, more, _numbered_on(report, offset),
                                                    seed + round_)
        history += [[it + offset, *rest] for it, *rest in more_history[1:]]
        aux = pts.value(jnp.asarray(c), problem)[1]  # the report is against the user's limits
        errors, verified = verify(aux)
        notes.append(f"verified at the fit's resolution, {note}; searched on {len(more_history) - 1} iterations "
                     f"({more_message})")
    return c, aux, history, message, errors, verified, "".join(f"; {n}" for n in notes)

