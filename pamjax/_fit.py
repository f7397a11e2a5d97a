"""`fit`: least-squares identification of named parameters of a model against experiments.

Workflow only: the physics lives in the components; the residuals come from `Experiment.residuals`, the optimiser
is optimistix (Levenberg-Marquardt by default), the Jacobian forward-mode through diffrax.
"""

import dataclasses
import json
import math
import pathlib
import re
import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._errors import PamjaxInputError, require_float64
from ._experiment import predict
from ._fingerprint import check_resume, encode, fingerprint

# Residual entries of a trial step whose simulation failed (non-finite): large and finite, so the step is rejected.
FAILED_RESIDUAL = 1e6

# Default transform by field name: positive quantities fitted in log space, ratios in (0, 1) through a logistic;
# everything else (signed coefficients) linearly, scaled by its starting magnitude.
_LOG_NAMES = {
    "discharge_coefficient", "area", "sonic_conductance", "flow_coefficient", "v0", "volume", "coulomb_force",
    "viscous_coefficient", "payload_mass", "k0", "k2", "supply_pressure", "pwm_frequency", "switch_on_delay",
    "switch_off_delay", "edge_width", "velocity_width", "bristle_stiffness", "bristle_damping", "max_pressure",
    "strand_length", "turns", "nominal_length", "radius", "stiffness", "damping", "temperature", "gas_constant",
}
_LOGISTIC_NAMES = {"critical_ratio", "laminar_ratio"}


class PamjaxIdentifiabilityWarning(UserWarning):
    """Some free parameters (or combinations of them) are not determined by the data."""


_TOKEN = re.compile(r"^([A-Za-z_]\w*)((?:\[\d+(?:,\s*\d+)*\])?)$")


def _parse(path):
    parts = path.split(".")
    attrs, index = [], None
    for i, part in enumerate(parts):
        m = _TOKEN.match(part.strip())
        if m is None or (m.group(2) and i != len(parts) - 1):
            raise PamjaxInputError(f"parameter path {path!r} is malformed (expected e.g. 'valve.inflate.area' or "
                                   "'muscle.force_law.max_force_coefficients[2]')")
        attrs.append(m.group(1))
        if m.group(2):
            index = tuple(int(k) for k in m.group(2)[1:-1].split(","))
    return attrs, index


def parameter_paths(model, prefix=""):
    """All array-valued parameter paths of `model` with their shapes, e.g. {'valve.inflate.area': ()}."""
    out = {}
    if isinstance(model, eqx.Module):
        for f in dataclasses.fields(model):
            if f.metadata.get("static", False):
                continue
            out.update(parameter_paths(getattr(model, f.name), f"{prefix}{f.name}."))
    elif eqx.is_array(model):
        out[prefix[:-1]] = tuple(model.shape)
    return out


def _getter(attrs):
    def get(m):
        for a in attrs:
            m = getattr(m, a)
        return m

    return get


class _Group(eqx.Module):
    """One free entry: an array leaf (or some of its elements) and how it maps from the unconstrained θ."""

    path: str = eqx.field(static=True)
    attrs: tuple = eqx.field(static=True)
    index: tuple | None = eqx.field(static=True)
    transform: str = eqx.field(static=True)
    labels: tuple = eqx.field(static=True)
    scale: jax.Array  # linear: value = scale θ; log: value = scale exp(θ); nodes: F(nodes) = scale θ
    lower: jax.Array
    upper: jax.Array
    basis: jax.Array | None  # nodes: coefficients = basis @ F(nodes)

    @property
    def size(self):
        return len(self.labels)

    def physical(self, theta):
        if self.transform == "linear":
            return self.scale * theta
        if self.transform == "log":
            return self.scale * jnp.exp(theta)
        if self.transform == "logistic":
            return self.lower + (self.upper - self.lower) * jax.nn.sigmoid(theta)
        return self.basis @ (self.scale * theta)  # nodes

    def theta(self, value):
        value = jnp.asarray(value, dtype=float)
        if self.transform == "linear":
            return value / self.scale
        if self.transform == "log":
            return jnp.log(value / self.scale)
        if self.transform == "logistic":
            z = (value - self.lower) / (self.upper - self.lower)
            return jnp.log(z) - jnp.log1p(-z)
        return jnp.linalg.solve(self.basis, value) / self.scale


def _labels(path, attrs, shape, index):
    if index is not None:
        return (path,)
    idx = list(np.ndindex(*shape)) if shape else [()]
    if attrs[-1] == "max_force_coefficients":
        return tuple(f"a{i[0]}" for i in idx)
    if attrs[-1] == "coefficients" and shape == (3, 3):
        return tuple(f"m{3 * i[0] + i[1] + 1}" for i in idx)
    return tuple(f"{path}[{','.join(map(str, i))}]" if i else path for i in idx)


# Keys of a free-parameter entry given as a dict (the `pamjax fit` config's free tables take the same).
FREE_ENTRY_KEYS = ("path", "transform", "bounds", "scale")


def _zero_start_scale(full, index):
    """Scale of linear parameters that start at exactly 0 (their own magnitude gives none).

    Entries of one column of a 2-D coefficient array share units (eq. 13: m_ij multiplies u^i p_g^j, u
    dimensionless), so a zero entry takes its column's largest magnitude; in a 1-D array, the array's largest; else 1
    (give the free entry a 'scale' then). Without this, eq. 13's m1 = 0 would be fitted in units of 1 kg/s beside
    m4 and m7 of ~1e-3 kg/s: badly scaled for Levenberg-Marquardt's isotropic damping."""
    if full.ndim == 2:
        s = np.broadcast_to(np.max(np.abs(full), axis=0), full.shape)
    elif full.ndim == 1:
        s = np.full(full.shape, np.max(np.abs(full), initial=0.0))
    else:
        s = np.zeros(full.shape)
    s = np.ravel(s if index is None else s[index])
    return np.where(s > 0, s, 1.0)


def _make_group(model, entry, valid):
    spec = {"path": entry} if isinstance(entry, str) else dict(entry)
    path = spec.pop("path", None)
    if path is None:
        raise PamjaxInputError(f"free parameter entry {entry!r} needs a 'path'")
    transform = spec.pop("transform", None)
    bounds = spec.pop("bounds", None)
    user_scale = spec.pop("scale", None)
    if spec:
        raise PamjaxInputError(
            f"free parameter {path!r}: unknown keys {sorted(spec)}; valid: {', '.join(FREE_ENTRY_KEYS)}"
        )
    attrs, index = _parse(path)
    leaf_path = ".".join(attrs)
    if leaf_path not in valid:
        raise PamjaxInputError(
            f"unknown parameter {path!r}; the model's parameters are:\n  " + "\n  ".join(sorted(valid))
        )
    value = np.asarray(_getter(attrs)(model), dtype=float)
    full = value  # the whole leaf; `value` becomes the indexed entry
    if index is not None:
        if len(index) != value.ndim or any(not 0 <= i < n for i, n in zip(index, value.shape)):
            raise PamjaxInputError(f"index {list(index)} out of range for {leaf_path!r} of shape {value.shape}")
        value = value[index]
    leaf = attrs[-1]
    if bounds is not None:
        lo, hi = (float(b) for b in bounds)
        if not (lo < hi and np.all(value > lo) and np.all(value < hi)):
            raise PamjaxInputError(f"bounds {bounds} of {path!r} must satisfy lo < start value {value} < hi")
        transform = transform or "logistic"
    if transform is None:
        if leaf == "max_force_coefficients" and index is None and value.shape == (5,):
            transform = "nodes"
        elif leaf in _LOGISTIC_NAMES:
            transform, bounds = "logistic", (0.0, 1.0)
        elif leaf in _LOG_NAMES and np.all(value > 0):
            transform = "log"
        else:
            transform = "linear"
    if transform not in ("linear", "log", "logistic", "nodes"):
        raise PamjaxInputError(f"transform of {path!r} must be linear, log, logistic or nodes, got {transform!r}")
    if transform == "log" and not np.all(value > 0):
        raise PamjaxInputError(f"{path!r} starts at {value}: a log transform needs a positive start value")
    if transform == "logistic" and bounds is None:
        raise PamjaxInputError(f"{path!r}: a logistic transform needs bounds (lo, hi)")
    flat = value.reshape(-1)
    scale = np.where(flat != 0, np.abs(flat), _zero_start_scale(full, index))
    if user_scale is not None:
        if transform != "linear":
            raise PamjaxInputError(
                f"free parameter {path!r}: 'scale' applies to the linear transform, not {transform!r}"
            )
        user = np.broadcast_to(np.asarray(user_scale, dtype=float), value.shape).reshape(-1)
        if not np.all(np.isfinite(user) & (user > 0)):
            raise PamjaxInputError(f"free parameter {path!r}: scale must be finite and > 0, got {user_scale!r}")
        scale = user
    basis = None
    lower = upper = np.zeros_like(flat)
    if transform == "logistic":
        lower, upper = np.full_like(flat, bounds[0]), np.full_like(flat, bounds[1])
    if transform == "nodes":
        # Well-conditioned basis for the quartic F_max: its values at 5 Chebyshev nodes over the stroke.
        muscle = _getter(attrs[:-2])(model)
        lo, hi = float(muscle.min_position), float(muscle.max_position)
        nodes = 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.cos(np.pi * (2 * np.arange(5) + 1) / 10)
        vander = np.vander(nodes, 5, increasing=True)  # F(nodes) = V a
        basis = np.linalg.inv(vander)
        scale = np.full(5, np.max(np.abs(vander @ flat)))
    labels = _labels(path, attrs, value.shape, index)
    return _Group(path, tuple(attrs), index, transform, labels, jnp.asarray(scale), jnp.asarray(lower),
                  jnp.asarray(upper), None if basis is None else jnp.asarray(basis))


class ParameterSpace(eqx.Module):
    """Maps the unconstrained, O(1)-scaled vector θ to a model with the free parameters set (everything else
    fixed). `free` entries: a path string, or a dict {path, transform ('linear'|'log'|'logistic'|'nodes'),
    bounds (lo, hi), scale (linear transform: the O(1) unit of θ; default the start magnitude, see
    `_zero_start_scale` for parameters starting at 0)}."""

    base: eqx.Module
    groups: tuple

    def __init__(self, model, free):
        if isinstance(free, str) or not free:
            raise PamjaxInputError(f"free must be a non-empty list of parameter paths, got {free!r}")
        valid = parameter_paths(model)
        self.base = model
        self.groups = tuple(_make_group(model, e, valid) for e in free)
        labels = self.labels
        if len(set(labels)) != len(labels):
            raise PamjaxInputError(f"a parameter is named twice in free: {labels}")

    @property
    def labels(self):
        return [label for g in self.groups for label in g.labels]

    @property
    def size(self):
        return sum(g.size for g in self.groups)

    def _split(self, vec):
        out, k = [], 0
        for g in self.groups:
            out.append(vec[k : k + g.size])
            k += g.size
        return out

    def physical(self, theta):
        """The free parameters' physical values (flat; F_max as a0…a4)."""
        return jnp.concatenate([g.physical(t) for g, t in zip(self.groups, self._split(theta))])

    def theta(self, values):
        return jnp.concatenate([g.theta(v) for g, v in zip(self.groups, self._split(jnp.asarray(values)))])

    def initial_theta(self):
        return self.theta(self.initial_values())

    def initial_values(self):
        vals = []
        for g in self.groups:
            v = jnp.asarray(_getter(g.attrs)(self.base), dtype=float)
            vals.append((v if g.index is None else v[g.index]).reshape(-1))
        return jnp.concatenate(vals)

    def with_values(self, values, model=None):
        """`model` (default the base) with the free parameters set to physical `values`."""
        model = self.base if model is None else model
        for g, v in zip(self.groups, self._split(jnp.asarray(values))):
            get = _getter(g.attrs)
            old = jnp.asarray(get(model), dtype=float)
            new = v.reshape(old.shape) if g.index is None else old.at[g.index].set(v[0])
            model = eqx.tree_at(get, model, new)
        return model

    def model(self, theta):
        return self.with_values(self.physical(theta))


@dataclasses.dataclass
class FitResult:
    """The outcome of `fit`. Physical values in SI units (F_max as a0…a4 [N/mⁱ], eq. 13 as m1…m9).

    - `labels`, `paths` (the `free` spec), `values`, `initial_values`, `standard_errors` (inf for parameters in a
      non-identifiable combination), `correlation` (matrix).
    - `cost` ½Σr² at the end (r = (model − data)/scale), `initial_cost`, `iterations`, `accepted_steps`,
      `status` ('converged', 'max_steps', or the solver's message), `converged`.
    - `channel_errors`: experiment → channel → rmse, max_error, range, rmse_percent, max_error_percent (of the
      data's range, as paper 000 reports them), and the same with `validation_` for the held-out part.
    - `non_identifiable`: lists of labels whose combination the data do not fix; `warnings`.
    - `history`: per iteration (step, cost at last accepted point, trial cost, step size, accepted).
    - `fit_s`, `compile_s`: wall time after compilation, and the first step's compile estimate.
    - `model`: the fitted model (not stored in JSON; `apply(base_model)` rebuilds it).
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
    channel_errors: dict
    non_identifiable: list
    warnings: list
    history: list
    fit_s: float
    compile_s: float
    num_residuals: int
    model: object = dataclasses.field(default=None, repr=False, compare=False)

    def to_dict(self):
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "model"}

    @classmethod
    def from_dict(cls, d):
        return cls(**d)

    def to_json(self, path, overwrite=False):
        """Write the result (floats exact via repr); refuses to replace an existing file unless `overwrite`."""
        path = pathlib.Path(path)
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path

    @classmethod
    def from_json(cls, path):
        return cls.from_dict(json.loads(pathlib.Path(path).read_text()))

    def apply(self, model):
        """`model` with the fitted values set (the free spec in `paths`)."""
        return ParameterSpace(model, self.paths).with_values(jnp.asarray(self.values))

    def table(self, truth=None):
        """Text table: label, (true), initial, fitted ± standard error."""
        head = f"{'parameter':<44}" + (f"{'true':>14}" if truth is not None else "") + f"{'initial':>14}{'fitted':>14}"
        rows = [head + f"{'± std err':>12}"]
        for i, label in enumerate(self.labels):
            t = "" if truth is None else f"{truth.get(label, float('nan')):>14.6g}"
            rows.append(f"{label:<44}{t}{self.initial_values[i]:>14.6g}{self.values[i]:>14.6g}"
                        f"{self.standard_errors[i]:>12.3g}")
        return "\n".join(rows)


def _stack_residuals(space, experiments, part):
    def fn(theta, exps):
        model = space.model(theta)
        r = jnp.concatenate([e.residuals(model, part) for e in exps])
        ok = jnp.all(jnp.isfinite(r))
        return jnp.where(ok, r, FAILED_RESIDUAL), None

    return fn


def _channel_errors(model, experiments):
    out = {}
    for e in experiments:
        pred = jax.tree_util.tree_map(np.asarray, predict(model, e))
        out[e.name] = {}
        for c in e.channels:
            if hasattr(e, "times"):
                used = np.asarray(e.weights[c]) > 0
                err, data = pred[c] - np.asarray(e.data[c]), np.asarray(e.data[c])
                ident = used & (np.asarray(e.times) <= float(e.split_time))
                valid = used & ~ident
            else:
                f = pred[c]
                slack = np.asarray(e.slack)
                data = np.asarray(e.forces)
                err = np.where(slack, np.maximum(f, 0.0), f - data)
                ident, valid = np.ones_like(slack), np.zeros_like(slack)
            span = float(np.ptp(data[ident | valid])) or 1.0
            stats = {"range": span}
            for prefix, sel in (("", ident), ("validation_", valid)):
                if np.any(sel):
                    rmse, mx = float(np.sqrt(np.mean(err[sel] ** 2))), float(np.max(np.abs(err[sel])))
                    stats.update({f"{prefix}rmse": rmse, f"{prefix}max_error": mx,
                                  f"{prefix}rmse_percent": 100 * rmse / span,
                                  f"{prefix}max_error_percent": 100 * mx / span})
            out[e.name][c] = stats
    return out


def _identifiability(jac, labels, tol):
    """Null directions of the column-normalised Jacobian: lists of labels that the data cannot separate."""
    norms = np.linalg.norm(jac, axis=0)
    groups = [[labels[i]] for i in np.flatnonzero(norms == 0)]
    live = np.flatnonzero(norms > 0)
    if live.size:
        _, s, vt = np.linalg.svd(jac[:, live] / norms[live], full_matrices=False)
        for k in np.flatnonzero(s < tol * s[0]):
            v = vt[k]
            groups.append([labels[live[i]] for i in np.flatnonzero(np.abs(v) > 0.1 * np.max(np.abs(v)))])
    return groups


@eqx.filter_jit
def _solver_init(solver, space, theta, exps):
    """The solver's initial state. Module-level and given `space` as an argument, so that fits of one problem
    structure from different start models (random restarts, resumed fits) share one compilation."""
    fn = _stack_residuals(space, exps, "identification")
    f_struct = jax.eval_shape(lambda t: fn(t, exps)[0], theta)
    return solver.init(fn, theta, exps, {}, f_struct, None, frozenset())


@eqx.filter_jit
def _solver_step(solver, space, theta, state, exps):
    """One optimiser iteration, its termination test, and the cost, step size, Jacobian and residuals after it."""
    fn = _stack_residuals(space, exps, "identification")
    theta, state, _ = solver.step(fn, theta, exps, {}, state, frozenset())
    done, result = solver.terminate(fn, theta, exps, {}, state, frozenset())
    info = state.f_info
    cost = 0.5 * jnp.sum(info.residual**2)
    step_size = getattr(state.search_state, "step_size", jnp.nan)
    return theta, state, done, result, cost, step_size, info.jac.as_matrix(), info.residual


_CHECKPOINT_FORMAT = 1


def _check_checkpoint_path(checkpoint, resume, overwrite):
    """Before any fit: `checkpoint` may only replace an existing file if asked to, or if it is the file resumed."""
    if checkpoint is None:
        return
    path = pathlib.Path(checkpoint)
    if path.suffix != ".npz":
        raise PamjaxInputError(f"checkpoint must be an .npz path, got {str(checkpoint)!r}")
    same = resume is not None and path.resolve() == pathlib.Path(resume).resolve()
    if path.exists() and not (overwrite or same):
        raise FileExistsError(f"checkpoint {path} exists; pass overwrite=True to replace it (or resume from it)")


def _write_checkpoint(path, labels, carry, history, fingerprint=None):
    """Save the optimiser carry (θ, the optimistix state, done, result, Jacobian, residuals: every array leaf,
    exactly) and the history after an iteration. Written to a temporary file and renamed, so an interruption leaves
    the previous checkpoint intact."""
    path = pathlib.Path(path)
    leaves = [np.asarray(x) for x in jax.tree_util.tree_leaves(eqx.filter(carry, eqx.is_array))]
    weak = [bool(getattr(x, "weak_type", False)) for x in jax.tree_util.tree_leaves(eqx.filter(carry, eqx.is_array))]
    arrays = {f"leaf_{i}": x for i, x in enumerate(leaves)}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    extra = {} if fingerprint is None else {"fingerprint": encode(fingerprint)}  # see _fingerprint
    np.savez(tmp, format=_CHECKPOINT_FORMAT, labels=np.asarray(labels, dtype=str), weak=np.asarray(weak, dtype=bool),
             history=np.asarray(history, dtype=float).reshape(-1, 4), **arrays, **extra)
    tmp.replace(path)


def _read_checkpoint(path, labels, template):
    """The carry and history saved by `_write_checkpoint`; `template` (a fresh carry of this problem) gives the
    structure, and every leaf's shape and dtype must match it."""
    path = pathlib.Path(path)
    if not path.exists():
        raise PamjaxInputError(f"resume: checkpoint {path} does not exist")
    with np.load(path) as f:
        data = {k: f[k] for k in f.files}
    if int(data.get("format", -1)) != _CHECKPOINT_FORMAT:
        raise PamjaxInputError(f"resume: {path} is not a pamjax fit checkpoint (format {_CHECKPOINT_FORMAT})")
    if list(data["labels"]) != list(labels):
        raise PamjaxInputError(f"resume: {path} was saved for parameters {list(data['labels'])}, not {list(labels)}")
    arrays, static = eqx.partition(template, eqx.is_array)
    old, treedef = jax.tree_util.tree_flatten(arrays)
    if len(old) != len(data["weak"]):
        raise PamjaxInputError(f"resume: {path} holds a different optimiser state (another solver or problem)")
    new = []
    for i, (t, weak) in enumerate(zip(old, data["weak"])):
        v = data[f"leaf_{i}"]
        if v.shape != t.shape or v.dtype != t.dtype:
            raise PamjaxInputError(f"resume: {path} leaf {i} has shape {v.shape} {v.dtype}, this fit needs "
                                   f"{t.shape} {t.dtype} (another problem or solver)")
        if isinstance(t, np.ndarray):
            new.append(v)
        elif weak and v.ndim == 0:
            new.append(jnp.asarray(v.item()))  # a Python scalar keeps JAX's weak type (same trace as uninterrupted)
        else:
            new.append(jnp.asarray(v))
    carry = eqx.combine(jax.tree_util.tree_unflatten(treedef, new), static)
    history = [[int(s), float(c), float(z), bool(a)] for s, c, z, a in data["history"]]
    return carry, history


def fit(
    model,
    experiments,
    free,
    *,
    solver=None,
    max_steps: int = 100,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    progress=True,
    identifiability_tol: float = 1e-6,
    stall_steps: int = 8,
    out=None,
    overwrite: bool = False,
    checkpoint=None,
    resume=None,
) -> FitResult:
    """Fit the parameters named in `free` of `model` to `experiments` by nonlinear least squares.

    Minimises ½ Σ rᵢ² over all experiments' residuals r = (model − data) / scale (identification part only), with
    optimistix's Levenberg-Marquardt (default) and Jacobians in forward mode through the diffrax solves. Parameters
    are fitted in an unconstrained, O(1)-scaled space: log for positive quantities (v = v₀ eᶿ), a logistic for ratios
    and bounded ones, a scale by the starting magnitude for signed coefficients, and the quartic F_max of eq. 7 as its
    values at five nodes over the stroke (reported as a0…a4). A trial step whose simulation fails (non-finite
    residuals) gets large finite residuals and is rejected by the trust region.

    **Arguments:**

    - `model`: the object whose parameters are fitted (e.g. a `MuscleSystem`; valve tests use its valve).
    - `experiments`: a list of `Experiment` / `ForceMapExperiment`.
    - `free`: parameter paths, e.g.
      `["valve.inflate.discharge_coefficient", "muscle.force_law.max_force_coefficients"]`,
      or dicts `{"path": ..., "transform": "log"|"linear"|"logistic"|"nodes", "bounds": (lo, hi)}`.
    - `solver`: an optimistix least-squares solver (default `LevenbergMarquardt(rtol, atol)`); `max_steps`.
    - `progress`: True prints one line per iteration (cost, step size); a callable gets (step, cost, step_size,
      accepted); False is silent.
    - `stall_steps`: stop after this many rejected trial steps in a row ('converged' if Gauss-Newton predicts a
      further decrease below 1e-4 of the cost, else 'stalled').
    - `identifiability_tol`: singular values of the column-normalised Jacobian below this × the largest mark a
      non-identifiable combination (warned about by name; its parameters get infinite standard errors).
    - `out`: a JSON path to write the result to; checked BEFORE the fit; never replaced unless `overwrite=True`.
    - `checkpoint`: an `.npz` path; after every iteration the optimiser state (θ, the optimistix solver state and
      the last Jacobian, every array exactly), the iteration count and the history are written to it (atomically).
      Never replaces an existing file unless `overwrite=True` or it is the `resume` file.
    - `resume`: an `.npz` checkpoint of this same problem (model, experiments, free, solver): the fit continues from
      it and ends bitwise where an uninterrupted fit with the same `max_steps` ends (values, cost, iterations,
      history). Stop a long fit early with a small `max_steps` (or an interrupt) and resume with the full one. The
      checkpoint carries a fingerprint of the start model, free spec, experiments, data and solver
      (`pamjax._fingerprint`); a resume of another problem is refused, saying what differs.

    **Returns:** a `FitResult` (values, standard errors, correlation, per-channel RMSE, status, fitted `model`).

    **Raises:** `PamjaxInputError` for an unknown parameter (listing the valid ones) or bad experiment input, before
    any fit; `FileExistsError` if `out` (or `checkpoint`) exists and `overwrite` is False.
    """
    require_float64("pamjax.fit")
    if out is not None and pathlib.Path(out).exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True to replace it")
    _check_checkpoint_path(checkpoint, resume, overwrite)
    experiments = list(experiments) if isinstance(experiments, (list, tuple)) else [experiments]
    if not experiments:
        raise PamjaxInputError("experiments must be a non-empty list")
    for e in experiments:
        if not hasattr(e, "residuals"):
            raise PamjaxInputError(f"experiments must be Experiment/ForceMapExperiment objects, got {type(e)}")
    names = [e.name for e in experiments]
    if len(set(names)) != len(names):
        raise PamjaxInputError(f"experiment names must be unique, got {names}")
    if not (isinstance(max_steps, int) and max_steps > 0):
        raise PamjaxInputError(f"max_steps must be a positive int, got {max_steps}")
    space = ParameterSpace(model, free)
    problem = fingerprint(model, experiments, free, solver, rtol, atol)  # start model, free, experiments, data
    if resume is not None:
        check_resume(resume, problem)  # before any solve: a checkpoint of another problem is refused, naming why
    for e in experiments:
        e.check(model)
    labels = space.labels
    exps = tuple(e.bind(model) if hasattr(e, "bind") else e for e in experiments)  # PWM grids sized
    fn = _stack_residuals(space, exps, "identification")
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol) if solver is None else solver
    theta = space.initial_theta()
    if not np.all(np.isfinite(np.asarray(theta))):
        raise PamjaxInputError(f"start values give non-finite transformed parameters: {dict(zip(labels, theta))}")
    f_struct = jax.eval_shape(lambda t: fn(t, exps)[0], theta)

    def init(theta, exps):
        return _solver_init(solver, space, theta, exps)

    def step(theta, state, exps):
        return _solver_step(solver, space, theta, state, exps)

    report = progress if callable(progress) else None
    state = init(theta, exps)
    history, t_first, t_rest = [], None, 0.0
    done = False
    result = optx.RESULTS.successful
    initial_cost = None
    k = 0
    prev_accepted = 0
    jac = jnp.zeros((f_struct.size, theta.size))
    resid = jnp.zeros(f_struct.shape)
    if resume is not None:
        template = (theta, state, jnp.asarray(False), result, jac, resid)
        (theta, state, done, result, jac, resid), history = _read_checkpoint(resume, labels, template)
        initial_cost, cost = history[0][1], history[-1][1]
        prev_accepted = int(state.num_accepted_steps)
    finished = bool(done) or (bool(history) and int(state.num_steps_since_acceptance) >= stall_steps)
    for k in range(len(history) + 1, 0 if finished else max_steps + 2):  # step 1 only evaluates the start point
        t = time.perf_counter()
        theta, state, done, result, cost, step_size, jac, resid = step(theta, state, exps)
        cost, step_size = float(cost), float(step_size)
        elapsed = time.perf_counter() - t
        if t_first is None:
            t_first = elapsed
        else:
            t_rest += elapsed
        if initial_cost is None:
            initial_cost = cost
        accepted = int(state.num_accepted_steps) > prev_accepted
        prev_accepted = int(state.num_accepted_steps)
        history.append([k - 1, cost, step_size, bool(accepted)])
        if checkpoint is not None:
            _write_checkpoint(checkpoint, labels, (theta, state, done, result, jac, resid), history, problem)
        if report is not None:
            report(k - 1, cost, step_size, accepted)
        elif progress:
            verdict = "accepted" if accepted else "rejected"
            print(f"  iter {k - 1:4d}  cost {cost:.6e}  step size {step_size:.3e}  {verdict}",
                  flush=True)
        if bool(done) or int(state.num_steps_since_acceptance) >= stall_steps:
            break
    n_steps = len(history) - 1
    t_first = 0.0 if t_first is None else t_first  # a resumed fit that had already finished
    steady = t_rest / max(n_steps, 1)
    compile_s = max(t_first - steady, 0.0)
    fit_s = t_rest + (t_first - compile_s)
    jac = np.asarray(jac)
    resid = np.asarray(resid)
    # Gauss-Newton's predicted decrease ½‖P r‖² (P: projection onto the Jacobian's range), relative to the cost.
    u_, s_, _ = np.linalg.svd(jac, full_matrices=False)
    proj = u_[:, s_ > 1e-12 * (s_[0] if s_.size else 1.0)].T @ resid
    predicted = 0.5 * float(proj @ proj) / max(float(cost), 1e-300)
    if bool(done):
        status = "converged" if result == optx.RESULTS.successful else optx.RESULTS[result]
    elif int(state.num_steps_since_acceptance) >= stall_steps:
        # Trial steps keep failing to lower the cost: a minimum (to the solver's accuracy) if Gauss-Newton predicts
        # almost no further decrease.
        status = "converged" if predicted < 1e-4 else f"stalled: {stall_steps} rejected steps in a row"
    else:
        status = "max_steps"
    converged = status == "converged"
    values = np.asarray(space.physical(theta))
    init_values = np.asarray(space.initial_values())
    used = int(np.count_nonzero(np.any(jac != 0, axis=1) | (resid != 0)))
    dof = max(used - len(labels), 1)
    sigma2 = 2.0 * float(cost) / dof
    groups = _identifiability(jac, labels, identifiability_tol)
    bad = sorted({label for g in groups for label in g})
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    keep = s > identifiability_tol * s[0] if s.size and s[0] > 0 else np.zeros_like(s, dtype=bool)
    cov_theta = (vt[keep].T / s[keep] ** 2) @ vt[keep] * sigma2
    g = np.asarray(jax.jacfwd(space.physical)(theta))
    cov = g @ cov_theta @ g.T
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    se = np.where(np.isin(labels, bad), np.inf, se)
    msgs = []
    for grp in groups:
        msg = (f"parameter {grp[0]} has no effect on the data" if len(grp) == 1
               else "non-identifiable combination: " + ", ".join(grp) + " (only a combination of them is fixed by the "
               "data; hold one fixed, e.g. k2 in eq. 7)")
        msgs.append(msg)
        warnings.warn(msg, PamjaxIdentifiabilityWarning, stacklevel=2)
    fitted = space.with_values(jnp.asarray(values))
    res = FitResult(
        labels=labels,
        paths=[e if isinstance(e, str) else {k: (list(v) if isinstance(v, tuple) else v) for k, v in e.items()}
               for e in free],
        values=[float(v) for v in values],
        initial_values=[float(v) for v in init_values],
        standard_errors=[float(v) for v in se],
        correlation=[[float(c) for c in row] for row in corr],
        cost=float(cost),
        initial_cost=float(initial_cost),
        iterations=n_steps,
        accepted_steps=int(state.num_accepted_steps),
        status=str(status),
        converged=bool(converged),
        channel_errors=_channel_errors(fitted, exps),
        non_identifiable=groups,
        warnings=msgs,
        history=history,
        fit_s=float(fit_s),
        compile_s=float(compile_s),
        num_residuals=used,
        model=fitted,
    )
    if math.isnan(res.cost):
        raise RuntimeError("fit produced a NaN cost; this is a bug in pamjax")
    if out is not None:
        res.to_json(out, overwrite=overwrite)
    return res
