"""The sweeps users map an actuator with: steady state against duty, the valve's averaged flow surface, frequency
response. Thin recipes over `sweep` and `cycle_averaged_flow`; no physics here."""

import inspect
import numbers
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import Float, RealArrayLike, RealScalarLike, RealVectorLike
from .._core.errors import PamjaxInputError, check_finite, check_nonnegative, check_positive
from .._physics.gas import Air
from .._physics.signals import Constant, Sine
from .._physics.valves.averaged import check_cycle_average, cycle_averaged_flow
from .._physics.valves.base import AbstractSwitchingValve
from .._solve.simulate import solve
from .._systems.base import AbstractSystem
from .reductions import AbstractReduction, WindowMean, check_window
from .result import SweepResult
from .sweep import channel_names, sweep

# Output samples per PWM period before the steady-state window (and `frequency_response`'s grid): sampling at 100 Hz,
# two phases per 50 Hz period, aliased the pressure ripple into a mean by up to 3.8 kPa (0.7 % of range) at duty 0.2.
SAMPLES_PER_PWM_PERIOD = 20
# Output samples per PWM period inside the steady-state window, whose trapezoid mean is the map. The ripple's kinks at
# the valve's edges alias into a mean over 20 phases wherever the edges fall between samples: on the MAS-10 (MHE2,
# 50 Hz, horizon 2 s, window 0.4 s) 43 Pa off a tight time average at duty 0.23, 36 at 0.43, 27 at 0.63, 21 at 0.87,
# and 1-2 Pa only at 0.3 and 0.7, whose edges land on the 1 ms grid; at 40 phases up to 1.0 Pa, at 100 (0.2 ms, the
# default RK4 step there: two 0.1 ms edge widths, so no step more) within 0.03 Pa at every duty (measured). Only the
# window is sampled so densely: the times before it enter no mean (each output time costs an observation).
WINDOW_SAMPLES_PER_PWM_PERIOD = 100
# Without a switching valve the outputs carry no ripple: 100 Hz samples (the mean is over settled, smooth outputs).
SMOOTH_SAMPLE_INTERVAL = 0.01  # s


def steady_state_map(system: AbstractSystem, commands: RealVectorLike, *, horizon: RealScalarLike = 5.0,
                     window: RealScalarLike = 1.0, sample_interval: RealScalarLike | None = None,
                     over: dict[str, RealArrayLike] | None = None, **sweep_kwargs: Any) -> SweepResult:
    """Settled outputs against a constant command (duty ratio): each channel averaged over the last `window` [s]
    of a `horizon` [s] run (with a PWM valve, a whole number of periods, e.g. 1 s = 50 periods at 50 Hz). With the
    switching valve the dead band shows: below ~10 % and above ~90 % duty the valve does not switch (paper 000).

    **Arguments:** `commands` 1-D; `horizon` [s] (default 5 s: on the MAS-10 with 9.6 kg the position still creeps
    by ~2 mm between 2 s and 5 s at duty 0.5); `window` [s] (default 1 s = 50 PWM periods); `sample_interval` [s]
    of the output times (default: for a switching valve 1/100 of the PWM period in the window, whose trapezoid mean
    is then within 0.03 Pa of the exact time average on the MAS-10, and 1/20 before it; else 0.01 s; with a
    switching valve one coarser than 1/20 of its PWM period is refused, `check_pwm_sampling`); `over`:
    further swept paths, broadcast against `commands[:, None]`-style shapes by the caller (not "signal.value": the
    map's axis, `commands`); `sweep_kwargs` go to `sweep` (not `reduce`: the window's mean is the map).
    **Returns:** a `SweepResult` with `over["signal.value"]`.
    """
    check_map_arguments(steady_state_map, "signal.value", "commands", over, sweep_kwargs,
                        "the mean over the last window")
    try:
        commands = np.asarray(commands, dtype=float)
    except (TypeError, ValueError):
        raise PamjaxInputError(f"commands must be a non-empty 1-D array of duties, got {commands!r}") from None
    if commands.ndim != 1 or commands.size == 0:
        raise PamjaxInputError(f"commands must be a non-empty 1-D array, got shape {commands.shape}")
    check_finite(commands, "commands")  # named as the map's argument, not as over['signal.value']
    horizon, window = duration(horizon, "horizon"), duration(window, "window")
    if not 0 < window <= horizon:
        raise PamjaxInputError(f"window must lie in (0, horizon = {horizon}] s, got {window}")
    pwm = _pwm_frequency(system, over)  # Hz, 0 without a switching valve
    if sample_interval is not None:
        sample_interval = duration(sample_interval, "sample_interval")
        check_pwm_sampling(sample_interval, pwm)
    if sample_interval is None and pwm > 0:
        ts = window_grid(horizon, window, 1.0 / (SAMPLES_PER_PWM_PERIOD * pwm),
                         1.0 / (WINDOW_SAMPLES_PER_PWM_PERIOD * pwm))
    else:
        sample_interval = SMOOTH_SAMPLE_INTERVAL if sample_interval is None else sample_interval
        if not sample_interval <= window:  # a window of no sample ("ts needs at least two times" named neither)
            raise PamjaxInputError(f"sample_interval must be at most the window ({window} s) and the horizon "
                                   f"({horizon} s), got {sample_interval}")
        ts = np.linspace(0.0, horizon, int(round(horizon / sample_interval)) + 1)
    return sweep(system, Constant(0.5), ts, {"signal.value": commands, **(over or {})}, reduce=WindowMean(window),
                 **sweep_kwargs)


def duration(x, name):
    """A duration [s] a map takes (`horizon`, `window`, `sample_interval`) as a float > 0, or `PamjaxInputError`
    naming it: a string ("0.2") was a raw TypeError from a comparison."""
    if isinstance(x, (bool, np.bool_)) or not (isinstance(x, numbers.Real) or (
            isinstance(x, (np.ndarray, jax.Array)) and np.ndim(x) == 0 and np.asarray(x).dtype.kind in "iuf")):
        raise PamjaxInputError(f"{name} must be a duration [s], a number > 0, got {x!r}")
    check_positive(x, name)
    return float(x)


def check_pwm_sampling(sample_interval, pwm):
    """`PamjaxInputError` for a `sample_interval` [s] coarser than 1/`SAMPLES_PER_PWM_PERIOD` of the PWM period of a
    switching valve (`pwm` [Hz], 0 without one): the window's mean of outputs sampled so coarsely aliases the PWM
    ripple (on the MAS-10's 50 Hz valve, duties 0.2 and 0.4: 3.4 and 5.4 kPa off at 0.01 s, 0.8 and 2.0 kPa at
    0.005 s; the default grid is within 0.03 Pa of the exact time average)."""
    if pwm <= 0:
        return
    finest = 1.0 / (SAMPLES_PER_PWM_PERIOD * pwm)
    if sample_interval > finest * (1 + 1e-9):
        raise PamjaxInputError(
            f"sample_interval = {sample_interval:g} s is coarser than 1/{SAMPLES_PER_PWM_PERIOD} of the switching "
            f"valve's PWM period (1/({SAMPLES_PER_PWM_PERIOD} x {pwm:g} Hz) = {finest:g} s): the window's mean of "
            "samples that coarse aliases the PWM ripple (kPa off on the MAS-10 at 0.01 s). Drop sample_interval (the "
            f"default samples the window at 1/{WINDOW_SAMPLES_PER_PWM_PERIOD} of the period) or give at most "
            f"{finest:g} s")


def window_grid(horizon, window, before, inside):
    """Output times [s] over [0, `horizon`]: `before` apart up to the window's start `horizon` − `window`, a node,
    and `inside` apart in the window (each spacing rounded to fit its span)."""
    dense = np.linspace(horizon - window, horizon, max(int(round(window / inside)), 1) + 1)
    if horizon - window <= 0:
        return dense
    coarse = np.linspace(0.0, horizon - window, max(int(round((horizon - window) / before)), 1) + 1)
    return np.concatenate([coarse[:-1], dense])


def _pwm_frequency(system, over):
    """The highest PWM frequency [Hz] of a switching valve over the map's points (its `valve.pwm_frequency`, swept
    or not), 0 without one: `frequency_response` samples its ripple `SAMPLES_PER_PWM_PERIOD` times a period, as
    `steady_state_map` does. At 40 samples per period of 5 Hz (200 Hz) the 50 Hz ripple's 4th harmonic aliased onto
    5 Hz: the MAS-10's pressure gain 0.15 % and phase 0.15 deg off a tight reference (-79.17 deg against -79.33)."""
    f = pwm_frequencies(system, over)
    return float(f.max()) if f.size else 0.0


def pwm_frequencies(system: AbstractSystem, over: dict[str, RealArrayLike] | None = None) -> np.ndarray:
    """The PWM frequencies [Hz] of `system`'s switching valve over a map's points (its `valve.pwm_frequency`, or
    the values `over["valve.pwm_frequency"]` sweeps), 1-D; empty without a switching valve. Swept values that are no
    positive finite numbers give the valve's own (the sweep's checks name them)."""
    valve = system.valve if isinstance(system, AbstractSystem) else None
    if valve is None or not valve.switches:
        return np.zeros(0)
    swept = (over or {}).get("valve.pwm_frequency")
    try:
        f = np.ravel(np.asarray(valve.pwm_frequency if swept is None else swept, dtype=float))
    except (TypeError, ValueError):  # not numbers: the sweep names them
        f = np.full(1, np.nan)
    return f if f.size and np.all(np.isfinite(f) & (f > 0)) else np.ravel(np.asarray(valve.pwm_frequency, float))


def check_below_pwm_nyquist(system: AbstractSystem, frequencies: RealVectorLike,
                            over: dict[str, RealArrayLike] | None = None, name: str = "frequencies") -> None:
    """`PamjaxInputError` naming `name` where a command frequency [Hz] reaches half the PWM frequency of `system`'s
    switching valve (the lowest over `over`'s points): the valve latches one duty per period, so the command is
    sampled at the PWM frequency and a sine at or above its Nyquist frequency aliases (at 50 Hz on the MAS-10's
    50 Hz valve the latched duty was 0.5 every period, yet `frequency_response` reported 94,765 Pa/duty at -124 deg:
    the ripple). Nothing to check without a switching valve. `frequency_response`'s check, and the CLI's before it
    takes its output folder."""
    pwm = pwm_frequencies(system, over)
    f = np.ravel(np.asarray(frequencies, dtype=float))
    if not pwm.size or not f.size:
        return
    nyquist = 0.5 * float(pwm.min())
    bad = f[f >= nyquist]
    if bad.size:
        raise PamjaxInputError(
            f"{name} must lie below half the switching valve's PWM frequency ({2 * nyquist:g} Hz / 2 = {nyquist:g} "
            f"Hz), got {np.array2string(bad, threshold=6)} Hz: the valve latches one duty per PWM period, so a "
            "command at or above that frequency aliases and its gain is the PWM ripple. To map beyond it, use the "
            "averaged valve (paper 000 eq. 13: a preset's valve='averaged', or pj.AveragedValve / "
            "pj.fit_averaged_valve(valve, air))")


# tolerances and step limits of the adaptive solve (`solve`'s keywords), which a map passes only in `solve_options`
SOLVE_OPTIONS = tuple(sorted(set(inspect.signature(solve).parameters) - {"system", "signal", "ts", "y0", "t0",
                                                                         "throw"}))


def check_map_arguments(caller, axis, axis_name, over, sweep_kwargs, reduction):
    """`PamjaxInputError` for what a map sets itself: its own axis in `over` (the map's values would be silently
    replaced: a frequency_response over {"signal.frequency": [2, 3]} reported its gains at 2 and 3 Hz as those of
    `frequencies`), a `reduce` among the arguments passed to `sweep` (the map's reduction is its result), and a
    keyword neither the map (`caller`, the function) nor `sweep` takes (`rtol=1e-9` was a raw TypeError from inside
    `sweep`)."""
    name = caller.__name__
    if over is not None and not isinstance(over, dict):
        raise PamjaxInputError(f"{name}: over must be None or a dict {{path: values}}, got {over!r}")
    if axis in (over or {}):
        raise PamjaxInputError(f"{name}: over must not hold {axis!r}, the map's own axis: pass those values as "
                               f"{axis_name}")
    if "reduce" in sweep_kwargs:
        raise PamjaxInputError(f"{name} takes no reduce: it reduces each run itself ({reduction}); call "
                               "pamjax.sweep for another reduction")
    own = [p for p, spec in inspect.signature(caller).parameters.items() if spec.kind is not spec.VAR_KEYWORD]
    passed = [p for p, spec in inspect.signature(sweep).parameters.items()
              if spec.kind is spec.KEYWORD_ONLY and p != "reduce" and p not in own]
    for key in sweep_kwargs:
        if key not in passed:
            hint = (f" ({key} is an option of the adaptive solve: method='adaptive', solve_options={{{key!r}: ...}})"
                    if key in SOLVE_OPTIONS else "")
            raise PamjaxInputError(f"{name} got the keyword {key}=, which neither it nor pamjax.sweep takes{hint}; "
                                   f"its arguments: {', '.join(own[1:])}, and for pamjax.sweep: {', '.join(passed)}")


def flow_surface(valve: AbstractSwitchingValve, commands: RealVectorLike, pressures: RealVectorLike, air: Air,
                 samples: int = 400) -> Float[np.ndarray, "commands pressures"]:
    """Cycle-averaged mass flow ṁ_eq(u, p) [kg/s] into a chamber HELD at `pressures` [Pa abs] for duty `commands`:
    the surface paper 000's eq. 13 is fitted to. Shape (len(commands), len(pressures)); one vmapped call.
    `samples` phases per period (midpoint rule; with the smoothed edges 400 agree with 4000 to 2e-16 of the
    range on the MHE2 preset, measured)."""
    commands, pressures = check_flow_surface(valve, commands, pressures, samples, "samples")
    if not isinstance(air, eqx.Module):  # None was a raw AttributeError from inside the traced flow
        raise PamjaxInputError(f"air must be the gas the valve passes, a pamjax Air (pj.Air(), or the system's "
                               f"system.air), got {air!r}")
    return np.asarray(_flow_surface(valve, commands, pressures, air, samples))


def check_flow_surface(valve, commands, pressures, samples, samples_name):
    """`flow_surface`'s checks, on the host before anything is traced (shared with `flow_surface_band`): 1-D
    commands in the valve's `command_range`, positive ABSOLUTE pressures (bar and gauge refused, as
    `fit_averaged_valve` refuses them), a switching valve (the surface is its flow averaged over a PWM period) and a
    positive int of phases per period (`samples_name` names it): `cycle_averaged_flow`'s `check_cycle_average`.
    Returns the commands and pressures as float arrays."""
    commands = np.asarray(commands, dtype=float)  # no eager device operations
    pressures = np.asarray(pressures, dtype=float)
    if commands.ndim != 1 or pressures.ndim != 1:
        raise PamjaxInputError(f"commands and pressures must be 1-D, got {commands.shape} and {pressures.shape}")
    check_cycle_average(valve, commands, pressures, samples, ("commands", "pressures", samples_name),
                        "the flow surface")
    return commands, pressures


@eqx.filter_jit
def _flow_surface(valve, commands, pressures, air, samples):
    """The (commands × pressures) surface as one program, jitted once here with the valve, air, commands and
    pressures as its arguments (`samples`, an int, static): a lambda jitted per call compiled anew on every call,
    its valve and air baked in as constants."""
    per_pressure = jax.vmap(lambda u, p: cycle_averaged_flow(valve, u, p, air, samples), (None, 0))
    return jax.vmap(per_pressure, (0, None))(commands, pressures)


class _FourierIntegral(AbstractReduction):
    """Fourier coefficient over exactly the last `periods` periods of the lane's `signal.frequency` f,
    Y = (2/T_w) ∫ y(t) exp(−i 2π f t) dt over [t_end − T_w, t_end], T_w = periods/f (the `FourierCoefficient`
    convention: y ≈ mean + Re(Y exp(i 2π f t))), by the trapezoid rule with the window's start interpolated linearly.

    On one common time grid for many frequencies most windows do not hold a whole number of samples;
    `FourierCoefficient`'s plain sum over the samples then covers a fraction of a period too few, and the plant's
    harmonics and mean leak in (0.5 % in gain, 0.45° in phase at 1.5 Hz with 2 periods on a 160 Hz grid, measured on
    the MAS-10; a least-squares sinusoid fit on the same samples still leaks 0.06 %). On a whole window it differs
    from `FourierCoefficient` only in taking half of each end sample (the same for a settled, periodic response);
    otherwise the error is the trapezoid rule's on the fractional interval, O(h³)."""

    periods: int = eqx.field(static=True)

    def check(self, ts, lanes):  # a guard: frequency_response sizes the run for its lowest frequency
        f = np.concatenate([np.ravel(np.asarray(signal.cycle_frequency(), dtype=float)) for _, signal in lanes()])
        check_window(self.periods / f.min(), ts, f"frequency_response's {self.periods} periods at {f.min():.6g} Hz")

    def weights(self, ts, system, signal):
        window = self.periods / signal.frequency  # s
        start = ts[-1] - window
        h = jnp.diff(ts)
        theta = jnp.clip((start - ts[:-1]) / h, 0.0, 1.0)  # fraction of each interval before the window
        inside = h * (1.0 - theta)  # length of each interval inside the window
        # trapezoid over [max(t_k, start), t_k+1] with y(start) = (1 − θ) y_k + θ y_k+1
        node = jnp.zeros_like(ts).at[:-1].add(0.5 * inside * (1.0 - theta)).at[1:].add(0.5 * inside * (1.0 + theta))
        return node * (2.0 / window) * jnp.exp(-2j * jnp.pi * signal.frequency * ts)


def frequency_response(system: AbstractSystem, frequencies: RealVectorLike, *, offset: RealScalarLike = 0.5,
                       amplitude: RealScalarLike = 0.2, settle_periods: RealScalarLike = 3, periods: RealScalarLike = 3,
                       samples_per_period: RealScalarLike = 40, channels: Sequence[str] = ("position", "pressure"),
                       over: dict[str, RealArrayLike] | None = None, **sweep_kwargs: Any) -> dict[str, Any]:
    """Gain and phase of outputs against a sinusoidal command u = offset + amplitude sin(2π f t), at each of
    `frequencies` [Hz], from the Fourier coefficient over exactly the last `periods` periods after
    `settle_periods`.

    All frequencies run in one sweep on a common time grid (as long as the lowest frequency needs, sampled with
    `samples_per_period` samples of the highest, and with a switching valve at least 20 of its PWM period, so that
    the ripple does not alias into the harmonic). Defaults: mid-range duty 0.5 ± 0.2, inside the valve's 10-90 %
    usable band; 3 settling periods (on the MAS-10 with the averaged valve the harmonic at 0.5 Hz is the same to
    8 digits after 3 and 8 periods, measured). `over`: further swept paths (as `steady_state_map`'s), broadcast
    against the frequencies, which are the last axis (e.g. values of shape (k, 1) map k models at every frequency);
    not "signal.frequency" (the map's axis: `frequencies`). `sweep_kwargs` go to `sweep`, but not `reduce`. With a
    switching valve the frequencies must lie below half its PWM frequency (`check_below_pwm_nyquist`: above, the duty
    it latches once a period aliases); the averaged valve maps beyond it.
    **Returns:** dict with `frequency`, and per channel `gain` (|Y|/|U|, channel units per unit command) and `phase`
    [deg] (arg Y − arg U, unwrapped along increasing frequency), U = −i·amplitude the commanded sine's coefficient
    (exact, whatever the valve: a PWM valve's latched duty is not the reference), plus the `SweepResult`.
    """
    check_map_arguments(frequency_response, "signal.frequency", "frequencies", over, sweep_kwargs,
                        "the Fourier integral over the last periods")
    names = channel_names(channels)
    if names is None:
        raise PamjaxInputError('channels must be a non-empty sequence of channel names such as ("position",), '
                               "got None")
    frequencies = np.asarray(frequencies, dtype=float)
    if frequencies.ndim != 1 or frequencies.size == 0:
        raise PamjaxInputError(f"frequencies must be a non-empty 1-D array [Hz], got shape {frequencies.shape}")
    check_positive(frequencies, "frequencies")
    check_below_pwm_nyquist(system, frequencies, over)
    check_finite(amplitude, "amplitude")
    if amplitude == 0:
        raise PamjaxInputError("amplitude must be non-zero (the gain divides by the command's amplitude)")
    if int(periods) != periods or periods < 1:
        raise PamjaxInputError(f"periods must be a positive integer, got {periods}")
    check_nonnegative(settle_periods, "settle_periods")  # NaN and inf too (a horizon of inf, or NaN samples)
    check_finite(samples_per_period, "samples_per_period")
    if samples_per_period < 4:
        raise PamjaxInputError(f"samples_per_period must be >= 4 (twice the Nyquist rate of the highest frequency), "
                               f"got {samples_per_period}")
    horizon = (settle_periods + periods) / frequencies.min()
    n = int(np.ceil(horizon * frequencies.max() * samples_per_period))
    n = max(n, int(np.ceil(horizon * _pwm_frequency(system, over) * SAMPLES_PER_PWM_PERIOD)))
    ts = np.linspace(0.0, horizon, n + 1)
    result = sweep(system, Sine(offset, amplitude, 1.0), ts, {"signal.frequency": frequencies, **(over or {})},
                   reduce=_FourierIntegral(int(periods)), channels=(*names, "command"), **sweep_kwargs)
    # the reference is the commanded sine itself, U = −i A e^{iφ} (u = offset + Re(U e^{i2πft})), not the harmonic
    # of the "command" channel: a switching valve's channel is the duty latched once per PWM period, whose sampled
    # steps moved the phase with `samples_per_period` (−65.7° at 40, −62.3° at 64 at 5 Hz on the MAS-10, against a
    # steady −79.33°). With the averaged valve the channel is the sine, and the two agree to rounding.
    lane_amplitude = np.broadcast_to(result.over.get("signal.amplitude", amplitude), result.status.shape)
    lane_phase = np.broadcast_to(result.over.get("signal.phase", 0.0), result.status.shape)
    u = -1j * lane_amplitude * np.exp(1j * lane_phase)
    order = np.argsort(frequencies)
    out = dict(frequency=frequencies, result=result)
    for c in names:
        ratio = result[c] / u
        phase = np.empty(ratio.shape)
        phase[..., order] = np.degrees(np.unwrap(np.angle(ratio[..., order]), axis=-1))
        out[c] = dict(gain=np.abs(ratio), phase=phase)
    return out
