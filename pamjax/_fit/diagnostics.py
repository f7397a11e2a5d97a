"""What a fit's residuals say: per-channel errors, noise, whiteness, model mismatch, and the parameter statistics.

A least-squares fit's standard errors assume the residuals are the measurement noise: independent, of the stated
level. Where the model cannot follow the data, the residuals are larger than the noise and correlated in time, and
the linearised standard errors understate the uncertainty. `channel_errors` measures both per channel:

- the noise level: the experiment's scale where the user gave it (the noise standard deviation), else an estimate
  from the residuals themselves, 1.4826 MAD(Δe)/√2 of their first differences (a smooth model error cancels in Δe;
  white noise of level σ gives σ);
- `rmse_over_noise`: the residual RMSE over that level (1 for a model that reproduces the data up to the noise);
- `autocorrelation`: the residuals' sample autocorrelation at lags 1, 2, 5, 10 and 20 samples (±2/√N for white
  noise);
- `se_inflation` = rmse_over_noise · √((1 + ρ₁)/(1 − ρ₁)), ρ₁ the lag-1 autocorrelation clipped to [0, 0.99]: the
  factor by which an AR(1) error of that size and correlation widens the true uncertainty over the linearised one.

Slack points (`slack`, a boolean per sample, of the force-map experiments `SLACK_EXPERIMENTS`: `ForceMapExperiment`,
`LoopForceMapExperiment`, `HysteresisLoopExperiment`) are an inequality, "measured F ≤ slack_force, so the model may
not push", not a measurement of 0 N: their residual is 0 wherever the model is slack too, so counting them would
dilute every statistic (on the DMSP-20-300 map, 66 of 126 points slack, the RMSE of eq. 7 read 3.1 N instead of the
loaded points' 4.3 N). The statistics are taken over the measured (loaded) samples only (`measured_samples`); the
slack points are counted apart (`slack_points`) with the largest push the model gives there (`slack_max_violation`).
The `range` stays that of all the data (the map's forces from 0 N up).

A parameter `Measurement` (`pamjax._fit.measurement`) is one datum, not a noise sample: its entry gives the measured
and fitted values and z, and takes no part in `mismatch` (its contradictions are named apart).

`mismatch` flags the fit ("model mismatch: standard errors understate the uncertainty") when any channel's
`se_inflation` exceeds `MISMATCH_THRESHOLD` (1.2: the residuals are then not noise).
"""

import numpy as np

from .._core.errors import PamjaxInputError
from .measurement import is_measurement, measurement_stats
from .static_experiments import ForceMapExperiment, HysteresisLoopExperiment, LoopForceMapExperiment

MISMATCH_THRESHOLD = 1.2  # se_inflation above which the residuals are not noise
_LAGS = (1, 2, 5, 10, 20)


def _noise_estimate(err):
    """1.4826 · MAD of the first differences / √2: the white-noise level of `err` (a smooth part cancels)."""
    if err.size < 3:
        return float("nan")
    d = np.diff(err)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def _autocorrelation(err):
    e = err - np.mean(err)
    denom = float(e @ e)
    out = {}
    for lag in _LAGS:
        out[str(lag)] = float(e[:-lag] @ e[lag:] / denom) if e.size > lag and denom > 0 else 0.0
    return out


def _residual_stats(err, noise_given):
    rmse = float(np.sqrt(np.mean(err**2)))
    estimate = _noise_estimate(err)
    noise = noise_given if noise_given is not None else estimate
    ratio = rmse / noise if noise and np.isfinite(noise) and noise > 0 else float("nan")
    acf = _autocorrelation(err)
    rho = min(max(acf["1"], 0.0), 0.99)
    return dict(noise=noise, noise_estimate=estimate, noise_given=noise_given is not None, rmse_over_noise=ratio,
                autocorrelation=acf, se_inflation=float(ratio * np.sqrt((1 + rho) / (1 - rho))))


SLACK_EXPERIMENTS = (ForceMapExperiment, LoopForceMapExperiment, HysteresisLoopExperiment)  # declare `slack`


def measured_samples(experiment, size):
    """Boolean mask over a channel's `size` samples: True where the sample is a measured value, False at the slack
    points of a force-map experiment (`SLACK_EXPERIMENTS`' `slack`: an inequality, see the module docstring). All
    True for any other experiment."""
    if not isinstance(experiment, SLACK_EXPERIMENTS) or np.shape(experiment.slack) != (size,):
        return np.ones(size, dtype=bool)
    return ~np.asarray(experiment.slack, dtype=bool)


def channel_errors(experiments, residuals):
    """experiment → channel → errors (rmse, max_error, range, % of range, noise, whiteness; `validation_` for the
    held-out part), from the residual vector of all samples (`part="all"`, in the experiments' `layout` order)."""
    out, k = {}, 0
    for e in experiments:
        out[e.name] = {}
        for c, scale, data, used, ident_all in e.layout():
            r = np.asarray(residuals[k : k + data.size])
            k += data.size
            if is_measurement(e):  # one datum with its uncertainty: measured, fitted, z (no noise statistics)
                out[e.name][c] = measurement_stats(e, r[0])
                continue
            err = r * scale
            measured = measured_samples(e, data.size)  # slack points are an inequality, not a value: left out
            ident = used & ident_all & measured
            valid = used & ~ident_all & measured
            given = scale if c in e.noise_channels else None
            span = float(np.ptp(data[used])) if np.any(used) else 0.0
            span = span or 1.0
            stats = {"range": span}
            if not np.all(measured):
                stats.update(slack_points=int(np.sum(used & ~measured)),
                             slack_max_violation=float(np.max(np.abs(err[used & ~measured]), initial=0.0)))
            for prefix, sel in (("", ident), ("validation_", valid)):
                if np.any(sel):
                    rmse, mx = float(np.sqrt(np.mean(err[sel] ** 2))), float(np.max(np.abs(err[sel])))
                    stats.update({f"{prefix}rmse": rmse, f"{prefix}max_error": mx,
                                  f"{prefix}rmse_percent": 100 * rmse / span,
                                  f"{prefix}max_error_percent": 100 * mx / span})
            if np.any(ident):
                stats.update(_residual_stats(err[ident], given))
            out[e.name][c] = stats
    return out


def mismatch(errors):
    """(flag, note): whether any channel's residuals are not noise, and which ones, worst first."""
    bad = []
    for name, chans in errors.items():
        for c, st in chans.items():
            factor = st.get("se_inflation", float("nan"))
            if np.isfinite(factor) and factor > MISMATCH_THRESHOLD:
                bad.append((factor, f"{name}/{c} (RMSE {st['rmse_over_noise']:.2f}× noise, lag-1 autocorrelation "
                                    f"{st['autocorrelation']['1']:.2f})"))
    if not bad:
        return False, ""
    bad.sort(reverse=True)
    return True, ("model mismatch: standard errors understate the uncertainty; the residuals are not noise in "
                  + ", ".join(b for _, b in bad))


def check_identifiability_tol(tol):
    """`fit`'s `identifiability_tol` as a float, a finite number in (0, 1): singular values below tol × the largest
    mark the null directions (`identifiability`, `covariance`), so 0 or less (or NaN) would mark none (NaN: and
    leave every direction out of the covariance, standard errors of 0), 1 or more all but the first."""
    value = None
    if not isinstance(tol, (bool, np.bool_, str)) and np.ndim(tol) == 0:
        try:
            value = float(tol)
        except (TypeError, ValueError):
            value = None
    if value is None or not 0.0 < value < 1.0:
        raise PamjaxInputError(f"identifiability_tol must be a number in (0, 1), got {tol!r}")
    return value


def _seen_columns(jac, tol):
    """(column norms, which columns the data see) of the Jacobian in θ (an O(1)-scaled space: a column is what an
    e-fold or 100 % change of its parameter does to the residuals): a column at or below `tol` × the largest is a
    parameter the data do not see. muscle.slack_width's column on a triangle run was 2.4e-10 beside ~300: a direction
    that the covariance left out, so its standard error read 9e-19 with no warning (σ²(JᵀJ)⁻¹ gives 2.6e9)."""
    norms = np.linalg.norm(jac, axis=0)
    return norms, norms > tol * np.max(norms, initial=0.0) if np.any(norms > 0) else np.zeros(norms.shape, bool)


def _normalised_svd(jac, norms, seen):
    """The SVD of the seen columns scaled to unit norm, where the directions the data do not fix are those with
    singular values below tol × the largest (whatever the parameters' units or sensitivities)."""
    return np.linalg.svd(jac[:, seen] / norms[seen], full_matrices=False)


def identifiability(jac, labels, tol):
    """What the data cannot fix: lists of labels, one per parameter whose Jacobian column is at or below `tol` × the
    largest (the data do not see it), one per null direction (singular value below `tol` × the largest) of the
    column-normalised Jacobian of the others (a combination the data cannot separate)."""
    norms, seen = _seen_columns(jac, tol)
    groups = [[labels[i]] for i in np.flatnonzero(~seen)]
    live = np.flatnonzero(seen)
    if live.size:
        _, s, vt = _normalised_svd(jac, norms, seen)
        for k in np.flatnonzero(s < tol * s[0]):
            v = vt[k]
            groups.append([labels[live[i]] for i in np.flatnonzero(np.abs(v) > 0.1 * np.max(np.abs(v)))])
    return groups


def covariance(jac, cost, used, tol):
    """Covariance of θ from the Jacobian at the optimum, σ² (JᵀJ)⁺ with σ² = 2 cost / (used − n), in the
    column-normalised coordinates `identifiability` judges in (J = Ĵ D, D the column norms: D⁻¹ (ĴᵀĴ)⁺ D⁻¹), so the
    two leave out the same things: the parameters the data do not see (rows and columns 0) and the null directions
    of Ĵ. Where nothing is left out this is σ² (JᵀJ)⁻¹ (to rounding); a pseudo-inverse of J unscaled cut directions by
    singular values that mix units and sensitivities, and gave a parameter the data barely see a standard error of
    0 instead of its true, huge one."""
    n = jac.shape[1]
    sigma2 = 2.0 * float(cost) / max(used - n, 1)
    norms, seen = _seen_columns(jac, tol)
    cov = np.zeros((n, n))
    if np.any(seen):
        _, s, vt = _normalised_svd(jac, norms, seen)
        keep = s >= tol * s[0]  # the complement of `identifiability`'s null directions
        inner = (vt[keep].T / s[keep] ** 2) @ vt[keep]
        cov[np.ix_(seen, seen)] = inner / np.outer(norms[seen], norms[seen]) * sigma2
    return cov
