"""`profile_likelihood`: profile likelihoods of fitted parameters, their likelihood-ratio intervals and what they say.

The profile of a parameter ψ is the best cost with ψ held at each value and every other free parameter re-fitted:

    PL(v) = min_{θ : ψ(θ) = v} ½ Σ r(θ)²,      Δχ²(v) = 2 (PL(v) − PL(ψ̂)) / σ²,

σ² = 2 cost / (samples − parameters) as in the fit's standard errors (1 when the scales are the noise and the model
fits). {v : Δχ²(v) ≤ χ²₁(level)} (3.84 at 95 %) is the likelihood-ratio interval; for a model linear in its
parameters it is the linearised ψ̂ ± 1.96 se, elsewhere it follows the likelihood where the linearisation does not
(Raue et al. 2009, "Structural and practical identifiability analysis of partially observed dynamical models by
exploiting the profile likelihood", Bioinformatics 25(15)). Verdicts:

- identifiable: Δχ² crosses the threshold on both sides;
- practically non-identifiable (lower / upper / both sides): the profile rises but stays below the threshold out to
  the search span (the data bound ψ on that side only weakly, or not before a physical limit);
- structurally non-identifiable: the profile is flat (Δχ² < `profile_walk.FLAT` over the whole span on both
  sides): other parameters compensate exactly (e.g. k0, k1, k2 of paper 000 eq. 7, which enter only as k0/k2 and
  k1/k2);
- at the lower / upper bound of its range: a fit that ended "at bound" left ψ there (the data pull it beyond); its
  profile is taken inwards only and its interval is one-sided, from the bound. Such parameters are held on their
  bound while the others are profiled (`pamjax._identifiability.profile_walk`).

Profiles need the fit at a minimum: a fit that stopped at `max_steps` (or stalled) is refused before any work, and
when a re-fitted point lies below the fit's cost (Δχ² < `NOT_A_MINIMUM`: the fit had not reached the minimum after
all) every verdict reads "not a minimum: ..." and `ProfileResult.warnings` says where the lower cost is.

Each point is re-fitted by the fit's solver (`pamjax._fit.solver`) in the coordinates orthogonal to ψ's, warm
started from the previous point plus the linearised change of the others along ψ; the residuals and Jacobians are
the fit's compiled functions (`pamjax._fit.problem`: no new compilation for a problem already fitted). The branches
(parameter × side) are independent and run in a pool of threads, which XLA executes on separate cores.
"""

import concurrent.futures
import dataclasses
import math
import numbers
import pathlib
import statistics
import time
from collections.abc import Callable, Sequence

import jax.numpy as jnp
import numpy as np

from .._core import jsonio
from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError, require_float64
from .._core.paths import writable_path
from .._fit.experiment import AbstractExperiment, Experiments
from .._fit.fit import FitResult
from .._fit.parameters import ParameterSpace
from .._fit.problem import Problem
from .profile_walk import Branch, bound_side, bound_verdict, crossing, direction, physical_at, verdict

# Δχ²: a re-fitted point this far BELOW the fit's cost shows that the fit is not at a minimum (a converged fit's
# re-fits lie within ~1e-6 of it: the stopping tolerances); every verdict is then void, not "non-identifiable"
NOT_A_MINIMUM = -0.1
# statuses of a fit whose end point is a minimum (of the cost, or of the cost within the bounds): what profiles need
PROFILED_STATUSES = ("converged", "at bound")


def chi2_quantile_1dof(level):
    """χ²₁ quantile: (Φ⁻¹((1 + level)/2))² (3.841 at 0.95)."""
    return statistics.NormalDist().inv_cdf(0.5 * (1.0 + level)) ** 2


@dataclasses.dataclass
class LikelihoodProfile:
    """One parameter's profile: `values` (physical, ascending), `delta` (Δχ² at each), `others` (the re-fitted
    values of the other parameters, by label), `converged` (per point), the likelihood-ratio `interval` (±inf on a
    side not crossed), the `linearised` interval ψ̂ ± z se, and the `verdict`."""

    label: str
    value: float
    values: list
    delta: list
    others: dict
    converged: list
    interval: list
    linearised: list
    verdict: str


@dataclasses.dataclass
class ProfileResult:
    """The outcome of `profile_likelihood`: `profiles` (one `LikelihoodProfile` per parameter, by `labels`), `level`,
    `threshold` (Δχ²), `sigma2` (the residual variance the Δχ² is measured in), `cost` at the fit, `profile_s` (wall
    time), `warnings` (e.g. that a re-fit found a lower cost than the fit's: the verdicts then say nothing)."""

    profiles: list
    labels: list
    level: float
    threshold: float
    sigma2: float
    cost: float
    profile_s: float
    warnings: list = dataclasses.field(default_factory=list)

    def __getitem__(self, label):
        for p in self.profiles:
            if p.label == label:
                return p
        raise KeyError(f"no profile of {label!r}; profiled: {self.labels}")

    def to_dict(self):
        return dataclasses.asdict(self)

    def lowest(self):
        """(Δχ², {label: value}) of the lowest re-fitted point of every profile: the profiled parameter there and the
        others as re-fitted; None when no point lies below the fit by more than `NOT_A_MINIMUM`."""
        delta, p, k = min(((d, p, k) for p in self.profiles for k, d in enumerate(p.delta)), key=lambda x: x[0],
                          default=(0.0, None, None))
        if not delta < NOT_A_MINIMUM:
            return None
        return float(delta), {p.label: float(p.values[k]), **{lbl: float(v[k]) for lbl, v in p.others.items()}}

    def lower_start(self, result):
        """`result`'s model with every fitted parameter at the lowest re-fitted point (`lowest`), to fit again from
        (`pamjax.fit(profile.lower_start(result), experiments, result.paths)`) when the profiles found a lower cost
        than the fit's; None when they did not."""
        found = self.lowest()
        if found is None:
            return None
        values = found[1]
        if set(values) != set(result.labels):
            raise PamjaxInputError(f"result: this profile is of a fit of {sorted(values)}, not of {result.labels}")
        return ParameterSpace(result.model, result.paths).with_values(np.asarray([values[k] for k in result.labels]))

    def to_json(self, path, overwrite=False):
        """Write the result; refuses to replace an existing file unless `overwrite`."""
        path = writable_path(path, overwrite)
        path.write_text(jsonio.dumps(self.to_dict(), indent=1))
        return path

    def table(self):
        """Text table: label, fitted value, likelihood-ratio interval, linearised interval, verdict."""
        rows = [f"{'parameter':<40}{'fitted':>13}{'LR lower':>13}{'LR upper':>13}{'lin. lower':>13}"
                f"{'lin. upper':>13}  verdict"]
        for p in self.profiles:
            rows.append(f"{p.label:<40}{p.value:>13.6g}{p.interval[0]:>13.6g}{p.interval[1]:>13.6g}"
                        f"{p.linearised[0]:>13.6g}{p.linearised[1]:>13.6g}  {p.verdict}")
        rows += [f"WARNING: {w}" for w in self.warnings]
        return "\n".join(rows)

    def plot(self, path):
        """Figure: every profile (Δχ² against the value) with the threshold, the fitted value and the linearised
        interval's quadratic Δχ² = ((v − ψ̂)/se)²."""
        from .profile_plot import plot_profiles

        return plot_profiles(self, path)

    def write(self, out, overwrite=False, report=False):
        """`out/profile.json` and `out/profile.png` (the figure skipped without matplotlib); returns the paths.
        `report` prints the table and what was written (`pamjax fit --profile`)."""
        out = pathlib.Path(out)
        figure = out / "profile.png"
        if figure.exists() and not overwrite:
            raise FileExistsError(f"{figure} exists; pass overwrite=True to replace it")
        paths = [self.to_json(out / "profile.json", overwrite=overwrite)]
        try:
            paths.append(self.plot(figure))
        except ModuleNotFoundError:
            pass
        if report:
            print(f"profiles ({self.profile_s:.1f} s):\n{self.table()}\nwrote {', '.join(map(str, paths))}")
        return paths


class _Evaluator:
    """The fit's host problem (`pamjax._fit.problem.Problem`: its compiled residual and Jacobian programs, through the
    CLI's program cache when it is on; identification samples only) with the cost and residual variance at the
    fit."""

    def __init__(self, space, exps, theta):
        self.problem = Problem(space, exps)
        self.space, self.exps = space, exps
        r, j = self.problem.start(theta)
        self.cost = 0.5 * float(r @ r)
        self.jac = j
        dof = max(int(np.count_nonzero(np.any(j != 0, axis=1) | (r != 0))) - j.shape[1], 1)
        self.sigma2 = 2.0 * self.cost / dof
        self.residuals, self.jacobian = self.problem.residuals, self.problem.jacobian  # θ → r; θ → (r, J)


def _sayer(progress):
    """Where `progress` lines go: printed (True), to the callable (a string each, as `pamjax.sweep`'s), or nowhere."""
    if callable(progress):
        return progress
    return (lambda line: print(f"  {line}", flush=True)) if progress else None


def _walk_all(jobs, names, workers, say):
    """Walk every branch in a pool of `workers` threads; with `say`, a line as each parameter's two branches
    finish (a profile takes seconds to minutes)."""
    if say:
        say(f"profiling {len(names)} parameter(s): {len(jobs)} branches on {workers} thread(s) ...")
    with concurrent.futures.ThreadPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(job[1].walk) for job in jobs]
        if say:
            left = {name: 2 for name in names}
            for future in concurrent.futures.as_completed(futures):
                name = jobs[futures.index(future)][0]
                left[name] -= 1
                if left[name] == 0:
                    say(f"profiled {name} ({sum(v == 0 for v in left.values())} of {len(names)})")
        return [f.result() for f in futures]


def _not_a_minimum(jobs, done, space, labels, values):
    """[a warning] when some re-fitted point lies below the fit's cost by more than `NOT_A_MINIMUM`, naming it."""
    delta, name, branch = min(((d, n, b) for (n, _), b in zip(jobs, done) for _, d, _, _ in b.points),
                              key=lambda x: x[0], default=(0.0, None, None))
    if not delta < NOT_A_MINIMUM:
        return []
    theta = min(branch.points, key=lambda p: p[1])[2]
    k = labels.index(name)
    at = float(space.physical(jnp.asarray(theta))[k])
    return [f"the fit is not at a minimum: with {name} = {at:.6g} (fitted {values[k]:.6g}) and the others re-fitted "
            f"the cost is lower by Δχ² = {-delta:.3g}; the profiles are taken around a point that is not the best "
            "fit, so their intervals and verdicts say nothing: fit again from that point and profile the new result "
            "(pamjax.profile_to_minimum does both; or pamjax.fit(profile.lower_start(result), experiments, "
            "result.paths))"]


def _validate(result, names, experiments, level, max_points, span, max_steps, workers):
    require_float64("pamjax.profile_likelihood")
    if not isinstance(result, FitResult):
        raise PamjaxInputError(f"result must be a pamjax.FitResult, got {type(result)}")
    experiments = result.experiments if experiments is None else experiments
    # read from JSON: neither experiments nor model (asking for the experiments alone led to a second refusal)
    rebuild = "set its fitted model from the model the fit started from: result.model = result.apply(start_model)"
    if experiments is None:
        raise PamjaxInputError("experiments: this FitResult does not carry its experiments (it was read from JSON); "
                               "pass the experiments it was fitted to" + (f", and {rebuild}" if result.model is None
                                                                          else ""))
    experiments = list(experiments) if isinstance(experiments, (list, tuple)) else [experiments]
    if not experiments:
        raise PamjaxInputError("experiments must hold the experiments the fit was made of, got none")
    if not all(isinstance(e, AbstractExperiment) for e in experiments):
        raise PamjaxInputError(f"experiments must be pamjax experiments, got {[type(e).__name__ for e in experiments]}")
    if result.model is None:
        raise PamjaxInputError(f"result has no fitted model (read from JSON): {rebuild}, or profile the FitResult "
                               "`fit` returned")
    status = result.status
    if status not in PROFILED_STATUSES:
        raise PamjaxInputError(
            f"the fit stopped with status {status!r} ({result.message}): its end point is not a "
            "minimum of the cost, so every profile would fall below it and read as non-identifiable; continue the fit "
            "to convergence first (pamjax.fit(..., checkpoint=..., resume=...) with a larger max_steps; on the command "
            "line raise [fit] max_steps and run pamjax fit CONFIG --out FOLDER --resume --profile)")
    names = list(result.labels) if names is None else ([names] if isinstance(names, str) else list(names))
    unknown = [n for n in names if n not in result.labels]
    if unknown or not names:
        raise PamjaxInputError(f"names {unknown or names!r} must be fitted parameters; they are {result.labels}")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PamjaxInputError(f"names {twice} given more than once: name each fitted parameter once")
    real = [isinstance(x, numbers.Real) and not isinstance(x, bool) for x in (level, span)]
    if not (real[0] and 0.0 < level < 1.0):
        raise PamjaxInputError(f"level must be in (0, 1), a number (0.95: 95 %), got {level!r}")
    if not (real[1] and 0.0 < span < math.inf):  # span="4" was a raw TypeError; inf steps to θ = inf
        raise PamjaxInputError(f"span must be a finite number > 0 (in the fit's scaled coordinates), got {span!r}")
    for key, value, least in (("max_points", max_points, 2), ("max_steps", max_steps, 1), ("workers", workers, 1)):
        if not (isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= least):
            raise PamjaxInputError(f"{key} must be an int >= {least}, got {value!r}")  # np.int64(5) too
    return names, experiments


def _branches(space, theta, ev, result, names, settings):
    """(name, `Branch`) for both sides of every parameter in `names`. The parameters the fit left at a bound of its
    range (`ParameterSpace.at_bound`: what made its status "at bound") are held there while the others are profiled
    (`profile_walk`: re-fitted, the flat transform spoiled every step); one of them is profiled inwards only, the
    bound closing its other side, over its whole range: from its θ to the range's middle (a logistic's θ = 0; a
    log's start value) and `span` beyond (its θ of ~15-37 is a physical step of ~1e-7 of the range or less)."""
    labels = list(space.labels)
    pinned = space.at_bound(theta)
    free = ~pinned
    jac = ev.jac[:, free]
    cov = ev.sigma2 * np.linalg.pinv(jac.T @ jac)  # the others' covariance, the pinned held (as the fit's errors)
    jobs = []
    for name in names:
        i = labels.index(name)
        u = direction(space, theta, i)
        held = pinned & (np.arange(theta.size) != i)
        if pinned[i]:
            outward = 1 if bound_side(theta[i]) == "upper" else -1
            inwards = dict(settings, span=abs(float(theta[i])) + settings["span"])
            jobs += [(name, Branch(ev, i, u, side, theta, ev.jac, math.inf, inwards, held, closed=side == outward))
                     for side in (-1, 1)]
            continue
        loose = any(name in group for group in result.non_identifiable)  # linearised error infinite
        se_tau = math.inf if loose else math.sqrt(max(float(u[free] @ cov @ u[free]), 0.0))
        jobs += [(name, Branch(ev, i, u, side, theta, ev.jac, se_tau, settings, held)) for side in (-1, 1)]
    return jobs


def _profile(space, theta, result, name, branches, threshold, warnings):
    """The `LikelihoodProfile` of `name` from its two walked branches (lower, upper)."""
    labels = list(space.labels)
    i = labels.index(name)
    lower_b, upper_b = branches
    u = lower_b.u
    value = float(result.values[i])
    pinned = any(b.closed for b in branches)
    if pinned:  # one branch closed by the bound, where the interval ends; the other interpolated in the value
        ends = [value if b.closed else crossing(b.points, threshold, value,
                                                lambda p: float(space.physical(jnp.asarray(p[2]))[i]))
                for b in branches]
    else:
        crossings = [crossing(b.points, threshold, b.tau0) for b in branches]
        ends = [None if c is None else physical_at(space, theta, i, u, c) for c in crossings]
    points = sorted([(float(space.physical(jnp.asarray(th))[i]), d, th, ok)
                     for b in branches for _, d, th, ok in b.points]
                    + [(value, 0.0, theta, True)], key=lambda p: p[0])
    others = {lbl: [float(space.physical(jnp.asarray(th))[k]) for _, _, th, _ in points]
              for k, lbl in enumerate(labels) if k != i}
    se = float(result.standard_errors[i])
    z = math.sqrt(threshold)
    lo_hi = sorted([e if e is not None else -math.inf * side for e, side in zip(ends, (1, -1))])
    # a decreasing transform (none today) would swap the sides; sorting keeps [lower, upper]
    if warnings:
        said = "not a minimum: see warnings"
    elif pinned:
        side = bound_side(theta[i])
        said = bound_verdict(side, ends[0] if side == "upper" else ends[1])
    else:
        said = verdict(*ends, branches)
    return LikelihoodProfile(
        label=name, value=value, values=[p[0] for p in points], delta=[float(p[1]) for p in points],
        others=others, converged=[bool(p[3]) for p in points], interval=[float(v) for v in lo_hi],
        linearised=[value - z * se, value + z * se], verdict=said)


def profile_likelihood(
    result: FitResult,
    names: str | Sequence[str] | None = None,
    *,
    experiments: Experiments | None = None,
    level: RealScalarLike = 0.95,
    max_points: int = 12,
    span: RealScalarLike = 4.0,
    max_steps: int = 30,
    workers: int = 2,
    progress: bool | Callable[[str], object] = True,
) -> ProfileResult:
    """Profile likelihoods of the parameters `names` (labels of `result`; default all) of a fit.

    For each, the other free parameters are re-fitted with it held at values stepping away from the fit on both
    sides, until Δχ² passes the `level` threshold (3.84 at 95 %) by half again, `max_points` points are taken,
    another parameter reaches a bound of its range, or the step has gone `span` from the fit in the fit's scaled
    coordinates (4: a factor e⁴ ≈ 55 for a positive parameter fitted in log space). Steps start at 0.6 linearised
    standard errors and adapt to the profile's rise. Of a fit that ended "at bound", the parameters at a bound are
    held there while the others are profiled, and each is profiled inwards from its bound only (a one-sided
    interval; docs/identifiability.md).

    **Arguments:**

    - `result`: the `FitResult` of `pamjax.fit` (it carries the fitted model and its experiments).
    - `names`: labels to profile (e.g. `["friction.coulomb_force", "a2"]`); default every fitted parameter.
    - `experiments`: the experiments fitted (default: those the result carries).
    - `level`: of the likelihood-ratio interval; `max_points` per side; `span`; `max_steps`: Levenberg-Marquardt
      steps per point.
    - `workers`: threads running the branches (parameter × side) side by side; 1 runs them in turn.
    - `progress`: True prints one line per finished parameter, a callable gets each line (a string), False: none.

    **Returns:** a `ProfileResult` (`table()`, `plot(path)`, `to_json(path)`, `write(folder)`).
    """
    names, experiments = _validate(result, names, experiments, level, max_points, span, max_steps, workers)
    say = _sayer(progress)
    t_start = time.perf_counter()
    space = ParameterSpace(result.model, result.paths)
    theta = np.asarray(space.initial_theta())
    exps = tuple(e.bind(result.model) for e in experiments)
    ev = _Evaluator(space, exps, theta)
    threshold = chi2_quantile_1dof(level)
    settings = dict(threshold=threshold, overshoot=1.5, max_points=int(max_points), span=float(span), first_step=0.6,
                    max_steps=int(max_steps), ftol=1e-10, xtol=1e-10, gtol=1e-10)
    labels = list(space.labels)
    jobs = _branches(space, theta, ev, result, names, settings)
    done = _walk_all(jobs, names, int(workers), say)
    warnings = _not_a_minimum(jobs, done, space, labels, result.values)
    profiles = []
    for name in names:
        profiles.append(_profile(space, theta, result, name, [b for (n, _), b in zip(jobs, done) if n == name],
                                 threshold, warnings))
        if say:
            p = profiles[-1]
            say(f"{name}: {p.verdict}; {level:.0%} LR interval [{p.interval[0]:.6g}, {p.interval[1]:.6g}] "
                f"(linearised [{p.linearised[0]:.6g}, {p.linearised[1]:.6g}])")
    for w in warnings if say else ():
        say(f"WARNING: {w}")
    return ProfileResult(profiles=profiles, labels=names, level=level, threshold=threshold, sigma2=ev.sigma2,
                         cost=ev.cost, profile_s=time.perf_counter() - t_start, warnings=warnings)

