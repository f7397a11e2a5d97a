"""Design points beside the model's own: a design robust over the plant's spread (`design_experiment(spread=...)`).

A design is local: its information F(u; θ) is computed at one parameter vector θ₀, the model's values, and a plant
whose parameters lie away from θ₀ rests, lifts off and sticks elsewhere, so the same duty tells less about it (the
example design's 10 % over E3 + E4 at the presets was 0.87–2.04× on plants ±20 % away: benchmarks/RESULTS.md,
Session 56). With a `spread`, the design is scored at `spread_points` further design points θ₁ … θ_K drawn around θ₀
(a Latin hypercube: each free parameter p × (1 + s (2 u − 1)), u stratified in K equal bins of [0, 1], one point per
bin and parameter, seeded), and the objective is the average over θ₀ … θ_K of each point's criterion and baseline
penalty, with the limits' penalties of the model's point θ₀:

    J(u) = 1/(K + 1) Σ_j [ crit(F(u; θ_j)) + floor penalty(u; θ_j) + limits' penalties(u; θ_j) · [j = 0] ],

the criterion in the sense of a Bayesian D- (or A-) optimal design with the points as its sample of the prior
(Chaloner & Verdinelli 1995, "Bayesian experimental design: a review", Statist. Sci. 10(3): the expected log det F);
with a baseline, each point has its own target, the baseline's information at that point: `baseline_margin` at the
model's point (the best estimate), and at the others the baseline's own standard errors (a margin of 1, or the
user's if smaller): "beat my protocol by 10 % where I expect the plant, and nowhere do worse than it". (A margin of
1.1 at every point as well was out of reach of the 33 s MAS-10 example in 80 iterations: it ended 0.93–1.28× E3 + E4
at the points, below the local design: Session 57, benchmarks/RESULTS.md.) The limits (stroke, pressure, duty step,
eq. 7's force) are kept at the model's point, as without a spread: their margins are the bench's allowance for the
plant being elsewhere, and asking them of every point at once leaves a 33 s MAS-10 run little but a calm duty (the
default start broke eq. 7's 20 N by up to 52 N at points ±20 % away, and the search crawled along the limits:
Session 57, benchmarks/RESULTS.md). What each point's plant would do at the design's limits is reported
(`DesignResult.points`: `worst_violation`). Each point is the same compiled objective with another θ (its limits set
infinite: the same program): no further compilation, (K + 1)× the work per iteration.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.errors import PamjaxInputError
from . import design_objective as obj

SPREAD_POINTS = 4  # design points drawn beside the model's own: one per quarter of each parameter's spread
SPREAD_STREAM = 1  # the points' NumPy stream beside `seed` (the carrier and the probes use `seed` alone)


def spread_fractions(labels, spread, count):
    """The relative spread of each free parameter (labels order; 0 where a dict leaves one out) for `spread` (a number
    in (0, 1) for every one, or {label: fraction}), checked with `count`; None without a spread."""
    if spread is None:
        if not (isinstance(count, (int, np.integer)) and not isinstance(count, bool) and count == SPREAD_POINTS):
            raise PamjaxInputError(f"spread_points = {count!r} is given without spread: the points are drawn from the "
                                   "plant's spread; give spread too (e.g. 0.2: ±20 %), or leave spread_points out")
        return None
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise PamjaxInputError(f"spread_points must be a positive integer (design points beside the model's own; "
                               f"default {SPREAD_POINTS}), got {count!r}")
    if isinstance(spread, dict):
        unknown = sorted(set(spread) - set(labels))
        if unknown:
            raise PamjaxInputError(f"spread: unknown parameter label(s) {unknown}; the free parameters are {labels}")
        fractions = [spread.get(label, 0.0) for label in labels]
    else:
        fractions = [spread] * len(labels)
    for label, f in zip(labels, fractions):
        if isinstance(f, bool) or not isinstance(f, (int, float, np.floating, np.integer)) or not 0.0 <= f < 1.0:
            raise PamjaxInputError(f"spread: the relative spread of {label} must be a number in [0, 1) (0.2: the "
                                   f"plant's value within ±20 % of the model's), got {f!r}")
    if not any(fractions):
        raise PamjaxInputError("spread: every fraction is 0, so there is no spread to design over; give e.g. 0.2")
    return np.asarray(fractions, dtype=float)


def spread_values(values, fractions, count, seed):
    """(count, n) parameter values around `values`: a seeded Latin hypercube, value × (1 + f (2 u − 1))."""
    values = np.asarray(values, dtype=float)
    rng = np.random.default_rng((int(seed), SPREAD_STREAM))
    strata = np.stack([rng.permutation(count) for _ in values], axis=1)  # (count, n): one point per bin per parameter
    u = (strata + rng.uniform(size=strata.shape)) / count
    return values[None, :] * (1.0 + fractions[None, :] * (2.0 * u - 1.0))


def design_thetas(space, spread, count, seed):
    """(the points' physical values (K, n), their θ (K, n)) for `spread`; empty arrays without one."""
    n = len(space.labels)
    fractions = spread_fractions(space.labels, spread, count)
    if fractions is None:
        return np.zeros((0, n)), np.zeros((0, n))
    values = spread_values(np.asarray(space.initial_values()), fractions, int(count), seed)
    thetas = np.stack([np.asarray(space.theta(v)) for v in values])
    bad = [space.labels[i] for i in range(n) if not np.all(np.isfinite(thetas[:, i]))]
    if bad:
        raise PamjaxInputError(f"spread: design points put {bad} outside their bounds (their transform has none "
                               f"there); give them a smaller spread (spread = {{ label = fraction }})")
    return values, thetas


def with_stroke(problem, limits):
    """`problem` with its own stroke limits (a point's payload rests elsewhere: its start is within them)."""
    if problem.stroke is None or limits is None:
        return problem
    return eqx.tree_at(lambda p: p.stroke, problem, jnp.asarray(limits))


def without_limits(problem):
    """`problem` with every limit infinite (penalties exactly 0, worst violations 0): the same compiled program."""
    out = problem
    if problem.stroke is not None:
        out = eqx.tree_at(lambda p: p.stroke, out, jnp.asarray([-jnp.inf, jnp.inf]))
    out = eqx.tree_at(lambda p: (p.max_pressure, p.max_step), out, (jnp.asarray(jnp.inf), jnp.asarray(jnp.inf)))
    if problem.min_force is not None:
        out = eqx.tree_at(lambda p: p.min_force, out, jnp.asarray(-jnp.inf))
    return out


def value(c, problem):
    """(objective, aux) of one `DesignProblem` or the average over a tuple of them (the model's first; the others'
    limits `without_limits` for the search): the criterion and the penalties averaged, the worst violations the
    largest over the points, the rest (duty, predictions, information) the model's, and `points`: each point's aux."""
    if not isinstance(problem, tuple):
        return obj.value(c, problem)
    results = [obj.value(c, p) for p in problem]
    auxes = [a for _, a in results]
    aux = dict(auxes[0])
    for key in ("criterion", "penalty", "floor_penalty"):
        aux[key] = jnp.mean(jnp.stack([a[key] for a in auxes]))
    for key in ("worst_stroke", "worst_pressure", "worst_step", "worst_force"):
        aux[key] = jnp.max(jnp.stack([a[key] for a in auxes]))
    aux["points"] = [a for a in auxes]
    return jnp.mean(jnp.stack([v for v, _ in results])), aux


def gradient(grad, c, problem):
    """`grad(c, problem)` of one problem, or the average over the design points."""
    if not isinstance(problem, tuple):
        return grad(c, problem)
    return sum(np.asarray(grad(c, p)) for p in problem) / len(problem)


def points_start(c0, problem):
    """The objective's aux at the start `c0` over the design points, which must each determine every parameter. A
    point whose solve fails there (its predictions not finite: a long run out of `max_steps`, a plant that diverges)
    is named as such, not as one the start signal does not determine (was: "does not determine every free parameter"
    for a failed solve, and the advice to change the signal)."""
    _, aux = value(c0, problem)
    failed, loose = [], []
    for k, a in enumerate(aux["points"]):
        predictions = [np.asarray(a[key]) for key in ("position", "pressure") if a.get(key) is not None]
        if not all(np.all(np.isfinite(p)) for p in predictions):
            failed.append(k)
        elif not math.isfinite(float(a["criterion"])):
            loose.append(k)
    if failed:
        raise PamjaxInputError(f"spread: at design point(s) {failed} (0: the model's) the designed run's solve fails "
                               "at the start signal (its predictions are not finite: out of max_steps, or a plant that "
                               "runs away there): give a smaller spread or a shorter duration")
    if loose:
        raise PamjaxInputError(f"spread: at design point(s) {loose} (0: the model's) the start signal does not "
                               "determine every free parameter, so the criterion is undefined there; give a smaller "
                               "spread or start from another signal (`initial`)")
    return aux
