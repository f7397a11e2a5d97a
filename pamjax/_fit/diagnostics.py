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

`mismatch` flags the fit ("model mismatch: standard errors understate the uncertainty") when a channel's
`se_inflation` exceeds `mismatch_threshold`: the larger of `MISMATCH_THRESHOLD` (1.2: standard errors understated by
less are not worth a warning) and the value that white noise at the channel's level exceeds with probability
`FALSE_ALARM` / (the channels tested) over its number of samples, so that a fit of the true model is flagged in at most
1 % of noise draws, however short its recordings (a fixed 1.2 flagged 10 % of them at 101 samples, 26 % at 41: the
statistic of N white-noise samples scatters by ~1/√N). See `null_exceedance` for its distribution.
"""

import functools
import math

import numpy as np

from .._core.errors import PamjaxInputError
from .measurement import is_measurement, measurement_stats
from .static_experiments import ForceMapExperiment, HysteresisLoopExperiment, LoopForceMapExperiment

MISMATCH_THRESHOLD = 1.2  # se_inflation below which a mismatch is not worth a warning (the floor of the test)
# The chance that a fit of the true model to white noise at the stated level flags mismatch, split over its channels
# (Bonferroni). Measured per fit of 2 channels of N white-noise samples (20000 draws; ± 0.07 %), noise given /
# estimated: N = 12: 0.92 % / 0.33 %; 20: 0.82 / 0.82; 41: 1.01 / 1.00; 61: 0.98 / 0.81; 101: 1.09 / 0.95; 201: 1.04 /
# 1.00; 300: 0.78 / 0.92; 1001: 0 / 0.15 (the floor 1.2 rules). A fixed 1.2 flagged 26 % / 45 % of them at N = 41,
# 10 % / 28 % at 101, 2.5 % / 13 % at 201. The docs' example (docs/fitting.md "From Python": the true model, 61
# identification samples per channel) over 30 noise seeds: 1 fit flagged (seed 29, 1.46 beside 1.456), was 4.
FALSE_ALARM = 0.01
_ETA_VARIANCE = 0.90  # N × var of the noise estimate's own scatter (`null_exceedance`)
_LAGS = (1, 2, 5, 10, 20)
_Z = np.linspace(-8.0, 8.0, 641)  # quadrature over the lag-1 autocorrelation's standard normal deviate
_PHI_DZ = np.exp(-0.5 * _Z**2) / math.sqrt(2.0 * math.pi) * (_Z[1] - _Z[0])
_ERFC = np.frompyfunc(math.erfc, 1, 1)


def _upper_tail(z):
    """P(Z > z) of a standard normal Z, elementwise."""
    return _ERFC(np.asarray(z, dtype=float) / math.sqrt(2.0)).astype(float) / 2.0


def null_exceedance(inflation: float, samples: int, noise_given: bool) -> float:
    """P(se_inflation > `inflation`) for `samples` (N ≥ 5) samples of Gaussian white noise at the channel's level,
    the level given (`noise_given`) or estimated from the residuals (`_noise_estimate`). From the statistic's
    definition, ln se_inflation = ln(rmse/σ) + atanh(ρ₁⁺) (ρ₁⁺ the lag-1 autocorrelation clipped at 0), with

    - ρ₁ of white noise (its mean removed) near normal, mean −1/N, variance (N−2)²/(N²(N−1)) (0.854/N at N = 20, as
      measured), integrated over;
    - noise given: rmse²/σ² = χ²_N/N, independent of ρ₁ (a ratio of quadratic forms of a spherical vector does not
      depend on its length), through Wilson–Hilferty: (χ²_N/N)^⅓ normal, mean 1 − 2/(9N), variance 2/(9N);
    - noise estimated, σ̂ = 1.4826 MAD(Δe)/√2: the first differences' mean square is 2 rmse² (1 − ρ₁), so rmse/σ̂ =
      (1 − ρ₁)^−½ / W, W = σ̂ over the differences' RMS/√2, the MAD's own scatter: its influence function gives
      var(ln σ̂) = 1.36 (1 + 2 × 0.106)/N = 1.65/N over differences of lag-1 correlation −½, of which the RMS of the
      differences carries (2 + 2 × ¼)/4N = 0.75/N (the efficient estimate: the rest is independent of it), so var W =
      0.90/(N − 3), W taken normal (the skewness of ln W, 3/√N, is that of a normal W; N − 3 for the variance measured
      at N = 20, 1.06/N): a small estimate makes the ratio large, the long upper tail of short recordings.
    """
    n = float(samples)
    rho = -1.0 / n + (n - 2.0) / (n * math.sqrt(n - 1.0)) * _Z
    rest = math.log(inflation) - np.arctanh(np.clip(rho, 0.0, 0.99))  # what ln(rmse/σ) must exceed
    if noise_given:
        a = 2.0 / (9.0 * n)
        tail = _upper_tail((np.exp(2.0 * rest / 3.0) - 1.0 + a) / math.sqrt(a))
    else:
        rest = rest + 0.5 * np.log1p(-np.clip(rho, -0.99, 0.99))  # what −ln W must exceed
        tail = _upper_tail((1.0 - np.exp(-rest)) / math.sqrt(_ETA_VARIANCE / (n - 3.0)))
    return float(_PHI_DZ @ tail)


@functools.lru_cache(maxsize=1024)
def _null_quantile(samples, noise_given, alpha):
    """The se_inflation that white noise exceeds with probability `alpha` (bisection in its log, up to e⁵ ≈ 148:
    a noise estimate from a handful of samples tests nothing)."""
    lo, hi = 0.0, 5.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if null_exceedance(math.exp(mid), samples, noise_given) > alpha else (lo, mid)
    return math.exp(hi)


def mismatch_threshold(samples: int, noise_given: bool, channels: int = 1) -> float:
    """The se_inflation above which a channel of `samples` identification samples flags `mismatch` in a fit of
    `channels` tested channels: the larger of `MISMATCH_THRESHOLD` and the value white noise exceeds with probability
    `FALSE_ALARM` / `channels` (`null_exceedance`; fewer than 5 samples are tested as 5). Noise given, 2 channels: 1.57
    at 41 samples, 1.35 at 101, the floor 1.2 from about 280 on; noise estimated, 2 channels: 2.13, 1.60, 1.2 from
    about 700 on."""
    alpha = FALSE_ALARM / max(int(channels), 1)
    return max(MISMATCH_THRESHOLD, _null_quantile(max(int(samples), 5), bool(noise_given), alpha))


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
                autocorrelation=acf, se_inflation=float(ratio * np.sqrt((1 + rho) / (1 - rho))), samples=int(err.size))


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
    """(flag, note): whether any channel's residuals are not noise (`se_inflation` above `mismatch_threshold` for
    its samples, among all the channels tested), and which ones, worst first. A channel's statistics without
    `samples` (written before it was stored) are held to the floor, `MISMATCH_THRESHOLD`."""
    tested = [(name, c, st) for name, chans in errors.items() for c, st in chans.items()
              if np.isfinite(st.get("se_inflation", float("nan")))]
    bad = []
    for name, c, st in tested:
        factor = st["se_inflation"]
        limit = (mismatch_threshold(st["samples"], st.get("noise_given", False), len(tested)) if "samples" in st
                 else MISMATCH_THRESHOLD)
        if factor > limit:
            bad.append((factor, f"{name}/{c} (se_inflation {factor:.3f}, above the {limit:.3f} that white noise over "
                                f"its {st.get('samples', '?')} samples stays below in 99 % of fits; RMSE "
                                f"{st['rmse_over_noise']:.2f}× noise, lag-1 autocorrelation "
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


def stopped_at_bound(jac, labels, tol, at_bound):
    """The labels of the parameters at a bound of their range (`at_bound`, per label: `ParameterSpace.at_bound`)
    whose Jacobian column in θ vanishes there (at or below `tol` × the largest): the transform to the range is flat at
    its bound (the logistic's derivative 4e-10 of the range at 240 − 5e-8 of (100, 240)), not the data blind to the
    parameter (a viscous coefficient of 250 held below 240: its standard error 1.35 when free). Their standard error
    is undefined there; `identifiability` leaves them out."""
    _, seen = _seen_columns(jac, tol)
    return [labels[i] for i in np.flatnonzero(~seen & np.asarray(at_bound, dtype=bool))]


def identifiability_notes(pinned, groups):
    """The sentences `fit` warns with: one per parameter stopped at a bound of its range (`stopped_at_bound`), one
    per group of `identifiability` (a parameter the data do not see; a combination they cannot separate)."""
    return [f"parameter {label} is at a bound of its range, where the data pull it: its standard error is undefined "
            "there (the transform to the range is flat at its bound); widen its bounds if they are not physical "
            "limits, or hold it" for label in pinned] + [
        f"parameter {grp[0]} has no effect on the data" if len(grp) == 1
        else "non-identifiable combination: " + ", ".join(grp) + " (only a combination of them is fixed by the data; "
        "hold one of them fixed)" for grp in groups]


def identifiability(jac, labels, tol, at_bound=None):
    """What the data cannot fix: lists of labels, one per parameter whose Jacobian column is at or below `tol` × the
    largest (the data do not see it; but not one at a bound of its range, `at_bound` per label: `stopped_at_bound`),
    one per null direction (singular value below `tol` × the largest) of the column-normalised Jacobian of the others
    (a combination the data cannot separate)."""
    norms, seen = _seen_columns(jac, tol)
    pinned = np.zeros(seen.shape, dtype=bool) if at_bound is None else np.asarray(at_bound, dtype=bool)
    groups = [[labels[i]] for i in np.flatnonzero(~seen & ~pinned)]
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
