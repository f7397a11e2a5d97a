"""`prediction_band`: a fit's covariance carried to any prediction of the fitted model.

Two methods, and the band says which made it:

- `"linear"`: the delta method. The prediction's Jacobian J = ∂y/∂θ at the fitted θ̂, in forward mode through the
  solves, in the fit's unconstrained parameters θ (`pamjax.ParameterSpace`), and var y = diag(J Σθ Jᵀ); the band is
  ŷ ± z σ, z the two-sided normal quantile of `level`. Exact for a prediction linear in θ; one solve with n
  tangents. A check of that linearity comes with it (`nonlinearity`): the prediction at θ̂ ± sₖ along the principal
  axes sₖ of Σθ (1 σ each, 2n solves), whose second difference cₖ = (y(θ̂+sₖ) + y(θ̂−sₖ) − 2ŷ)/2 is the curvature the
  linear band leaves out; the index is max √Σcₖ² / max σ per output. The 95 % band's edges then move by about
  z² · index σ (3.8 × index): above 0.1 a `PamjaxBandWarning` says to use "samples".
- `"samples"`: θₖ ~ N(θ̂, Σθ) drawn in the unconstrained space (so positive parameters stay positive and ratios in
  their range), each simulated (vmapped, in batches), the band the (1 − level)/2 and (1 + level)/2 quantiles of the
  predictions. Not symmetric about ŷ where the prediction is nonlinear; its Monte-Carlo error is that of a quantile
  of `samples` draws (with 200 draws the 2.5 % quantile of a normal scatters by √(p(1 − p)/N)/φ(z) ≈ 0.19 σ).

Both take the covariance as the fit computed it (σ² (JᵀJ)⁺ with σ² from the residuals: `docs/fitting.md`), so they
answer "how much do the predictions vary with the parameters the data allow": a confidence band of the model's
prediction, not a prediction interval of new measurements (add the noise for that).
"""

import dataclasses
import numbers
import statistics
import warnings
from collections.abc import Callable
from typing import Any, Literal

import equinox as eqx
import jax
import numpy as np

from .._core.arrays import device_array
from .._core.custom_types import PyTreeLike
from .._core.errors import PamjaxInputError, PamjaxSolveError
from .uncertainty import PamjaxBandWarning, ResultLike, propagation

Method = Literal["linear", "samples"]

METHODS = ("linear", "samples")
NONLINEARITY_WARNING = 0.1  # index above which the linear band's 95 % edges are ~0.4 σ or more off (module docstring)
FAILED_WARNING = 0.01  # fraction of failed draws above which the samples band is warned about (it is conditional)


def real_scalar(x):
    """`x` as a float where it is one real number (a Python or NumPy number, a 0-d NumPy or concrete JAX array; not a
    bool or a string), else None. `np.float32(0.95)` and `jnp.asarray(0.9)` were refused as levels."""
    if isinstance(x, (bool, np.bool_, str, bytes)) or isinstance(x, jax.core.Tracer):
        return None
    if isinstance(x, numbers.Real) or (isinstance(x, (np.ndarray, jax.Array)) and np.ndim(x) == 0
                                       and np.issubdtype(np.asarray(x).dtype, np.number)
                                       and not np.iscomplexobj(x)):
        return float(x)
    return None


def z_of(level):
    """The two-sided normal quantile of a confidence `level` in (0, 1) (1.96 for 0.95)."""
    value = real_scalar(level)
    if value is None or not 0 < value < 1:
        raise PamjaxInputError(f"level must be a confidence level in (0, 1), e.g. 0.95, got {level!r}")
    return statistics.NormalDist().inv_cdf(0.5 + 0.5 * value)


def check_method(method, samples, seed=0):
    """`method`, `samples` and the draws' `seed` of a band, refused by name before any work (a seed NumPy's generator
    refuses, -1 or 1.5, failed only after the fitted model was read, and on the command line after the simulation)."""
    if method not in METHODS:
        raise PamjaxInputError(f"method must be one of {list(METHODS)}, got {method!r}")
    if not (isinstance(samples, int) and not isinstance(samples, bool) and samples >= 20):
        raise PamjaxInputError(f"samples must be an integer >= 20 (draws whose quantiles make the band), "
                               f"got {samples!r}")
    if not (seed is None or (isinstance(seed, numbers.Integral) and not isinstance(seed, bool) and seed >= 0)):
        raise PamjaxInputError(f"seed must be an integer >= 0 (the draws' generator; None: a fresh one each call), "
                               f"got {seed!r}")


def principal_steps(cov):
    """(n, n): row k is sₖ = √λₖ vₖ, the k-th principal axis of `cov` scaled to one standard deviation (Σ sₖsₖᵀ =
    cov; directions the fit left out, λ ≤ 0, are zero steps)."""
    lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    return (vec * np.sqrt(np.clip(lam, 0.0, None))).T


def sigma_points(theta, cov):
    """(2n + 1, n): θ̂, then θ̂ + sₖ, then θ̂ − sₖ (`principal_steps`)."""
    steps = principal_steps(cov)
    return np.concatenate([theta[None], theta + steps, theta - steps])


def draws(theta, cov, samples, seed):
    """(samples, n) draws from N(θ̂, Σθ), seeded (NumPy's default generator)."""
    z = np.random.default_rng(seed).standard_normal((samples, theta.size))
    return theta + z @ principal_steps(cov)


def wrap(d, period):
    """`d` taken into [-period/2, period/2) (a phase difference in degrees: period 360); as it is for None."""
    return d if period is None else (d + 0.5 * period) % period - 0.5 * period


def linear_from_points(y0, plus, minus, period=None):
    """(σ, nonlinearity index) of one output from its values at θ̂ (`y0`) and at θ̂ ± sₖ (`plus`, `minus`: (n, ...)):
    σ² = Σ ((y₊ − y₋)/2)² (central differences at ±1 σ: the delta method where no Jacobian is traced), the index as
    in the module docstring. `period` (e.g. 360 for a phase in degrees): differences taken modulo it."""
    slope = wrap(plus - minus, period) / 2.0
    curve = (wrap(plus - y0[None], period) + wrap(minus - y0[None], period)) / 2.0
    sigma = np.sqrt(np.sum(slope**2, axis=0))
    return sigma, nonlinearity_index(sigma, curve)


def nonlinearity_index(sigma, curve):
    """max √Σcₖ² / max σ over an output (0 where it has no spread; NaN points ignored)."""
    top = np.nanmax(sigma) if np.any(np.isfinite(sigma)) else 0.0
    bend = np.sqrt(np.sum(curve**2, axis=0))
    return float(np.nanmax(bend) / top) if top > 0 and np.any(np.isfinite(bend)) else 0.0


def quantile_band(ys, level, about=None, period=None):
    """(lower, upper, std) of draws `ys` (samples, ...) over the draws that did not fail (NaN rows left out). With a
    `period` (360 for a phase in degrees), each draw is first taken within half a period of `about` (the prediction
    at θ̂), as `linear_from_points` differences them: draws of a phase near ±180° fall on both sides of the cut, and
    their raw quantiles spanned the whole turn."""
    if period is not None:
        ys = about + wrap(ys - about, period)
    alpha = 0.5 * (1.0 - level)
    lower, upper = np.nanquantile(ys, [alpha, 1.0 - alpha], axis=0)
    return lower, upper, np.nanstd(ys, axis=0, ddof=1)


@dataclasses.dataclass
class PredictionBand:
    """A confidence band on a prediction of a fitted model.

    - `prediction`: the prediction at the fitted values; `lower`, `upper`: the band at `level`; `std`: its standard
      deviation (linear: σ of the delta method; samples: of the draws). Each has the structure `predict` returned
      (an array, or a dict of them).
    - `method` ("linear" or "samples") and `how` (one sentence: which Jacobian or how many draws).
    - `parameters`: the labels propagated; `marginalised`: a rig fit's nuisances left out (the plant's band).
    - `draws`, `failed`: predictions made for the band and those that failed (NaN; left out of "samples"; in
      "linear", of its linearity check, with a warning).
    - `nonlinearity`: per output, the curvature index of the module docstring, with the structure `predict` returned
      (a float per array leaf; linear method; None for samples).
    - `notes`: what the band cannot promise (model mismatch, a fit not converged, strong nonlinearity).
    """

    prediction: PyTreeLike
    lower: PyTreeLike
    upper: PyTreeLike
    std: PyTreeLike
    level: float
    method: str
    how: str
    parameters: list[str]
    marginalised: list[str]
    draws: int
    failed: int
    nonlinearity: float | PyTreeLike | None
    notes: list[str]

    def describe(self):
        """A few lines saying what the band is and how it was made."""
        lines = [f"{100 * self.level:g} % confidence band ({self.method}): {self.how}; "
                 f"{len(self.parameters)} parameters ({', '.join(self.parameters)})"]
        if self.nonlinearity is not None:
            leaves = named_leaves(self.nonlinearity)
            worst = max((v for _, v in leaves), default=0.0)
            verdict = (f"> {NONLINEARITY_WARNING}: see the note" if worst > NONLINEARITY_WARNING else
                       "on the axes whose ±1 σ predictions did not fail: see the note" if self.failed else
                       f"< {NONLINEARITY_WARNING}: the linear band holds")
            lines.append("nonlinearity index " + ", ".join(f"{k} {v:.3g}".strip() for k, v in leaves)
                         + f" ({verdict})")
        if self.failed:
            lines.append(f"{self.failed} of {self.draws} predictions failed and were left out")
        return "\n".join(lines + [f"note: {n}" for n in self.notes])


# Not jitted here: under an outer jit every leaf of the model would be traced, the fixed values too (a PWM frequency,
# which a fixed grid's size needs concrete); transformed at the top level, only the free parameters are, and the
# solves inside `predict` compile their own programs once per structure (`pamjax.simulate`'s jitted solve).
def _value_and_jacobian(predict, space, theta):
    def f(t):
        y = predict(space.model(t))
        return y, y

    try:
        jac, y = jax.jacfwd(f, has_aux=True)(theta)
    except (TypeError, PamjaxInputError) as err:  # a reverse-mode-only solve inside `predict` (simulate's default
        # adjoint: JAX's TypeError, or simulate's own naming of it)
        if "custom_vjp" not in str(err) and "forward-differentiated" not in str(err):
            raise
        raise PamjaxInputError(
            "predict must be differentiable in forward mode for method='linear': a pamjax.simulate inside it needs "
            "adjoint=\"forward\" (e.g. lambda m: pj.simulate(m, signal, ts, adjoint=\"forward\", throw=False)"
            ".channel(\"position\")), or use method='samples'") from None
    return y, jac


def _evaluate(predict, space, thetas):
    return jax.vmap(lambda t: predict(space.model(t)))(thetas)


def evaluate(predict, space, thetas, batch):
    """`predict` at every row of `thetas`, vmapped `batch` rows at a time (the last batch padded with the first row:
    one compiled program for all), as NumPy arrays with a leading axis over the rows."""
    thetas = np.asarray(thetas, dtype=float)
    rows = thetas.shape[0]
    size = min(batch, rows)
    pieces = []
    for start in range(0, rows, size):
        chunk = thetas[start : start + size]
        pad = size - chunk.shape[0]
        if pad:
            chunk = np.concatenate([chunk, np.repeat(thetas[:1], pad, axis=0)])
        out = _evaluate(predict, space, device_array(chunk))
        pieces.append(jax.tree_util.tree_map(lambda a, n=size - pad: np.asarray(a)[:n], out))
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *pieces)


def _finite_rows(tree, rows):
    ok = np.ones(rows, dtype=bool)
    for leaf in jax.tree_util.tree_leaves(tree):
        ok &= np.all(np.isfinite(np.asarray(leaf).reshape(rows, -1)), axis=1)
    return ok


def _key_name(key):
    if isinstance(key, jax.tree_util.DictKey):
        return f".{key.key}"
    if isinstance(key, jax.tree_util.SequenceKey):
        return f"[{key.idx}]"
    if isinstance(key, jax.tree_util.GetAttrKey):
        return f".{key.name}"
    return str(key)


def named_leaves(tree):
    """[(name, value)] of a pytree of numbers (a band's `nonlinearity`): the leaf's path, dict keys and attributes
    joined by dots, sequence indices in brackets ("tank.pressure", "[0]"); "" for a bare number. Any structure that
    `predict` may return (a tuple, a list, a nested dict) named its leaves; a dict-only reading raised TypeError."""
    return [("".join(_key_name(k) for k in path).lstrip("."), float(v))
            for path, v in jax.tree_util.tree_flatten_with_path(tree)[0]]


def nonlinearity_warning(index, notes):
    leaves = named_leaves(index)
    worst = max((v for _, v in leaves), default=0.0)
    if worst > NONLINEARITY_WARNING:
        where = ""
        if any(name for name, _ in leaves):
            where = " in " + ", ".join(f"{k} ({v:.2g})" for k, v in sorted(leaves, key=lambda kv: -kv[1])
                                       if v > NONLINEARITY_WARNING)
        note = (f"the prediction is nonlinear in the parameters over their uncertainty{where}: index "
                f"{worst:.2g} > {NONLINEARITY_WARNING}, the linear band's edges off by about {3.8 * worst:.1f} σ "
                "(or the solver's error is not small against the band); use method='samples'")
        notes.append(note)
        warnings.warn(note, PamjaxBandWarning, stacklevel=3)


def _delta_std(jac, cov):
    """√diag(J Σθ Jᵀ) per output. Σθ is positive semi-definite (`check_covariance`), so a negative J Σθ Jᵀ is
    rounding, at most ~1e-12 of Σ |J| |Σθ| |J| (set to 0); a larger one is refused, not clipped to a band of width 0."""
    var = np.einsum("...i,ij,...j->...", jac, cov, jac)
    scale = np.einsum("...i,ij,...j->...", np.abs(jac), np.abs(cov), np.abs(jac))
    if np.any(var < -1e-9 * scale):
        raise PamjaxInputError("the covariance propagated is not positive semi-definite: J Σ Jᵀ < 0 for some output "
                               "(a band of width 0 there); check the fit's covariance (pamjax.FitUncertainty)")
    return np.sqrt(np.clip(var, 0.0, None))


def _linear(predict, prop, z, check, batch, notes):
    y, jac = _value_and_jacobian(predict, prop.space, device_array(prop.theta))
    y = jax.tree_util.tree_map(np.asarray, y)
    if not all(np.all(np.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(y)):
        raise PamjaxSolveError("the prediction of the fitted model is not finite (a failed solve): check the "
                               "prediction (e.g. pamjax.simulate(..., throw=True) outside the band) first")
    cov = prop.covariance
    std = jax.tree_util.tree_map(lambda j: _delta_std(np.asarray(j), cov), jac)
    if not all(np.all(np.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(std)):
        raise PamjaxSolveError("the prediction's Jacobian is not finite at the fitted values (forward mode through "
                               "the solve failed); use method='samples'")
    lower = jax.tree_util.tree_map(lambda a, s: a - z * s, y, std)
    upper = jax.tree_util.tree_map(lambda a, s: a + z * s, y, std)
    index, count, failed = None, 1, 0
    if check:
        points = sigma_points(prop.theta, cov)
        n = prop.theta.size
        ys = evaluate(predict, prop.space, points[1:], batch)
        count += 2 * n
        ok = _finite_rows(ys, 2 * n)
        failed = int(np.count_nonzero(~ok))
        axes = ok[:n] & ok[n:]  # a failed point's axis is left out of the index (its NaN hid every output's curvature)
        index = jax.tree_util.tree_map(
            lambda s, a, yy: nonlinearity_index(s, (yy[:n][axes] + yy[n:][axes] - 2 * a[None]) / 2.0), std, y, ys)
        if failed:
            note = (f"{failed} of the {2 * n} linearity-check predictions at ±1 σ failed (a solve that fails within "
                    "the band's own width): the linear band cannot be trusted there; use method='samples'")
            notes.append(note)
            warnings.warn(note, PamjaxBandWarning, stacklevel=3)
        nonlinearity_warning(index, notes)
    how = ("delta method, forward-mode Jacobian in the fit's unconstrained parameters"
           + (f"; linearity checked at ±1 σ along the {prop.theta.size} principal axes" if check else ""))
    return y, lower, upper, std, how, count, failed, index


def _samples(predict, prop, level, samples, seed, batch, notes):
    points = np.concatenate([prop.theta[None], draws(prop.theta, prop.covariance, samples, seed)])
    ys = evaluate(predict, prop.space, points, batch)
    y = jax.tree_util.tree_map(lambda a: a[0], ys)
    if not all(np.all(np.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(y)):
        raise PamjaxSolveError("the prediction of the fitted model is not finite (a failed solve)")
    ok = _finite_rows(ys, samples + 1)[1:]
    failed = int(np.count_nonzero(~ok))
    if samples - failed < 20:
        raise PamjaxSolveError(f"{failed} of {samples} draws failed: too few left for a band")
    if failed > FAILED_WARNING * samples:
        note = (f"{failed} of {samples} draws failed and were left out: the band is conditional on a successful "
                "solve")
        notes.append(note)
        warnings.warn(note, PamjaxBandWarning, stacklevel=3)
    leaves, tree = jax.tree_util.tree_flatten(ys)
    bands = [quantile_band(a[1:][ok], level) for a in leaves]
    lower, upper, std = (jax.tree_util.tree_unflatten(tree, [b[i] for b in bands]) for i in range(3))
    how = (f"{samples} draws of the parameters from N(θ̂, Σθ) in the fit's unconstrained space (seed {seed}), "
           "each simulated; band = their quantiles")
    return y, lower, upper, std, how, samples + 1, failed, None


def prediction_band(result: ResultLike, predict: Callable[[Any], PyTreeLike], *, model: eqx.Module | None = None,
                    level: float = 0.95, method: Method = "linear", samples: int = 200, seed: int = 0, batch: int = 64,
                    check_linearity: bool = True) -> PredictionBand:
    """A confidence band on `predict(model)` from a fit's covariance.

    **Arguments:**

    - `result`: a `FitResult`, or the path of a fit's `model.json` (written by `pamjax fit`: it carries the
      covariance) or `fit.json`.
    - `predict`: a function model → array or dict of arrays, JAX-traceable (it is differentiated in forward mode
      and vmapped): e.g. `lambda m: pj.simulate(m, signal, ts, adjoint="forward", throw=False).channel("position")`.
      A failed solve should give NaN (`throw=False`), which "samples" leaves out and counts.
    - `model`: the model `predict` takes (default: the result's fitted model; a `Rig`'s plant for a fit of a rig;
      the model file's for a path). The fitted values are set on it, so the fit's start model serves as well.
    - `level`: confidence level (0.95). `method`: "linear" (delta method, forward-mode Jacobian) or "samples"
      (`samples` draws, `seed`). `batch`: predictions vmapped per compiled call.
    - `check_linearity` (linear): also evaluate at θ̂ ± 1 σ along the covariance's principal axes (2n predictions)
      and report the `nonlinearity` index (a `PamjaxBandWarning` above 0.1).

    A fit of a `Rig` gives the band of the PLANT's prediction: its nuisances (sensors, run conditions) are
    marginalised, the plant block of the covariance. A fit that flagged model mismatch or did not converge gives a
    band with a note (and a `PamjaxBandWarning`): it understates the uncertainty.

    **Returns:** a `PredictionBand` (`prediction`, `lower`, `upper`, `std`, `method`, `how`, `nonlinearity`, ...).
    """
    z_of(level)
    check_method(method, samples, seed)
    if not callable(predict):
        raise PamjaxInputError(f"predict must be a function model -> prediction, got {type(predict).__name__}")
    if not (isinstance(batch, int) and batch >= 1):
        raise PamjaxInputError(f"batch must be a positive integer, got {batch!r}")
    return propagated_band(predict, propagation(result, model), level, method, samples, seed, batch,
                           check_linearity)


def propagated_band(predict, prop, level, method, samples, seed, batch, check_linearity):
    """`prediction_band` on a `Propagation` already made (its arguments checked): for a caller that checks the
    fitted model before anything is traced (`flow_surface_band`)."""
    z = z_of(level)
    notes = list(prop.notes)
    if method == "linear":
        out = _linear(predict, prop, z, check_linearity, batch, notes)
    else:
        out = _samples(predict, prop, float(level), samples, seed, batch, notes)
    y, lower, upper, std, how, count, failed, index = out
    return PredictionBand(prediction=y, lower=lower, upper=upper, std=std, level=float(level), method=method, how=how,
                          parameters=list(prop.labels), marginalised=list(prop.marginalised), draws=count,
                          failed=failed, nonlinearity=index, notes=notes)
