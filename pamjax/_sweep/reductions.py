"""Reductions of a sweep's outputs over the output times, evaluated on the fly: each is a weighted sum Σ_k w_k y(t_k)
with per-lane weights (`FinalValue`, `WindowMean`, `FourierCoefficient`)."""

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

    def weights(self, ts, system, signal):
        f = _lane_value(self.frequency, system, signal)
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
        return get(root, parts)
    return jnp.asarray(path_or_number, dtype=float)
