"""The fingerprint of a fit problem, stored in its checkpoint: a resume whose start model, free parameters,
experiments, data or solver differ from the checkpoint's is refused with what differs, instead of returning the
checkpoint's old result attached to the new model.

What is fingerprinted (SHA-256 of the exact bytes; `max_steps` and `stall_steps` are not: stopping a fit early and
resuming it with the full budget is what checkpoints are for):

- `model`: every array leaf of the start model by path (values, shape, dtype), and its structure (classes and static
  fields such as a valve's `mode`);
- `free`: the free-parameter spec (paths, transforms, bounds, scales);
- `experiments`: per experiment (by name, in order) its data (times, recorded values, weights and masks) and its
  settings (signal, channels, scales, initial state, solver settings, ...);
- `solver`: the optimiser (its class and settings; of pamjax's own `LevenbergMarquardt` only whether its geodesic
  acceleration is on). Its termination settings (`ftol`, `xtol`, `gtol`) are not: like `max_steps`, they only
  decide when the same iterations stop.
"""

import dataclasses
import json
import pathlib
import warnings
import zipfile

import equinox as eqx
import numpy as np

from .._core.describe import describe as _describe, digest as _digest
from .._core.errors import PamjaxInputError
from .._core.jsonio import plain

_DATA_FIELDS = {"times", "data", "weights", "positions", "pressures", "forces", "slack"}
_VERSION = 1
# what reading a damaged .npz raises: a truncated one is no zip file (BadZipFile; 0 bytes: EOFError), a cut member
# ends early, a foreign one is no npz (an .npy is an array: TypeError); here and in the CLI (`pamjax._cli.fit_start`)
UNREADABLE = (OSError, KeyError, ValueError, IndexError, EOFError, TypeError, zipfile.BadZipFile)


def _leaves_by_path(model, prefix=""):
    """Array leaves of `model` by dotted path (the paths of `parameter_paths`), static fields by path too."""
    out = {}
    if isinstance(model, eqx.Module):
        for f in dataclasses.fields(model):
            out.update(_leaves_by_path(getattr(model, f.name), f"{prefix}{f.name}."))
    elif isinstance(model, (list, tuple)):
        for i, v in enumerate(model):
            out.update(_leaves_by_path(v, f"{prefix}{i}."))
    else:
        out[prefix[:-1]] = _digest(_describe(model))
    return out


def _solver(solver):
    if solver is None:
        return {"class": "pamjax Levenberg-Marquardt (pamjax._fit.lm)"}
    if callable(getattr(solver, "fingerprint", None)):  # pamjax's LevenbergMarquardt: only what changes its steps
        return solver.fingerprint()
    items = ((f.name, getattr(solver, f.name, None)) for f in dataclasses.fields(solver)) if dataclasses.is_dataclass(
        solver) else sorted(vars(solver).items())
    settings = {k: repr(v) for k, v in items if isinstance(v, (int, float, str, bool)) or eqx.is_array(v)}
    return {"class": type(solver).__qualname__, **settings}


def fingerprint(model, experiments, free, solver=None):
    """The fingerprint of a fit problem (a JSON-serialisable dict; see the module docstring)."""
    experiment_prints = []
    for e in experiments:
        fields = dataclasses.fields(e) if dataclasses.is_dataclass(e) else ()
        data = {f.name: _describe(getattr(e, f.name)) for f in fields if f.name in _DATA_FIELDS}
        settings = {f.name: _describe(getattr(e, f.name)) for f in fields if f.name not in _DATA_FIELDS}
        experiment_prints.append({"name": str(e.name), "class": type(e).__qualname__,
                                  "data": _digest(data), "settings": _digest(settings)})
    return {
        "version": _VERSION,
        "model": {"class": type(model).__qualname__, "leaves": _leaves_by_path(model)},
        # NumPy or JAX numbers in a free entry (bounds `np.array([100, 400])`), which `ParameterSpace` accepts
        "free": json.loads(json.dumps(free, default=lambda v: plain(v) if hasattr(v, "tolist") else list(v))),
        "experiments": experiment_prints,
        "solver": _solver(solver),
    }


def differences(saved, current):
    """What differs between two fingerprints, as a list of phrases (empty if they match)."""
    out = []
    old_model, new_model = saved.get("model", {}), current["model"]
    if old_model.get("class") != new_model["class"]:
        out.append(f"the model is a {new_model['class']}, the checkpoint's a {old_model.get('class')}")
    else:
        old, new = old_model.get("leaves", {}), new_model["leaves"]
        changed = sorted(p for p in set(old) | set(new) if old.get(p) != new.get(p))
        if changed:
            shown = ", ".join(changed[:8]) + (f" and {len(changed) - 8} more" if len(changed) > 8 else "")
            out.append(f"the start model differs in {shown}")
    if saved.get("free") != current["free"]:
        out.append(f"the free parameters differ (checkpoint: {saved.get('free')}, now: {current['free']})")
    old_exps, new_exps = saved.get("experiments", []), current["experiments"]
    if [e["name"] for e in old_exps] != [e["name"] for e in new_exps]:
        out.append(f"the experiments differ (checkpoint: {[e['name'] for e in old_exps]}, now: "
                   f"{[e['name'] for e in new_exps]})")
    else:
        for old, new in zip(old_exps, new_exps):
            if old["data"] != new["data"]:
                out.append(f"experiment {new['name']!r} has other data (times, recorded values or masks)")
            if old["settings"] != new["settings"] or old.get("class") != new["class"]:
                out.append(f"experiment {new['name']!r} has other settings (signal, channels, scales, initial "
                           "state or solver settings)")
    if saved.get("solver") != current["solver"]:
        out.append(f"the solver differs (checkpoint: {saved.get('solver')}, now: {current['solver']})")
    return out


def encode(print_):
    return np.asarray(json.dumps(print_, sort_keys=True))


def check_resume(path, current):
    """Refuse to resume from checkpoint `path` if its fingerprint differs from `current` (a `PamjaxInputError` saying
    what differs). A missing file is left to the checkpoint reader; a checkpoint without a fingerprint (written
    before pamjax stored one) is resumed with a warning."""
    path = pathlib.Path(path)
    if not path.is_file():
        return
    try:
        with path.open("rb") as handle, np.load(handle, allow_pickle=False) as f:  # closed on a BadZipFile too
            arrays = {k: f[k] for k in f.files}  # every member read: a file cut short fails here, not in the fit
        saved = json.loads(str(arrays["fingerprint"])) if "fingerprint" in arrays else None
    except UNREADABLE as err:  # a checkpoint cut short (a full disk, a partial copy): BadZipFile, 0 bytes: EOFError
        raise PamjaxInputError(f"resume: {path} is not a readable pamjax fit checkpoint ({type(err).__name__}: "
                               f"{err}); resume from a whole checkpoint, or start again without resume") from None
    if saved is None:
        warnings.warn(f"resume: {path} holds no fingerprint (written by an older pamjax): pamjax cannot check that it "
                      "belongs to this model, these experiments and data", UserWarning, stacklevel=3)
        return
    diff = differences(saved, current)
    if diff:
        raise PamjaxInputError(
            f"resume: {path} was saved by a different fit: " + "; ".join(diff) + ". Resume with the same model, free "
            "parameters, experiments and data, or start again without resume (pamjax fit: --overwrite)"
        )
