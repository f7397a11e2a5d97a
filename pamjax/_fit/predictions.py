"""Predictions of a model for a list of experiments, in one compiled program: fixed-grid experiments of one system
structure share one integration loop (`pamjax._solve.synchronous.solve_runs`)."""

import equinox as eqx
import jax
import numpy as np

from .._core.errors import require_float64
from .._solve.run_outputs import run_trajectories
from .._solve.scaled import scaled
from .._solve.simulate import fixed_trajectory
from .._solve.synchronous import solve_runs
from .experiment import Experiments
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
    program (experiments of one kind share one loop, as in a fit). Checks the experiments first."""
    require_float64("pamjax.predictions")
    experiments = list(experiments) if isinstance(experiments, (list, tuple)) else [experiments]
    for e in experiments:
        e.check(model)
    model = strong_types(model)
    exps = tuple(e.bind(model) for e in experiments)
    return [jax.tree_util.tree_map(np.asarray, p) for p in _predictions(model, exps)]


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
