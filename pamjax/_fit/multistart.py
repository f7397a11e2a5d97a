"""`multistart` (many starts of one fit) and `fit_fleet` (one fit per set of experiments): many `fit`s, spread over
the processes of a multi-process run, every outcome gathered on every process.

Workflow only: each task is one call of `pamjax.fit`; fits of one problem structure share one compilation (`fit`'s
solver step takes the parameter space as an argument). With `jax.distributed` initialised, task i runs on process
i mod P, on that process's own default device; the outcomes (the `FitResult` fields, floats exact) are gathered
with `process_allgather`, so every process returns the same result.
"""

import dataclasses
import inspect
import json
import os
import pathlib
import time
import warnings
from collections.abc import Callable
from typing import Any

import equinox as eqx
import numpy as np

from .._core import jsonio
from .._core.custom_types import RealArrayLike, RealScalarLike, RealVectorLike
from .._core.errors import PamjaxInputError, PamjaxSolveError, check_count, check_progress, require_float64
from .diagnostics import check_identifiability_tol
from .experiment import Experiments
from .fit import FitResult, check_fit_inputs, fit
from .parameters import Free

DEFAULT_SPREAD = 0.5  # the draws' standard deviation in the unconstrained space: a factor ~1.65 for a positive one
DEFAULT_SEED = 0  # `multistart`'s seed: the same starts on every run unless another seed (or None) is given
_NOT_PASSED = ("out", "checkpoint", "resume", "overwrite", "progress")  # per-task files/output: not for many fits


@dataclasses.dataclass
class MultistartResult:
    """The outcome of `multistart`.

    - `best`: the `FitResult` of lowest final cost among the starts that finished (any status; see its `status`),
      `best_index` its start.
    - `results`: a `FitResult` per start (None where the start failed), `errors`: None or the failure's message
      per start ("PamjaxInputError: ..."), `starts`: the start values (n_starts × parameters, physical units, in
      the order of `labels`), `processes`: the process that ran each start.
    - `seed`: the seed the starts were drawn with (the one given, or with `seed=None` the fresh one drawn, process
      0's in a multi-process run): `multistart(..., seed=result.seed)` draws the same starts again; None where the
      starts were given as an array.
    """

    best: FitResult
    best_index: int
    results: list[FitResult | None]
    errors: list[str | None]
    starts: np.ndarray
    labels: list[str]
    processes: list[int]
    seed: int | None = None

    @property
    def costs(self):
        """Final cost per start (inf where it failed)."""
        return np.array([np.inf if r is None else r.cost for r in self.results])

    def table(self):
        """Text table: one row per start (cost, status, iterations, process), the best marked."""
        rows = [f"{'start':>5} {'cost':>14} {'iter':>5} {'proc':>4}  status"]
        for i, (r, e, p) in enumerate(zip(self.results, self.errors, self.processes)):
            mark = " *" if i == self.best_index else ""
            if r is None:
                rows.append(f"{i:>5} {'failed':>14} {'':>5} {p:>4}  {e}")
            else:
                rows.append(f"{i:>5} {r.cost:>14.6e} {r.iterations:>5} {p:>4}  {r.status}{mark}")
        return "\n".join(rows)

    def to_json(self, path: str | os.PathLike, overwrite: bool = False) -> pathlib.Path:
        """Write every start's result and error (floats exact); refuses to replace a file unless `overwrite`."""
        path = pathlib.Path(path)
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        data = dict(best_index=self.best_index, labels=self.labels, starts=self.starts.tolist(), seed=self.seed,
                    processes=self.processes, errors=self.errors,
                    results=[None if r is None else r.to_dict() for r in self.results])
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(jsonio.dumps(data, indent=1))
        return path


@dataclasses.dataclass
class FleetResult:
    """The outcome of `fit_fleet`: per member name, its `FitResult` (`results`, None where the fit failed), the
    failure's message (`errors`, None where it ran) and the process that ran it (`processes`)."""

    results: dict[str, FitResult | None]
    errors: dict[str, str | None]
    processes: dict[str, int]

    @property
    def failed(self):
        return [name for name, e in self.errors.items() if e is not None]

    def table(self):
        rows = [f"{'member':<24} {'cost':>14} {'iter':>5} {'proc':>4}  status"]
        for name, r in self.results.items():
            if r is None:
                rows.append(f"{name:<24} {'failed':>14} {'':>5} {self.processes[name]:>4}  {self.errors[name]}")
            else:
                rows.append(f"{name:<24} {r.cost:>14.6e} {r.iterations:>5} {self.processes[name]:>4}  {r.status}")
        return "\n".join(rows)


def _check_fit_options(fit_options):
    """The options passed to every `fit`: their names against `fit`'s signature, then their values as `fit` checks
    them before anything is set up, so that a bad value is one `PamjaxInputError` here, not a failed fit per task."""
    signature = inspect.signature(fit)
    known = set(signature.parameters) - {"model", "experiments", "free"}
    for key in fit_options:
        if key in _NOT_PASSED:
            raise PamjaxInputError(f"{key!r} is not passed to the individual fits (write the chosen result with "
                                   "its to_json; progress is per task here)")
        if key not in known:
            raise PamjaxInputError(f"unknown fit option {key!r}; valid: {sorted(known - set(_NOT_PASSED))}")
    options = {name: p.default for name, p in signature.parameters.items() if name in known} | fit_options
    check_count(options["max_steps"], "max_steps")  # as `fit` checks them
    check_identifiability_tol(options["identifiability_tol"])  # 2.0 was a failed fit per start ("every start failed")
    from .drive import choose_solver  # `fit`'s check of `solver`, and of ftol/xtol/gtol/stall_steps (by its solver)

    choose_solver(options["solver"], options["ftol"], options["xtol"], options["gtol"], options["stall_steps"],
                  None, None)


def _use_processes(distributed):
    import jax

    if distributed is None:
        return jax.process_count() > 1
    if not isinstance(distributed, bool):
        raise PamjaxInputError(f"distributed must be None, True or False, got {distributed!r}")
    return distributed and jax.process_count() > 1


def _run_fits(tasks, free, fit_options, spread_over_processes, progress, what):
    """Run `fit(model, experiments, free)` for each task (name, model, experiments): all here, or this process's
    share. Returns per task (FitResult or None, error message or None, the warnings its fit issued as (category
    name, message), process index), the same on every process."""
    import jax

    from .._core.distributed import gather_bytes, my_tasks

    me = jax.process_index()
    mine = my_tasks(len(tasks)) if spread_over_processes else range(len(tasks))
    check_progress(progress)  # before any fit
    say = (print if progress is True else progress) if progress else None
    local = {}
    for i in mine:
        name, model, experiments = tasks[i]
        start = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:  # re-issued by the caller for the fits it reports
            warnings.simplefilter("always")
            try:
                if isinstance(model, PamjaxInputError):  # a start that is no model (a NaN value): its failure
                    raise model
                res, err = fit(model, experiments, free, progress=False, **fit_options), None
            except Exception as exc:  # a failed task is recorded, the others go on
                res, err = None, f"{type(exc).__name__}: {exc}"
        local[i] = (res, err, [(w.category.__name__, str(w.message)) for w in caught])
        if say is not None:
            outcome = f"failed: {err}" if res is None else f"{res.status}, cost {res.cost:.6e}, {res.iterations} iter"
            where = f" on process {me}" if spread_over_processes else ""
            say(f"{what} {name} ({i + 1}/{len(tasks)}){where}: {outcome}, {time.perf_counter() - start:.2f} s")
    if not spread_over_processes:
        return [(*local[i], me) for i in range(len(tasks))]
    payload = {str(i): (None if r is None else _sent(r), e, w) for i, (r, e, w) in local.items()}
    outcomes = {}
    for process, blob in enumerate(gather_bytes(json.dumps(payload).encode())):
        for i, (d, e, w) in json.loads(blob).items():
            _, model, experiments = tasks[int(i)]
            outcomes[int(i)] = (None if d is None else _received(d, model, experiments), e, [tuple(x) for x in w],
                                process)
    return [outcomes[i] for i in range(len(tasks))]


def _sent(res):
    """A `FitResult` as JSON for the other processes: its stored fields and its predictions (floats exact through
    JSON: Python writes a float's shortest repr that reads back to the same bits; NaN where a sample was masked)."""
    predictions = {name: {c: np.asarray(v).tolist() for c, v in channels.items()}
                   for name, channels in res.predictions.items()}
    return dict(res.to_dict(), predictions=predictions)


def _received(d, model, experiments):
    """The `FitResult` of `_sent`'s dict, with what a single-process fit's result carries besides its stored fields
    (without them every process's `best` was refused by `profile_likelihood`, and its `predictions` were None): the
    fitted model (`apply` on the task's start model: the same bits, values being exact floats), the experiments as
    `fit` bound them to that model, and the predictions sent."""
    d = dict(d)
    predictions = d.pop("predictions")
    res = FitResult.from_dict(d)
    res.model = res.apply(model)
    listed = experiments if isinstance(experiments, (list, tuple)) else [experiments]  # as `fit` lists them
    res.experiments = tuple(e.bind(model) for e in listed)
    res.predictions = {name: {c: np.asarray(v, dtype=float) for c, v in channels.items()}
                       for name, channels in predictions.items()}
    return res


def _start_model(space, values):
    """The model at one start's `values`, or the `PamjaxInputError` that refuses them (a NaN in a given row): that
    start fails and is recorded, as a fit that fails, and the others go on."""
    try:
        return space.with_values(values)
    except PamjaxInputError as err:
        return err


def _reissue(caught, prefix=""):
    """Issue again the warnings a fit issued (category by name: pamjax's own, else Python's, else UserWarning)."""
    import builtins

    from . import parameters as _parameters, recording as _recording

    for category, message in caught:
        cls = next((c for c in (getattr(m, category, None) for m in (_parameters, _recording, builtins))
                    if isinstance(c, type) and issubclass(c, Warning)), UserWarning)
        warnings.warn(prefix + message, cls, stacklevel=3)


def _check_seed(seed):
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0):
        raise PamjaxInputError(f"seed must be None or an integer >= 0, got {seed!r}")


def _drawn_seed(seed, shared):
    """The seed the starts are drawn with: `seed`, or for None a fresh one (NumPy's entropy); when the starts are
    spread over processes, process 0's, sent to every process (each process drawing its own would fit starts that
    differ from the ones recorded)."""
    if seed is not None:
        return int(seed)
    entropy = int(np.random.SeedSequence().entropy)
    if not shared:
        return entropy
    from .._core.distributed import gather_bytes

    return int(gather_bytes(str(entropy).encode())[0])  # every process calls it: process 0's value on all


def _spread_values(space, spread):
    """`spread` (None: the default) as one standard deviation per parameter, or `PamjaxInputError` naming it."""
    n_params = space.size
    given = DEFAULT_SPREAD if spread is None else spread
    try:
        values = np.asarray(given, dtype=float)
    except (TypeError, ValueError):
        values = None
    if values is None or values.ndim > 1 or values.size not in (1, n_params) or \
            not np.all(np.isfinite(values) & (values >= 0)):
        raise PamjaxInputError(f"spread must be a number >= 0 or one per parameter ({n_params}: "
                               f"{space.labels}), got {spread!r}")
    return np.broadcast_to(values, (n_params,))


def _start_values(space, starts, seed, spread, shared=False):
    """((n_starts, n_params) physical start values, the seed they were drawn with): the model's own, then draws
    around it in the fit's unconstrained space (θ = θ₀ + spread · N(0, 1)), or the rows given (seed None).
    `shared`: the starts are spread over processes (a seed of None is then drawn once, on process 0). `spread`
    None: the default; a `spread`, or a `seed` other than the default 0, with rows given is refused (it would
    be ignored)."""
    n_params = space.size
    drawn_spread = _spread_values(space, spread)  # checked whatever the starts (-5 with rows given passed, unseen)
    if isinstance(starts, int | np.integer) and not isinstance(starts, bool):
        if starts < 1:
            raise PamjaxInputError(f"starts must be >= 1 (or an array of start values), got {starts}")
        spread = drawn_spread
        theta0 = np.asarray(space.initial_theta())
        seed = _drawn_seed(seed, shared)
        draws = np.random.default_rng(seed).standard_normal((int(starts) - 1, n_params))
        drawn = [np.asarray(space.physical(theta0 + spread * z)) for z in draws]
        return np.stack([np.asarray(space.initial_values()), *drawn]), seed  # start 0: the model's values, exactly
    values = np.asarray(starts, dtype=float) if not isinstance(starts, str) else None
    if values is None or values.ndim != 2 or values.shape[1] != n_params or values.shape[0] < 1:
        raise PamjaxInputError(f"starts must be a count or an array (n_starts, {n_params}) of start values for "
                               f"{space.labels}, got {np.shape(starts) if values is not None else starts!r}")
    ignored = [f"{name}={value!r}" for name, value, unset in (("spread", spread, spread is None),
                                                               ("seed", seed, isinstance(seed, int | np.integer)
                                                                and seed == DEFAULT_SEED)) if not unset]
    if ignored:
        raise PamjaxInputError(f"{' and '.join(ignored)}: spread and seed draw the starts, and the starts are given "
                               f"as an array ({values.shape[0]} rows); drop them, or pass starts as a count")
    return values, None


def multistart(
    model: eqx.Module,
    experiments: Experiments,
    free: Free,
    *,
    starts: int | RealArrayLike = 8,
    seed: int | None = DEFAULT_SEED,
    spread: RealScalarLike | RealVectorLike | None = None,
    distributed: bool | None = None,
    progress: bool | Callable[[str], object] = True,
    **fit_options: Any,
) -> MultistartResult:
    """Fit the parameters named in `free` from many starts, and keep the best: a guard against local minima.

    Each start is one `pamjax.fit` of `model` with the free parameters set to the start's values, all else equal;
    the starts share one compilation. Start 0 is the model's own values; the others are drawn around them in the
    fit's unconstrained space, θ = θ₀ + `spread` · N(0, 1): for a positive parameter (log transform) a factor
    e^(spread·z), for a bounded one a shift of its logit, for a signed one a shift of `spread` times its start
    magnitude. A start that fails (bad start values, a solve that breaks, a NaN cost) is recorded with its
    message and the others go on. With `jax.distributed` initialised (`pamjax.runtime.initialize_distributed`), the
    starts are spread over the processes (start i on process i mod P), each process fitting its own on its own device,
    and every result is gathered on every process: the same result as in one process, bitwise.

    **Arguments:**

    - `model`, `experiments`, `free`: as for `pamjax.fit`.
    - `starts`: the number of starts (default 8), or an array (n_starts, n_params) of physical start values in
      the order of `ParameterSpace(model, free).labels` (e.g. a Latin hypercube of your own).
    - `seed`: the NumPy seed of the drawn starts, an integer >= 0 (the same starts on every process and every run),
      or None for fresh ones each run (drawn once, on process 0, when the starts are spread over processes: the
      same starts on every process); the seed used is `result.seed`.
    - `spread`: standard deviation of the draws in the unconstrained space (default None: 0.5, a factor ~1.65 for
      positive parameters), a number or one per parameter. With `starts` an array, neither `spread` nor a `seed`
      (other than the default 0) may be given: nothing is drawn.
    - `distributed`: None (default: spread over the processes when there are several), or False (every process
      runs every start).
    - `progress`: True prints one line per finished start (from the process that ran it), a callable gets that
      line, False is silent.
    - `**fit_options`: passed to every `fit` (`max_steps`, tolerances, `stall_steps`, `identifiability_tol`, ...;
      checked against `fit`'s signature); not `out`, `checkpoint` or `resume` (write the best with
      `result.best.to_json`).

    **Returns:** a `MultistartResult`: `best` (a `FitResult`, lowest cost among the starts that finished),
    `best_index`, `results` and `errors` per start, `starts`, `labels`, `processes`; `table()` lists them.

    **Raises:** `PamjaxInputError` for bad arguments (before any fit); `PamjaxSolveError` if every start failed
    (with each start's message). The warnings `fit` issues (identifiability) are issued once, for the best start.
    """
    require_float64("pamjax.multistart")
    _check_fit_options(fit_options)
    _check_seed(seed)
    spread_over_processes = _use_processes(distributed)
    # the experiments and free parameters as `fit` checks them: one error here, not a failed fit per start
    _, space = check_fit_inputs(model, experiments, free, fit_options.get("max_steps", 1))
    values, seed = _start_values(space, starts, seed, spread, spread_over_processes)
    tasks = [(f"start {i}", _start_model(space, v), experiments) for i, v in enumerate(values)]
    outcomes = _run_fits(tasks, free, fit_options, spread_over_processes, progress, "multistart:")
    results, errors, caught, processes = (list(x) for x in zip(*outcomes))
    finished = [i for i, r in enumerate(results) if r is not None]
    if not finished:
        raise PamjaxSolveError("every start failed:\n" + "\n".join(f"  start {i}: {e}" for i, e in enumerate(errors)))
    best = min(finished, key=lambda i: (results[i].cost, i))
    _reissue(caught[best])
    return MultistartResult(best=results[best], best_index=best, results=results, errors=errors, starts=values,
                            labels=space.labels, processes=processes, seed=seed)


def fit_fleet(
    model: eqx.Module | dict[str, eqx.Module],
    fleet: dict[str, Experiments],
    free: Free,
    *,
    distributed: bool | None = None,
    progress: bool | Callable[[str], object] = True,
    **fit_options: Any,
) -> FleetResult:
    """Fit the same parameters to each member of a fleet (one muscle, valve or bench per set of experiments),
    one `pamjax.fit` per member, spread over the processes of a multi-process run like `multistart`.

    **Arguments:**

    - `model`: the start model of every member, or a dict {member name: its start model}.
    - `fleet`: {member name: its experiments (a list, or one `Experiment`)}.
    - `free`: as for `pamjax.fit` (the same for every member).
    - `distributed`, `progress`, `**fit_options`: as for `multistart`.

    **Returns:** a `FleetResult`: per member its `FitResult` (None where it failed), its error message (None where
    it ran) and the process that ran it; `table()` lists them. A failed member is recorded, not raised; the
    warnings of each member's fit are issued again, prefixed with its name.

    **Raises:** `PamjaxInputError` for bad arguments, before any fit.
    """
    require_float64("pamjax.fit_fleet")
    _check_fit_options(fit_options)
    if not isinstance(fleet, dict) or not fleet:
        raise PamjaxInputError(f"fleet must be a non-empty dict {{member name: experiments}}, got {type(fleet)}")
    if isinstance(model, dict):
        missing = sorted(set(fleet) - set(model))
        if missing:
            raise PamjaxInputError(f"model has no start model for fleet members {missing}")
    names = list(fleet)
    tasks = [(str(n), model[n] if isinstance(model, dict) else model, fleet[n]) for n in names]
    for name, member_model, experiments in tasks:  # as `fit` checks them: refused here, not a failed member
        try:
            check_fit_inputs(member_model, experiments, free, fit_options.get("max_steps", 1))
        except PamjaxInputError as err:
            raise PamjaxInputError(f"fleet member {name!r}: {err}") from None
    outcomes = _run_fits(tasks, free, fit_options, _use_processes(distributed), progress, "fleet: member")
    for name, outcome in zip(names, outcomes):
        _reissue(outcome[2], prefix=f"fleet member {name!r}: ")
    return FleetResult(results={n: o[0] for n, o in zip(names, outcomes)},
                       errors={n: o[1] for n, o in zip(names, outcomes)},
                       processes={n: o[3] for n, o in zip(names, outcomes)})
