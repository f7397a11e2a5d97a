"""A fit as a design's prior: the information in hand read from the fit's covariance.

`design_experiment(..., prior=...)` takes experiments already in hand (their information at the design point, every
other parameter of their model known), and fits of them: a `FitResult`, or the path of its `fit.json`. A fit's
covariance says what its runs determine with every parameter the fit freed still free, a rig's nuisances included
(sensor offset and gain, each run's supply pressure, a start logged mid-way): its plant block is the marginal
covariance of the plant's parameters, and its inverse their information. The experiments alone would count those
nuisances as known: on the bench shipped with pamjax, a pilot fitted with its nuisances free determines the valve's
critical ratio b12 4.4x and C_v23 3.2x less well than its experiments say with the nuisances held (Session 58,
benchmarks/RESULTS.md, design)."""

import math
import os
import pathlib
import warnings
from collections.abc import Sequence

import numpy as np

from .._core.arrays import device_array
from .._core.errors import PamjaxInputError
from .._fit.diagnostics import understatement
from .._fit.experiment import AbstractExperiment
from .._fit.fit import FitResult
from .._fit.force_balance import is_weak_motion
from .._fit.problem import physical_and_jacobian
from .._fit.rig import is_nuisance, plant_label
from .design_result import PamjaxDesignWarning

# What `prior` may hold besides experiments: fits of them, or the paths of their fit.json, alone or mixed in a list.
PriorFits = FitResult | str | os.PathLike | Sequence[AbstractExperiment | FitResult | str | os.PathLike]


def split_prior(prior):
    """`prior` as (experiments, fits): pamjax experiments, `FitResult`s and paths of fit.json files, in any mix (a
    single one, a list or a tuple; None or () for nothing), or a `PamjaxInputError` naming it. Each fit is a pair
    (FitResult, where it came from)."""
    items = [] if prior is None else list(prior) if isinstance(prior, (list, tuple)) else [prior]
    experiments, fits = [], []
    for item in items:
        if isinstance(item, AbstractExperiment):
            experiments.append(item)
        elif isinstance(item, FitResult):
            fits.append((item, "a FitResult"))
        elif isinstance(item, (str, os.PathLike)):
            fits.append((_read(pathlib.Path(item)), str(item)))
        else:
            raise PamjaxInputError(f"prior must be pamjax experiments (Experiment, ...), fits of them (FitResult) or "
                                   f"paths of a fit's fit.json, got {type(item).__name__}")
    return experiments, fits


def _read(path):
    if not path.is_file():
        raise PamjaxInputError(f"prior: {path} is not a file (give the fit.json that pamjax fit wrote)")
    try:
        return FitResult.from_json(path)
    except (ValueError, KeyError, TypeError) as err:
        raise PamjaxInputError(f"prior: {path} is not a fit's fit.json ({err!r})") from None


def fit_information(space, theta, fits, at_point=True):
    """The information about the design's θ that `fits` hold: for each, the inverse of its covariance's block of the
    design's free parameters (the plant's, nuisances and other parameters marginalised; parameters it did not
    determine carry none), mapped to θ through the design space's physical Jacobian at θ. Warns (`PamjaxDesignWarning`)
    where a fit's covariance may not hold: not converged, a model mismatch, a payload that barely moved, or (with
    `at_point`: θ is the design's model, not another point of a spread) fitted values other than the design point's."""
    n = len(space.labels)
    total = np.zeros((n, n))
    if not fits:
        return total
    values, g = (np.asarray(a) for a in physical_and_jacobian(space, device_array(theta)))
    for fit, source in fits:
        labels = [plant_label(label) for label in fit.labels]
        se = np.asarray(fit.standard_errors, dtype=float)
        keep = [i for i, label in enumerate(labels) if not is_nuisance(fit.labels[i]) and label in space.labels
                and math.isfinite(se[i]) and se[i] > 0]
        if not keep:
            raise PamjaxInputError(f"prior: {source} determines none of the design's free parameters (it fitted "
                                   f"{list(fit.labels)}; the design frees {list(space.labels)})")
        corr = np.asarray(fit.correlation, dtype=float)[np.ix_(keep, keep)]
        rows = [space.labels.index(labels[i]) for i in keep]
        total += g[rows].T @ _precision(se[keep], corr) @ g[rows]
        if at_point:
            _cautions(fit, source, [labels[i] for i in keep], np.asarray(fit.values, dtype=float)[keep], values[rows])
    return total


def _precision(se, corr):
    """The inverse of the covariance diag(se) · corr · diag(se), inverted in the correlation's scale (the physical
    variances span 25 orders of magnitude, v0's to a4's). A direction of (numerically) zero variance, e.g. two values
    rounded to a correlation of ±1 in fit.json, counts as no information rather than an infinite one: the prior errs
    on the side of knowing less, and a singular block is no error."""
    w, v = np.linalg.eigh(0.5 * (corr + corr.T))
    good = w > 1e-12 * max(float(w.max()), 1e-300)
    return ((v[:, good] / w[good]) @ v[:, good].T) / np.outer(se, se)


def _cautions(fit, source, labels, fitted, design):
    notes = []
    if fit.status != "converged":
        notes.append(f"it ended '{fit.status}', not converged")
    if fit.mismatch and understatement(fit.channel_errors) > 1.0:
        notes.append("it flagged a model mismatch (its residuals are correlated in time: its standard errors "
                     "understate the uncertainty)")
    elif fit.mismatch:  # white residuals above the stated noise: σ² is the residuals' own, the errors hold
        notes.append("its residuals are above the noise level its experiments state (check the stated noise)")
    if any(is_weak_motion(w) for w in fit.warnings if isinstance(w, str)):
        notes.append("its payload barely moved (its force law's and friction's standard errors may understate their "
                     "uncertainty several-fold)")
    off = [label for label, a, b in zip(labels, fitted, design) if not np.isclose(a, b, rtol=1e-6, atol=0.0)]
    if off:
        notes.append(f"the design point's {', '.join(off)} differ from its fitted values (design at the fit's "
                     "model.json: its covariance describes the fit's point)")
    for note in notes:
        warnings.warn(f"pamjax.design_experiment: prior {source}: {note}", PamjaxDesignWarning, stacklevel=4)
