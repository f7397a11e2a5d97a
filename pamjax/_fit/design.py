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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.errors import PamjaxInputError, require_float64
from .._physics.signals import AbstractSignal, Sampled, Triangle
from .._systems.base import AbstractSystem
from . import design_objective as obj
from .design_result import DesignResult
from .experiment import Experiment
from .fit import _physical_and_jacobian, _residuals_and_jacobian
from .parameters import ParameterSpace, strong_types
from .recording import Recording

# Defaults and their sources.
DUTY_BAND = (0.1, 0.9)  # paper 000: with the MHE2's ~2 ms switching time, only duty 10-90 % has an effect at 50 Hz
STROKE_MARGIN = 0.005  # m; assumed (paper 000 gives no clearance): ≈ 5 % of the MAS-10's 95 mm stroke
START_LEVEL = (0.05, 0.95, 0.08)  # paper 000's E3 duty (Triangle low, high, Hz): the start of the envelope's level
# (built when used: a component made at import would start JAX's backend, fixing its devices before the user can)
START_AMPLITUDE = 0.25  # of the band; assumed: the carrier swings the duty by ±20 % of 0.8 around the level
CARRIER_HOLD = 10  # PWM periods (0.2 s at 50 Hz): the hold of the most informative of the multilevel signals
# compared in docs/identifiability.md (0.1, 0.2, 0.5 and 1 s holds)
DESIGN_RATE = 250.0  # Hz: the objective's samples; the information matrix agrees within 0.2 % with 1 kHz (docs)
DESIGN_SUBSTEPS = 4  # RK4 nodes per PWM period in the objective: within 0.2 % of the fit's 16 (docs)
FIT_SUBSTEPS = inspect.signature(Experiment.__init__).parameters["substeps"].default  # what a fit integrates with


def information(space, theta, experiments):
    """Fisher information about θ of `experiments` (identification samples, as the fit uses them): JᵀJ of the
    scaled residuals at θ (the fit's compiled Jacobian, shared with fits of the same problem structure)."""
    model = space.with_values(_physical_and_jacobian(space, device_array(theta))[0])  # compiled, not op by op
    exps = tuple(e.bind(model) if hasattr(e, "bind") else e for e in experiments)
    mask = np.concatenate([used & ident for e in exps for _, _, _, used, ident in e.layout()])
    _, jac = _residuals_and_jacobian(space, device_array(theta), exps)
    jac = np.asarray(jac)[mask]
    return jac.T @ jac


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
              stroke_margin, max_pressure, max_duty_step, period, build, start):
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
        raise PamjaxInputError("period: the model's valve has no pwm_frequency; give the PWM period [s] explicitly")
    period = float(1.0 / float(frequency)) if period is None else float(period)
    if not period > 0:
        raise PamjaxInputError(f"period must be > 0 [s], got {period}")
    if not channels:
        raise PamjaxInputError("channels must name at least one recorded channel, e.g. ('pressure', 'position')")
    if not isinstance(noise, dict) or not set(channels) <= set(noise):
        raise PamjaxInputError(f"noise must give the noise standard deviation of every channel {list(channels)} "
                               f"(e.g. {{'pressure': 2e3, 'position': 1e-4}} [Pa, m]), got {noise!r}")
    for c in channels:
        if not (math.isfinite(float(noise[c])) and float(noise[c]) > 0):
            raise PamjaxInputError(f"noise[{c!r}] must be > 0 (the channel's standard deviation), got {noise[c]!r}")
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
    if max_duty_step is not None and not 0 < max_duty_step <= 1:
        raise PamjaxInputError(f"max_duty_step must be in (0, 1] (duty change per PWM period), got {max_duty_step!r}")
    space = ParameterSpace(model, free)
    subset = list(space.labels) if subset is None else list(subset)
    unknown = [s for s in subset if s not in space.labels]
    if unknown or not subset:
        raise PamjaxInputError(f"subset {unknown or subset!r} must name free parameters; they are {space.labels}")
    return space, subset, period, channels, system, start


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


def _start_coefficients(parametrisation, times, duration, knots, carrier, band, initial):
    """The start: z = level + START_AMPLITUDE ξ, the level from `initial` (a signal or per-period duties; default
    paper 000's E3 triangle), in the units of the soft clip (0 and 1 the band's ends; beyond them saturated)."""
    lo, hi = band
    if initial is None:
        level = (np.asarray(_sampled(Triangle(*START_LEVEL), device_array(times))) - lo) / (hi - lo)
    else:
        duty = (np.asarray(_sampled(initial, device_array(times))) if isinstance(initial, AbstractSignal)
                else np.asarray(initial, dtype=float))
        if duty.shape != times.shape:
            raise PamjaxInputError(f"initial must be a signal or one duty per PWM period ({times.size}), got shape "
                                   f"{duty.shape}")
        level = obj.unclip01((np.clip(duty, lo, hi) - lo) / (hi - lo))
    if parametrisation == "periods":
        return level + (START_AMPLITUDE * carrier if initial is None else 0.0), None
    b = obj.bspline_basis(times, 0.0, duration, knots)
    c_level = np.linalg.lstsq(b, level, rcond=None)[0]
    amplitude = np.full(knots, START_AMPLITUDE if initial is None else 0.0)
    return np.concatenate([c_level, amplitude]), obj.envelope_basis(times, duration, knots, carrier)


def _floor(prior_info, base_info, margin):
    """Variances of θ the design must reach: those of a run carrying `margin`² times the baseline run's information
    about each parameter beyond the prior's, 1/v = 1/v_prior + margin² (1/v_baseline − 1/v_prior) (`margin` = 1:
    the baseline's variances; where the prior alone fixes a parameter as well as the baseline does, its own)."""
    v_base = variances(base_info)
    prior_precision = 1.0 / variances(prior_info)  # 0 where the prior leaves a parameter free
    gain = np.maximum(1.0 / v_base - prior_precision, 0.0)
    return 1.0 / (prior_precision + margin**2 * gain)


def _violation(aux):
    """The largest constraint violation in its penalty's units (mm, kPa, duty %)."""
    return max(float(aux["worst_stroke"]) / obj.STROKE_UNIT, float(aux["worst_pressure"]) / obj.PRESSURE_UNIT,
               float(aux["worst_step"]) / obj.STEP_UNIT)


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
    x0 = float(getattr(model.initial_state(**dict(start or {})), "position", np.nan))
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


def _constraints(aux, band, max_duty_step, stroke, max_pressure):
    """The `constraints` report of a design: limits, the predicted extremes, and whether all hold."""
    # on the host: NumPy reductions of a JAX array would each compile a program
    duty, position, pressure = (None if a is None else np.asarray(a) for a in
                                (aux["duty"], aux.get("position"), aux.get("pressure")))
    return dict(
        duty_band=list(band), duty_range=[float(duty.min()), float(duty.max())],
        largest_duty_step=float(np.max(np.abs(np.diff(duty)))) if duty.size > 1 else 0.0,
        max_duty_step=max_duty_step, stroke_limits=None if stroke is None else [float(s) for s in stroke],
        position_range=None if position is None else [float(np.min(position)), float(np.max(position))],
        max_pressure=max_pressure,
        pressure_range=None if pressure is None else [float(np.min(pressure)), float(np.max(pressure))],
        feasible=_violation(aux) <= 1e-9)


def _prepare(problem, gradient, c0, space, theta, prior, baseline, index, margin):
    """The design problem with the information in hand, compiling the gradient (the long pole) in a second thread
    meanwhile; checks that the start determines every parameter. Returns (problem, prior information, prior +
    baseline information or None, seconds to the first iteration)."""
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
                               "so the criterion is undefined there; start from another signal (`initial`) or add "
                               "prior experiments that fix them")
    return prob, prior_info, base_info, time.perf_counter() - t_compile


def _problem(space, theta, exp, basis, weight, band, limits, max_pressure, max_duty_step, index, criterion,
             prior_info, floor):
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
    stroke_margin: float = STROKE_MARGIN,
    max_pressure=None,
    max_duty_step=None,
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
    - `duty_band`: (lo, hi) duty the valve acts on (0.1, 0.9: paper 000); `stroke_margin` [m] kept from the end
      stops (`muscle.min_position`, `max_position`); `max_pressure` [Pa abs] (default none: a valve cannot exceed
      its supply); `max_duty_step`: largest duty change from one period to the next (default none).
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
    space, subset, period, channels, system, start = _validate(
        model, free, duration, noise, channels, duty_band, criterion, subset, parametrisation, knots, steps,
        float(rate), stroke_margin, max_pressure, max_duty_step, period, build, start)
    model = strong_types(model)
    space = ParameterSpace(model, free)
    theta = np.asarray(space.initial_theta())
    lo, hi = (float(b) for b in duty_band)
    count = int(math.ceil(duration / period - 1e-9))
    times = np.arange(count) * period
    c0, basis = _start_coefficients(parametrisation, times, float(duration), knots,
                                    obj.multilevel_carrier(count, CARRIER_HOLD, seed), (lo, hi), initial)
    z0 = device_array(c0 if basis is None else basis @ c0)
    exp = _template(model, float(duration), period, float(design_rate), channels, noise, start, substeps,
                    lo + (hi - lo) * np.asarray(obj.clip01_and_slope(z0)[0]), build)
    limits = stroke_limits(system, start, stroke_margin) if "position" in channels else None
    n, index = len(space.labels), tuple(space.labels.index(s) for s in subset)

    problem = functools.partial(_problem, space, theta, exp, basis, float(rate) / float(design_rate), (lo, hi),
                                limits, max_pressure, max_duty_step, index, criterion)

    gradient = obj.reverse_gradient if parametrisation == "periods" else obj.forward_gradient
    report = _printer(progress, f"design: {count} PWM periods, {len(c0)} coefficients ({parametrisation}), "
                                f"{criterion}-optimal over {len(subset)} of {n} parameters; compiling the objective "
                                "and its gradient ...")
    prob, prior_info, base_info, compile_s = _prepare(problem, gradient, c0, space, theta, prior, baseline, index,
                                                      float(baseline_margin))
    c, aux, history, message = _optimise(np.asarray(c0, dtype=float), prob, gradient, steps, report)
    duty, info = np.asarray(aux["duty"]), np.asarray(aux["information"])
    if verify:  # at the fit's resolution (the Experiment's default substeps, the recording's rate)
        full = _template(model, float(duration), period, float(rate), channels, noise, start, FIT_SUBSTEPS, duty,
                         build)
        info = prior_info + information(space, theta, [full])
    errors = {key: _physical_errors(space, theta, i) for key, i in
              (("design", info), ("prior", prior_info), ("baseline", base_info)) if i is not None}
    position, pressure = aux.get("position"), aux.get("pressure")
    return DesignResult(
        times=[float(t) for t in times], duty=[float(d) for d in duty], period=period, labels=list(space.labels),
        values=[float(v) for v in np.asarray(space.initial_values())], subset=subset, criterion=criterion,
        standard_errors=errors, objective=[history[0][2], float(aux["criterion"])], history=history,
        constraints=_constraints(aux, (lo, hi), max_duty_step, limits, max_pressure), parametrisation=parametrisation,
        iterations=len(history) - 1, message=message, design_s=time.perf_counter() - t_start, compile_s=compile_s,
        prediction=dict(t=np.asarray(exp.times), position=None if position is None else np.asarray(position),
                        pressure=None if pressure is None else np.asarray(pressure)))


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
