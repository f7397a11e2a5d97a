"""`design_experiment`: a PWM duty signal chosen by gradient to maximise what a recording will tell about named
parameters.

Workflow only: the objective (Fisher information through the solve, criteria, constraint penalties) is in
`design_objective`, everything before the first solve (checks, the valve's thresholds, limits, the start, defaults)
in `design_setup`, the result and its constraints report in `design_result`; the Jacobians of experiments already
in hand come from the fit's compiled residual function (`pamjax._fit.problem`); the iteration is a BFGS on the host
with a backtracking line search on the objective's value (one forward-mode Jacobian per trial) and a gradient only at
accepted points.
"""

import functools
import inspect
import math
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.custom_types import RealScalarLike, RealVectorLike
from .._core.errors import PamjaxInputError
from .._fit.experiment import AbstractExperiment, Experiments
from .._fit.parameters import Free
from .._fit.problem import failed_solves, physical_and_jacobian, residuals_and_jacobian, solve_failure
from .._physics.signals import AbstractSignal
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from . import design_objective as obj, design_points as pts
from .design_repair import search, start_within_limits
from .design_result import DesignResult, PamjaxDesignWarning, constraints_report, worst_violation
from .design_search import optimise
from .design_setup import (
    DESIGN_RATE,
    DESIGN_SUBSTEPS,
    DUTY_BAND,
    FIT_SUBSTEPS,
    MIN_FORCE,
    SETUP_ARGS,
    STROKE_MARGIN,
    designed_experiment,
    set_up,
    static_force_along,
    stroke_limits,
)
from .prior_fit import PriorFits, fit_information, split_prior


def information(space, theta, experiments, predictions=False, role="experiments", remedy=None):
    """Fisher information about θ of `experiments` (identification samples, as the fit uses them): JᵀJ of the
    scaled residuals at θ (the fit's compiled Jacobian, shared with fits of the same problem structure). With
    `predictions`, also each experiment's predicted channels {channel: values at its samples}, read back from the
    same residuals (data + scale · residual: no further solve, no further compilation). A failed solve is no
    information (its residuals are NaN, its Jacobian exact zeros): a `PamjaxInputError` naming `role`, the run and
    why (`failed_solves`; `remedy` its advice for runs without a max_steps of their own)."""
    model = space.with_values(physical_and_jacobian(space, device_array(theta))[0])  # compiled, not op by op
    exps = tuple(e.bind(model) for e in experiments)
    layouts = [e.layout() for e in exps]
    mask = np.concatenate([used & ident for layout in layouts for _, _, _, used, ident in layout])
    residuals, jac = (np.asarray(a) for a in residuals_and_jacobian(space, device_array(theta), exps))
    if not (np.all(np.isfinite(residuals[mask])) and np.all(np.isfinite(jac[mask]))):
        named = failed_solves(space, theta, exps, residuals[mask], remedy)
        raise PamjaxInputError(f"{role}: not counted as information, as its simulation at the design point fails: "
                               + (named or "non-finite residuals or Jacobian"))
    jac = jac[mask]
    if not predictions:
        return jac.T @ jac
    k, preds = 0, []
    for layout in layouts:
        pred = {}
        for name, scale, data, _, _ in layout:
            data = np.asarray(data, dtype=float)
            pred[name] = data + float(scale) * residuals[k:k + data.size]
            k += data.size
        preds.append(pred)
    return jac.T @ jac, preds


def _experiments(value, argument):
    """`prior` or `baseline` as a list of pamjax experiments (None stays None), or a `PamjaxInputError` naming it."""
    if value is None:
        return None
    value = list(value) if isinstance(value, (list, tuple)) else [value]
    for e in value:
        if not isinstance(e, AbstractExperiment):
            raise PamjaxInputError(f"{argument} must be pamjax experiments (Experiment, ...), got {type(e).__name__}")
    return value


def _floor(prior_info, base_info, margin):
    """Variances of θ the design must reach: those of a run carrying `margin`² times the baseline run's information
    about each parameter beyond the prior's, 1/v = 1/v_prior + margin² (1/v_baseline − 1/v_prior) (`margin` = 1:
    the baseline's variances; where the prior alone fixes a parameter as well as the baseline does, its own)."""
    v_base = variances(base_info)
    prior_precision = 1.0 / variances(prior_info)  # 0 where the prior leaves a parameter free
    gain = np.maximum(1.0 / v_base - prior_precision, 0.0)
    with np.errstate(divide="ignore"):  # inf (no floor) where neither the prior nor the baseline fixes a parameter
        return 1.0 / (prior_precision + margin**2 * gain)


def variances(info, transform=None):
    """Diagonal of G F⁺ Gᵀ (G = `transform`, default the identity): the Cramér-Rao variances, inf for every entry
    that moves along a direction F does not fix (an eigenvalue below 1e-9 of the largest)."""
    g = np.eye(info.shape[0]) if transform is None else np.asarray(transform)
    w, v = np.linalg.eigh(0.5 * (info + info.T))
    good = w > 1e-9 * max(float(w.max()), 1e-300)
    var = np.clip(np.diag(g @ ((v[:, good] / w[good]) @ v[:, good].T) @ g.T), 0.0, None)
    null = g @ v[:, ~good]
    loose = (np.abs(null).max(axis=1) > 1e-9 * np.abs(g).max(axis=1)) if null.size else np.zeros(var.shape, bool)
    return np.where(loose, np.inf, var)


def _physical_errors(space, theta, info):
    """Predicted standard errors in physical units (inf along directions the information does not fix)."""
    g = np.asarray(physical_and_jacobian(space, device_array(theta))[1])  # the fit's compiled Jacobian
    return [float(math.sqrt(v)) for v in variances(info, g)]


def _in_hand(space, theta, prior, baseline, index, margin, at_point=True):
    """(prior information, prior + baseline information or None, the variance floor on `index` or None); `prior`:
    (experiments, fits) (`prior_fit.split_prior`)."""
    n = len(space.labels)
    experiments, fits = prior
    prior_info = information(space, theta, experiments, role="prior") if experiments else np.zeros((n, n))
    prior_info = prior_info + fit_information(space, theta, fits, at_point)
    if baseline is None:
        return prior_info, None, None
    base_info = prior_info + information(space, theta, baseline, role="baseline")
    floor = np.full(n, np.inf)
    floor[list(index)] = _floor(prior_info, base_info, margin)[list(index)]
    return prior_info, base_info, floor


def _prepare(problem, gradient, c0, space, theta, prior, baseline, index, margin):
    """The design problem with the information in hand, compiling the gradient (the long pole) in a second thread
    meanwhile; checks that the start determines every parameter. Returns (problem, prior information, prior +
    baseline information or None, seconds to the first iteration, the objective's aux at the start)."""
    n = len(space.labels)
    placeholder = problem(np.eye(n), None if baseline is None else np.ones(n))
    warm = threading.Thread(target=lambda: jax.block_until_ready(gradient(jnp.asarray(c0), placeholder)), daemon=True)
    t_compile = time.perf_counter()
    warm.start()
    prior_info, base_info, floor = _in_hand(space, theta, prior, baseline, index, margin)
    prob = problem(prior_info, floor)
    start_value, start_aux = obj.value(jnp.asarray(c0), prob)
    warm.join()
    if not np.isfinite(float(start_value)):
        _failed_start(prob, start_aux, space, theta)
        loose = [lbl for lbl, v in zip(space.labels, variances(np.asarray(start_aux["information"]))) if np.isinf(v)]
        raise PamjaxInputError(f"initial: the start signal (with the prior experiments) does not determine {loose}, "
                               "so the criterion is undefined there. They enter the run, but not independently of "
                               "the other free parameters, or not at the start signal's duties: start from another "
                               "signal (`initial`, e.g. a constant duty in the middle of the band), add prior "
                               "experiments that fix them, or remove them from free")
    return prob, prior_info, base_info, time.perf_counter() - t_compile, start_aux


def _failed_start(prob, aux, space, theta):
    """A `PamjaxInputError` where the designed run's solve fails at the start signal (its predictions NaN: nothing
    determined, for want of a solve, not of information), saying why (`solve_failure`)."""
    if all(np.all(np.isfinite(np.asarray(aux[k]))) for k in ("position", "pressure") if aux.get(k) is not None):
        return
    model = space.with_values(physical_and_jacobian(space, device_array(theta))[0])
    failure = solve_failure(eqx.tree_at(lambda e: e.signal.values, prob.experiment, aux["duty"]), model)
    cause = "its predictions are not finite" if failure is None else failure[0]
    fix = ("design a shorter run (duration)" if failure and failure[1]  # its budget ran out (the Experiment's default)
           else "check the model's parameters and the start state")
    raise PamjaxInputError(f"duration: the designed run's solve fails at the start signal: {cause}; {fix}")


def _problem(space, theta, exp, basis, weight, band, windows, limits, max_pressure, max_duty_step, force_law,
             min_force, index, criterion, prior_info, floor, offset=None):
    """The design's `DesignProblem` with a prior information and a variance floor. An absent limit or floor is an
    infinite one (its penalty and worst violation are exactly 0), not None: the problem's structure, and so the
    compiled objective and gradient, is then the same whichever limits and baseline a design of this system,
    parametrisation and duration has (one compilation for all of them). `offset`: the envelope's fixed part of a
    given start (`design_setup.start_offset`)."""
    return obj.DesignProblem(
        space=space, theta=device_array(theta), experiment=exp,
        basis=None if basis is None else device_array(basis), prior=device_array(prior_info),
        weight=jnp.asarray(weight), band=jnp.asarray(band),
        windows=device_array(np.asarray(windows, dtype=float)) if len(windows) else None,
        stroke=None if limits is None else jnp.asarray(limits),
        max_pressure=jnp.asarray(np.inf if max_pressure is None else float(max_pressure)),
        max_step=jnp.asarray(np.inf if max_duty_step is None else float(max_duty_step)),
        min_force=(jnp.asarray(-np.inf if min_force is None else float(min_force)) if force_law else None),
        floor=device_array(np.full(len(space.labels), np.inf) if floor is None else floor), subset=index,
        criterion=criterion, offset=None if offset is None else device_array(offset))


def design_experiment(
    model: AbstractSystem,
    free: Free,
    duration: float | int,
    *,
    noise: dict[str, RealScalarLike],
    channels: Sequence[str] = ("pressure", "position"),
    start: dict[str, RealScalarLike] | None = None,
    build: Callable[[AbstractSystem], AbstractSystem] | None = None,
    rate: RealScalarLike = 1000.0,
    prior: Experiments | PriorFits = (),
    baseline: Experiments | None = None,
    baseline_margin: RealScalarLike = 1.0,
    criterion: Literal["D", "A"] = "D",
    subset: Sequence[str] | None = None,
    duty_band: Sequence[RealScalarLike] = DUTY_BAND,
    duty_margin: float | int | Literal["auto"] = "auto",
    stroke_margin: RealScalarLike = STROKE_MARGIN,
    max_pressure: RealScalarLike | None = None,
    max_duty_step: RealScalarLike | None = None,
    min_force: float | int | None = MIN_FORCE,
    parametrisation: Literal["envelope", "periods"] = "envelope",
    knots: int = 12,
    steps: int = 20,
    initial: AbstractSignal | RealVectorLike | None = None,
    seed: int = 0,
    period: float | int | None = None,
    design_rate: RealScalarLike = DESIGN_RATE,
    substeps: int = DESIGN_SUBSTEPS,
    verify: bool = True,
    spread: RealScalarLike | dict[str, RealScalarLike] | None = None,
    spread_points: int = pts.SPREAD_POINTS,
    progress: bool | Callable[..., object] = True,
) -> DesignResult:
    """Choose a PWM duty signal (one value per PWM period) that maximises the information a recording of
    `duration` seconds gives about the parameters `free` of `model`, under a bench's constraints.

    Maximises the Fisher information F = F_prior + Σ JᵀJ (J: the noise-scaled outputs' forward-mode Jacobian with
    respect to the fit's scaled parameters, through the solve) in the D sense (minimise log det F⁻¹ on `subset`) or
    the A sense (log tr F⁻¹), by BFGS with gradients through the solve, the PWM edges and the stick-slip events
    (`design_objective`), and seeded random probes where the cost's kinks stop the line search (`PROBES`). The
    design is local: it is optimal near the parameter values of `model`, from the start signal. Design at your best
    estimate — the fit of a short pilot run, not the datasheet: at the MAS-10 presets the payload rests 11 mm higher
    than on the bench plant, and a design there predicted gains on the force law's a3, a4 that the plant did not give
    (docs/identifiability.md).

    **Arguments:**

    - `model`: the system at the design point (e.g. `presets.mas10_system(valve="pwm", friction="karnopp")`); its
      valve's PWM frequency sets the period (`period` [s]: for a valve without one; another refused).
    - `free`: the parameters of interest, as `fit` takes them.
    - `duration`: of the designed run [s], from `start` (keyword arguments of the system's `initial_state`; default
      at rest at atmospheric pressure; checked as `simulate` checks a `y0`: a position inside the stroke).
    - `build`: model → the system the designed signal drives, as `Experiment(build=...)` takes it (default: `model`
      itself). E.g. `pamjax.TankFromModel(5e-5)` with `channels=("pressure",)` and `start={"pressure": 101325.0}`
      designs a constant-volume tank test of `model`'s valve: the test that separates the valve's flow scales from
      the muscle's volume, which no muscle run can (docs/identifiability.md). `free` are still `model`'s paths (name
      only those the built system depends on, e.g. the valve's); the stroke limit applies only to a system with a
      muscle and a `position` channel.
    - `noise`: channel → noise standard deviation of the bench [channel unit], e.g. `{"pressure": 2e3, "position":
      1e-4}`; `channels`: those recorded; `rate`: the recording's sample rate [Hz] (at least the PWM frequency: 1 kHz
      is 1000.0, not 1.0).
    - `prior`: experiments already in hand (or run anyway, e.g. constant-volume tank tests): their information is
      added (a muscle run alone cannot separate the valve's flow scale from the muscle's volume); or a fit of them
      (a `FitResult`, the path of its fit.json): its covariance's information, a rig's nuisances marginalised, which
      the experiments alone count as known (`prior_fit`).
    - `baseline`: experiments the design must match or beat on every parameter of `subset` (predicted standard
      errors); with `baseline_margin` m > 1 the designed run must carry m² times the baseline run's information on
      each of them beyond what `prior` gives (`_floor`); a penalty enforces it.
    - `criterion`: "D" (default) or "A"; `subset`: labels the criterion is on (default all).
    - `duty_band`: (lo, hi) duty the valve acts on (0.1, 0.9: paper 000); `duty_margin`: every period's duty is kept
      this far from the valve's switching thresholds (`switching_thresholds`: the duties below which a period does not
      open it and above which it does not close it, 0.1 and 0.9 for paper 000's valve), where whether a real valve
      switches is a coin toss; "auto" (default): a quarter of each threshold's distance from 0 or 1, i.e. of its own
      switching time (0.025 at 50 Hz and 2 ms: `DUTY_MARGIN_FRACTION`; t_off 4 ms: 0.05 at 0.8); 0 for none. The band
      less the margins (`duty_limits`) must be one interval. `stroke_margin` [m] kept from the end stops
      (`muscle.min_position`, `max_position`); `max_pressure` [Pa abs] (default none: a valve cannot exceed its supply);
      `max_duty_step`: largest duty change from one period to the next (default none); `min_force` [N]: eq. 7's force
      (the muscle's force law before the slack) kept at or above it along the run, so that the muscle stays in tension
      where its force law is backed by data (default `MIN_FORCE`, 20 N; None for no limit; only for a system with a
      muscle). Each limit is checked against the run's start before any solve (a limit the start breaks is refused,
      naming it); the design's `constraints` report them, and a design that ends outside one warns
      (`PamjaxDesignWarning`) and is refused by `to_csv`.
    - `parametrisation`: "envelope" (default: a level and an amplitude, `knots` cubic B-spline coefficients each,
      modulating a seeded multilevel carrier; gradient in forward mode, 2·knots tangents) or "periods" (one free value
      per period; gradient in reverse mode: exact but ~50× a Jacobian per step on a 2-core CPU for 33 s).
    - `steps`: BFGS iterations at most; `initial`: start signal (a pamjax signal or one duty per period, e.g. an
      earlier design's `duty`, started from as it is: under "envelope", the part its level cannot represent is kept
      as a fixed offset; default paper 000's E3 triangle with the carrier on top; where it breaks a limit, repaired
      or calmed, `design_repair`);
      `seed`: the carrier's and the probes'.
    - `design_rate` [Hz], `substeps`: resolution of the objective (docs/identifiability.md: within 0.2 % of the
      fit's); `verify`: recompute the final standard errors and the limits at the fit's resolution (16 substeps,
      `rate`); where the run there passes a limit that the objective's samples keep, the search goes on with that
      limit tightened (`design_repair.search`; the message says so).
    - `spread`: the plant's expected spread around `model` (a fraction for every free parameter, e.g. 0.2 for
      ±20 %, or {label: fraction}): the design is then scored at `spread_points` further design points drawn from it
      (a seeded Latin hypercube) beside the model's own, its objective the average of theirs (`design_points`): a
      design robust over the plant's spread, at (1 + `spread_points`)× the work per iteration. The limits are kept
      at the model's point; with a baseline, the design must beat it by `baseline_margin` there and match it (margin
      1) at every other point. The result's `points` report each point (its standard errors, and whether its plant
      would pass a limit). `steps=0` with a spread scores the start signal over the spread.
    - `progress`: True prints one line per iteration; a callable gets (iteration, objective, criterion, step,
      accepted); False is silent.

    **Returns:** a `DesignResult` (`signal()`, `to_csv`, `to_json`, `plot`, `table`).
    """
    t_start = time.perf_counter()
    prior, baseline = split_prior(prior), _experiments(baseline, "baseline")
    setup = set_up(model, free, duration, noise=noise, channels=channels, start=start, build=build, rate=rate,
                   criterion=criterion, subset=subset, duty_band=duty_band, stroke_margin=stroke_margin,
                   max_pressure=max_pressure, max_duty_step=max_duty_step, parametrisation=parametrisation,
                   knots=knots, steps=steps, initial=initial, seed=seed, period=period, design_rate=design_rate,
                   substeps=substeps, duty_margin=duty_margin, min_force=min_force, baseline_margin=baseline_margin)
    space, subset, c0 = setup["space"], setup["subset"], setup["c0"]
    theta = np.asarray(space.initial_theta())
    index = tuple(space.labels.index(s) for s in subset)
    point_values, thetas = pts.design_thetas(space, spread, spread_points, seed)  # checked before any solve
    problem = _problem_of(setup, theta, index, float(rate) / float(design_rate), max_pressure, max_duty_step,
                          criterion)
    gradient = obj.reverse_gradient if parametrisation == "periods" else obj.forward_gradient
    report = _printer(progress, f"design: {setup['count']} PWM periods, {len(c0)} coefficients ({parametrisation}), "
                                f"{criterion}-optimal over {len(subset)} of {len(space.labels)} parameters (objective: "
                                "the criterion plus the penalties of the limits" + " and the baseline's target"
                                * (baseline is not None) + "); compiling the objective and its gradient ...")
    prob, prior_info, base_info, compile_s, start_aux = _prepare(problem, gradient, c0, space, theta, prior, baseline,
                                                                 index, float(baseline_margin))
    points = [_at_point(setup, th, prior, baseline, index, min(float(baseline_margin), 1.0), stroke_margin,
                        _problem_of(setup, th, index, float(rate) / float(design_rate), max_pressure, max_duty_step,
                                    criterion)) for th in thetas]
    if points:  # the search: the points' criteria and targets, the limits at the model's point (`design_points`)
        prob = (prob, *(pts.without_limits(p) for p, _ in points))
        start_aux = pts.points_start(jnp.asarray(c0), prob)
    c0, note = (start_within_limits(prob, setup, parametrisation, float(duration), knots, seed, start_aux)
                if initial is None and worst_violation(start_aux) > 0 else (c0, ""))  # calmer, else repaired
    c, aux, history, message, errors, verified, tightened = search(
        np.asarray(c0, dtype=float), prob, gradient, steps, report, seed, setup, optimise,
        lambda a: _standard_errors(setup, a, theta, prior_info, base_info, verify, float(duration), float(rate),
                                   noise, build))
    nominal = prob[0] if points else prob
    if base_info is not None:  # what `baseline_margin` asks of each parameter of `subset` (inf elsewhere), physical
        errors["target"] = _targets(space, theta, nominal.floor, base_info)
    constraints = constraints_report(aux, setup, verified)
    _warn_undetermined([space.labels[i] for i in index if not math.isfinite(errors["design"][i])])
    if not constraints["feasible"]:
        warnings.warn("pamjax.design_experiment: the design violates its limits (a bench must not play it; to_csv "
                      "refuses it): " + "; ".join(constraints["violations"]), PamjaxDesignWarning, stacklevel=2)
    result = _result(setup, aux, history, errors, constraints, message + note + tightened, criterion, parametrisation,
                     float(duration), t_start, compile_s, designed_payload(model, setup["system"]))
    if points:
        result.points = _points_report(space, theta, point_values, thetas, [prob[0], *(p for p, _ in points)],
                                       [base_info, *(b for _, b in points)], c, aux)
    return result


def _warn_undetermined(loose):
    """A `PamjaxDesignWarning` naming the parameters of `subset` the design leaves free (infinite standard errors)."""
    if loose:
        warnings.warn(f"pamjax.design_experiment: the design with the prior leaves {loose} undetermined (infinite "
                      "predicted standard errors: a direction of the parameters the runs do not fix), so no ratio or "
                      "target says anything about them; design at a converged fit, or free fewer parameters",
                      PamjaxDesignWarning, stacklevel=3)


def designed_payload(model, system):
    """The payload [kg] the designed run carries where `build` made it another than the model's (a bench must load
    the rig so, and log it: `payload_kg`), else None."""
    if not (isinstance(system, AbstractMuscleSystem) and isinstance(model, AbstractMuscleSystem)):
        return None
    mass = float(system.payload_mass)
    return None if mass == float(model.payload_mass) else mass


def _problem_of(setup, theta, index, weight, max_pressure, max_duty_step, criterion):
    """`_problem` with all but the prior information and the variance floor bound: (prior, floor) → the problem."""
    return functools.partial(_problem, setup["space"], theta, setup["experiment"], setup["basis"], weight,
                             setup["band"], setup["windows"], setup["limits"], max_pressure, max_duty_step,
                             setup["force_law"], setup["min_force"], index, criterion, offset=setup["offset"])


def _at_point(setup, theta, prior, baseline, index, margin, stroke_margin, make):
    """The design problem at another design point θ (`make`: (prior information, floor) → problem): its own prior
    information, baseline target and stroke limits (its payload rests elsewhere); and its prior + baseline
    information (None without a baseline)."""
    space = setup["space"]
    prior_info, base_info, floor = _in_hand(space, theta, prior, baseline, index, margin, at_point=False)
    model = space.with_values(physical_and_jacobian(space, device_array(theta))[0])  # compiled, not op by op
    limits = stroke_limits(setup["experiment"].system_for(model), setup["start"], stroke_margin)
    return pts.with_stroke(make(prior_info, floor), limits), base_info


def _targets(space, theta, floor, base_info):
    """The standard errors [physical units] a variance floor on θ asks for (inf where none): the baseline's, each
    scaled as the floor scales the baseline's variance of its θ. Exactly √floor × |∂value/∂θ| where each value has a
    θ of its own; where a transform mixes them (a force law's a0…a4), the baseline's physical standard errors over the
    margin, as the table's ratio column reads (not that diagonal, which mixes units)."""
    base = np.asarray(_physical_errors(space, theta, base_info))
    with np.errstate(invalid="ignore"):  # inf / inf where the baseline leaves a parameter free: no target
        scale = np.sqrt(np.asarray(floor, dtype=float) / variances(base_info))
    return [float(b * f) if math.isfinite(f) and math.isfinite(b) else math.inf for b, f in zip(base, scale)]


def _points_report(space, theta, values, thetas, problems, base_infos, c, aux):
    """`DesignResult.points`: per design point (the model's first) its values, criterion, worst violation and
    predicted standard errors (design; baseline and target with a baseline), at the objective's resolution. Each
    other point's plant is evaluated at the design's limits (`problems`: with them); the model's is the search's."""
    auxes = [aux["points"][0], *(obj.value(jnp.asarray(c), p)[1] for p in problems[1:])]
    out = []
    for k, (th, vals, a) in enumerate(zip([theta, *thetas], [np.asarray(space.initial_values()), *values], auxes)):
        errors = {"design": _physical_errors(space, th, np.asarray(a["information"]))}
        if base_infos[k] is not None:
            errors["baseline"] = _physical_errors(space, th, base_infos[k])
            errors["target"] = _targets(space, th, problems[k].floor, base_infos[k])
        out.append(dict(values=[float(v) for v in vals], criterion=float(a["criterion"]),
                        worst_violation=worst_violation(a), standard_errors=errors))
    return out


def _standard_errors(setup, aux, theta, prior_info, base_info, verify, duration, rate, noise, build):
    """The predicted standard errors {"design", "prior", "baseline"} in physical units, and the designed run's channels
    at the fit's resolution (None without `verify`: then the design's own information, at the design's resolution)."""
    info, verified = np.asarray(aux["information"]), None
    if verify:  # at the fit's resolution (the Experiment's default substeps, the recording's rate)
        run_info, verified = _verified(setup, np.asarray(aux["duty"]), duration, rate, noise, build)
        info = prior_info + run_info
    errors = {key: _physical_errors(setup["space"], theta, i) for key, i in
              (("design", info), ("prior", prior_info), ("baseline", base_info)) if i is not None}
    return errors, verified


def _result(setup, aux, history, errors, constraints, message, criterion, parametrisation, duration, t_start,
            compile_s, payload_kg):
    """The `DesignResult` of the search's last point `aux` (its duty, criterion and predicted channels)."""
    space, exp = setup["space"], setup["experiment"]
    position, pressure, force = (aux.get(k) for k in ("position", "pressure", "force"))
    return DesignResult(
        times=[float(t) for t in setup["times"]], duty=[float(d) for d in np.asarray(aux["duty"])],
        period=setup["period"], labels=list(space.labels),
        values=[float(v) for v in np.asarray(space.initial_values())], subset=setup["subset"], criterion=criterion,
        standard_errors=errors,
        objective=[history[0][2], float(aux["criterion"])], history=history, constraints=constraints,
        parametrisation=parametrisation, iterations=len(history) - 1, message=message,
        design_s=time.perf_counter() - t_start, compile_s=compile_s, duration=duration, payload_kg=payload_kg,
        prediction=dict(t=np.asarray(exp.times), position=None if position is None else np.asarray(position),
                        pressure=None if pressure is None else np.asarray(pressure),
                        force=None if force is None else np.asarray(force)))


def _verified(setup, duty, duration, rate, noise, build):
    """The designed run at the fit's resolution (the Experiment's default substeps, the recording's rate): its
    information and its predicted channels, with eq. 7's force where the system has a muscle."""
    full = designed_experiment(setup["model"], duration, setup["period"], rate, setup["channels"], noise,
                               setup["start"], FIT_SUBSTEPS, duty, build)
    info, (verified,) = information(setup["space"], np.asarray(setup["space"].initial_theta()), [full],
                                    predictions=True, role="duration: the designed run at the fit's resolution",
                                    remedy="design a shorter run")
    if setup["force_law"] and {"position", "pressure"} <= set(verified):
        verified["force"] = np.asarray(static_force_along(setup["system"], device_array(verified["position"]),
                                                          device_array(verified["pressure"])))
    return info, verified


def check_design(model, free, duration, **kwargs):
    """Every check `design` makes before its first solve (the arguments, the valve's thresholds and the duties they
    leave, each limit against the run's start), without designing: a `PamjaxInputError` naming the argument, or
    None. `pamjax design` runs it before it makes the output folder."""
    known = set(inspect.signature(design_experiment).parameters) - {"model", "free", "duration"}
    unknown = sorted(set(kwargs) - known)
    if unknown:
        raise PamjaxInputError(f"unknown design argument(s) {unknown}")
    args = {k: v.default for k, v in inspect.signature(design_experiment).parameters.items()
            if k in known and k in SETUP_ARGS}
    args.update({k: v for k, v in kwargs.items() if k in SETUP_ARGS})
    setup = set_up(model, free, duration, **args)
    split_prior(kwargs.get("prior"))  # a fit's file read and checked
    pts.design_thetas(setup["space"], kwargs.get("spread"), kwargs.get("spread_points", pts.SPREAD_POINTS),
                      kwargs.get("seed", 0))


def _printer(progress, announce):
    """The per-iteration report `progress` asks for; True prints `announce` first."""
    if callable(progress):
        return progress
    if not progress:
        return None
    print(announce, flush=True)

    def report(it, objective, criterion, step, accepted, probe=False):
        print(f"  iter {it:3d}  objective {objective:.6f}  criterion {criterion:.6f}  step {step:.3g}  "
              f"{('accepted (a random probe past a kink)' if probe else 'accepted') if accepted else 'no descent'}",
              flush=True)

    report.says_probes = True
    return report
