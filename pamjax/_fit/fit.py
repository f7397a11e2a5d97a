"""`fit`: least-squares identification of named parameters of a model against experiments.

Workflow only: the physics lives in the components; the residuals come from `Experiment.residuals`; the iteration
is an optimistix least-squares solver — pamjax's `LevenbergMarquardt` (`pamjax._fit.solver`), driven from the host
around two compiled functions per problem structure, the residuals and their forward-mode Jacobian, or any other
through `optimistix.least_squares` on the same two programs; the statistics and the mismatch diagnostics are in
`pamjax._fit.diagnostics`.
"""

import dataclasses
import importlib
import json
import math
import os
import pathlib
import re
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import equinox as eqx
import numpy as np

from .._core import jsonio
from .._core.cache import cache_turned_off, program_cache
from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError
from .._files.checkpoint import read_checkpoint, write_checkpoint
from .._files.fingerprint import check_resume, fingerprint
from .._files.model_file import FORMAT as MODEL_FORMAT, replace_text
from .diagnostics import (
    channel_errors,
    check_identifiability_tol,
    covariance,
    identifiability,
    identifiability_notes,
    mismatch,
    stopped_at_bound,
)
from .experiment import AbstractExperiment, Experiments
from .fit_checks import check_fit_inputs as check_fit_inputs, check_free, check_settings, validate_fit
from .force_balance import weak_motion
from .measurement import contradictions
from .parameters import Free, PamjaxIdentifiabilityWarning, ParameterSpace
from .predictions import evaluate as evaluate
from .problem import Problem
from .rig_hints import nuisance_hints

if TYPE_CHECKING:  # annotations only: importing optimistix costs ~0.3 s that a fit from the cache never needs
    import optimistix as optx

# FitResult's fields that hold numbers (written "inf" / "nan" where not finite: strict JSON)
_NUMERIC_FIELDS = ("values", "initial_values", "standard_errors", "correlation", "cost", "initial_cost",
                   "channel_errors", "history", "fit_s", "compile_s")

# paths of the parameters a payload's motion determines: the muscle's force law and the friction (`weak_motion`
# checks the data where one of them is free)
_MOVES_WITH_THE_PAYLOAD = re.compile(r"(^|\.)(force_law|friction)\.")

# `fit`'s progress: True prints, False is silent, a callable gets (step, cost, damping, accepted); None: as False,
# but the first compilation is announced (`staged_start`'s stages)
Progress = bool | Callable[[int, float, float, bool], object] | None


@dataclasses.dataclass
class FitResult:
    """The outcome of `fit`. Physical values in SI units (F_max as a0…a4 [N/mⁱ], eq. 13 as m1…m9).

    - `labels`, `paths` (the `free` spec), `values`, `initial_values`, `standard_errors` (inf for parameters in a
      non-identifiable combination, that the data do not see, or stopped at a bound of their range), `correlation`
      (matrix; NaN off the diagonal in the rows and columns of those with an infinite standard error: their direction
      is left out, nothing to correlate).
    - `cost` ½Σr² at the end (r = (model − data)/scale), `initial_cost`, `iterations` (trial steps),
      `accepted_steps`, `status` ('converged', 'at bound', 'stalled', 'max_steps'), `converged`, `message` (why it
      stopped).
    - `channel_errors`: experiment → channel → rmse, max_error, range, rmse_percent, max_error_percent (of the
      data's range, as paper 000 reports them), the same with `validation_` for the held-out part, and the residual
      diagnostics of `pamjax._fit.diagnostics` (noise, rmse_over_noise, autocorrelation, se_inflation).
    - `mismatch`: True when some channel's residuals are not noise at the stated level (`pamjax._fit.diagnostics`:
      correlated in time, when the standard errors understate the uncertainty by `se_inflation`, or white but above
      the stated noise, when they do not; the note, which says which, is in `warnings`).
    - `non_identifiable`: lists of labels whose combination the data do not fix; `warnings`.
    - `diagnosis`: where `mismatch` is flagged, what the residuals point to among a real rig's nuisances (an offset
      at rest, an acquisition lag, a start not at rest, per-run supply pressures; `pamjax._fit.rig_hints`), each with
      the option that frees it.
    - `history`: per iteration [step, cost at the current point, damping λ, accepted].
    - `fit_s`, `compile_s`: wall time of the fit without compilation, and the compilation (each compiled
      function's first call less its median later call).
    - `model`: the fitted model (not stored in JSON; `apply(base_model)` rebuilds it); `predictions`: experiment →
      channel → the fitted model at the recording's times (NaN where a sample was masked; not stored in JSON);
      `experiments`: the experiments as fitted (not stored in JSON; `pamjax.profile_likelihood` re-optimises
      against them).
    """

    labels: list
    paths: list
    values: list
    initial_values: list
    standard_errors: list
    correlation: list
    cost: float
    initial_cost: float
    iterations: int
    accepted_steps: int
    status: str
    converged: bool
    message: str
    channel_errors: dict
    mismatch: bool
    non_identifiable: list
    warnings: list
    history: list
    fit_s: float
    compile_s: float
    num_residuals: int
    diagnosis: list = dataclasses.field(default_factory=list)  # what a mismatch's residuals point to (rig_hints)
    model: eqx.Module | None = dataclasses.field(default=None, repr=False, compare=False)
    predictions: dict | None = dataclasses.field(default=None, repr=False, compare=False)
    experiments: Sequence[AbstractExperiment] | None = dataclasses.field(default=None, repr=False,
                                                                         compare=False)  # as fitted (profiles)

    def to_dict(self):
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name not in ("model", "predictions", "experiments")}

    def __eq__(self, other: object) -> bool:
        """Every stored field (`to_dict`'s), floats exactly and NaN equal to NaN (the correlations of a parameter
        with an infinite standard error; a noise not estimated): a fit.json read back equals its result."""
        if not isinstance(other, FitResult):
            return NotImplemented
        return jsonio.dumps(self.to_dict()) == jsonio.dumps(other.to_dict())

    __hash__ = None  # mutable, as the dataclass's own equality left it

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FitResult":
        if not isinstance(d, dict) or d.get("format") == MODEL_FORMAT:  # a model.json's TypeError named `format`
            raise PamjaxInputError("not a fit result (fit.json): " + (
                "a model file (model.json): read it with pamjax.load_model; pamjax fit writes the FitResult to "
                "fit.json beside it" if isinstance(d, dict) else f"a {type(d).__name__}, not a dict of its fields"))
        d = dict(d)
        for name in _NUMERIC_FIELDS:  # "inf", "nan" (strict JSON) back to floats
            if name in d:
                d[name] = jsonio.numbers(d[name])
        d.setdefault("message", d.get("status", ""))  # results written before these fields existed
        d.setdefault("mismatch", False)
        try:
            return cls(**d)
        except TypeError as err:  # a field unknown or missing, named by the message
            raise PamjaxInputError(f"not a fit result (fit.json): {err}") from None

    def to_json(self, path: str | os.PathLike, overwrite: bool = False) -> pathlib.Path:
        """Write the result (floats exact via repr); refuses to replace an existing file unless `overwrite`. Through a
        temporary file renamed over `path`: a crash while overwriting leaves the previous fit.json whole."""
        path = pathlib.Path(path)
        if path.is_dir():  # with overwrite=True a raw IsADirectoryError from os.replace (as save_model refuses it)
            raise PamjaxInputError(f"FitResult.to_json: {path} is a folder; give the file's path (e.g. "
                                   f"{path / 'fit.json'})")
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        return replace_text(path, jsonio.dumps(self.to_dict(), indent=1))  # strict JSON: "inf" for an undetermined SE

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> "FitResult":
        try:
            return cls.from_dict(json.loads(pathlib.Path(path).read_text(encoding="utf-8-sig")))  # BOM: as load_model
        except (PamjaxInputError, json.JSONDecodeError, UnicodeDecodeError) as err:
            raise PamjaxInputError(f"{path}: {err}") from None

    def apply(self, model: eqx.Module) -> eqx.Module:
        """`model` with the fitted values set (the free spec in `paths`)."""
        return ParameterSpace(model, self.paths).with_values(np.asarray(self.values, dtype=float))

    def table(self, truth: dict[str, float] | None = None) -> str:
        """Text table: label, (true), initial, fitted ± standard error; `truth` by label (others refused)."""
        if truth is not None and (unknown := sorted(set(truth) - set(self.labels))):  # was printed as NaN
            raise PamjaxInputError(f"table: truth has label(s) {unknown} that the fit does not have: {self.labels}")
        head = f"{'parameter':<44}" + (f"{'true':>14}" if truth is not None else "") + f"{'initial':>14}{'fitted':>14}"
        rows = [head + f"{'± std err':>12}"]
        for i, label in enumerate(self.labels):
            t = "" if truth is None else f"{truth.get(label, float('nan')):>14.6g}"
            rows.append(f"{label:<44}{t}{self.initial_values[i]:>14.6g}{self.values[i]:>14.6g}"
                        f"{self.standard_errors[i]:>12.3g}")
        return "\n".join(rows)


def _setup(model, experiments, space):
    """The experiments checked against `model` and bound to it (PWM grids sized), the start θ and the
    compiled-function host of a fit (`Problem`)."""
    for e in experiments:
        e.check(model)
    exps = tuple(e.bind(model) for e in experiments)
    theta = np.asarray(space.initial_theta())
    check_start(space, theta)  # a parameter started on a bound of its logistic's range, named with its value
    return exps, theta, Problem(space, exps)


def check_start(space: ParameterSpace, theta: np.ndarray) -> None:
    """Refuse a start `theta` (`space.initial_theta()`) that is not finite, naming only the parameters at fault, their
    start values and the range their transform maps onto (`PamjaxInputError`): a Bouc–Wen exponent freed at Dahl's
    n = 1 is on the bound of its logistic's open range (1, 10) (the whole θ was listed, with no word of the bound)."""
    theta, values, lines, k = np.asarray(theta, dtype=float), np.asarray(space.initial_values()), [], 0
    for g in space.groups:
        for label, v, t, lo, hi in zip(g.labels, values[k:k + g.size], theta[k:k + g.size], np.asarray(g.lower),
                                       np.asarray(g.upper)):
            if g.transform == "logistic" and not np.isfinite(t):  # on (or past) a bound: θ = ±inf
                inside = lo + 0.01 * (hi - lo) if v <= lo else hi - 0.01 * (hi - lo)
                lines.append(f"{label} = {v:g} is {'on the bound' if v in (lo, hi) else 'outside'} of its range "
                             f"({lo:g}, {hi:g}), an open interval (the logistic transform reaches a bound only at "
                             f"θ = ±inf): free it from a value inside, e.g. {inside:.4g}, or keep it fixed")
            elif not np.isfinite(t):
                lines.append(f"{label} = {v:g} has no finite θ under its {g.transform} transform")
        k += g.size
    if lines:
        raise PamjaxInputError("start values give non-finite transformed parameters (outside the range a free "
                               "parameter's transform maps onto):\n  "
                               + "\n  ".join(lines))


def precompile(model, experiments, free):
    """Compile (or load from the CLI's cache) the programs `fit(model', experiments, free)` will use, for any
    `model'` of `model`'s structure: the residuals, their Jacobian and the statistics' transform, each evaluated
    once at `model`'s values. Returns the wall time [s]. `staged_start` runs this in a second thread while its
    stages fit, so that the joint fit after them starts at once."""
    t0 = time.perf_counter()
    experiments = validate_fit(experiments, 1, None, False, None, None)
    _, theta, problem = _setup(model, experiments, ParameterSpace(model, free))
    problem.start(theta)
    return time.perf_counter() - t0


def start_cost(model, experiments, free):
    """½Σr² of `fit(model, experiments, free)` at its start (one evaluation of the residuals, the program
    `precompile` compiles); inf where the start's simulation fails."""
    experiments = validate_fit(experiments, 1, None, False, None, None)
    _, theta, problem = _setup(model, experiments, ParameterSpace(model, free))
    r = problem.residuals(theta)
    return np.inf if r is None else 0.5 * float(r @ r)


def _progress_printer(progress):
    if callable(progress):
        return progress
    if not progress:
        return None

    def report(step, cost, damping, accepted):
        if math.isnan(damping):  # another optimistix solver: one line per evaluation, lower than all before or not
            print(f"  eval {step:4d}  cost {cost:.6e}  {'lowest yet' if accepted else 'not lower'}", flush=True)
            return
        verdict = "accepted" if accepted else "rejected"
        print(f"  iter {step:4d}  cost {cost:.6e}  damping {damping:.3e}  {verdict}", flush=True)

    return report


def _status(state, space, theta):  # state: a `solver.Outcome`
    """(status, converged, message) from the final iteration state."""
    if not state.done:
        return "max_steps", False, "the iteration budget (max_steps) ran out before convergence"
    if state.reason.startswith("converged"):
        at_bound = [label for label, hit in zip(space.labels, space.at_bound(theta)) if hit]
        if at_bound:
            return "at bound", False, (f"{state.reason}, with {', '.join(at_bound)} at the bound of its range: the "
                                       "data pull it outside the physical range the fit allows")
        return "converged", True, state.reason
    return "stalled", False, state.reason


def fit(
    model: eqx.Module,
    experiments: Experiments,
    free: Free,
    *,
    max_steps: int = 100,
    ftol: float | int = 1e-10,
    xtol: float | int = 1e-10,
    gtol: float | int = 1e-10,
    progress: Progress = True,
    identifiability_tol: RealScalarLike = 1e-6,
    stall_steps: int = 8,
    out: str | os.PathLike | None = None,
    overwrite: bool = False,
    checkpoint: str | os.PathLike | None = None,
    resume: str | os.PathLike | None = None,
    solver: "optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser | None" = None,
    warn: bool = True,
) -> FitResult:
    """Fit the parameters named in `free` of `model` to `experiments` by nonlinear least squares.

    Minimises ½ Σ rᵢ² over all experiments' residuals r = (model − data) / scale (identification part only) by an
    optimistix least-squares solver, by default pamjax's `LevenbergMarquardt` (Nielsen's damping, Moré's scaling,
    geodesic acceleration; `pamjax._fit.solver`), with Jacobians in forward mode through the solves. Parameters
    are fitted in an unconstrained, O(1)-scaled space (`pamjax.ParameterSpace`): log for physically positive
    quantities (volumes, areas, conductances, friction: a trial value is never ≤ 0), a logistic over the range
    their component accepts for bounded ones (critical ratios, discharge coefficients, the polytropic index), a
    scale by the starting magnitude for signed coefficients, and the quartic F_max of eq. 7 as its values at five
    nodes over the stroke (reported as a0…a4). A trial step whose simulation fails (non-finite residuals) is
    rejected, never fatal.

    **Arguments:**

    - `model`: the object whose parameters are fitted (e.g. a `MuscleSystem`; valve tests use its valve).
    - `experiments`: a list of `Experiment` / `ForceMapExperiment`.
    - `free`: parameter paths, e.g.
      `["valve.inflate.discharge_coefficient", "muscle.force_law.max_force_coefficients"]`,
      or dicts `{"path": ..., "transform": "log"|"linear"|"logistic"|"nodes", "bounds": (lo, hi), "scale": s}`
      (bounds apply through the logistic transform, their default; with another one they are refused).
    - `max_steps`: trial steps at most. `ftol`, `xtol`, `gtol`: convergence on the relative cost decrease (actual
      and predicted), on the scaled step, and on the gradient's cosine with the residuals (MINPACK's tests).
    - `stall_steps`: rejected trials in a row after which a fit whose step has shrunk below `xtol` while the local
      model still promises a decrease stops as 'stalled' (the Jacobian is then checked against the cost and the
      result says by how much they disagree). Rejections alone never stop a fit before its first accepted step.
    - `solver`: None (pamjax's `LevenbergMarquardt(ftol, xtol, gtol, stall_steps)`, run from the host: no program
      besides the residuals and their Jacobian is compiled), a `pamjax.LevenbergMarquardt` of your settings, or any
      optimistix least-squares solver or minimiser (e.g. `optimistix.LevenbergMarquardt(rtol=1e-8, atol=1e-8)`),
      run by `optimistix.least_squares` on a function whose value and forward-mode derivative are the same two
      compiled programs (its loop is compiled too, with the programs as host callbacks: not kept by the persistent
      cache); it stops by its own tests ('converged' when it reports success), and takes no `ftol`, `xtol`, `gtol`,
      `stall_steps`, `checkpoint` or `resume`. Progress then prints one line per evaluation.
    - `progress`: True prints one line per iteration (cost, damping, accepted); a callable gets
      (step, cost, damping, accepted); False is silent; None prints only the notice of a first compilation.
    - `identifiability_tol`: a number in (0, 1): a parameter whose Jacobian column (in θ) is at most this × the
      largest has no effect on the data, and singular values of the others' column-normalised Jacobian below this ×
      the largest mark a non-identifiable combination (both warned about by name; their parameters get infinite
      standard errors); the covariance is computed in the same column-normalised coordinates, these left out.
    - `out`: a JSON path to write the result to; checked BEFORE the fit (a file path, in a writable folder or one
      that can be made there); never replaced unless `overwrite=True`.
    - `checkpoint`: an `.npz` path written (atomically) after every iteration with the whole iteration state.
      Never replaces an existing file unless `overwrite=True` or it is the `resume` file.
    - `resume`: an `.npz` checkpoint of this same problem: the fit continues from it and ends bitwise where an
      uninterrupted fit with the same `max_steps` ends (values, cost, iterations, history). The checkpoint carries a
      fingerprint of the start model, free spec, experiments and data (`pamjax._files.fingerprint`): a resume of another
      problem is refused before any solve, saying what differs.
    - `warn`: also emit the result's warnings about identifiability (non-identifiable combinations, a payload that
      barely moves) as `PamjaxIdentifiabilityWarning`s; they are in `FitResult.warnings` either way (False: a fit
      inside a procedure that reports its own, e.g. the stages of `pamjax.staged_start`).

    **Returns:** a `FitResult`: values, standard errors, correlation, `status` ('converged', 'at bound',
    'stalled', 'max_steps') with `message` saying why, per-channel errors with the noise level and residual
    whiteness, `mismatch` (the residuals are not noise: the standard errors understate the uncertainty), the
    fitted `model`.

    **Raises:** `PamjaxInputError` for an unknown parameter (listing the valid ones) or bad experiment input, before
    any fit, and for an `out` or `checkpoint` that cannot be written (a folder, a path under a file);
    `FileExistsError` if `out` (or `checkpoint`) exists and `overwrite` is False.
    """
    experiments = validate_fit(experiments, max_steps, out, overwrite, checkpoint, resume)
    max_steps = int(max_steps)  # a NumPy integer (np.int64(40)) as well
    identifiability_tol = check_identifiability_tol(identifiability_tol)
    if solver is None:  # the default: its module (optimistix, lineax: ~0.1 s) is imported beside the set-up
        stall_steps = check_settings(ftol, xtol, gtol, stall_steps)
        beside = threading.Thread(target=importlib.import_module, args=(f"{__package__}.drive",), daemon=True)
        beside.start()
    else:  # an optimistix object: optimistix is imported
        from .drive import choose_solver

        solver, _ = choose_solver(solver, ftol, xtol, gtol, stall_steps, checkpoint, resume)
    space = check_free(model, experiments, free)
    print_ = fingerprint(model, experiments, free, solver)  # start model, free spec, experiments, data (None: default)
    if resume is not None:
        check_resume(resume, print_)  # before any solve: a checkpoint of another problem is refused, naming why
    labels = space.labels
    exps, theta, problem = _setup(model, experiments, space)
    used = int(np.count_nonzero(problem.mask))
    if used < len(labels):  # fewer equations than unknowns: no fit determines them, its statistics would be noise
        raise PamjaxInputError(
            f"the experiments give {used} residuals (samples × channels used for identification) for {len(labels)} "
            f"free parameters ({', '.join(labels)}): fewer data than unknowns cannot determine them; add samples or "
            "experiments, or free fewer parameters")
    problem.preload(theta)  # a second run's compiled programs, loaded while the solver's module is imported
    if solver is None:
        beside.join(timeout=10.0)  # ~0.1 s; an import thread blocked on a lock another thread kept (a signal raised
        # inside the import machinery) is left behind: this thread imports the module itself below
    from .drive import choose_solver, run_fit, run_optimistix, state_arrays, state_from_arrays

    solver, own = choose_solver(solver, ftol, xtol, gtol, stall_steps, checkpoint, resume)
    report = _progress_printer(progress)
    t_start = time.perf_counter()
    announce = resume is None and progress is not False and not problem.cached(theta)
    if announce:
        cache = ("cached afterwards" if program_cache() is not None
                 else "not kept: the compilation cache is off" if cache_turned_off()  # --no-cache
                 else "pamjax.runtime.enable_compilation_cache() keeps it")  # a Python program's default
        print(f"fit: {len(labels)} parameters, {len(exps)} experiments; compiling the residuals and their "
              f"Jacobian (first run; {cache}) ...", flush=True)
    if own:
        start = None if resume is None else state_from_arrays(solver, read_checkpoint(resume, labels, used))

        def save(y, state, history):
            write_checkpoint(checkpoint, labels, state_arrays(y, state, history), print_)

        outcome = run_fit(solver, problem, theta, max_steps, report, announce, start, save if checkpoint else None)
        extra_compile = 0.0
    else:
        outcome, extra_compile = run_optimistix(solver, problem, theta, max_steps, report, announce)
    res = _result(model, exps, free, space, outcome, identifiability_tol, problem, warn)
    res.compile_s = problem.compile_seconds() + extra_compile
    res.fit_s = time.perf_counter() - t_start - res.compile_s
    res.compile_s += problem.preload_s  # loading a second run's programs (before t_start)
    if out is not None:
        res.to_json(out, overwrite=overwrite)
    return res


def _predictions_from(exps, residuals):
    """experiment → channel → model values at the data's times, from the residuals of all samples (data + r scale;
    NaN where a sample was masked)."""
    out, k = {}, 0
    for e in exps:
        out[e.name] = {}
        for c, scale, data, used, _ in e.layout():
            r = np.asarray(residuals[k : k + data.size])
            k += data.size
            out[e.name][c] = np.where(used, data + r * scale, np.nan)
    return out


def _result(model, exps, free, space, state, identifiability_tol, problem, warn=True):
    from .drive import jacobian_check, statistics_jacobian  # optimistix's import only where a fit runs

    labels = space.labels
    theta = state.theta
    status, converged, message = _status(state, space, theta)
    if status == "stalled":
        mismatch_j = jacobian_check(state, problem.residuals)
        message += (f"; the Jacobian disagrees with the cost by {mismatch_j:.2g} (relative) along the steepest "
                    "descent" if mismatch_j > 1e-3 else "; the Jacobian agrees with the cost (a minimum to the "
                    "solver's precision, or a very flat valley)")
    jac, resid = statistics_jacobian(state, problem.jacobian)  # at a kink: a hair off it
    used = int(np.count_nonzero(np.any(jac != 0, axis=1) | (resid != 0)))
    hit = space.at_bound(theta)
    groups = identifiability(jac, labels, identifiability_tol, hit)
    pinned = stopped_at_bound(jac, labels, identifiability_tol, hit)  # a flat transform there, not blind data
    bad = sorted({label for g in groups for label in g} | set(pinned))
    values, g = problem.physical(theta)
    cov = g @ covariance(jac, state.cost, used, identifiability_tol) @ g.T
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    se = np.where(np.isin(labels, bad), np.inf, se)
    undetermined = np.isinf(se)  # its covariance entries are those of a direction left out: no correlation to show
    corr[undetermined, :] = corr[:, undetermined] = np.nan
    np.fill_diagonal(corr, 1.0)
    msgs = identifiability_notes(pinned, groups)
    for msg in msgs if warn else []:
        warnings.warn(msg, PamjaxIdentifiabilityWarning, stacklevel=3)
    fitted = space.with_values(np.asarray(values))
    r_all = problem.all_residuals(theta)
    errors = channel_errors(exps, r_all)
    flagged, note = mismatch(errors)
    predicted = _predictions_from(exps, r_all)
    diagnosis = nuisance_hints(fitted, exps, predicted, labels) if flagged else []
    if flagged:
        msgs.append(note + ("; the residuals point to " + "; ".join(diagnosis) if diagnosis else ""))
    msgs += contradictions(exps, errors)  # a parameter Measurement more than 3 uncertainties from its fitted value
    if any(_MOVES_WITH_THE_PAYLOAD.search(g.path) for g in space.groups):  # the force law or the friction is free
        for msg in weak_motion(fitted, exps):  # muscle runs that barely move: few samples fix them
            msgs.append(msg)
            if warn:
                warnings.warn(msg, PamjaxIdentifiabilityWarning, stacklevel=3)
    res = FitResult(
        labels=labels,
        paths=[e if isinstance(e, str) else {k: (list(v) if isinstance(v, tuple) else v) for k, v in e.items()}
               for e in free],
        values=[float(v) for v in values],
        initial_values=[float(v) for v in np.asarray(space.initial_values())],
        standard_errors=[float(v) for v in se],
        correlation=[[float(c) for c in row] for row in corr],
        cost=float(state.cost),
        initial_cost=float(state.history[0][1]),
        iterations=int(state.step),
        accepted_steps=int(state.accepted),
        status=status,
        converged=converged,
        message=message,
        channel_errors=errors,
        mismatch=flagged,
        non_identifiable=groups,
        warnings=msgs,
        history=state.history,
        fit_s=0.0,
        compile_s=0.0,
        num_residuals=used,
        diagnosis=diagnosis,
        model=fitted,
        predictions=predicted,
        experiments=exps,
    )
    if math.isnan(res.cost):
        raise RuntimeError("fit produced a NaN cost; this is a bug in pamjax")
    return res
