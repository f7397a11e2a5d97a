"""What a fit's residuals say: per-channel errors, noise, whiteness, model mismatch, and the parameter statistics.

A least-squares fit's standard errors assume the residuals are the measurement noise: independent, of one level.
`covariance` scales them by the residuals' own variance, σ² = 2 cost / (m − n), not by the noise level the user
stated: a residual RMSE twice the stated noise (a noise level misjudged, or a model error) already gives standard
errors twice as wide (the tank of tests/test_bands.py fitted to 2 kPa noise stated as 1 kPa: the spread of refits over
10 noise seeds over the reported standard errors 0.88, 1.01, 0.74). What σ² does not absorb is the residuals'
correlation in time: where the model cannot follow the data, its error is smooth, and N correlated residuals hold
fewer than N samples' information. `channel_errors` measures per channel:

- the noise level: the experiment's scale where the user gave it (the noise standard deviation), else an estimate
  from the residuals themselves, 1.4826 MAD(Δe)/√2 of their first differences (a smooth model error cancels in Δe;
  white noise of level σ gives σ);
- `rmse_over_noise`: the residual RMSE over that level (1 for a model that reproduces the data up to the noise);
- `autocorrelation`: the residuals' sample autocorrelation at lags 1, 2, 5, 10 and 20 samples (±2/√N for white
  noise);
- `se_inflation` = √((1 + ρ₁)/(1 − ρ₁)) (`correlation_factor`), ρ₁ the lag-1 autocorrelation clipped to [0, 0.99]:
  the factor by which an AR(1) error of that correlation widens the true uncertainty over the linearised one, which
  σ² has already scaled to the residuals' size. (It was rmse_over_noise times this factor, counting the size twice:
  the tank above was flagged "standard errors understated by up to 2x" in 10 of 10 fits, whose residuals were white,
  lag-1 autocorrelation 0.07, and whose standard errors held.)

Slack points (`slack`, a boolean per sample, of the force-map experiments `SLACK_EXPERIMENTS`: `ForceMapExperiment`,
`LoopForceMapExperiment`, `HysteresisLoopExperiment`) are an inequality, "measured F ≤ slack_force, so the model may
not push", not a measurement of 0 N: their residual is 0 wherever the model is slack too, so counting them would
dilute every statistic (on the DMSP-20-300 map, 66 of 126 points slack, the RMSE of eq. 7 read 3.1 N instead of the
loaded points' 4.3 N). The statistics are taken over the measured (loaded) samples only (`measured_samples`); the
slack points are counted apart (`slack_points`) with the largest push the model gives there (`slack_max_violation`).
The `range` stays that of all the data (the map's forces from 0 N up).

An experiment without a time axis (`split_time` None: the static maps and curves of `static_experiments.py`) has no
order to its samples: its rows are in whatever order the file lists them, so the statistics read off neighbouring
samples (the first-difference noise estimate, the autocorrelation, `se_inflation`) are not computed for it (left
out, `ordered` False) and it takes no part in the correlation test of `mismatch`: the same 126 points of the DMSP-20-300
map gave a lag-1 autocorrelation of 0.59 and "correlated in time" in file order (by length, then pressure), −0.24
sorted by pressure, −0.03 shuffled. Its RMSE and its residuals' size are what it reports; σ² scales the standard
errors by them. `HysteresisLoopExperiment`, whose samples are the path in the order measured, keeps them.

A parameter `Measurement` (`pamjax._fit.measurement`) is one datum, not a noise sample: its entry gives the measured
and fitted values and z, and takes no part in `mismatch` (its contradictions are named apart).

`mismatch` flags the fit on either of two tests per channel, each at the larger of `MISMATCH_THRESHOLD` (1.2: less
is not worth a warning) and the value that white noise at the stated level exceeds with probability `FALSE_ALARM` /
(the tests made), so that a fit of the true model is flagged in at most ~1 % of noise draws, however short its
recordings (a fixed 1.2 flagged 10 % of them at 101 samples, 26 % at 41: the statistics of N white-noise samples
scatter by ~1/√N):

- correlated residuals, `se_inflation` above `mismatch_threshold`: "model mismatch: standard errors understate the
  uncertainty" (by that factor);
- where the noise level was given, white residuals whose `rmse_over_noise` is above `level_threshold`: the stated
  level is too low, or the model misfits by errors that change from sample to sample. Reported as residuals above
  the stated noise, not as standard errors understated by that ratio (σ² absorbs it), except that a fit of several
  channels pools one σ² over them, so a channel stated too low against the others is weighted too much.
"""

import functools
import math
import statistics

import numpy as np

from .._core.errors import PamjaxInputError
from .measurement import is_measurement, measurement_stats
from .static_experiments import ForceMapExperiment, HysteresisLoopExperiment, LoopForceMapExperiment

MISMATCH_THRESHOLD = 1.2  # se_inflation (or rmse_over_noise) below which a mismatch is not worth a warning
# The chance that a fit of the true model to white noise at the stated level flags mismatch, split over its tests
# (Bonferroni: one per channel, two where the noise level is given). Measured per fit of 2 channels of N white-noise
# samples at the stated level (10000 draws; ± 0.1 %), noise given / estimated: N = 12: 0.81 % / 0.63 %; 20: 0.93 /
# 0.93; 41: 1.00 / 0.89; 101: 1.01 / 1.11; 201: 0.39 / 0.79; 1001 (3000 draws): 0 / 0 (the floor 1.2 rules). A fixed
# 1.2 on the former statistic (the RMSE ratio times the correlation factor) flagged 26 % / 45 % of them at N = 41,
# 10 % / 28 % at 101, 2.5 % / 13 % at 201.
FALSE_ALARM = 0.01
_LAGS = (1, 2, 5, 10, 20)


def correlation_factor(rho: float) -> float:
    """√((1 + ρ)/(1 − ρ)) for a lag-1 autocorrelation ρ clipped to [0, 0.99]: the factor by which residuals
    correlated as an AR(1) process widen a parameter's true uncertainty over the linearised standard error (the
    variance of a mean of N such samples is σ²/N · (1 + ρ)/(1 − ρ) for N ≫ 1/(1 − ρ)). 1 for white residuals; the
    clip keeps it below √199 ≈ 14 (a residual that is all model error)."""
    rho = min(max(float(rho), 0.0), 0.99)
    return math.sqrt((1.0 + rho) / (1.0 - rho))


def _z_above(alpha):
    """The standard normal deviate exceeded with probability `alpha`."""
    return statistics.NormalDist().inv_cdf(1.0 - alpha)


def null_exceedance(inflation: float, samples: int) -> float:
    """P(se_inflation > `inflation`) for `samples` (N ≥ 5) samples of Gaussian white noise: se_inflation exceeds s > 1
    where ρ₁ > tanh(ln s), ρ₁ the lag-1 autocorrelation of white noise (its mean removed), near normal with mean −1/N
    and variance (N − 2)²/(N²(N − 1)) (0.854/N at N = 20, as measured). It does not depend on the noise level, given
    or estimated: ρ₁ is a ratio of quadratic forms of the residuals, whatever their size."""
    if inflation < 1.0:
        return 1.0
    n = float(samples)
    rho = math.tanh(math.log(inflation))
    z = (rho + 1.0 / n) / ((n - 2.0) / (n * math.sqrt(n - 1.0)))
    return 0.5 * math.erfc(z / math.sqrt(2.0))


@functools.lru_cache(maxsize=1024)
def _correlation_limit(samples, tests):
    """The se_inflation that white noise of `samples` samples exceeds with probability FALSE_ALARM / `tests`
    (`null_exceedance` inverted), at least the floor."""
    n = float(max(int(samples), 5))
    rho = -1.0 / n + (n - 2.0) / (n * math.sqrt(n - 1.0)) * _z_above(FALSE_ALARM / max(int(tests), 1))
    return max(MISMATCH_THRESHOLD, correlation_factor(rho))


@functools.lru_cache(maxsize=1024)
def _level_limit(samples, tests):
    """The rmse_over_noise that white noise at the stated level exceeds with probability FALSE_ALARM / `tests` over
    `samples` samples: rmse²/σ² = χ²_N/N, through Wilson–Hilferty ((χ²_N/N)^⅓ normal, mean 1 − 2/(9N), variance
    2/(9N)), at least the floor."""
    a = 2.0 / (9.0 * max(int(samples), 5))
    return max(MISMATCH_THRESHOLD, (1.0 - a + _z_above(FALSE_ALARM / max(int(tests), 1)) * math.sqrt(a)) ** 1.5)


def mismatch_threshold(samples: int, noise_given: bool, channels: int = 1) -> float:
    """The se_inflation above which a channel of `samples` identification samples flags `mismatch` (correlated
    residuals) in a fit of `channels` tested channels, each with its noise level given (`noise_given`: its level
    tested too) or not: the larger of `MISMATCH_THRESHOLD` and the value white noise exceeds with probability
    `FALSE_ALARM` / (the tests made; `null_exceedance`; fewer than 5 samples are tested as 5). 2 channels, noise given:
    1.52 at 41 samples, 1.31 at 101, 1.21 at 201, the floor 1.2 (a lag-1 autocorrelation of 0.18) from about 220 on;
    noise estimated: 1.46, 1.28, the floor from about 200 on."""
    return _correlation_limit(samples, max(int(channels), 1) * (2 if noise_given else 1))


def level_threshold(samples: int, channels: int = 1) -> float:
    """The rmse_over_noise above which a channel of `samples` identification samples, its noise level given, flags
    `mismatch` (residuals above the stated noise) in a fit of `channels` such channels (each tested twice: its
    level and its correlation): 2 channels, 1.59 at 12 samples, 1.32 at 41, the floor 1.2 from about 100 on."""
    return _level_limit(samples, 2 * max(int(channels), 1))


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


def _residual_stats(err, noise_given, ordered=True):
    """The noise statistics of one channel's residuals `err`; `ordered` False (samples without a time order,
    `in_time_order`): those read off neighbouring samples (noise estimate, autocorrelation, se_inflation) are left
    out, and the RMSE over the noise only where the noise was given (keys absent, not NaN: NaN ≠ NaN made two equal
    results unequal)."""
    rmse = float(np.sqrt(np.mean(err**2)))
    if not ordered:
        out = dict(noise_given=noise_given is not None, samples=int(err.size), ordered=False)
        if noise_given is not None and np.isfinite(noise_given) and noise_given > 0:
            out.update(noise=noise_given, rmse_over_noise=rmse / noise_given)
        return out
    estimate = _noise_estimate(err)
    noise = noise_given if noise_given is not None else estimate
    ratio = rmse / noise if noise and np.isfinite(noise) and noise > 0 else float("nan")
    acf = _autocorrelation(err)
    return dict(noise=noise, noise_estimate=estimate, noise_given=noise_given is not None, rmse_over_noise=ratio,
                autocorrelation=acf, se_inflation=correlation_factor(acf["1"]) if np.isfinite(ratio) else float("nan"),
                samples=int(err.size), ordered=True)


SLACK_EXPERIMENTS = (ForceMapExperiment, LoopForceMapExperiment, HysteresisLoopExperiment)  # declare `slack`


def measured_samples(experiment, size):
    """Boolean mask over a channel's `size` samples: True where the sample is a measured value, False at the slack
    points of a force-map experiment (`SLACK_EXPERIMENTS`' `slack`: an inequality, see the module docstring). All
    True for any other experiment."""
    if not isinstance(experiment, SLACK_EXPERIMENTS) or np.shape(experiment.slack) != (size,):
        return np.ones(size, dtype=bool)
    return ~np.asarray(experiment.slack, dtype=bool)


def in_time_order(experiment) -> bool:
    """Whether an experiment's samples are in the order measured, so that neighbouring residuals are neighbours in
    time: one with a time axis (`split_time` not None), or a hysteresis loop read as the path travelled. A static
    map's or curve's rows are in any order (see the module docstring)."""
    return experiment.split_time is not None or isinstance(experiment, HysteresisLoopExperiment)


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
                stats.update(_residual_stats(err[ident], given, in_time_order(e)))
            out[e.name][c] = stats
    return out


def _tested(errors):
    """(experiment, channel, statistics, se_inflation) of every channel with noise statistics. The factor is read
    from the lag-1 autocorrelation where it is stored: a fit result written before se_inflation was the correlation
    factor alone stored rmse_over_noise times it."""
    out = []
    for name, chans in errors.items():
        for c, st in chans.items():
            if not np.isfinite(st.get("se_inflation", float("nan"))):
                continue
            rho = (st.get("autocorrelation") or {}).get("1")
            out.append((name, c, st, correlation_factor(rho) if rho is not None else float(st["se_inflation"])))
    return out


def mismatched_channels(errors):
    """([(se_inflation, words)] of the channels whose residuals are correlated beyond `mismatch_threshold`,
    [(rmse_over_noise, words)] of those, their noise level given, whose residuals are white but above
    `level_threshold`), each worst first. Statistics written without `samples` are held to the floor."""
    tested = _tested(errors)
    tests = sum(1 + bool(st.get("noise_given", False)) for *_, st, _ in tested)
    correlated, high = [], []
    for name, c, st, factor in tested:
        n = st.get("samples")
        ratio, rho = st.get("rmse_over_noise", float("nan")), (st.get("autocorrelation") or {}).get("1", float("nan"))
        limit = _correlation_limit(n, tests) if n else MISMATCH_THRESHOLD
        if factor > limit:
            correlated.append((factor, f"{name}/{c} (se_inflation {factor:.3f}, above the {limit:.3f} that white "
                                       f"noise over its {n or '?'} samples stays below in 99 % of fits; lag-1 "
                                       f"autocorrelation {rho:.2f}, RMSE {ratio:.2f}× noise)"))
            continue
        level = _level_limit(n, tests) if n else MISMATCH_THRESHOLD
        if st.get("noise_given", False) and ratio > level:
            high.append((ratio, f"{name}/{c} (RMSE {st.get('rmse', float('nan')):.3g}, {ratio:.3g}× the stated noise "
                                f"{st.get('noise', float('nan')):.3g}, "
                                f"above the {level:.3f} that white noise at that level over its {n or '?'} samples "
                                f"stays below in 99 % of fits; lag-1 autocorrelation {rho:.2f})"))
    return sorted(correlated, reverse=True), sorted(high, reverse=True)


def understatement(errors: dict) -> float:
    """The factor by which a fit's standard errors understate the uncertainty by its residuals (`channel_errors`):
    the largest se_inflation among the channels `mismatched_channels` flags as correlated, 1 where none is (residuals
    above the stated noise alone do not make the standard errors understate: σ² is the residuals' own)."""
    correlated, _ = mismatched_channels(errors)
    return correlated[0][0] if correlated else 1.0


def mismatch(errors):
    """(flag, note): whether any channel's residuals are not noise at the stated level (`mismatched_channels`:
    correlated in time, or white but above the stated noise), which ones, worst first, and what it means for the
    standard errors."""
    correlated, high = mismatched_channels(errors)
    notes = []
    if correlated:
        notes.append(f"model mismatch: standard errors understate the uncertainty (by up to {correlated[0][0]:.2g}x: "
                     "the residuals are correlated in time; their size is already in the standard errors); the "
                     "residuals are not noise in " + ", ".join(b for _, b in correlated))
    if high:
        pooled = ("; but the fit weighs each channel by its stated noise and pools one variance over them, so the "
                  "parameters this channel fixes may be understated by up to its ratio over the others'"
                  if len(_tested(errors)) > 1 else "")
        notes.append(
            "residuals above the stated noise level, yet white, in " + ", ".join(b for _, b in high) + ": the noise "
            "level stated in the experiment's scales is too low, or the model misfits by errors that change from "
            "sample to sample (a model error is usually smooth, its residuals correlated in time); the standard "
            "errors are scaled by the residuals' own variance, not by the stated level, so they are not understated "
            "by this ratio (state each channel's noise level as about its RMSE)" + pooled)
    return bool(notes), "; ".join(notes)


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
    is undefined there; `identifiability` leaves them out. The columns are measured against the largest of the
    parameters NOT at a bound: where every one is (two discharge coefficients pushed to 1), all are pinned, though
    their columns, all vanishing, compared with one another looked seen (standard errors of 0.01 at C_v = 1)."""
    at_bound = np.asarray(at_bound, dtype=bool)
    norms = np.linalg.norm(jac, axis=0)
    largest = np.max(norms[~at_bound], initial=0.0)
    pinned = at_bound & (norms <= tol * largest) if largest > 0 else at_bound
    return [labels[i] for i in np.flatnonzero(pinned)]


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
