"""`design`'s set-up: everything before the first solve. The arguments checked, the valve's switching thresholds
(from its contract, `switching_gates`) and the duties they leave, the limits checked against the run's start state
(a limit no run from there can keep is refused, naming it), the start signal's coefficients and the designed
experiment. Defaults and their sources are here."""

import inspect
import math

import equinox as eqx
import jax
import numpy as np

from .._control.estimator import check_noise_scale
from .._core.arrays import device_array
from .._core.errors import PamjaxInputError, require_float64
from .._fit.experiment import Experiment
from .._fit.parameters import ParameterSpace, strong_types
from .._fit.recording import Recording
from .._physics.signals import AbstractSignal, Sampled, Triangle
from .._solve.checks import check_start_state
from .._solve.hints import default_max_steps
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from . import design_objective as obj

# Defaults and their sources.
DUTY_BAND = (0.1, 0.9)  # paper 000: with the MHE2's ~2 ms switching time, only duty 10-90 % has an effect at 50 Hz
STROKE_MARGIN = 0.005  # m; assumed (paper 000 gives no clearance): ≈ 5 % of the MAS-10's 95 mm stroke
REST_SLACK = 1e-9  # m: a stroke limit set by the start's rest position lies this much beyond it (below)
DUTY_MARGIN_FRACTION = 0.25  # of a switching threshold's distance from the end of [0, 1] (t_on·f below, t_off·f above):
# paper 000 gives the MHE2's switching time only as "approximately 2 ms", ±0.5 ms in its rounding (±25 %); a duty within
# that of a threshold (0.1 ± 0.025 and 0.9 ± 0.025 at 50 Hz) may or may not switch a real valve in its period. Each
# threshold keeps a quarter of its own switching time (t_on 2 ms, t_off 4 ms: 0.025 at 0.1, 0.05 at 0.8)
MIN_FORCE = 20.0  # N; eq. 7 is backed by data only above it: the measured DMSP-20-300 force map it was derived from
# (Martens & Boblan 2017, Appendix A1; `presets`) is affine in pressure within 2 N down to its smallest non-zero
# force, 21 N, and has no point between slack and 21 N. No braid model is checked below that, nor is the slack itself
START_LEVEL = (0.05, 0.95, 0.08)  # paper 000's E3 duty (Triangle low, high, Hz): the start of the envelope's level
# (built when used: a component made at import would start JAX's backend, fixing its devices before the user can)
START_AMPLITUDE = 0.25  # of the band; assumed: the carrier swings the duty by ±20 % of 0.8 around the level
CARRIER_HOLD = 10  # PWM periods (0.2 s at 50 Hz): the hold of the most informative of the multilevel signals
# compared in docs/identifiability.md (0.1, 0.2, 0.5 and 1 s holds)
DESIGN_RATE = 250.0  # Hz: the objective's samples; the information matrix agrees within 0.2 % with 1 kHz (docs)
DESIGN_SUBSTEPS = 4  # RK4 nodes per PWM period in the objective: within 0.2 % of the fit's 16 (docs)
PERIOD_RTOL = 1e-9  # a `period` given for a switching valve must be its own to this (float round-off of 1/f)
OFFSET_TOLERANCE = 1e-9  # in the soft clip's units (the band's width): a given start the envelope represents to this is
# represented; a larger remainder (an earlier design's per-period duties) is kept as the envelope's offset
FIT_SUBSTEPS = inspect.signature(Experiment.__init__).parameters["substeps"].default  # what a fit integrates with


def built_system(model, build, start, channels):
    """`build(model)` (the model itself when `build` is None), checked before any solve: a pamjax system whose
    initial state takes `start` and whose outputs include every channel of `channels`."""
    if build is None:
        system = model
    elif not callable(build):
        raise PamjaxInputError(f"build must be a callable model → system (e.g. pamjax.TankFromModel(5e-5), as "
                               f"pamjax.Experiment takes it), got {build!r}")
    else:
        try:
            system = build(model)
        except Exception as err:  # a user's callable: any failure is bad input, named
            raise PamjaxInputError(f"build(model) failed: {type(err).__name__}: {err}") from err
    if not isinstance(system, AbstractSystem):
        raise PamjaxInputError(f"build(model) must give a pamjax system (e.g. pamjax.TankFromModel(5e-5) gives a "
                               f"TankSystem), got {type(system).__name__}")
    try:  # traced, not solved
        y0 = jax.eval_shape(lambda s: s.initial_state(**start), system)
    except TypeError as err:
        raise PamjaxInputError(f"start: bad keys {sorted(start)} for {type(system).__name__}.initial_state: "
                               f"{err}") from err
    outputs = jax.eval_shape(lambda s, y: s.outputs(0.0, y, 0.5), system, y0)
    missing = [c for c in channels if c not in outputs]
    if missing:
        raise PamjaxInputError(f"channels {missing}: the designed system ({type(system).__name__}"
                               f"{'' if build is None else ', from build'}) has no such output; it has "
                               f"{sorted(outputs)}")
    return system


def _real(value):
    """`value` as a float where it is one real number (a Python or NumPy number, a 0-d array; not a bool, not a
    string), else None."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or np.ndim(value) != 0:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _check_numbers(noise, channels, band, rate, design_rate, stroke_margin, max_pressure, max_duty_step, seed,
                   baseline_margin):
    """The numeric arguments' types and ranges: each a `PamjaxInputError` naming it (a string or a list where a number
    is due would otherwise fail deep inside, unnamed)."""
    for c in channels:
        v = _real(noise[c])
        if not (v is not None and math.isfinite(v) and v > 0):
            raise PamjaxInputError(f"noise[{c!r}] must be a number > 0 (the channel's standard deviation), got "
                                   f"{noise[c]!r}")
    try:  # a sequence of two numbers (a scalar, a string or a ragged list: refused below)
        pair = [_real(b) for b in band] if np.ndim(band) == 1 else []
    except (TypeError, ValueError):
        pair = []
    if len(pair) != 2 or None in pair or not 0.0 <= pair[0] < pair[1] <= 1.0:
        raise PamjaxInputError(f"duty_band must be (lo, hi) with 0 <= lo < hi <= 1, got {band!r}")
    for name, value, what in (("rate", rate, "the recording's sample rate"),
                              ("design_rate", design_rate, "the objective's sample rate")):
        v = _real(value)
        if not (v is not None and math.isfinite(v) and v > 0):
            raise PamjaxInputError(f"{name} must be {what} [Hz], a number > 0, got {value!r}")
    v = _real(stroke_margin)
    if not (v is not None and v >= 0):
        raise PamjaxInputError(f"stroke_margin must be >= 0 [m], got {stroke_margin!r}")
    v = None if max_pressure is None else _real(max_pressure)
    if max_pressure is not None and not (v is not None and v > 0):
        raise PamjaxInputError(f"max_pressure must be an absolute pressure > 0 [Pa], got {max_pressure!r}")
    v = None if max_duty_step is None else _real(max_duty_step)
    if max_duty_step is not None and not (v is not None and 0 < v <= 1):
        raise PamjaxInputError(f"max_duty_step must be in (0, 1] (duty change per PWM period), got {max_duty_step!r}")
    if not (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0):
        raise PamjaxInputError(f"seed must be an integer >= 0 (of the start's carrier and the spread's points), got "
                               f"{seed!r}")
    v = _real(baseline_margin)  # the same range as `pamjax design`'s schema: a positive number
    if not (v is not None and math.isfinite(v) and v > 0):
        raise PamjaxInputError(f"baseline_margin must be a positive number, e.g. 1.0 (the baseline's standard errors "
                               f"matched; 2.0: halved), got {baseline_margin!r}")


def _period(system, period):
    """The design's PWM period [s]: the switching valve's own, or `period` for a valve without one (checked)."""
    valve_period = system.valve.period  # a switching valve's PWM period (None for a continuous one)
    if period is None and valve_period is None:
        raise PamjaxInputError("period: the model's valve has no pwm_frequency; give the PWM period [s] the bench's "
                               "PWM driver latches the duty with: period=0.02 in pamjax.design_experiment, "
                               "`period = 0.02` in the [design] table of a config")
    if period is not None and not ((p := _real(period)) is not None and math.isfinite(p) and p > 0):
        raise PamjaxInputError(f"period must be the PWM period, a number > 0 [s] (e.g. 0.02 at 50 Hz), got {period!r}")
    if period is not None and valve_period is not None and not math.isclose(period, float(valve_period),
                                                                             rel_tol=PERIOD_RTOL, abs_tol=0.0):
        raise PamjaxInputError(f"period {period!r} s differs from the PWM period of the model's switching valve "
                               f"({float(valve_period):g} s, {1.0 / float(valve_period):g} Hz), which latches one duty "
                               f"per {float(valve_period):g} s whatever the design sets: leave period out (None) or "
                               f"give {float(valve_period):g}; a valve at another frequency is another model "
                               "(its pwm_frequency)")
    return float(valve_period) if period is None else float(period)


MAX_DURATION = 3600.0  # s: a designed run of an hour; 4000 s asked 109 GB of the 2-core CI machine's 24 GB


def _validate(model, free, duration, noise, channels, band, criterion, subset, parametrisation, knots, steps, rate,
              stroke_margin, max_pressure, max_duty_step, period, build, start, duty_margin, min_force, design_rate,
              seed, baseline_margin):
    require_float64("pamjax.design_experiment")
    if not ((d := _real(duration)) is not None and math.isfinite(d) and d > 0):
        raise PamjaxInputError(f"duration must be a positive number of seconds, got {duration!r}")
    if d > MAX_DURATION:  # 33000 (33 s in ms) ran out of memory after 18 s, its output folder left empty
        raise PamjaxInputError(f"duration = {d:g} s is more than {MAX_DURATION:g} s (an hour of bench time, whose "
                               f"periods a design would not fit in memory): that looks like ms ({d / 1e3:g} s)")
    duration = d
    for name, value, what in (("channels", channels, "recorded channels, e.g. ['pressure', 'position']"),
                              ("subset", subset, "free parameter labels, e.g. ['friction.coulomb_force']")):
        if isinstance(value, (str, bytes)):  # a bare string was split into its letters
            raise PamjaxInputError(f"{name} must be a list of {what}, got the string {value!r}")
    start = {} if start is None else start
    if not isinstance(start, dict):
        raise PamjaxInputError(f"start must be a dict of keyword arguments of the system's initial_state (e.g. "
                               f"{{'pressure': 101325.0}}), got {start!r}")
    start = dict(start)
    channels = tuple(channels)
    system = built_system(model, build, start, channels)
    period = _period(system, period)
    if duration < period * (1.0 - 1e-9):
        raise PamjaxInputError(f"duration {duration!r} s is shorter than one PWM period ({period:g} s): a design sets "
                               f"one duty per period, so it needs at least one (duration >= {period:g} s; designs that "
                               "tell much last seconds: docs/identifiability.md)")
    if not channels:
        raise PamjaxInputError("channels must name at least one recorded channel, e.g. ('pressure', 'position')")
    if not isinstance(noise, dict) or not set(channels) <= set(noise):
        raise PamjaxInputError(f"noise must give the noise standard deviation of every channel {list(channels)} "
                               f"(e.g. {{'pressure': 2e3, 'position': 1e-4}} [Pa, m]), got {noise!r}")
    _check_numbers(noise, channels, band, rate, design_rate, stroke_margin, max_pressure, max_duty_step, seed,
                   baseline_margin)
    for name, value in (("rate", rate), ("design_rate", design_rate)):  # 1.0 meant in kHz: 3 samples of a 2 s run
        if float(value) < (1.0 - 1e-9) / period:
            raise PamjaxInputError(f"{name} {value!r} Hz is below the PWM frequency ({1.0 / period:g} Hz): a run "
                                   "sampled slower than one sample per PWM period cannot show what its duties do; "
                                   f"{name} is a sample rate in Hz (1 kHz = 1000.0)")
    check_noise_scale(system, {c: noise[c] for c in channels}, "noise")
    if criterion not in ("D", "A"):
        raise PamjaxInputError(f"criterion must be 'D' or 'A', got {criterion!r}")
    if parametrisation not in ("envelope", "periods"):
        raise PamjaxInputError(f"parametrisation must be 'envelope' or 'periods', got {parametrisation!r}")
    if not (isinstance(knots, int) and not isinstance(knots, bool) and knots >= 4):
        raise PamjaxInputError(f"knots must be an int >= 4 (cubic B-spline coefficients), got {knots!r}")
    if not (isinstance(steps, int) and not isinstance(steps, bool) and steps >= 0):
        raise PamjaxInputError(f"steps must be a non-negative int, got {steps!r}")
    if not (duty_margin == "auto" or (isinstance(duty_margin, (int, float)) and not isinstance(duty_margin, bool)
                                      and 0 <= duty_margin < 0.5)):
        raise PamjaxInputError(f"duty_margin must be 'auto' (a quarter of the valve's switching time, in duty) or a "
                               f"duty in [0, 0.5) kept from the valve's switching thresholds (0: none), got "
                               f"{duty_margin!r}")
    if not (min_force is None or min_force is False or (isinstance(min_force, (int, float)) and
                                                        not isinstance(min_force, bool) and math.isfinite(min_force))):
        raise PamjaxInputError(f"min_force must be the force [N] eq. 7 must keep along the run (default "
                               f"{MIN_FORCE:g}), or None / false for no limit, got {min_force!r}")
    space = ParameterSpace(model, free)
    subset = list(space.labels) if subset is None else list(subset)
    unknown = [s for s in subset if s not in space.labels]
    if unknown or not subset:
        raise PamjaxInputError(f"subset {unknown or subset!r} must name free parameters; they are {space.labels}")
    twice = sorted({s for s in subset if subset.count(s) > 1})
    if twice:
        raise PamjaxInputError(f"subset names {twice} more than once: name each free parameter at most once (they "
                               f"are {space.labels})")
    if build is not None:
        _check_seen(model, space, build, system)
    extra = [c for c in noise if c not in channels]  # after the rest: a muscle's noise table kept for its tank test
    if extra:  # a level the design would not weight: a typo, or a channel left out of `channels`
        raise PamjaxInputError(f"noise: {extra} not among the design's channels {list(channels)}: give a level for "
                               "those channels only (or add the channel to channels)")
    return space, subset, period, channels, system, start


def _check_seen(model, space, build, system):
    """Free parameters that the system `build` makes of `model` does not depend on (a tank test of the valve never
    sees the muscle): refused, naming them (perturbed one at a time, rebuilt, compared; no solve)."""
    import jax.tree_util as jtu

    from .._fit.parameters import getter

    leaves = [np.asarray(x) for x in jtu.tree_leaves(eqx.filter(system, eqx.is_array))]
    unseen = []
    for g in space.groups:
        get = getter(g.attrs)
        old = np.asarray(get(model), dtype=float)
        try:
            other = build(eqx.tree_at(get, model, device_array(old * 1.25 + 1e-3)))
        except Exception:  # noqa: BLE001 - a build that refuses the perturbed value depends on it
            continue
        new = [np.asarray(x) for x in jtu.tree_leaves(eqx.filter(other, eqx.is_array))]
        if len(new) == len(leaves) and all(a.shape == b.shape and np.array_equal(a, b) for a, b in zip(leaves, new)):
            unseen += list(g.labels)
    if unseen:
        raise PamjaxInputError(f"free: {unseen} do not enter the designed system ({type(system).__name__}, from "
                               "build): no run of it can determine them; remove them from free (design the muscle run "
                               "separately, with this test's fit as its prior)")


@eqx.filter_jit
def _gates(valve, duty):
    return valve.switching_gates(duty)


def switching_thresholds(valve):
    """The duties in [0, 1] where a switching valve's gates change (`switching_gates`, the valve contract): below the
    first a period's on-pulse is too short to open it, above the last its off-pulse too short to close it (paper
    000's 10 % and 90 % at 50 Hz with 2 ms switching). Located on nested grids to 1e-12; () for a valve that does not
    switch (an averaged valve)."""
    if not valve.switches:
        return ()
    found = []
    for gate in (0, 1):
        lo, hi = 0.0, 1.0
        grid = np.linspace(lo, hi, 4097)
        values = np.asarray(_gates(valve, device_array(grid))[gate])
        for i in np.nonzero(values[1:] != values[:-1])[0]:
            a, b = grid[i], grid[i + 1]
            while b - a > 1e-12:
                fine = np.linspace(a, b, 4097)
                v = np.asarray(_gates(valve, device_array(fine))[gate])
                j = int(np.nonzero(v[1:] != v[:-1])[0][0])
                a, b = fine[j], fine[j + 1]
            found.append(0.5 * (a + b))
    return tuple(sorted(found))


def auto_margins(thresholds):
    """`duty_margin="auto"`: each threshold's own margin, `DUTY_MARGIN_FRACTION` of its distance from 0 or 1 (of its
    switching time in duty: t_on·f, t_off·f). One margin for both, the smaller, let a 1 ms t_off's 0.0125 stand at
    the 2 ms opening's 0.1 too, inside its ±0.025 coin toss."""
    return [DUTY_MARGIN_FRACTION * min(float(t), 1.0 - float(t)) for t in thresholds]


def duty_limits(band, thresholds, margin):
    """The duties a design may use: (lo, hi, windows): the band less the margin m of a switching threshold θ at
    either end where θ lies within m of it, and the windows (θ − m, θ + m) of the thresholds inside it, which no
    period's duty may enter (`design_objective.skip_windows`). `margin`: one for every threshold, or one per threshold
    (`auto_margins`). A band the margins leave empty is refused."""
    lo, hi = band
    margins = [float(margin)] * len(thresholds) if np.ndim(margin) == 0 else [float(m) for m in margin]
    if not any(margins):
        return lo, hi, ()
    for th, m in zip(thresholds, margins):  # a threshold within its margin of an end: that end moves inside
        if m and th - m <= lo < th + m:
            lo = th + m
        if m and th - m < hi <= th + m:
            hi = th - m
    windows = tuple((th - m, th + m) for th, m in zip(thresholds, margins) if m and lo < th - m and th + m < hi)
    if not hi > lo:
        one = max(margins) - min(margins) <= 1e-9 * max(margins)
        shown = f"{min(margins):g}" if one else f"{', '.join(f'{m:.6g}' for m in margins)} (each threshold's)"
        raise PamjaxInputError(
            f"duty_band ({band[0]:g}, {band[1]:g}) lies within duty_margin {shown} of the valve's switching "
            f"thresholds {', '.join(f'{t:.6g}' for t in thresholds)} (a period's duty below {thresholds[0]:.6g} does "
            f"not open it, above {thresholds[-1]:.6g} does not close it): no duty is left; use a wider band, e.g. "
            f"({thresholds[0] + margins[0]:.6g}, {thresholds[-1] - margins[-1]:.6g}), or a smaller duty_margin")
    return lo, hi, windows


def _skip(duty, windows):
    """`design_objective.skip_windows` on the host."""
    duty = np.asarray(duty, dtype=float).copy()
    for lo, hi in windows:
        inside = (duty > lo) & (duty < hi)
        duty[inside] = np.where(duty[inside] < 0.5 * (lo + hi), lo, hi)
    return duty


@eqx.filter_jit
def static_force_along(system, position, pressure):
    """Eq. 7 (the muscle's force law before the slack) along a run, compiled as one program."""
    return system.muscle.static_force(position, pressure, system.air)


def _has_force_law(system):
    return isinstance(system, AbstractMuscleSystem)


def stroke_limits(model, start, margin):
    """(lo, hi) positions [m] a design may reach: the muscle's stops less `margin`, or as far as the start position
    itself where that lies nearer a stop (a payload hanging at rest within the margin: the run may return there and
    no duty can avoid it). None for a model without a muscle."""
    if not isinstance(model, AbstractMuscleSystem):
        return None
    lo, hi = float(model.muscle.min_position) + margin, float(model.muscle.max_position) - margin
    x0 = float(np.asarray(getattr(_start_state(model, dict(start or {})), "position", np.nan)))
    # Where the rest sets a limit, it lies `REST_SLACK` (1 nm) beyond it: the objective's solve holds the payload at
    # a rest it computes in another program, a few units in the last place away (4e-17 m below on a pilot fit's
    # model), which the start's check read as a broken limit: ten repairs spent on it, and a start of them instead
    # of the default one.
    return ((min(lo, x0 - REST_SLACK), max(hi, x0 + REST_SLACK)) if math.isfinite(x0) else (lo, hi))


@eqx.filter_jit
def _initial_state(system, start):
    return system.initial_state(**start)


def _start_state(system, start):
    """`system.initial_state(**start)`, compiled as one program (eagerly, its static equilibrium compiles each of
    its operations on its own)."""
    return _initial_state(system, {k: device_array(np.asarray(v, dtype=float)) for k, v in start.items()})


def designed_experiment(model, duration, period, rate, channels, noise, start, substeps, duty, build=None):
    """The designed experiment (a Sampled duty, a blank recording at `rate`; the system `build(model)`) bound to
    `model`."""
    times = np.arange(0.0, duration + 0.5 / rate, 1.0 / rate)
    blank = {c: np.full(times.shape, 101325.0 if c.startswith("pressure") else 0.0) for c in channels}
    rec = Recording(times, blank, name="design")
    starts = np.arange(len(duty)) * period
    signal = Sampled(device_array(starts), device_array(duty, dtype=float), period=period)
    exp = Experiment(rec, signal, channels=list(channels), scales={c: float(noise[c]) for c in channels},
                     build=build, initial=start, name="design", substeps=substeps, **run_step_budget(model, duration))
    exp.check(model)
    return exp.bind(model)


def run_step_budget(system, duration):
    """The `max_steps` of a designed or planned run of `duration` [s] (none has a key for one): the Experiment's
    default (100,000) up to 50 s (its compiled program), else `simulate`'s budget for twice the run
    (`default_max_steps`): an 800 s design ran out of the default at 96 s (~1,040 steps/s at the Experiment's rtol
    1e-9 with a duty per period, above that budget's 1,000/s), and an 800 s planned triangle of the averaged MAS-10
    needs ~253,000; with the default their solves failed and read as no information."""
    return {} if duration <= 50.0 else {"max_steps": default_max_steps(system, 0.0, 2.0 * duration)}


@eqx.filter_jit
def _sampled(signal, times):
    """`signal` at `times`, compiled as one program (run eagerly, each operation compiles on its own)."""
    return jax.vmap(signal)(times)


def _start_level(times, band, initial):
    """The start's level per period, in the units of the soft clip (0 and 1 the band's ends): of `initial` (a signal
    or per-period duties, checked), or of paper 000's E3 triangle."""
    lo, hi = band
    if initial is None:
        return (np.asarray(_sampled(Triangle(*START_LEVEL), device_array(times))) - lo) / (hi - lo)
    duty = (np.asarray(_sampled(initial, device_array(times))) if isinstance(initial, AbstractSignal)
            else np.asarray(initial, dtype=float))
    if duty.shape != times.shape:
        raise PamjaxInputError(f"initial must be a signal or one duty per PWM period ({times.size}), got shape "
                               f"{duty.shape}")
    if not np.all(np.isfinite(duty)) or np.min(duty) < 0.0 or np.max(duty) > 1.0:
        raise PamjaxInputError(f"initial: the start duty must lie in [0, 1] (a duty ratio: 0.5, not 50 %), its "
                               f"range is [{np.min(duty):g}, {np.max(duty):g}]")
    return obj.unclip01((np.clip(duty, lo, hi) - lo) / (hi - lo))


def start_coefficients(parametrisation, times, duration, knots, carrier, band, initial, amplitude=START_AMPLITUDE):
    """The start: z = level + `amplitude` ξ, the level from `initial` (a signal or per-period duties; default paper
    000's E3 triangle; no carrier on a given one), in the units of the soft clip (0 and 1 the band's ends; beyond
    them saturated). (coefficients, basis: None for one per period); the envelope's level is the level's
    least-squares fit (`start_offset`: what it leaves of a given start)."""
    level = _start_level(times, band, initial)
    if parametrisation == "periods":
        return level + (amplitude * carrier if initial is None else 0.0), None
    b = obj.bspline_basis(times, 0.0, duration, knots)
    c_level = np.linalg.lstsq(b, level, rcond=None)[0]
    return (np.concatenate([c_level, np.full(knots, amplitude if initial is None else 0.0)]),
            obj.envelope_basis(times, duration, knots, carrier))


def start_offset(parametrisation, times, duration, knots, band, initial):
    """The envelope's offset (`DesignProblem.offset`): the part of a given start its B-spline level cannot represent
    (an earlier design's per-period duties, its carrier), kept as a fixed term of z, so that the design starts from
    the duty given, not its smoothed level (up to 0.17 off, the standard errors up to 19 % apart). None where there is
    none: one per period, no given start (the default start is the envelope's own), a start the level represents to
    `OFFSET_TOLERANCE` (a constant)."""
    if parametrisation == "periods" or initial is None:
        return None
    level = _start_level(times, band, initial)
    b = obj.bspline_basis(times, 0.0, duration, knots)
    offset = level - b @ np.linalg.lstsq(b, level, rcond=None)[0]
    return offset if np.max(np.abs(offset)) > OFFSET_TOLERANCE else None


SETUP_ARGS = ("noise", "channels", "start", "build", "rate", "criterion", "subset", "duty_band", "stroke_margin",
              "max_pressure", "max_duty_step", "parametrisation", "knots", "steps", "initial", "seed", "period",
              "design_rate", "substeps", "duty_margin", "min_force", "baseline_margin")


def set_up(model, free, duration, *, noise, channels, start, build, rate, criterion, subset, duty_band, stroke_margin,
           max_pressure, max_duty_step, parametrisation, knots, steps, initial, seed, period, design_rate, substeps,
           duty_margin, min_force, baseline_margin):
    """Everything before the first solve, as a dict: the checked arguments, the valve's switching thresholds and the
    duties they leave, the limits (each checked against the run's start state), the start coefficients and the
    designed experiment. `baseline_margin` is only checked here (`design` uses it). The start state is checked as
    `simulate` checks a `y0` (`check_start_state`: a position outside the stroke was widened into the stroke limit
    and failed 35 s later, misnamed)."""
    space, subset, period, channels, system, start = _validate(
        model, free, duration, noise, channels, duty_band, criterion, subset, parametrisation, knots, steps, rate,
        stroke_margin, max_pressure, max_duty_step, period, build, start, duty_margin, min_force, design_rate, seed,
        baseline_margin)
    model = strong_types(model)
    space = ParameterSpace(model, free)
    y0 = _start_state(system, start)  # where simulate would refuse it (0.5 m: outside the stroke), before any work
    check_start_state(system, y0, "start")
    thresholds = switching_thresholds(system.valve)
    margin = auto_margins(thresholds) if duty_margin == "auto" else float(duty_margin)
    *band, windows = duty_limits(tuple(float(b) for b in duty_band), thresholds, margin)
    band = tuple(band)
    if np.ndim(margin):  # reported as one number where one serves every threshold (to the thresholds' round-off)
        one = not margin or np.ptp(margin) <= 1e-9 * max(margin)
        margin = (min(margin) if margin else 0.0) if one else margin
    force_law = _has_force_law(system)
    min_force = None if (min_force is None or min_force is False or not force_law) else float(min_force)
    limits = None
    if "position" in channels and isinstance(system, AbstractMuscleSystem):
        lo, hi = float(system.muscle.min_position), float(system.muscle.max_position)
        if lo + stroke_margin >= hi - stroke_margin:
            raise PamjaxInputError(
                f"stroke_margin {stroke_margin!r} m leaves no stroke: the end stops are {1e3 * lo:g} and {1e3 * hi:g} "
                f"mm ({1e3 * (hi - lo):.0f} mm apart) and the margin is kept from each; it is in metres (5 mm = "
                f"0.005, the default {STROKE_MARGIN:g})")
        limits = stroke_limits(system, start, stroke_margin)
    p0 = float(np.asarray(getattr(y0, "pressure", np.nan)))
    if max_pressure is not None and math.isfinite(p0) and max_pressure <= p0:
        raise PamjaxInputError(
            f"max_pressure {max_pressure!r} Pa abs is not above the run's start pressure ({p0:.0f} Pa abs): no run "
            f"from there keeps it. It is an ABSOLUTE pressure in Pa: 5 bar abs = 5e5, 5 bar gauge = "
            f"{5e5 + float(system.air.atmospheric_pressure):.6g}")
    if min_force is not None:
        x0 = float(np.asarray(y0.position, dtype=float))
        f0 = float(np.asarray(static_force_along(system, device_array(x0),
                                                 device_array(np.asarray(y0.pressure, dtype=float)))))
        floor = float(obj.force_floor(x0, float(system.muscle.min_position), min_force, xp=np))
        if f0 < floor:
            raise PamjaxInputError(
                f"min_force {min_force:g} N: eq. 7 gives {f0:.1f} N at the run's start, so no run from there keeps "
                f"the muscle's force above it; give min_force below {f0:.1f} N (default {MIN_FORCE:g}), or None / "
                "false for no limit" if floor == min_force else
                f"min_force: eq. 7 gives {f0:.1f} N at the run's start, on the lower stop: the muscle is slack there "
                "(the volume law holds only while it is taut); start from another state (start = {...}), or "
                "min_force = false for no limit")
    count = int(math.ceil(duration / period - 1e-9))
    times = np.arange(count) * period
    c0, basis = start_coefficients(parametrisation, times, float(duration), knots,
                                   obj.multilevel_carrier(count, CARRIER_HOLD, seed), band, initial)
    offset = start_offset(parametrisation, times, float(duration), knots, band, initial)
    z0 = device_array(c0 if basis is None else basis @ c0 + (0.0 if offset is None else offset))
    duty = _skip(band[0] + (band[1] - band[0]) * np.asarray(obj.clip01_and_slope(z0)[0]), windows)
    exp = designed_experiment(model, float(duration), period, float(design_rate), channels, noise, start, substeps,
                              duty, build)
    return dict(model=model, space=space, subset=subset, period=period, channels=channels, system=system, start=start,
                thresholds=thresholds, duty_margin=margin, duty_band=[float(b) for b in duty_band], band=band,
                windows=windows, force_law=force_law, min_force=min_force, limits=limits, max_pressure=max_pressure,
                max_duty_step=max_duty_step, count=count, times=times, c0=c0, basis=basis, offset=offset,
                experiment=exp)
