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


@dataclasses.dataclass(frozen=True)
class FitUncertainty:
    """The fitted parameters and their covariance: `labels`, `paths` (the fit's free spec), `values`, `covariance`
    (of the physical values, labels' order), and what qualifies them: `status` of the fit, `mismatch` (the residuals
    were not noise), `se_inflation` (the largest channel's factor, 1 for white noise at the stated level),
    `cautions` (the fit's warnings that its standard errors may understate the uncertainty: a payload that barely
    moved), `source` (where it was read)."""

    labels: tuple[str, ...]
    paths: tuple[str | dict[str, Any], ...]
    values: Float[np.ndarray, " n"]
    covariance: Float[np.ndarray, " n n"]
    status: str = "converged"
    mismatch: bool = False
    se_inflation: float = float("nan")
    source: str = "a FitResult"
    cautions: tuple[str, ...] = ()

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
        with np.errstate(invalid="ignore"):
            cov = corr * np.outer(se, se)
        cov = np.where(np.isfinite(cov), cov, 0.0)
        cov[np.diag_indices_from(cov)] = se**2  # inf stays on the diagonal: named when a band is asked for
        inflation = d.get("se_inflation")
        if inflation is None:
            factors = [st.get("se_inflation", float("nan")) for chans in d.get("channel_errors", {}).values()
                       for st in chans.values()]
            factors = [f for f in factors if f is not None and np.isfinite(f)]
            inflation = max(factors) if factors else float("nan")
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
        if self.mismatch:
            out.append(f"the fit flagged model mismatch (standard errors understated by up to "
                       f"{self.se_inflation:.2g}x): the band understates the uncertainty")
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
    return json.loads(pathlib.Path(path).read_text(encoding="utf-8")).get("format") == "pamjax-model"


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
        document = json.loads(path.read_text(encoding="utf-8"))
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
        return FitUncertainty.from_document(json.loads(fit_path.read_text(encoding="utf-8")), str(fit_path))
    raise PamjaxInputError(
        f"model file {path} carries no fit covariance: this model was not fitted (written by pamjax.save_model, or its "
        f"fit.json is not beside it); a band needs a fitted model: the model.json that pamjax fit writes (it carries "
        f"the covariance), or the fit.json of its fit in the same folder")
