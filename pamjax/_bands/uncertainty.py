"""A fit's parameter uncertainty, wherever it is kept: a `FitResult` in memory, the `fit.json` that `pamjax fit`
writes, or the `covariance` entry of a `model.json`'s provenance (written by `pamjax fit`, so that a fitted model file
carries its own uncertainty). Mapped into the fit's unconstrained parameter space θ for propagation.

The covariance is rebuilt from what every fit result stores: Σ = diag(SE) R diag(SE) of the physical values (the
standard errors and the correlation matrix R), which is the fit's own σ² G (JᵀJ)⁺ Gᵀ exactly (G = ∂values/∂θ);
then Σθ = G⁻¹ Σ G⁻ᵀ in the fit's unconstrained space (log for positive quantities, a logistic for ratios, Chebyshev
node values for a polynomial), where a draw θ ~ N(θ̂, Σθ) is always a physical model.

A fit of a `pamjax.Rig` (plant and the rig's nuisances: sensor offsets, gain and delay, each run's supply and start)
propagates to the PLANT: its predictions do not depend on the nuisances, and the plant block of the covariance is
the nuisances marginalised (for a Gaussian, the marginal of a block is that block). The nuisances left out are named.
"""

import dataclasses
import json
import math
import os
import pathlib
import warnings
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .._core.arrays import device_array
from .._core.custom_types import Float
from .._core.errors import PamjaxInputError
from .._fit.diagnostics import understatement
from .._fit.fit import FitResult
from .._fit.force_balance import is_weak_motion
from .._fit.parameters import ParameterSpace
from .._fit.rig import PLANT_PREFIX, Rig, is_nuisance, plant_label

SECTION = "covariance"  # the entry of a model file's provenance that carries the fit's uncertainty


class PamjaxBandWarning(UserWarning):
    """A band that may understate the uncertainty (model mismatch, a fit that did not converge, strong
    nonlinearity under the linear method, failed draws)."""


def _float(v):
    return float(v)  # "inf", "nan" strings (a model file's JSON has no Infinity) and numbers alike


def _json_float(v):
    v = float(v)
    return v if math.isfinite(v) else repr(v)


def _strip(entry):
    """A free entry (path string or {path, ...}) with a Rig's `plant.` prefix removed."""
    if isinstance(entry, str):
        return plant_label(entry)
    entry = dict(entry)
    entry["path"] = _strip(entry["path"])
    return entry


def _path_of(entry):
    return entry if isinstance(entry, str) else entry["path"]


# A covariance read from a file or built by hand is accepted as positive semi-definite up to rounding: its
# correlations within 1e-9 of symmetric and of [-1, 1], the correlation matrix's smallest eigenvalue ≥ -1e-8 (a fit's
# own, σ² G (JᵀJ)⁺ Gᵀ written with 17 digits, is off by ~1e-15; a correlation of 3.0 edited into a model file gave
# `--band` half-widths of 0 Pa at 11 of 31 rows: J Σ Jᵀ < 0 there, clipped).
CORRELATION_ROUNDING = 1e-9
EIGENVALUE_ROUNDING = 1e-8


def _correlation(cov):
    """The correlation matrix of `cov`'s rows with a finite, positive variance (the others: a parameter the fit did
    not determine, or one it fixed exactly), and those rows."""
    var = np.diag(cov)
    live = np.flatnonzero(np.isfinite(var) & (var > 0))
    sd = np.sqrt(var[live])
    return cov[np.ix_(live, live)] / np.outer(sd, sd), live


def _check_correlation(labels, se, corr, source):
    """`PamjaxInputError` naming the pair unless `corr` is a stored correlation matrix: a diagonal of 1 and finite
    entries, except in the rows and columns of a parameter the fit did not determine (standard error inf: a fit
    writes 0 there, older ones NaN). A NaN elsewhere was read as correlation 0, a diagonal edited to 0.3 accepted."""
    free = np.isposinf(se)
    for i, j in zip(*np.nonzero(~(free[:, None] | free[None, :]))):
        c = corr[i, j]
        if i == j and not abs(c - 1.0) <= CORRELATION_ROUNDING:
            raise PamjaxInputError(f"{source}: the correlation of {labels[i]} with itself is {float(c)!r}; a "
                                   "correlation matrix's diagonal is 1 (the variances are the standard errors squared)")
        if not np.isfinite(c):
            raise PamjaxInputError(f"{source}: the correlation of {labels[i]} and {labels[j]} is {float(c)!r}; it "
                                   "must be a number in [-1, 1] (only a parameter with standard error inf, "
                                   "undetermined, may have non-finite correlations)")


def check_covariance(labels, values, covariance, source):
    """`PamjaxInputError` naming `source` unless `covariance` is an (n, n) covariance of the n `labels`' `values`:
    symmetric, finite (an infinite variance, with zero covariances, is a parameter the fit did not determine: named
    when a band is asked for), no negative variance, correlations in [-1, 1] and positive semi-definite, each to
    rounding (`CORRELATION_ROUNDING`, `EIGENVALUE_ROUNDING`). A band of a covariance that is not one was silently
    zero wherever J Σ Jᵀ < 0."""
    n = len(labels)
    where = f"the covariance of {source}"
    if values.shape != (n,) or covariance.shape != (n, n):
        raise PamjaxInputError(f"{where}: its labels ({', '.join(labels)}) need {n} values and a ({n}, {n}) "
                               f"covariance, got values of shape {values.shape} and a covariance of shape "
                               f"{covariance.shape}")
    if not np.all(np.isfinite(values)):
        raise PamjaxInputError(f"the values of {source} must be finite, got {values}")
    var = np.diag(covariance)
    off = covariance[~np.eye(n, dtype=bool)]
    undetermined = np.isposinf(var)
    if np.any(np.isnan(var) | np.isneginf(var)) or not np.all(np.isfinite(off)) or np.any(
            covariance[undetermined][:, ~undetermined] != 0):
        raise PamjaxInputError(f"{where} must be finite (an infinite variance only for a parameter the fit did not "
                               f"determine, with covariances of 0), got {np.array2string(covariance, precision=3)}")
    if np.any(var < 0):
        bad = [label for label, v in zip(labels, var) if v < 0]
        raise PamjaxInputError(f"{where} gives {', '.join(bad)} a negative variance ({var[var < 0]}): a variance (a "
                               "standard error squared) is >= 0")
    corr, live = _correlation(np.where(np.isfinite(covariance), covariance, 0.0))
    if np.max(np.abs(corr - corr.T), initial=0.0) > CORRELATION_ROUNDING:
        raise PamjaxInputError(f"{where} is not symmetric: its correlations {np.array2string(corr, precision=4)}")
    worst = np.max(np.abs(corr - np.eye(live.size)), initial=0.0)
    if worst > 1.0 + CORRELATION_ROUNDING:
        i, j = np.unravel_index(np.argmax(np.abs(corr - np.eye(live.size))), corr.shape)
        raise PamjaxInputError(f"{where} correlates {labels[live[i]]} and {labels[live[j]]} by {corr[i, j]:.4g}: a "
                               "correlation lies in [-1, 1] (was the covariance edited?)")
    lowest = float(np.min(np.linalg.eigvalsh(0.5 * (corr + corr.T)), initial=0.0))
    if lowest < -EIGENVALUE_ROUNDING:
        raise PamjaxInputError(f"{where} is not positive semi-definite: its correlation matrix has the eigenvalue "
                               f"{lowest:.3g} (a combination of the parameters with a negative variance; each "
                               "correlation may lie in [-1, 1] and the set still not be possible: was it edited?)")


@dataclasses.dataclass(frozen=True)
class FitUncertainty:
    """The fitted parameters and their covariance: `labels`, `paths` (the fit's free spec), `values`, `covariance`
    (of the physical values, labels' order: checked on construction, `check_covariance`), and what qualifies them:
    `status` of the fit, `mismatch` (the residuals were not noise at the stated level), `se_inflation` (the factor by
    which the fit's residuals, correlated in time, make its standard errors understate the uncertainty:
    `pamjax._fit.diagnostics.understatement`, 1 where they do not), `cautions` (the fit's warnings that its standard
    errors may understate the uncertainty: a payload that barely moved), `source` (where it was read)."""

    labels: tuple[str, ...]
    paths: tuple[str | dict[str, Any], ...]
    values: Float[np.ndarray, " n"]
    covariance: Float[np.ndarray, " n n"]
    status: str = "converged"
    mismatch: bool = False
    se_inflation: float = float("nan")
    source: str = "a FitUncertainty"
    cautions: tuple[str, ...] = ()

    def __post_init__(self):
        labels = self.labels
        if isinstance(labels, str) or not all(isinstance(label, str) for label in labels):
            raise PamjaxInputError(f"{self.source}: labels must be a sequence of parameter labels (strings), got "
                                   f"{labels!r}")
        try:
            values = np.asarray(self.values, dtype=float)
            cov = np.asarray(self.covariance, dtype=float)
        except (TypeError, ValueError) as err:
            raise PamjaxInputError(f"{self.source}: values and covariance must be arrays of numbers: {err}") from None
        check_covariance(tuple(labels), values, cov, self.source)
        object.__setattr__(self, "labels", tuple(labels))
        object.__setattr__(self, "paths", tuple(self.paths))
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "covariance", cov)

    @classmethod
    def from_document(cls, d, source):
        """From a fit result's dict (fit.json, `FitResult.to_dict`) or a model file's `covariance` entry."""
        try:
            labels = tuple(d["labels"])
            se = np.array([_float(v) for v in d["standard_errors"]])
            corr = np.array([[_float(c) for c in row] for row in d["correlation"]], dtype=float).reshape(
                len(labels), len(labels))
            values = np.array([_float(v) for v in d["values"]])
            paths = tuple(d["paths"])
        except (KeyError, TypeError, ValueError) as err:
            raise PamjaxInputError(f"{source}: not a fit's covariance (labels, paths, values, standard_errors, "
                                   f"correlation): {err!r}") from None
        if not (se.shape == values.shape == (len(labels),)):
            raise PamjaxInputError(f"{source}: {len(labels)} labels but {se.size} standard errors, {values.size} "
                                   "values")
        _check_correlation(labels, se, corr, source)
        with np.errstate(invalid="ignore"):
            cov = corr * np.outer(se, se)
        cov = np.where(np.isfinite(cov), cov, 0.0)  # only the rows of an undetermined (inf) parameter: checked above
        cov[np.diag_indices_from(cov)] = se**2  # inf stays on the diagonal: named when a band is asked for
        inflation = d.get("se_inflation")
        if inflation is None:  # a fit result's dict: the factor its channels' statistics give
            errors = d.get("channel_errors")
            inflation = understatement(errors) if isinstance(errors, dict) and errors else float("nan")
        cautions = d.get("cautions")
        if cautions is None:  # a fit result's dict: its warnings; a model file's entry: its own list
            cautions = [w for w in d.get("warnings", []) if isinstance(w, str) and is_weak_motion(w)]
        return cls(labels, paths, values, cov, str(d.get("status", "converged")), bool(d.get("mismatch", False)),
                   _float(inflation), source, tuple(str(c) for c in cautions))

    @classmethod
    def of(cls, result):
        """From a `FitResult`, a `FitUncertainty`, or a path: a `model.json` of `pamjax fit` or a `fit.json`."""
        if isinstance(result, FitUncertainty):
            return result
        if isinstance(result, FitResult):
            return cls.from_document(result.to_dict(), "the fit result")
        if isinstance(result, (str, pathlib.Path)):
            return read_uncertainty(result)
        raise PamjaxInputError(f"result must be a pamjax.FitResult or the path of a fit's model.json / fit.json, "
                               f"got {type(result).__name__}")

    def document(self):
        """The JSON-able entry a model file's provenance carries (non-finite numbers as strings, as model files
        write them)."""
        se = np.sqrt(np.diag(self.covariance))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = self.covariance / np.outer(se, se)
        corr = np.where(np.isfinite(corr), corr, 0.0)
        return {"labels": list(self.labels), "paths": [p if isinstance(p, str) else dict(p) for p in self.paths],
                "values": [_json_float(v) for v in self.values],
                "standard_errors": [_json_float(v) for v in se],
                "correlation": [[_json_float(c) for c in row] for row in corr],
                "status": self.status, "mismatch": self.mismatch, "se_inflation": _json_float(self.se_inflation),
                "cautions": list(self.cautions)}

    @property
    def of_rig(self):
        """Whether the fit was of a `Rig` (its plant's labels prefixed `plant.`, or nuisances among them)."""
        return any(label.startswith(PLANT_PREFIX) or is_nuisance(label) for label in self.labels)

    def plant(self):
        """(the plant's block, the nuisance labels marginalised): labels and paths without `plant.`; the plant
        block of the covariance. Unchanged (and no labels) for a fit of a plain model."""
        if not self.of_rig:
            return self, []
        keep = [i for i, label in enumerate(self.labels) if not is_nuisance(label)]
        gone = [label for label in self.labels if is_nuisance(label)]
        paths = tuple(_strip(p) for p in self.paths if not is_nuisance(_path_of(p)))
        labels = tuple(_strip(self.labels[i]) for i in keep)
        cov = self.covariance[np.ix_(keep, keep)]
        return dataclasses.replace(self, labels=labels, paths=paths, values=self.values[keep], covariance=cov), gone

    def notes(self):
        """What the band cannot promise, in words (and as `PamjaxBandWarning`s)."""
        out = []
        if self.mismatch and not self.se_inflation <= 1.0:  # NaN: a factor not known (a FitUncertainty built so)
            by = f" by up to {self.se_inflation:.2g}x" if np.isfinite(self.se_inflation) else ""
            out.append(f"the fit flagged model mismatch (residuals correlated in time: standard errors understated{by})"
                       ": the band understates the uncertainty")
        elif self.mismatch:
            out.append("the fit flagged residuals above the stated noise level but white: a noise level stated too "
                       "low, which the covariance does not rest on (it is scaled by the residuals' own variance), or "
                       "a model error that changes from sample to sample, where the band understates the uncertainty")
        if self.status != "converged":
            out.append(f"the fit ended '{self.status}', not 'converged': the covariance is of a point that may not "
                       "be the optimum")
        out += [f"the fit warned: {c.split(': ', 1)[0]}'s payload barely moved, and its force law's and friction's "
                "standard errors may understate their uncertainty several-fold: the band understates it too"
                for c in self.cautions]
        return out


@dataclasses.dataclass(frozen=True)
class Propagation:
    """What a band propagates: the unconstrained space of the propagated parameters on the base model (`space`,
    fitted values set), θ̂, Σθ, the labels, the nuisances marginalised, the notes."""

    space: ParameterSpace
    theta: np.ndarray
    covariance: np.ndarray
    labels: tuple
    marginalised: tuple
    notes: tuple


# What a band's `result` may be: a fit result, its uncertainty, or the path of a fit's model.json / fit.json.
ResultLike = FitResult | FitUncertainty | str | pathlib.Path


@eqx.filter_jit
def _physical_jacobian(space, theta):
    return jax.jacfwd(space.physical)(theta)


def propagation(result, model=None, *, check_values=False):
    """The `Propagation` of a fit result (`FitUncertainty.of` takes it) on `model` (default: the result's fitted
    model; a `Rig`'s plant for a fit of a rig). The fitted values are set on `model`; with `check_values` a model
    whose values differ from the fit's is refused instead (the CLI: a model file and the covariance it carries)."""
    unc = FitUncertainty.of(result)
    if model is None:
        model = result.model if isinstance(result, FitResult) else None  # a FitUncertainty carries none
        if model is None and isinstance(result, (str, pathlib.Path)) and _is_model_file(result):
            from .._files.model_file import load_model

            model = load_model(result)  # a fit.json holds no model: refused below, asking for model=
        if model is None:
            raise PamjaxInputError("model: this fit result holds no model (read from JSON?): pass model= (the fitted "
                                   "model, or the fit's start model: the fitted values are set on it)")
    block, gone = unc.plant()
    if unc.of_rig and isinstance(model, Rig):
        model = model.plant
    bad = [label for label, v in zip(block.labels, np.diag(block.covariance)) if not np.isfinite(v)]
    if bad:
        raise PamjaxInputError(f"the fit does not determine {', '.join(bad)} (infinite standard errors: a "
                               "non-identifiable combination): a band would be unbounded; hold one of them fixed and "
                               "fit again")
    try:
        space = ParameterSpace(model, list(block.paths))
    except PamjaxInputError as err:
        raise PamjaxInputError(f"the fit's parameters ({unc.source}) are not parameters of this model: {err}") from None
    if tuple(space.labels) != block.labels:
        raise PamjaxInputError(f"the fit's labels {list(block.labels)} do not match this model's {space.labels} "
                               f"({unc.source})")
    if check_values:
        _check_values(space, block)
    space = ParameterSpace(space.with_values(block.values), list(block.paths))
    theta = np.asarray(space.initial_theta())
    g = np.asarray(_physical_jacobian(space, device_array(theta)))
    cov_theta = np.linalg.solve(g, np.linalg.solve(g, block.covariance).T)
    cov_theta = 0.5 * (cov_theta + cov_theta.T)
    notes = unc.notes()
    if gone:
        notes.append(f"a fit of a rig: the band is the plant's, its nuisances ({', '.join(gone)}) marginalised "
                     "(the plant block of the covariance)")
    for note in unc.notes():
        warnings.warn(note, PamjaxBandWarning, stacklevel=3)
    return Propagation(space, theta, cov_theta, block.labels, tuple(gone), tuple(notes))


def _is_model_file(path):
    """Whether `path` (a JSON document `read_uncertainty` has read) is a model file, not a fit result."""
    return json.loads(pathlib.Path(path).read_text(encoding="utf-8-sig")).get("format") == "pamjax-model"


def _check_values(space, block):
    have = np.asarray(space.initial_values())
    for label, a, b in zip(block.labels, have, block.values):
        if not np.isclose(a, b, rtol=1e-9, atol=0.0):
            raise PamjaxInputError(f"the model's {label} is {a!r} but the fit's covariance is for {b!r}: it belongs "
                                   "to another fit (or a fitted parameter was changed with set / over); --band "
                                   "propagates the fit's covariance around the fitted values only")


def read_uncertainty(path: str | os.PathLike[str]) -> FitUncertainty:
    """The `FitUncertainty` a file carries: a `model.json` written by `pamjax fit` (its provenance's `covariance`
    entry; for model files written before it, the `fit.json` its provenance names, beside it) or a `fit.json`."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise PamjaxInputError(f"{path} does not exist" + (" (it is a folder)" if path.is_dir() else ""))
    try:
        document = json.loads(path.read_text(encoding="utf-8-sig"))  # a byte-order mark skipped, as load_model does
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise PamjaxInputError(f"{path} is not a JSON file: {err}") from None
    if not isinstance(document, dict):
        raise PamjaxInputError(f"{path} is neither a model file nor a fit result")
    if document.get("format") != "pamjax-model":
        if "correlation" in document and "labels" in document:
            return FitUncertainty.from_document(document, str(path))
        raise PamjaxInputError(f"{path} is neither a pamjax model file nor a fit result (fit.json)")
    provenance = document.get("provenance") or {}
    if SECTION in provenance:
        return FitUncertainty.from_document(provenance[SECTION], f"{path} (provenance.{SECTION})")
    beside = provenance.get("result")
    if isinstance(beside, str) and (path.parent / beside).is_file():
        fit_path = path.parent / beside
        return FitUncertainty.from_document(json.loads(fit_path.read_text(encoding="utf-8-sig")), str(fit_path))
    raise PamjaxInputError(
        f"model file {path} carries no fit covariance: this model was not fitted (written by pamjax.save_model, or its "
        f"fit.json is not beside it); a band needs a fitted model: the model.json that pamjax fit writes (it carries "
        f"the covariance), or the fit.json of its fit in the same folder")
