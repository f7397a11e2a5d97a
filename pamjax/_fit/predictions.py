"""Predictions of a model for a list of experiments, in one compiled program: fixed-grid experiments of one system
structure share one integration loop (`pamjax._solve.synchronous.solve_runs`); `evaluate`, a model's errors against
them without fitting."""

from typing import Any

import equinox as eqx
import jax
import numpy as np

from .._core.errors import PamjaxSolveError, require_float64
from .._solve.run_outputs import run_trajectories
from .._solve.scaled import scaled
from .._solve.simulate import fixed_trajectory
from .._solve.synchronous import solve_runs
from .diagnostics import channel_errors
from .experiment import Experiments
from .fit_checks import check_experiments
from .parameters import strong_types


def predict_all(model, experiments):
    """Every experiment's predictions (traceable), in order. Fixed-grid experiments whose systems share one
    structure (e.g. six tank tests, or a muscle's triangle runs) are integrated in ONE loop (`solve_runs`), so the
    compiled program does not grow with their number."""
    preds = [None] * len(experiments)
    groups = {}
    for i, e in enumerate(experiments):
        key = e.batch_key(model)
        if key is None:
            preds[i] = e.predict(model)
        else:
            groups.setdefault(key, []).append(i)
    for (stepping, substeps, _), members in groups.items():
        exps = [experiments[i] for i in members]
        for i, pred in zip(members, _predict_runs(model, exps, stepping, substeps)):
            preds[i] = pred
    return preds


@eqx.filter_jit
def _predictions(model, exps):
    return predict_all(model, exps)


def predictions(model: eqx.Module, experiments: Experiments) -> list[dict[str, np.ndarray]]:
    """`model`'s channels at every experiment's times (list of dicts channel → NumPy array), in one compiled
    program (experiments of one kind share one loop, as in a fit). Checks the experiments first (as `fit` does).

    **Raises:** `PamjaxInputError` for bad experiments; `PamjaxSolveError` naming the experiment, the cause and the
    remedy where an experiment's solve fails (its predictions would be NaN)."""
    require_float64("pamjax.predictions")
    experiments = check_experiments(experiments, model)
    for e in experiments:
        e.check(model)
    model = strong_types(model)
    exps = tuple(e.bind(model) for e in experiments)
    preds = [jax.tree_util.tree_map(np.asarray, p) for p in _predictions(model, exps)]
    check_solved(model, exps, preds)
    return preds


def evaluate(model: eqx.Module, experiments: Experiments) -> dict[str, dict[str, dict[str, Any]]]:
    """Per-channel errors of `model` against `experiments` without fitting: experiment → channel → rmse, max error,
    % of range, noise, residual whiteness (as `FitResult.channel_errors`). One compiled program for all of them.
    Raises as `predictions` does (a failed solve is a `PamjaxSolveError`, not an rmse of NaN)."""
    experiments = check_experiments(experiments, model)
    preds = predictions(model, experiments)
    r = np.concatenate([np.asarray(e.residuals_of(p, "all")) for e, p in zip(experiments, preds)])
    return channel_errors(experiments, r)


def check_solved(model, exps, preds):
    """A `PamjaxSolveError` naming each experiment of `exps` whose predictions `preds` are not finite at its used
    samples: a failed solve gave NaN predictions silently (`evaluate` then reported an rmse of NaN and residual
    autocorrelations of 0, "white"). The cause and remedy are `solve_failure`'s, as `fit`'s start check says them."""
    from .problem import solve_failure  # (here: problem imports this module)

    phrases = []
    for e, p in zip(exps, preds):
        r = np.asarray(e.residuals_of(p, "all"))
        used = np.concatenate([np.ravel(u) for _, _, _, u, _ in e.layout()])
        if np.all(np.isfinite(r[used] if used.shape == r.shape else r)):
            continue
        failure = solve_failure(e, model)
        if failure is None:
            phrases.append(f"experiment {e.name!r}: its predictions are not finite though its solve alone succeeds "
                           "(check the model's parameters and the experiment's initial state)")
            continue
        cause, budget = failure
        fix = ("check its parameters and initial state" if budget is None else
               f"raise its max_steps (e.g. Experiment(..., max_steps={budget})) or shorten the run")
        phrases.append(f"experiment {e.name!r}: its solve fails: {cause}: {fix}")
    if phrases:
        raise PamjaxSolveError("the model's predictions are not finite: " + "; ".join(phrases))


def _predict_runs(model, exps, stepping, substeps):
    systems = [e.system_for(model) for e in exps]
    y0s = [e.start_for(s, model) for s, e in zip(systems, exps)]
    times = [e.sample_times(model) for e in exps]
    flats = [scaled(s, y0) for s, y0 in zip(systems, y0s)]
    sizes = [e.grid_size(s, stepping) for s, e in zip(systems, exps)]
    runs = solve_runs(systems, [e.signal for e in exps], times, [f[0] for f in flats], flats[0][1],
                      [e.t0 for e in exps], stepping=stepping, substeps=substeps, sizes=sizes)
    if len(exps) == 1:
        trajectories = [fixed_trajectory(systems[0], exps[0].signal, times[0], exps[0].t0, *runs[0], stepping)]
    else:  # the outputs traced once for all runs, not once per run (pamjax._solve.run_outputs)
        trajectories = run_trajectories(systems, [e.signal for e in exps], times, runs, [e.t0 for e in exps], stepping)
    return [e.observe(model, {c: traj.channel(c) for c in traj.channels()}) for e, traj in zip(exps, trajectories)]


@eqx.filter_jit
def _predict(model, experiment):
    return experiment.predict(model)


def predict(model, experiment):
    """`experiment.predict(model)`, jitted (one compile per experiment structure, shared by check and reports)."""
    return _predict(model, experiment.bind(model))
