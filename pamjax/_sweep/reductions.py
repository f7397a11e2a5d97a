"""Reductions of a sweep's outputs over the output times, evaluated on the fly: each is a weighted sum Σ_k w_k y(t_k)
with per-lane weights (`FinalValue`, `WindowMean`, `FourierCoefficient`), checked on the host before any solve
(`AbstractReduction.check`: a window longer than the run, a frequency that is not > 0)."""

import abc
import numbers

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.errors import PamjaxInputError
from .plan import get


class AbstractReduction(eqx.Module):
    """A reduction of each output channel over the output times, evaluated on the fly: Σ_k w_k y(t_k)."""

    @abc.abstractmethod
    def weights(self, ts, system, signal):
        """Weights over the output times `ts` [s] for one lane (real or complex, shape `ts.shape`); the lane's
        `system` and `signal` may set them (e.g. a swept frequency)."""

    def check(self, ts, lanes):
        """Refuse (`PamjaxInputError`), before any solve, a reduction that cannot be evaluated over the concrete
        output times `ts` [s] (e.g. a window longer than the run, which the weights would silently cut short).
        `lanes()` gives (system, signal) pairs that hold every lane's values (`pamjax._sweep.plan.host_lanes`), for
        a reduction whose weights read the lane; the default accepts any."""


# A window may exceed the run's span by rounding only: relative 1e-9, `FourierCoefficient`'s own tolerance on
# its window's start (a window computed as periods / f of an exact span differs from it by a few ulp).
WINDOW_TOLERANCE = 1e-9


def check_window(window, ts, what):
    """Refuse a reduction window [s] longer than the run `ts[-1] − ts[0]` (beyond `WINDOW_TOLERANCE`): its weights
    would average over whatever the run holds and return a wrong number without a word."""
    span = float(ts[-1] - ts[0])
    if not window <= span * (1 + WINDOW_TOLERANCE):
        raise PamjaxInputError(f"{what} needs a window of {window:.6g} s, longer than the run (ts[-1] - ts[0] = "
                               f"{span:.6g} s): lengthen ts or shorten the window")


class FinalValue(AbstractReduction):
    """The value at the last output time."""

    def weights(self, ts, system, signal):
        return jnp.zeros_like(ts).at[-1].set(1.0)


class WindowMean(AbstractReduction):
    """Time average over the last `window` [s] (e.g. the last N PWM periods: N / f_PWM) of the outputs interpolated
    linearly between the output times: the trapezoid rule, with the window's start interpolated where it falls
    between two output times. Over a whole number of periods sampled evenly each phase counts once (a plain mean
    of the samples in [t_end − window, t_end] counts the phase at both ends: 24 Pa of bias on the MAS-10's PWM
    pressure over a 1 s window, 120 Pa over 0.2 s, measured)."""

    window: float | int = eqx.field(static=True)

    def __check_init__(self):  # a window of no length averages nothing: 0/0 in every lane, silently
        if not (isinstance(self.window, numbers.Real) and np.isfinite(self.window) and self.window > 0):
            raise PamjaxInputError(f"WindowMean.window must be a duration > 0 [s], got {self.window!r}")

    def check(self, ts, lanes):
        check_window(self.window, ts, f"WindowMean({self.window!r})")

    def weights(self, ts, system, signal):
        if ts.shape[0] < 2:
            return jnp.ones_like(ts)
        start = ts[-1] - self.window
        h = jnp.diff(ts)
        theta = jnp.clip((start - ts[:-1]) / jnp.where(h > 0, h, 1.0), 0.0, 1.0)  # fraction before the window
        inside = h * (1.0 - theta)  # length of each interval inside the window
        # trapezoid over [max(t_k, start), t_k+1] with y(start) = (1 − θ) y_k + θ y_k+1
        node = jnp.zeros_like(ts).at[:-1].add(0.5 * inside * (1.0 - theta)).at[1:].add(0.5 * inside * (1.0 + theta))
        return node / jnp.sum(node)


class FourierCoefficient(AbstractReduction):
    """Complex Fourier coefficient at the lane's frequency f over its last `periods` periods:
    Y = (2/n) Σ y(t_k) exp(−i 2π f t_k), so y ≈ mean + Re(Y exp(i 2π f t)); |Y| is the amplitude, arg Y the phase.

    **Arguments:** `periods` (integer number of periods in the window); `frequency`: a path read from the lane
    (default "signal.frequency") or a number [Hz]. Needs output times that sample the window evenly.
    """

    periods: int = eqx.field(static=True, default=3)
    frequency: str | float | int = eqx.field(static=True, default="signal.frequency")

    def __check_init__(self):
        p = self.periods
        if isinstance(p, bool) or not (isinstance(p, numbers.Real) and np.isfinite(p) and p >= 1 and int(p) == p):
            raise PamjaxInputError(f"FourierCoefficient.periods must be a whole number of periods >= 1, got {p!r}")
        f = self.frequency
        if isinstance(f, str):
            if not f:
                raise PamjaxInputError("FourierCoefficient.frequency must be a path such as 'signal.frequency' or a "
                                       "frequency > 0 [Hz], got ''")
        elif isinstance(f, bool) or not (isinstance(f, numbers.Real) and np.isfinite(f) and f > 0):
            raise PamjaxInputError(f"FourierCoefficient.frequency must be a frequency > 0 [Hz] (or a path such as "
                                   f"'signal.frequency'), got {f!r}")

    def check(self, ts, lanes):
        if isinstance(self.frequency, str):  # every lane's frequency, read where its weights read it
            f = np.concatenate([np.ravel(np.asarray(self.lane_frequency(system, signal), dtype=float))
                                for system, signal in lanes()])
        else:
            f = np.array([float(self.frequency)])
        if not np.all(np.isfinite(f) & (f > 0)):
            bad = f[~(np.isfinite(f) & (f > 0))][0]
            raise PamjaxInputError(f"FourierCoefficient's frequency ({self.frequency!r}) must be finite and > 0 [Hz] "
                                   f"at every point, got {bad}")
        check_window(self.periods / f.min(), ts, f"FourierCoefficient({self.periods}) at {f.min():.6g} Hz")
        ts = np.asarray(ts, dtype=float)
        steps = np.diff(ts[ts >= ts[-1] - self.periods / f.min() * (1 + 1e-9)])
        if steps.size and np.ptp(steps) > 1e-6 * np.mean(steps):  # the sum is the integral's rule for even steps only
            raise PamjaxInputError(
                f"FourierCoefficient({self.periods}) needs output times that sample its window evenly (the sum "
                f"(2/n) Σ y(t_k) exp(−i 2π f t_k) weighs every sample alike), got steps from {steps.min():.6g} to "
                f"{steps.max():.6g} s in the last {self.periods / f.min():.6g} s: give ts from np.linspace, or use "
                "pamjax.frequency_response")

    def lane_frequency(self, system, signal):
        """The lane's frequency [Hz]: the number given, or read from the lane by its path ("signal.frequency": the
        signal's `cycle_frequency()`, the contract of a periodic signal)."""
        f = signal.cycle_frequency() if self.frequency == "signal.frequency" else None
        if f is not None:
            return f
        try:  # another path, or a signal of the user's that names its frequency without `cycle_frequency`
            return _lane_value(self.frequency, system, signal)
        except PamjaxInputError:
            if self.frequency != "signal.frequency":
                raise
        raise PamjaxInputError(
            f"FourierCoefficient needs the signal's frequency: the signal {type(signal).__name__} has none (it does "
            f"not repeat); pass FourierCoefficient({self.periods}, frequency=...) [Hz]")

    def weights(self, ts, system, signal):
        f = self.lane_frequency(system, signal)
        inside = ts >= ts[-1] - self.periods / f * (1 + 1e-9)
        # the window [t_end - P/f, t_end] sampled with both ends would count one point twice: drop the first
        first = jnp.argmax(inside)
        inside = inside.at[first].set(False)
        return inside * (2.0 / jnp.sum(inside)) * jnp.exp(-2j * jnp.pi * f * ts)


def _lane_value(path_or_number, system, signal):
    if isinstance(path_or_number, str):
        head, *rest = path_or_number.split(".")
        root = signal if head == "signal" else system
        parts = rest if head == "signal" else [head, *rest]
        try:
            return get(root, parts)
        except AttributeError:
            raise PamjaxInputError(f"FourierCoefficient.frequency: the {'signal' if head == 'signal' else 'system'} "
                                   f"({type(root).__name__}) has no leaf {'.'.join(parts)!r}; pass "
                                   "FourierCoefficient(periods, frequency=...) [Hz] or a path it has") from None
    return jnp.asarray(path_or_number, dtype=float)
