"""Input signals: the command (PWM duty ratio, reference voltage, ...) as a function of time.

Each signal is an `eqx.Module` called as `signal(t)` and reports `bounds()`, its concrete (min, max), so that a
command outside a valve's range is rejected before any solve.
"""

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.arrays import as_array, as_scalar, as_table
from .._core.custom_types import RealArray, RealScalar, Table
from .._core.errors import PamjaxInputError, check_finite, check_positive, check_time_grid, concrete_values
from .._core.fitting import parameter, positive
from .._papers import paper001
from .smooth import smooth_step
from .valves.onoff import MAX_EDGE_FRACTION, first_violation


class AbstractSignal(eqx.Module):
    """A command signal u(t). `__call__(t)` returns the command at time `t` [s]; `bounds()` its (min, max)."""

    @abc.abstractmethod
    def __call__(self, t):
        """The command at time `t` [s] (traceable; `t` may be an array of times under `vmap`)."""

    @abc.abstractmethod
    def bounds(self):
        """The concrete (min, max) of the command over all times, as floats: checked against the valve's
        `command_range` before any solve."""

    def cycle_frequency(self):
        """The frequency [Hz] at which a periodic signal repeats (its `frequency`; an array where swept), which a
        fixed step must resolve (a sweep's scheme takes it); None for a signal that does not repeat."""
        return None

    def jump_times(self):
        """The times [s] where the signal jumps (scalars or 1-D arrays of them, concrete or traced), which an adaptive
        solve takes as step boundaries (a jump inside a step is not seen by its error estimate; a traced jump time
        differentiates through the boundary); () for a continuous signal or one with too many to list."""
        return ()

    def command_shape(self):
        """The shape of the command at one time: () for a signal `simulate` runs; a sweep's batch shape for one
        holding a batch of values (a `Constant` of an array, as `pamjax.sweep` builds it), which `simulate` refuses."""
        return ()

    def table_length(self):
        """The number of samples of a signal read from a table (`Sampled`), None for one given by a formula: runs
        whose tables differ in length are stacked after `extended_to` (`pamjax._solve.run_signals`)."""
        return None

    def extended_to(self, length):
        """This signal with its table extended to `length` samples past its end, reading the same at every time (a
        signal without a table: itself)."""
        return self


class Constant(AbstractSignal):
    """u(t) = `value`, one number: an array of values is a sweep's batch (`pamjax.sweep`), refused by `simulate`."""

    value: RealArray = eqx.field(converter=as_array)

    def __check_init__(self):
        check_finite(self.value, "Constant.value")

    def __call__(self, t):
        return self.value + 0.0 * t

    def command_shape(self):
        return jnp.shape(self.value)

    def bounds(self):
        v = np.asarray(self.value, dtype=float)
        return float(v.min()), float(v.max())


class Step(AbstractSignal):
    """u(t) = `before` for t < `time`, `after` from `time` [s] on. An adaptive solve of a continuous valve ends a step
    at the jump, so that `simulate` is differentiable with respect to `time` (forward and reverse mode)."""

    before: RealScalar = eqx.field(converter=as_scalar)
    after: RealScalar = eqx.field(converter=as_scalar)
    time: RealScalar = parameter(0.0, unit="s")

    def __check_init__(self):
        check_finite(self.before, "Step.before")
        check_finite(self.after, "Step.after")
        check_finite(self.time, "Step.time")

    def __call__(self, t):
        return jnp.where(t < self.time, self.before, self.after)

    def bounds(self):
        b, a = float(self.before), float(self.after)
        return min(a, b), max(a, b)

    def jump_times(self):
        return (self.time,)


class Triangle(AbstractSignal):
    """Triangle wave between `low` and `high` at `frequency` [Hz], starting at `low` and rising (paper 000's system
    tests: duty 0.05-0.95 at 0.08 and 0.25 Hz)."""

    low: RealScalar = eqx.field(converter=as_scalar, default=0.05)
    high: RealScalar = eqx.field(converter=as_scalar, default=0.95)
    frequency: RealScalar = parameter(0.08, unit="Hz")

    def __check_init__(self):
        check_finite(self.low, "Triangle.low")
        check_finite(self.high, "Triangle.high")
        check_positive(self.frequency, "Triangle.frequency")

    def cycle_frequency(self):
        return self.frequency

    def __call__(self, t):
        phase = t * self.frequency - jnp.floor(t * self.frequency)  # in [0, 1)
        shape = 1.0 - jnp.abs(2.0 * phase - 1.0)  # 0 → 1 → 0
        return self.low + (self.high - self.low) * shape

    def bounds(self):
        lo, hi = float(self.low), float(self.high)
        return min(lo, hi), max(lo, hi)


class Sine(AbstractSignal):
    """u(t) = `offset` + `amplitude` sin(2π `frequency` t + `phase`)."""

    offset: RealScalar = eqx.field(converter=as_scalar)
    amplitude: RealScalar = eqx.field(converter=as_scalar)
    frequency: RealScalar = parameter(unit="Hz")
    phase: RealScalar = parameter(0.0, unit="rad")

    def __check_init__(self):
        check_finite(self.offset, "Sine.offset")
        check_finite(self.amplitude, "Sine.amplitude")
        check_positive(self.frequency, "Sine.frequency")
        check_finite(self.phase, "Sine.phase")

    def cycle_frequency(self):
        return self.frequency

    def __call__(self, t):
        return self.offset + self.amplitude * jnp.sin(2 * jnp.pi * self.frequency * t + self.phase)

    def bounds(self):
        o, a = float(self.offset), abs(float(self.amplitude))
        return o - a, o + a


# Sampled's hold changes listed as the adaptive solve's step boundaries, at most: a 40 s run of a duty latched per
# 50 Hz PWM period (paper 000's valve) has 2,000; a longer list (a 1 kHz log) is left to the solver's error control,
# its jumps being that many small ones
MAX_LISTED_JUMPS = 2000
LATCH_SLACK = 1e-9  # of a period: `Sampled` latches period k from (k − slack)·period on (a logged k·period one ulp low)


def latch_instants(k, period):
    """The time from which `Sampled(..., period)` reads period k's sample, (k − slack)·period: a subtraction and a
    product, each rounded once by IEEE arithmetic, so the listed jump and the latch agree to the last bit in NumPy
    and in any compiled program (floor(t / period + slack) did not: XLA at optimisation level 0 read 0.34999999995 s
    as period 7, NumPy as 6). A step boundary there lets no stage of the step before it read the new sample (listed
    at k·period, 5e-11 s later, a step ending there read it: 0.17 kPa off at simulate's default tolerances, 0.7 kPa
    with a sweep's RODAS5). NumPy or traced `k` alike."""
    return (k - LATCH_SLACK) * period


def latched_period(t, period):
    """The period whose sample `Sampled(..., period)` holds at t: floor(t / period + slack), corrected by exact
    comparisons with `latch_instants` where the division rounded across a period start."""
    k = jnp.floor(t / period + LATCH_SLACK)
    return k + (t >= latch_instants(k + 1.0, period)) - (t < latch_instants(k, period))


class Sampled(AbstractSignal):
    """A signal sampled from measured data, held constant between samples (zero-order hold).

    With `period` (e.g. the PWM period 1/f_PWM) the value used at time t is the sample in force at the start of the
    period containing t, as a PWM modulator latches its duty once per period.

    **Arguments:** `times` [s] strictly increasing; `values` of the same length; `period` [s] or None.
    """

    times: Table = eqx.field(converter=as_table)
    values: Table = eqx.field(converter=as_table)
    period: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        check_time_grid(self.times, "Sampled.times")
        check_finite(self.values, "Sampled.values")
        if jnp.shape(self.times) != jnp.shape(self.values):
            raise PamjaxInputError(
                f"Sampled.values must have the same shape as Sampled.times, got {jnp.shape(self.values)} "
                f"and {jnp.shape(self.times)}"
            )
        if self.period is not None and not (self.period > 0 and np.isfinite(self.period)):  # inf: every t in period 0
            raise PamjaxInputError(f"Sampled.period must be a finite number > 0 [s] (or None), got {self.period}")

    def __call__(self, t):
        if self.period is not None:  # the period's start, and the sample there whichever of the two rounds lower
            # (k·period against a logged time: 1234.5000000000002 > 61725 · 0.02 took the last period's duty)
            t = (latched_period(t, self.period) + LATCH_SLACK) * self.period
        index = jnp.clip(jnp.searchsorted(self.times, t, side="right") - 1, 0, self.times.shape[0] - 1)
        return self.values[index]

    def bounds(self):
        v = np.asarray(self.values, dtype=float)
        return float(v.min()), float(v.max())

    def jump_times(self):
        """The times where the held value changes (with `period`: the period starts where the latched sample
        changes), as one array; () where there are more than `MAX_LISTED_JUMPS` (each is a step boundary of the
        adaptive solve: a 1 kHz log's thousands of tiny steps would cost more than the solver's error control loses on
        them). A traced table (a sweep's lanes, which receive their tables traced): every time the held value may
        change, traced, as a swept `Step`'s time is (stepped over, a sweep's lanes were 0.6 kPa / 37 µm off
        `simulate` on the averaged MAS-10)."""
        if jnp.ndim(self.times) != 1 or self.times.shape[0] < 2:
            return ()
        times, values = concrete_values(self.times), concrete_values(self.values)
        if times is None:  # sample i is in force from its time on, or (with `period`) from the next period start
            if self.times.shape[0] > MAX_LISTED_JUMPS + 1:
                return ()
            later = self.times[1:]
            if self.period is not None:
                later = latch_instants(jnp.ceil(later / self.period - LATCH_SLACK), self.period)
            return (later,)
        if values is None:  # traced: each sample's (or period start's) time, whether or not the value changes there
            values = np.arange(times.size, dtype=float)
        if self.period is not None:  # the period starts from the first sample's period to the one after the last
            # sample's (which latches it), each with the sample it latches
            first = np.floor(times[0] / self.period + LATCH_SLACK)
            last = np.floor(times[-1] / self.period + LATCH_SLACK)
            if last - first > 2 * MAX_LISTED_JUMPS:
                return ()
            periods = np.arange(first, last + 2)
            times = np.asarray(latch_instants(periods, self.period))
            latched = (periods + LATCH_SLACK) * self.period  # as __call__ reads each period
            values = values[np.clip(np.searchsorted(concrete_values(self.times), latched, side="right") - 1, 0,
                                    values.size - 1)]
        changed = np.flatnonzero(values[1:] != values[:-1]) + 1
        return (times[changed],) if 0 < changed.size <= MAX_LISTED_JUMPS else ()

    def table_length(self):
        return self.times.shape[0] if jnp.ndim(self.times) == 1 else None

    def extended_to(self, length):
        # the added samples 1 s apart after the last, holding its value: the hold reads the last value there anyway
        pad = length - self.times.shape[0]
        if pad == 0:
            return self
        times = jnp.concatenate([self.times, self.times[-1] + jnp.arange(1, pad + 1, dtype=self.times.dtype)])
        values = jnp.concatenate([self.values, jnp.repeat(self.values[-1:], pad)])
        return eqx.tree_at(lambda s: (s.times, s.values), self, (times, values))


class SquareWave(AbstractSignal):
    """Square wave between `low` and `high` at `frequency` [Hz], duty 50 %, low at t = 0 and rising
    5 edge widths later (paper 001's 1.5 Hz, 0-3 V reference, Fig. 7). Edges are logistic steps of time width
    `edge_width` [s] (1e-3: 0.15 % of a 1.5 Hz period), at most 5 % of the period (`MAX_EDGE_FRACTION`, as
    `OnOffValve`'s; refused otherwise): the edges half a period apart are then 10 widths apart and the wave reaches
    within 1.5 % of `high` and `low`; 1e-3 s at 100 Hz (10 %) peaked at 2.55 of 3 and jumped at each period start."""

    low: RealScalar = parameter(0.0, unit="V")
    high: RealScalar = parameter(paper001.SQUARE_WAVE_HIGH, unit="V")
    frequency: RealScalar = parameter(paper001.SQUARE_WAVE_FREQUENCY, unit="Hz")
    edge_width: RealScalar = positive(1e-3, unit="s")

    def __check_init__(self):
        check_finite(self.low, "SquareWave.low")
        check_finite(self.high, "SquareWave.high")
        check_positive(self.frequency, "SquareWave.frequency")
        check_positive(self.edge_width, "SquareWave.edge_width")
        found = first_violation(lambda f, w: w <= MAX_EDGE_FRACTION / f, self.frequency, self.edge_width)
        if found is not None:
            (f, w), where = found
            raise PamjaxInputError(
                f"SquareWave.edge_width ({w:.6g} s) must not exceed {MAX_EDGE_FRACTION:.0%} of the period "
                f"1/SquareWave.frequency = {1.0 / f:.6g} s (frequency = {f:.6g} Hz), i.e. {MAX_EDGE_FRACTION / f:.6g} "
                f"s{where}: wider logistic edges never reach low or high within a half period (and the wave jumps at "
                "each period start); give a narrower edge_width or a lower frequency"
            )

    def cycle_frequency(self):
        return self.frequency

    def __call__(self, t):
        period = 1.0 / self.frequency
        phase = t - period * jnp.floor(t / period)  # [0, T)
        delay = 5.0 * self.edge_width  # edge centres at delay (rising) and T/2 + delay (falling): starts low
        level = (
            smooth_step(phase - delay, self.edge_width)
            - smooth_step(phase - 0.5 * period - delay, self.edge_width)
            + smooth_step(phase - period - delay, self.edge_width)
        )
        return self.low + (self.high - self.low) * jnp.clip(level, 0.0, 1.0)

    def bounds(self):
        lo, hi = float(self.low), float(self.high)
        return min(lo, hi), max(lo, hi)
