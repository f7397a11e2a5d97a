"""`design`: a PWM duty signal chosen by gradient to maximise what a recording will tell about named parameters.

Workflow only: the objective (Fisher information through the solve, criteria, constraint penalties) is in
`pamjax._design_objective`; the Jacobians of experiments already in hand come from the fit's compiled residual
function (`pamjax._fit`); the iteration is a BFGS on the host with a backtracking line search on the objective's
value (one forward-mode Jacobian per trial) and a gradient only at accepted points.
"""

import functools
import inspect
import math
import threading
import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.errors import PamjaxInputError, require_float64
from .._physics.signals import AbstractSignal, Sampled, Triangle
from .._systems.base import AbstractSystem
from . import design_objective as obj
from .design_result import DesignResult, PamjaxDesignWarning
from .experiment import Experiment
from .fit import _physical_and_jacobian, _residuals_and_jacobian
from .parameters import ParameterSpace, strong_types
from .recording import Recording

# Defaults and their sources.
DUTY_BAND = (0.1, 0.9)  # paper 000: with the MHE2's ~2 ms switching time, only duty 10-90 % has an effect at 50 Hz
STROKE_MARGIN = 0.005  # m; assumed (paper 000 gives no clearance): ≈ 5 % of the MAS-10's 95 mm stroke
DUTY_MARGIN_FRACTION = 0.25  # of a switching threshold's distance from the end of [0, 1] (t_on·f below, t_off·f above):
# paper 000 gives the MHE2's switching time only as "approximately 2 ms", ±0.5 ms in its rounding (±25 %); a duty within
# that of a threshold (0.1 ± 0.025 and 0.9 ± 0.025 at 50 Hz) may or may not switch a real valve in its period
MIN_FORCE = 20.0  # N; eq. 7 is backed by data only above it: the measured DMSP-20-300 force map it was derived from
# (Martens & Boblan 2017, Appendix A1; `presets`) is affine in pressure within 2 N down to its smallest non-zero
# force, 21 N, and has no point between slack and 21 N. No braid model is checked below that, nor is the slack itself
START_LEVEL = (0.05, 0.95, 0.08)  # paper 000's E3 duty (Triangle low, high, Hz): the start of the envelope's level
# (built when used: a component made at import would start JAX's backend, fixing its devices before the user can)
START_AMPLITUDE = 0.25  # of the band; assumed: the carrier swings the duty by ±20 % of 0.8 around the level
START_CALMER = (0.8, 0.6, 0.4, 0.2, 0.0)  # factors on START_AMPLITUDE tried, in turn, where the default start breaks a
# limit (a fast exhaust from high up slackens the muscle): a search that starts within its limits stays within them
CARRIER_HOLD = 10  # PWM periods (0.2 s at 50 Hz): the hold of the most informative of the multilevel signals
# compared in docs/identifiability.md (0.1, 0.2, 0.5 and 1 s holds)
DESIGN_RATE = 250.0  # Hz: the objective's samples; the information matrix agrees within 0.2 % with 1 kHz (docs)
DESIGN_SUBSTEPS = 4  # RK4 nodes per PWM period in the objective: within 0.2 % of the fit's 16 (docs)
# How far the run at the fit's resolution (1 kHz, 16 substeps) may pass a limit that the objective (250 Hz, 4 substeps)
# keeps: the objective samples a 20 ms PWM period 5 times, so the PWM ripple's peaks between its samples go unseen
# (measured: 2.1 kPa on the 5e-5 m³ tank, tests/test_design.py; the force follows the pressure at ~1 N per kPa)
VERIFY_TOLERANCE = dict(stroke=1e-4, pressure=5e3, force=5.0)  # m, Pa, N
FIT_SUBSTEPS = inspect.signature(Experiment.__init__).parameters["substeps"].default  # what a fit integrates with


def information(space, theta, experiments, predictions=False):
    """Fisher information about θ of `experiments` (identification samples, as the fit uses them): JᵀJ of the
    scaled residuals at θ (the fit's compiled Jacobian, shared with fits of the same problem structure). With
    `predictions`, also each experiment's predicted channels {channel: values at its samples}, read back from the
    same residuals (data + scale · residual: no further solve, no further compilation)."""
    model = space.with_values(_physical_and_jacobian(space, device_array(theta))[0])  # compiled, not op by op
    exps = tuple(e.bind(model) if hasattr(e, "bind") else e for e in experiments)
    layouts = [e.layout() for e in exps]
    mask = np.concatenate([used & ident for layout in layouts for _, _, _, used, ident in layout])
    residuals, jac = _residuals_and_jacobian(space, device_array(theta), exps)
    jac = np.asarray(jac)[mask]
    if not predictions:
        return jac.T @ jac
    residuals, k, preds = np.asarray(residuals), 0, []
    for layout in layouts:
        pred = {}
        for name, scale, data, _, _ in layout:
            data = np.asarray(data, dtype=float)
            pred[name] = data + float(scale) * residuals[k:k + data.size]
            k += data.size
        preds.append(pred)
    return jac.T @ jac, preds


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


def _validate(model, free, duration, noise, channels, band, criterion, subset, parametrisation, knots, steps, rate,
              stroke_margin, max_pressure, max_duty_step, period, build, start, duty_margin, min_force):
    require_float64("pamjax.design")
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise PamjaxInputError(f"duration must be a positive number of seconds, got {duration!r}")
    start = {} if start is None else start
    if not isinstance(start, dict):
        raise PamjaxInputError(f"start must be a dict of keyword arguments of the system's initial_state (e.g. "
                               f"{{'pressure': 101325.0}}), got {start!r}")
    start = dict(start)
    channels = tuple(channels)
    system = built_system(model, build, start, channels)
    valve = getattr(system, "valve", None)
    frequency = getattr(valve, "pwm_frequency", None)
    if period is None and frequency is None:
        raise PamjaxInputError("period: the model's valve has no pwm_frequency; give the PWM period [s] the bench's "
                               "PWM driver latches the duty with: period=0.02 in pamjax.design, `period = 0.02` in "
                               "the [design] table of a config")
    if period is not None and not (isinstance(period, (int, float)) and not isinstance(period, bool)
                                   and math.isfinite(period) and period > 0):
        raise PamjaxInputError(f"period must be the PWM period, a number > 0 [s] (e.g. 0.02 at 50 Hz), got {period!r}")
    period = float(1.0 / float(frequency)) if period is None else float(period)
    if duration < period * (1.0 - 1e-9):
        raise PamjaxInputError(f"duration {duration!r} s is shorter than one PWM period ({period:g} s): a design sets "
                               f"one duty per period, so it needs at least one (duration >= {period:g} s; designs that "
                               "tell much last seconds: docs/identifiability.md)")
    if not channels:
        raise PamjaxInputError("channels must name at least one recorded channel, e.g. ('pressure', 'position')")
    if not isinstance(noise, dict) or not set(channels) <= set(noise):
        raise PamjaxInputError(f"noise must give the noise standard deviation of every channel {list(channels)} "
                               f"(e.g. {{'pressure': 2e3, 'position': 1e-4}} [Pa, m]), got {noise!r}")
    for c in channels:
        if not (math.isfinite(float(noise[c])) and float(noise[c]) > 0):
            raise PamjaxInputError(f"noise[{c!r}] must be > 0 (the channel's standard deviation), got {noise[c]!r}")
    _check_noise_scale(system, noise, channels)
    lo, hi = (float(b) for b in band)
    if not 0.0 <= lo < hi <= 1.0:
        raise PamjaxInputError(f"duty_band must be (lo, hi) with 0 <= lo < hi <= 1, got {band!r}")
    if criterion not in ("D", "A"):
        raise PamjaxInputError(f"criterion must be 'D' or 'A', got {criterion!r}")
    if parametrisation not in ("envelope", "periods"):
        raise PamjaxInputError(f"parametrisation must be 'envelope' or 'periods', got {parametrisation!r}")
    if not (isinstance(knots, int) and knots >= 4):
        raise PamjaxInputError(f"knots must be an int >= 4 (cubic B-spline coefficients), got {knots!r}")
    if not (isinstance(steps, int) and steps >= 0):
        raise PamjaxInputError(f"steps must be a non-negative int, got {steps!r}")
    if not (math.isfinite(rate) and rate > 0):
        raise PamjaxInputError(f"rate must be the recording's sample rate [Hz] > 0, got {rate!r}")
    if not stroke_margin >= 0:
        raise PamjaxInputError(f"stroke_margin must be >= 0 [m], got {stroke_margin!r}")
    if max_pressure is not None and not max_pressure > 0:
        raise PamjaxInputError(f"max_pressure must be an absolute pressure > 0 [Pa], got {max_pressure!r}")
    if not (duty_margin == "auto" or (isinstance(duty_margin, (int, float)) and not isinstance(duty_margin, bool)
                                      and 0 <= duty_margin < 0.5)):
        raise PamjaxInputError(f"duty_margin must be 'auto' (a quarter of the valve's switching time, in duty) or a "
                               f"duty in [0, 0.5) kept from the valve's switching thresholds (0: none), got "
                               f"{duty_margin!r}")
    if not (min_force is None or min_force is False or (isinstance(min_force, (int, float)) and
                                                        not isinstance(min_force, bool) and math.isfinite(min_force))):
        raise PamjaxInputError(f"min_force must be the force [N] eq. 7 must keep along the run (default "
                               f"{MIN_FORCE:g}), or None / false for no limit, got {min_force!r}")
    if max_duty_step is not None and not 0 < max_duty_step <= 1:
        raise PamjaxInputError(f"max_duty_step must be in (0, 1] (duty change per PWM period), got {max_duty_step!r}")
    space = ParameterSpace(model, free)
    subset = list(space.labels) if subset is None else list(subset)
    unknown = [s for s in subset if s not in space.labels]
    if unknown or not subset:
        raise PamjaxInputError(f"subset {unknown or subset!r} must name free parameters; they are {space.labels}")
    if build is not None:
        _check_seen(model, space, build, system)
    return space, subset, period, channels, system, start


def _check_noise_scale(system, noise, channels):
    """A noise level no sensor of this system can have: a position noise of a tenth of the whole stroke or more, a
    pressure noise of a tenth of the supply's range or more (a unit slip: 0.1 meant in mm)."""
    muscle = getattr(system, "muscle", None)
    if "position" in channels and muscle is not None:
        stroke = float(muscle.max_position) - float(muscle.min_position)
        if float(noise["position"]) >= 0.1 * stroke:
            raise PamjaxInputError(f"noise['position'] = {noise['position']!r} m is "
                                   f"{float(noise['position']) / stroke:.2g} of the muscle's whole stroke "
                                   f"({1e3 * stroke:.0f} mm): the noise is a standard deviation in metres (0.1 mm = "
                                   "1e-4)")
    valve = getattr(system, "valve", None)
    try:
        span = float(valve.supply()) - float(system.air.atmospheric_pressure)
    except (AttributeError, PamjaxInputError):
        span = None
    if "pressure" in channels and span is not None and float(noise["pressure"]) >= 0.1 * span:
        raise PamjaxInputError(f"noise['pressure'] = {noise['pressure']!r} Pa is {float(noise['pressure']) / span:.2g} "
                               f"of the valve's whole range (supply − atmosphere, {span / 1e5:.2f} bar): the noise "
                               "is a standard deviation in Pa (2 kPa = 2e3)")


def _check_seen(model, space, build, system):
    """Free parameters that the system `build` makes of `model` does not depend on (a tank test of the valve never
    sees the muscle): refused, naming them (perturbed one at a time, rebuilt, compared; no solve)."""
    import jax.tree_util as jtu

    from .parameters import _getter

    leaves = [np.asarray(x) for x in jtu.tree_leaves(eqx.filter(system, eqx.is_array))]
    unseen = []
    for g in space.groups:
        get = _getter(g.attrs)
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
    if not getattr(valve, "switches", False):
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


def duty_limits(band, thresholds, margin):
    """The duties a design may use: the band less `margin` on either side of every switching threshold. One interval
    (lo, hi); a band that a threshold splits, or that the margins leave empty, is refused (the design moves each
    period's duty continuously within one interval, so it would pass through the threshold)."""
    lo, hi = band
    if not margin or not thresholds:
        return lo, hi
    pieces = [(lo, hi)]
    for th in thresholds:
        kept = []
        for a, b in pieces:
            if b <= th - margin or a >= th + margin:
                kept.append((a, b))
                continue
            if a < th - margin:
                kept.append((a, th - margin))
            if b > th + margin:
                kept.append((th + margin, b))
        pieces = kept
    where = (f"the valve's switching thresholds {', '.join(f'{t:.6g}' for t in thresholds)} (a period's duty below "
             f"{thresholds[0]:.6g} does not open it, above {thresholds[-1]:.6g} does not close it)")
    if not pieces:
        raise PamjaxInputError(f"duty_band ({lo:g}, {hi:g}) lies within duty_margin {margin:g} of {where}: no duty is "
                               f"left; use a wider band, e.g. ({thresholds[0] + margin:.6g}, "
                               f"{thresholds[-1] - margin:.6g}), or a smaller duty_margin")
    if len(pieces) > 1:
        inside = [t for t in thresholds if lo + margin < t < hi - margin]
        raise PamjaxInputError(
            f"duty_band ({lo:g}, {hi:g}) contains {inside[0]:.6g}, one of {where}; a design moves each period's duty "
            "continuously within the band, so some periods would sit at it, where whether a real valve switches is a "
            f"coin toss. Give a band on one side of it, e.g. ({thresholds[0] + margin:.6g}, "
            f"{thresholds[-1] - margin:.6g}), or duty_margin = 0 to allow duties at the thresholds")
    return pieces[0]


@eqx.filter_jit
def _static_force(system, position, pressure):
    """Eq. 7 (the muscle's force law before the slack) along a run, compiled as one program."""
    return system.muscle.static_force(position, pressure, system.air)


def _has_force_law(system):
    return hasattr(getattr(system, "muscle", None), "static_force")


def _template(model, duration, period, rate, channels, noise, start, substeps, duty, build=None):
    """The designed experiment (a Sampled duty, a blank recording at `rate`; the system `build(model)`) bound to
    `model`."""
    times = np.arange(0.0, duration + 0.5 / rate, 1.0 / rate)
    blank = {c: np.full(times.shape, 101325.0 if c.startswith("pressure") else 0.0) for c in channels}
    rec = Recording(times, blank, name="design")
    starts = np.arange(len(duty)) * period
    signal = Sampled(device_array(starts), device_array(duty, dtype=float), period=period)
    exp = Experiment(rec, signal, channels=list(channels), scales={c: float(noise[c]) for c in channels},
                     build=build, initial=start, name="design", substeps=substeps)
    exp.check(model)
    return exp.bind(model)


@eqx.filter_jit
def _sampled(signal, times):
    """`signal` at `times`, compiled as one program (run eagerly, each operation compiles on its own)."""
    return jax.vmap(signal)(times)


def _start_coefficients(parametrisation, times, duration, knots, carrier, band, initial, amplitude=START_AMPLITUDE):
    """The start: z = level + `amplitude` ξ, the level from `initial` (a signal or per-period duties; default paper
    000's E3 triangle; no carrier on a given one), in the units of the soft clip (0 and 1 the band's ends; beyond
    them saturated)."""
    lo, hi = band
    if initial is None:
        level = (np.asarray(_sampled(Triangle(*START_LEVEL), device_array(times))) - lo) / (hi - lo)
    else:
        duty = (np.asarray(_sampled(initial, device_array(times))) if isinstance(initial, AbstractSignal)
                else np.asarray(initial, dtype=float))
        if duty.shape != times.shape:
            raise PamjaxInputError(f"initial must be a signal or one duty per PWM period ({times.size}), got shape "
                                   f"{duty.shape}")
        if not np.all(np.isfinite(duty)) or np.min(duty) < 0.0 or np.max(duty) > 1.0:
            raise PamjaxInputError(f"initial: the start duty must lie in [0, 1] (a duty ratio: 0.5, not 50 %), its "
                                   f"range is [{np.min(duty):g}, {np.max(duty):g}]")
        level = obj.unclip01((np.clip(duty, lo, hi) - lo) / (hi - lo))
    if parametrisation == "periods":
        return level + (amplitude * carrier if initial is None else 0.0), None
    b = obj.bspline_basis(times, 0.0, duration, knots)
    c_level = np.linalg.lstsq(b, level, rcond=None)[0]
    return (np.concatenate([c_level, np.full(knots, amplitude if initial is None else 0.0)]),
            obj.envelope_basis(times, duration, knots, carrier))


def _floor(prior_info, base_info, margin):
    """Variances of θ the design must reach: those of a run carrying `margin`² times the baseline run's information
    about each parameter beyond the prior's, 1/v = 1/v_prior + margin² (1/v_baseline − 1/v_prior) (`margin` = 1:
    the baseline's variances; where the prior alone fixes a parameter as well as the baseline does, its own)."""
    v_base = variances(base_info)
    prior_precision = 1.0 / variances(prior_info)  # 0 where the prior leaves a parameter free
    gain = np.maximum(1.0 / v_base - prior_precision, 0.0)
    return 1.0 / (prior_precision + margin**2 * gain)


def _violation(aux):
    """The largest constraint violation in its penalty's units (mm, kPa, duty %, N)."""
    return max(float(aux["worst_stroke"]) / obj.STROKE_UNIT, float(aux["worst_pressure"]) / obj.PRESSURE_UNIT,
               float(aux["worst_step"]) / obj.STEP_UNIT, float(aux["worst_force"]) / obj.FORCE_UNIT)


def _optimise(c, problem, gradient, steps, report):
    """BFGS on the host: a backtracking line search on the value (cheap), a gradient at each accepted point; a
    trial may not leave the feasible set (or, from an infeasible start, increase the worst violation). The cost
    jumps where a stick-slip phase appears or vanishes, so a failed line search restarts from steepest descent;
    two failures in a row end the search."""
    v, aux = obj.value(jnp.asarray(c), problem)
    v = float(v)
    g = np.asarray(gradient(jnp.asarray(c), problem))
    eye = np.eye(c.size)
    h0 = 0.5 / max(float(np.max(np.abs(g))), 1e-12)  # first step moves z by at most 0.5 (the band is z ∈ [0, 1])
    inverse = eye * h0
    history = [[0, v, float(aux["criterion"]), 0.0, True]]
    failures, message = 0, f"{steps} iterations"
    for it in range(1, steps + 1):
        direction = -inverse @ g
        slope = float(g @ direction)
        if not slope < 0:
            inverse, direction = eye * h0, -h0 * g
            slope = float(g @ direction)
        step, accepted = 1.0, False
        for _ in range(8):
            trial = c + step * direction
            v_trial, aux_trial = obj.value(jnp.asarray(trial), problem)
            v_trial = float(v_trial)
            feasible = _violation(aux_trial) <= max(_violation(aux), 0.0) + 1e-9
            if math.isfinite(v_trial) and v_trial <= v + 1e-4 * step * slope and feasible:
                accepted = True
                break
            step *= 0.3
        history.append([it, v_trial if accepted else v, float((aux_trial if accepted else aux)["criterion"]), step,
                         accepted])
        if report is not None:
            report(it, history[-1][1], history[-1][2], step, accepted)
        if not accepted:
            failures += 1
            inverse = eye * h0 * 0.1
            if failures >= 2:
                message = f"stopped after {it} iterations: no descent along the gradient (a kink of the cost)"
                break
            continue
        failures = 0
        g_new = np.asarray(gradient(jnp.asarray(trial), problem))
        s, y = trial - c, g_new - g
        if s @ y > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
            rho = 1.0 / (s @ y)
            left = eye - rho * np.outer(s, y)
            inverse = left @ inverse @ left.T + rho * np.outer(s, s)
        decrease = v - v_trial
        c, g, v, aux = trial, g_new, v_trial, aux_trial
        if decrease < 1e-6 * max(abs(v), 1.0) and step == 1.0:
            message = f"converged after {it} iterations (objective decrease below 1e-6)"
            break
    return c, aux, history, message


def variances(info, transform=None):
    """Diagonal of G F⁺ Gᵀ (G = `transform`, default the identity): the Cramér-Rao variances, inf for every entry
    that moves along a direction F does not fix (an eigenvalue below 1e-9 of the largest)."""
    g = np.eye(info.shape[0]) if transform is None else np.asarray(transform)
    w, v = np.linalg.eigh(0.5 * (info + info.T))
    good = w > 1e-9 * max(float(w.max()), 1e-300)
    var = np.clip(np.diag(g @ ((v[:, good] / w[good]) @ v[:, good].T) @ g.T), 0.0, None)
    null = g @ v[:, ~good]
    loose = (np.abs(null).max(axis=1) > 1e-9 * np.abs(g).max(axis=1)) if null.size else np.zeros(var.shape, bool)
    return np.where(loose, np.inf, var)


def _physical_errors(space, theta, info):
    """Predicted standard errors in physical units (inf along directions the information does not fix)."""
    g = np.asarray(_physical_and_jacobian(space, device_array(theta))[1])  # the fit's compiled Jacobian
    return [float(math.sqrt(v)) for v in variances(info, g)]


def stroke_limits(model, start, margin):
    """(lo, hi) positions [m] a design may reach: the muscle's stops less `margin`, or as far as the start position
    itself where that lies nearer a stop (a payload hanging at rest within the margin: the run may return there and
    no duty can avoid it). None for a model without a muscle."""
    muscle = getattr(model, "muscle", None)
    if muscle is None:
        return None
    lo, hi = float(muscle.min_position) + margin, float(muscle.max_position) - margin
    x0 = float(np.asarray(getattr(_start_state(model, dict(start or {})), "position", np.nan)))
    return (min(lo, x0), max(hi, x0)) if math.isfinite(x0) else (lo, hi)


def _in_hand(space, theta, prior, baseline, index, margin):
    """(prior information, prior + baseline information or None, the variance floor on `index` or None)."""
    n = len(space.labels)
    prior_info = information(space, theta, prior) if len(prior) else np.zeros((n, n))
    if baseline is None:
        return prior_info, None, None
    base_info = prior_info + information(space, theta, baseline)
    floor = np.full(n, np.inf)
    floor[list(index)] = _floor(prior_info, base_info, margin)[list(index)]
    return prior_info, base_info, floor


def _range(a):
    return None if a is None else [float(np.min(a)), float(np.max(a))]


def _worst(values, lo, hi):
    """The largest excursion of `values` below `lo` or above `hi` (0 when within; None when not predicted)."""
    if values is None:
        return None
    values = np.asarray(values, dtype=float)
    return float(max(np.max(lo - values, initial=0.0), np.max(values - hi, initial=0.0), 0.0))


def _constraints(aux, setup, verified=None):
    """The `constraints` report of a design: the limits, the predicted extremes at the objective's samples and, when
    verified, at the fit's resolution, and whether every limit holds (within `VERIFY_TOLERANCE` at the fit's
    resolution, the objective's own resolution limit)."""
    # on the host: NumPy reductions of a JAX array would each compile a program
    duty, position, pressure, force = (None if aux.get(k) is None else np.asarray(aux[k])
                                       for k in ("duty", "position", "pressure", "force"))
    thresholds = setup["thresholds"]
    out = dict(
        duty_band=list(setup["duty_band"]), switching_thresholds=list(thresholds), duty_margin=setup["duty_margin"],
        duty_limits=list(setup["band"]), duty_range=_range(duty),
        threshold_distance=(float(np.min(np.abs(duty[:, None] - np.asarray(thresholds)[None, :])))
                            if thresholds else None),
        largest_duty_step=float(np.max(np.abs(np.diff(duty)))) if duty.size > 1 else 0.0,
        max_duty_step=setup["max_duty_step"],
        stroke_limits=None if setup["limits"] is None else [float(s) for s in setup["limits"]],
        position_range=_range(position), max_pressure=setup["max_pressure"], pressure_range=_range(pressure),
        min_force=setup["min_force"], force_range=_range(force), feasible=_violation(aux) <= 1e-9)
    if verified is not None:
        lo_x, hi_x = setup["limits"] if setup["limits"] is not None else (-np.inf, np.inf)
        p_max = np.inf if setup["max_pressure"] is None else setup["max_pressure"]
        f_min = -np.inf if setup["min_force"] is None else setup["min_force"]
        excess = dict(stroke=_worst(verified.get("position"), lo_x, hi_x),
                      pressure=_worst(verified.get("pressure"), -np.inf, p_max),
                      force=_worst(verified.get("force"), f_min, np.inf))
        out["verified"] = dict(
            position_range=_range(verified.get("position")), pressure_range=_range(verified.get("pressure")),
            force_range=_range(verified.get("force")), excess=excess,
            tolerance=dict(VERIFY_TOLERANCE),
            feasible=all(v is None or v <= VERIFY_TOLERANCE[k] for k, v in excess.items()))
        out["feasible"] = out["feasible"] and out["verified"]["feasible"]
    out["violations"] = _violations(out)
    return out


def _violations(report):
    """One line per violated limit, with what to change (empty when every limit holds)."""
    lines = []
    v = report.get("verified") or {}
    excess = v.get("excess", {})
    tol = v.get("tolerance", {})

    def over(kind, at_samples):
        return at_samples or (excess.get(kind) is not None and excess[kind] > tol.get(kind, 0.0))

    x, lim = report["position_range"], report["stroke_limits"]
    if lim is not None and over("stroke", x is not None and (x[0] < lim[0] - 1e-12 or x[1] > lim[1] + 1e-12)):
        xr = v.get("position_range") or x
        lines.append(f"stroke_margin: predicted {1e3 * xr[0]:.2f} … {1e3 * xr[1]:.2f} mm, limits {1e3 * lim[0]:.2f} "
                     f"… {1e3 * lim[1]:.2f} mm (the end stops less stroke_margin)")
    p, p_max = report["pressure_range"], report["max_pressure"]
    if p_max is not None and over("pressure", p is not None and p[1] > p_max + 1e-9):
        pr = v.get("pressure_range") or p
        lines.append(f"max_pressure: predicted up to {pr[1] / 1e5:.3f} bar abs, limit {p_max / 1e5:.3f} bar abs")
    f, f_min = report["force_range"], report["min_force"]
    if f_min is not None and over("force", f is not None and f[0] < f_min - 1e-9):
        fr = v.get("force_range") or f
        lines.append(f"min_force: eq. 7's force down to {fr[0]:.1f} N, limit {f_min:g} N (the muscle near slack)")
    if report["max_duty_step"] is not None and report["largest_duty_step"] > report["max_duty_step"] + 1e-9:
        lines.append(f"max_duty_step: a step of {report['largest_duty_step']:.3f}, limit {report['max_duty_step']:g}")
    return lines


def _prepare(problem, gradient, c0, space, theta, prior, baseline, index, margin):
    """The design problem with the information in hand, compiling the gradient (the long pole) in a second thread
    meanwhile; checks that the start determines every parameter. Returns (problem, prior information, prior +
    baseline information or None, seconds to the first iteration, the objective's aux at the start)."""
    n = len(space.labels)
    placeholder = problem(np.eye(n), None if baseline is None else np.ones(n))
    warm = threading.Thread(target=lambda: jax.block_until_ready(gradient(jnp.asarray(c0), placeholder)), daemon=True)
    t_compile = time.perf_counter()
    warm.start()
    prior_info, base_info, floor = _in_hand(space, theta, prior, baseline, index, margin)
    prob = problem(prior_info, floor)
    start_value, start_aux = obj.value(jnp.asarray(c0), prob)
    warm.join()
    if not np.isfinite(float(start_value)):
        loose = [lbl for lbl, v in zip(space.labels, variances(np.asarray(start_aux["information"]))) if np.isinf(v)]
        raise PamjaxInputError(f"initial: the start signal (with the prior experiments) does not determine {loose}, "
                               "so the criterion is undefined there. They enter the run, but not independently of "
                               "the other free parameters, or not at the start signal's duties: start from another "
                               "signal (`initial`, e.g. a constant duty in the middle of the band), add prior "
                               "experiments that fix them, or remove them from free")
    return prob, prior_info, base_info, time.perf_counter() - t_compile, start_aux


def _problem(space, theta, exp, basis, weight, band, limits, max_pressure, max_duty_step, force_law, min_force,
             index, criterion, prior_info, floor):
    """The design's `DesignProblem` with a prior information and a variance floor. An absent limit or floor is an
    infinite one (its penalty and worst violation are exactly 0), not None: the problem's structure, and so the
    compiled objective and gradient, is then the same whichever limits and baseline a design of this system,
    parametrisation and duration has (one compilation for all of them)."""
    return obj.DesignProblem(
        space=space, theta=device_array(theta), experiment=exp,
        basis=None if basis is None else device_array(basis), prior=device_array(prior_info),
        weight=jnp.asarray(weight), band=jnp.asarray(band), stroke=None if limits is None else jnp.asarray(limits),
        max_pressure=jnp.asarray(np.inf if max_pressure is None else float(max_pressure)),
        max_step=jnp.asarray(np.inf if max_duty_step is None else float(max_duty_step)),
        min_force=(jnp.asarray(-np.inf if min_force is None else float(min_force)) if force_law else None),
        floor=device_array(np.full(len(space.labels), np.inf) if floor is None else floor), subset=index,
        criterion=criterion)


def design(
    model,
    free,
    duration: float,
    *,
    noise: dict,
    channels=("pressure", "position"),
    start=None,
    build=None,
    rate: float = 1000.0,
    prior=(),
    baseline=None,
    baseline_margin: float = 1.0,
    criterion: str = "D",
    subset=None,
    duty_band=DUTY_BAND,
    duty_margin="auto",
    stroke_margin: float = STROKE_MARGIN,
    max_pressure=None,
    max_duty_step=None,
    min_force=MIN_FORCE,
    parametrisation: str = "envelope",
    knots: int = 12,
    steps: int = 20,
    initial=None,
    seed: int = 0,
    period=None,
    design_rate: float = DESIGN_RATE,
    substeps: int = DESIGN_SUBSTEPS,
    verify: bool = True,
    progress=True,
) -> DesignResult:
    """Choose a PWM duty signal (one value per PWM period) that maximises the information a recording of
    `duration` seconds gives about the parameters `free` of `model`, under a bench's constraints.

    Maximises the Fisher information F = F_prior + Σ JᵀJ (J: the noise-scaled outputs' forward-mode Jacobian with
    respect to the fit's scaled parameters, through the solve) in the D sense (minimise log det F⁻¹ on `subset`) or
    the A sense (log tr F⁻¹), by BFGS with gradients through the solve, the PWM edges and the stick-slip events
    (`pamjax._design_objective`). The design is local: it is optimal near the parameter values of `model`, from the
    start signal. Design at your best estimate — the fit of a short pilot run, not the datasheet: at the MAS-10
    presets the payload rests 11 mm higher than on the bench plant, and a design there predicted gains on the force
    law's a3, a4 that the plant did not give (docs/identifiability.md).

    **Arguments:**

    - `model`: the system at the design point (e.g. `presets.mas10_system(valve="pwm", friction="karnopp")`); its
      valve's PWM frequency sets the period (or give `period` [s]).
    - `free`: the parameters of interest, as `fit` takes them.
    - `duration`: of the designed run [s], from `start` (keyword arguments of the system's `initial_state`; default
      at rest at atmospheric pressure).
    - `build`: model → the system the designed signal drives, as `Experiment(build=...)` takes it (default: `model`
      itself). E.g. `pamjax.TankFromModel(5e-5)` with `channels=("pressure",)` and `start={"pressure": 101325.0}`
      designs a constant-volume tank test of `model`'s valve: the test that separates the valve's flow scales from
      the muscle's volume, which no muscle run can (docs/identifiability.md). `free` are still `model`'s paths (name
      only those the built system depends on, e.g. the valve's); the stroke limit applies only to a system with a
      muscle and a `position` channel.
    - `noise`: channel → noise standard deviation of the bench [channel unit], e.g. `{"pressure": 2e3, "position":
      1e-4}`; `channels`: those recorded; `rate`: the recording's sample rate [Hz].
    - `prior`: experiments already in hand (or run anyway, e.g. constant-volume tank tests): their information is
      added (a muscle run alone cannot separate the valve's flow scale from the muscle's volume).
    - `baseline`: experiments the design must match or beat on every parameter of `subset` (predicted standard
      errors); with `baseline_margin` m > 1 the designed run must carry m² times the baseline run's information on
      each of them beyond what `prior` gives (`_floor`); a penalty enforces it.
    - `criterion`: "D" (default) or "A"; `subset`: labels the criterion is on (default all).
    - `duty_band`: (lo, hi) duty the valve acts on (0.1, 0.9: paper 000); `duty_margin`: every period's duty is kept
      this far from the valve's switching thresholds (`switching_thresholds`: the duties below which a period does
      not open it and above which it does not close it, 0.1 and 0.9 for paper 000's valve), where whether a real
      valve switches is a coin toss; "auto" (default): a quarter of the threshold's distance from 0 or 1, i.e. of the
      switching time (0.025 at 50 Hz and 2 ms: `DUTY_MARGIN_FRACTION`); 0 for none. The band less the margins
      (`duty_limits`) must be one interval. `stroke_margin` [m] kept from the end stops (`muscle.min_position`,
      `max_position`); `max_pressure` [Pa abs] (default none: a valve cannot exceed its supply); `max_duty_step`:
      largest duty change from one period to the next (default none); `min_force` [N]: eq. 7's force (the muscle's
      force law before the slack) kept at or above it along the run, so that the muscle stays in tension where its
      force law is backed by data (default `MIN_FORCE`, 20 N; None for no limit; only for a system with a muscle).
      Each limit is checked against the run's start before any solve (a limit the start breaks is refused, naming
      it); the design's `constraints` report them, and a design that ends outside one warns
      (`PamjaxDesignWarning`) and is refused by `to_csv`.
    - `parametrisation`: "envelope" (default: a level and an amplitude, `knots` cubic B-spline coefficients each,
      modulating a seeded multilevel carrier; gradient in forward mode, 2·knots tangents) or "periods" (one free value
      per period; gradient in reverse mode: exact but ~50× a Jacobian per step on a 2-core CPU for 33 s).
    - `steps`: BFGS iterations at most; `initial`: start signal (a pamjax signal or one duty per period; default paper
      000's E3 triangle with the carrier on top); `seed`: the carrier's.
    - `design_rate` [Hz], `substeps`: resolution of the objective (docs/identifiability.md: within 0.2 % of the
      fit's); `verify`: recompute the final standard errors at the fit's resolution (16 substeps, `rate`).
    - `progress`: True prints one line per iteration; a callable gets (iteration, objective, criterion, step,
      accepted); False is silent.

    **Returns:** a `DesignResult` (`signal()`, `to_csv`, `to_json`, `plot`, `table`).
    """
    t_start = time.perf_counter()
    setup = _setup(model, free, duration, noise=noise, channels=channels, start=start, build=build, rate=rate,
                   criterion=criterion, subset=subset, duty_band=duty_band, stroke_margin=stroke_margin,
                   max_pressure=max_pressure, max_duty_step=max_duty_step, parametrisation=parametrisation,
                   knots=knots, steps=steps, initial=initial, seed=seed, period=period, design_rate=design_rate,
                   substeps=substeps, duty_margin=duty_margin, min_force=min_force)
    model, space, subset, c0, basis, exp = (setup[k] for k in ("model", "space", "subset", "c0", "basis", "experiment"))
    channels, start, period, count = setup["channels"], setup["start"], setup["period"], setup["count"]
    theta = np.asarray(space.initial_theta())
    n, index = len(space.labels), tuple(space.labels.index(s) for s in subset)

    problem = functools.partial(_problem, space, theta, exp, basis, float(rate) / float(design_rate), setup["band"],
                                setup["limits"], max_pressure, max_duty_step, setup["force_law"], setup["min_force"],
                                index, criterion)

    gradient = obj.reverse_gradient if parametrisation == "periods" else obj.forward_gradient
    report = _printer(progress, f"design: {count} PWM periods, {len(c0)} coefficients ({parametrisation}), "
                                f"{criterion}-optimal over {len(subset)} of {n} parameters; compiling the objective "
                                "and its gradient ...")
    prob, prior_info, base_info, compile_s, start_aux = _prepare(problem, gradient, c0, space, theta, prior, baseline,
                                                                 index, float(baseline_margin))
    note = ""
    if initial is None and _violation(start_aux) > 0:  # the default start breaks a limit: a calmer carrier
        for factor in START_CALMER:
            trial, _ = _start_coefficients(parametrisation, setup["times"], float(duration), knots,
                                           obj.multilevel_carrier(count, CARRIER_HOLD, seed), setup["band"], None,
                                           factor * START_AMPLITUDE)
            if _violation(obj.value(jnp.asarray(trial), prob)[1]) <= 0:
                c0, note = trial, (f"; the default start broke a limit, so its carrier's amplitude was lowered to "
                                   f"{factor * START_AMPLITUDE:g}")
                break
    c, aux, history, message = _optimise(np.asarray(c0, dtype=float), prob, gradient, steps, report)
    message += note
    duty, info = np.asarray(aux["duty"]), np.asarray(aux["information"])
    verified = None
    if verify:  # at the fit's resolution (the Experiment's default substeps, the recording's rate)
        full = _template(model, float(duration), period, float(rate), channels, noise, start, FIT_SUBSTEPS, duty,
                         build)
        run_info, (verified,) = information(space, theta, [full], predictions=True)
        info = prior_info + run_info
        if setup["force_law"] and {"position", "pressure"} <= set(verified):
            verified["force"] = np.asarray(_static_force(setup["system"], device_array(verified["position"]),
                                                         device_array(verified["pressure"])))
    errors = {key: _physical_errors(space, theta, i) for key, i in
              (("design", info), ("prior", prior_info), ("baseline", base_info)) if i is not None}
    constraints = _constraints(aux, setup, verified)
    if not constraints["feasible"]:
        warnings.warn("pamjax.design: the design violates its limits (a bench must not play it; to_csv refuses "
                      "it): " + "; ".join(constraints["violations"]), PamjaxDesignWarning, stacklevel=2)
    position, pressure, force = (aux.get(k) for k in ("position", "pressure", "force"))
    return DesignResult(
        times=[float(t) for t in setup["times"]], duty=[float(d) for d in duty], period=period,
        labels=list(space.labels), values=[float(v) for v in np.asarray(space.initial_values())], subset=subset,
        criterion=criterion, standard_errors=errors, objective=[history[0][2], float(aux["criterion"])],
        history=history, constraints=constraints, parametrisation=parametrisation, iterations=len(history) - 1,
        message=message, design_s=time.perf_counter() - t_start, compile_s=compile_s, duration=float(duration),
        prediction=dict(t=np.asarray(exp.times), position=None if position is None else np.asarray(position),
                        pressure=None if pressure is None else np.asarray(pressure),
                        force=None if force is None else np.asarray(force)))


def check_design(model, free, duration, **kwargs):
    """Every check `design` makes before its first solve (the arguments, the valve's thresholds and the duties they
    leave, each limit against the run's start), without designing: a `PamjaxInputError` naming the argument, or
    None. `pamjax design` runs it before it makes the output folder."""
    known = set(inspect.signature(design).parameters) - {"model", "free", "duration"}
    unknown = sorted(set(kwargs) - known)
    if unknown:
        raise PamjaxInputError(f"unknown design argument(s) {unknown}")
    args = {k: v.default for k, v in inspect.signature(design).parameters.items() if k in known and k in _SETUP_ARGS}
    args.update({k: v for k, v in kwargs.items() if k in _SETUP_ARGS})
    _setup(model, free, duration, **args)


_SETUP_ARGS = ("noise", "channels", "start", "build", "rate", "criterion", "subset", "duty_band", "stroke_margin",
               "max_pressure", "max_duty_step", "parametrisation", "knots", "steps", "initial", "seed", "period",
               "design_rate", "substeps", "duty_margin", "min_force")


def _setup(model, free, duration, *, noise, channels, start, build, rate, criterion, subset, duty_band, stroke_margin,
           max_pressure, max_duty_step, parametrisation, knots, steps, initial, seed, period, design_rate, substeps,
           duty_margin, min_force):
    """Everything before the first solve, as a dict: the checked arguments, the valve's switching thresholds and the
    duties they leave, the limits (each checked against the run's start state), the start coefficients and the
    designed experiment."""
    space, subset, period, channels, system, start = _validate(
        model, free, duration, noise, channels, duty_band, criterion, subset, parametrisation, knots, steps,
        float(rate), stroke_margin, max_pressure, max_duty_step, period, build, start, duty_margin, min_force)
    model = strong_types(model)
    space = ParameterSpace(model, free)
    thresholds = switching_thresholds(getattr(system, "valve", None))
    margin = (DUTY_MARGIN_FRACTION * min(min(t, 1.0 - t) for t in thresholds) if thresholds else 0.0) \
        if duty_margin == "auto" else float(duty_margin)
    band = duty_limits(tuple(float(b) for b in duty_band), thresholds, margin)
    force_law = _has_force_law(system)
    min_force = None if (min_force is None or min_force is False or not force_law) else float(min_force)
    y0 = _start_state(system, start)
    limits = None
    if "position" in channels and getattr(system, "muscle", None) is not None:
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
        f0 = float(np.asarray(_static_force(system, device_array(np.asarray(y0.position, dtype=float)),
                                            device_array(np.asarray(y0.pressure, dtype=float)))))
        if f0 < min_force:
            raise PamjaxInputError(
                f"min_force {min_force:g} N: eq. 7 gives {f0:.1f} N at the run's start, so no run from there keeps "
                f"the muscle's force above it; give min_force below {f0:.1f} N (default {MIN_FORCE:g}), or None / "
                "false for no limit")
    count = int(math.ceil(duration / period - 1e-9))
    times = np.arange(count) * period
    c0, basis = _start_coefficients(parametrisation, times, float(duration), knots,
                                    obj.multilevel_carrier(count, CARRIER_HOLD, seed), band, initial)
    z0 = device_array(c0 if basis is None else basis @ c0)
    exp = _template(model, float(duration), period, float(design_rate), channels, noise, start, substeps,
                    band[0] + (band[1] - band[0]) * np.asarray(obj.clip01_and_slope(z0)[0]), build)
    return dict(model=model, space=space, subset=subset, period=period, channels=channels, system=system, start=start,
                thresholds=thresholds, duty_margin=margin, duty_band=[float(b) for b in duty_band], band=band,
                force_law=force_law, min_force=min_force, limits=limits, max_pressure=max_pressure,
                max_duty_step=max_duty_step, count=count, times=times, c0=c0, basis=basis, experiment=exp)


@eqx.filter_jit
def _initial_state(system, start):
    return system.initial_state(**start)


def _start_state(system, start):
    """`system.initial_state(**start)`, compiled as one program (eagerly, its static equilibrium compiles each of
    its operations on its own)."""
    return _initial_state(system, {k: device_array(np.asarray(v, dtype=float)) for k, v in start.items()})


def _printer(progress, announce):
    """The per-iteration report `progress` asks for; True prints `announce` first."""
    if callable(progress):
        return progress
    if not progress:
        return None
    print(announce, flush=True)

    def report(it, objective, criterion, step, accepted):
        print(f"  iter {it:3d}  objective {objective:.6f}  criterion {criterion:.6f}  step {step:.3g}  "
              f"{'accepted' if accepted else 'no descent'}", flush=True)

    return report
