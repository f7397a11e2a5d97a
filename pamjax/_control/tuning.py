"""Gradient-based tuning of a closed loop's controller gains (Adam on their logarithms, reverse mode through the
whole sampled-data simulation)."""

import dataclasses
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError
from .closed_loop import ClosedLoop, checked_loop, run_closed_loop

# A controller's settings that are no gains: bounded (the duty limits lie in [0, 1], a PWM duty ratio) or an offset
# (the bias, the duty at zero error). Adam on a logarithm keeps a value > 0 but not below 1: tuning `duty_max` from 0.9
# gave 2.99, a duty the valve cannot take. They are set, not tuned.
# A PID's sensor (`measurement_noise`, `sample_time`) is the rig's, not a setting: tuned, the noise went down to lower
# the RMSE, a better sensor rather than a better controller.
_BOUNDED = ("the duty limits are bounds in [0, 1] (a PWM duty ratio) and the bias the duty at zero error, which a "
            "descent on the logarithm would push out of range (duty_max 0.9 went to 2.99)")
_SENSOR = ("the sensor's noise and sampling time are the rig's, not the controller's settings: tuned, the noise falls "
           "to lower the RMSE (a better sensor, not a better controller)")
NOT_GAINS = {"duty_min": _BOUNDED, "duty_max": _BOUNDED, "bias": _BOUNDED, "measurement_noise": _SENSOR,
             "sample_time": _SENSOR}


def tracking_rmse(loop: ClosedLoop, num_periods: int, start=0.0, **kwargs):
    """RMSE [m] of r − x over t ≥ `start` [s] of a closed-loop run of `num_periods` PWM periods (traceable)."""
    return run_closed_loop(loop, num_periods, **kwargs).tracking_error(start)[0]


def tune_controller(
    loop: ClosedLoop,
    gains: Sequence[str],
    duration: RealScalarLike,
    *,
    start: RealScalarLike = 0.0,
    steps: int = 30,
    learning_rate: RealScalarLike = 0.05,
    samples_per_period: int = 5,
    callback: Callable[[int, float, tuple[float, ...]], object] | None = None,
) -> tuple[ClosedLoop, list[tuple[float, tuple[float, ...]]]]:
    """Tune positive controller gains by gradient descent (Adam on their logarithms) on the tracking RMSE of the
    closed loop, differentiated through the whole sampled-data simulation (reverse mode).

    **Arguments:** `loop` a `ClosedLoop` (the plant it holds is the one tuned on); `gains` a tuple of attribute names
    of its controller, each a real-valued parameter > 0 (e.g. `("proportional_gain", "integral_gain")`; an integer
    value such as `proportional_gain=30` is tuned as the float 30.0), not a duty limit or the bias (`duty_min`,
    `duty_max`, `bias`: bounded settings, which a descent on the logarithm would push out of [0, 1]; set them
    yourself); `duration` [s]; `start` [s] the RMSE window's start; `steps` Adam steps (an int >= 0; 0
    evaluates the loop's own gains, without a step); `learning_rate` in log-gain units (finite, > 0);
    `samples_per_period` samples of the RMSE per PWM period (an int >= 1); `callback(step, rmse, gains)` for progress.

    **Returns:** `(tuned_loop, history)`: the loop with the best gains met and a list of (rmse [m], gains) per step.

    **Raises:** `PamjaxInputError`, before any solve, for what `simulate_closed_loop` refuses in the loop (parameters
    set with `eqx.tree_at` are checked as the constructors check them, a reference outside the muscle's stroke, a
    controller whose duty is not one number: `checked_loop`), a gain that is no positive real-valued
    controller parameter or is a duty limit or the bias or is named twice, a duration that is not a number > 0, a
    `start` at or after the run's end (`duration` rounded up to whole PWM periods), or a bad `steps`,
    `learning_rate` or `samples_per_period`.
    """
    loop = checked_loop(loop)  # as `simulate_closed_loop` checks it: parameters, reference, one duty per period
    _check_settings(loop.controller, gains, steps, learning_rate, samples_per_period)
    for value, name in ((duration, "duration"), (start, "start")):
        if not (isinstance(value, (int, float, np.number, np.ndarray, jax.Array)) and np.ndim(value) == 0
                and not isinstance(value, (bool, np.bool_))):
            raise PamjaxInputError(f"tune_controller: {name} must be a number [s], got {value!r}")
    duration, start = float(duration), float(start)
    if not (np.isfinite(duration) and duration > 0):
        raise PamjaxInputError(f"tune_controller: duration must be > 0 [s], got {duration}")
    num_periods = int(np.ceil(duration / float(loop.period) - 1e-9))
    end = num_periods * float(loop.period)  # s, the run's end: whole PWM periods
    if not start < end:  # an empty RMSE window: every step's loss and gradient would be NaN (also a NaN start)
        raise PamjaxInputError(f"tune_controller: start = {start} s (the RMSE window's start) is at or after the "
                               f"run's end ({end} s for duration {duration} s); give a start before it or a longer "
                               "duration")
    gains = tuple(gains)
    get = _getter(gains)
    # integer-valued gains (PIController(proportional_gain=30) keeps an int array) as floats: a log to descend on
    loop = eqx.tree_at(lambda lp: get(lp.controller), loop,
                       tuple(jnp.asarray(g, dtype=float) for g in get(loop.controller)))

    def value_and_grad(log_gains):
        return _rmse_and_gradient(log_gains, loop, gains, num_periods, start, samples_per_period)

    params = tuple(jnp.log(jnp.asarray(g, dtype=float)) for g in get(loop.controller))
    m = jtu.tree_map(jnp.zeros_like, params)
    v = jtu.tree_map(jnp.zeros_like, params)
    beta1, beta2, eps = 0.9, 0.999, 1e-12
    history, best = [], (np.inf, params)
    for step in range(steps + 1):
        rmse, grad = value_and_grad(params)
        rmse = float(rmse)
        current = tuple(float(jnp.exp(p)) for p in params)
        history.append((rmse, current))
        if callback is not None:
            callback(step, rmse, current)
        if np.isfinite(rmse) and rmse < best[0]:
            best = (rmse, params)
        if step == steps or not all(np.all(np.isfinite(np.asarray(g))) for g in grad):
            break
        m = jtu.tree_map(lambda a, g: beta1 * a + (1 - beta1) * g, m, grad)
        v = jtu.tree_map(lambda a, g: beta2 * a + (1 - beta2) * g * g, v, grad)
        k = step + 1
        params = jtu.tree_map(
            lambda p, a, b: p - learning_rate * (a / (1 - beta1**k)) / (jnp.sqrt(b / (1 - beta2**k)) + eps),
            params,
            m,
            v,
        )
    controller = eqx.tree_at(get, loop.controller, tuple(jnp.exp(g) for g in best[1]))
    return eqx.tree_at(lambda lp: lp.controller, loop, controller), history


def _check_settings(controller, gains, steps, learning_rate, samples_per_period):
    """The tuning's own arguments, checked on the host before any solve (`PamjaxInputError` naming each)."""
    if isinstance(gains, str) or not isinstance(gains, Sequence) or not gains:
        raise PamjaxInputError(f"tune_controller: gains must be a non-empty tuple of controller parameter names, got "
                               f"{gains!r}")
    static = {f.name for f in dataclasses.fields(controller) if f.metadata.get("static", False)}
    for name in gains:
        if name in NOT_GAINS:
            raise PamjaxInputError(f"tune_controller: {name!r} is no gain: {NOT_GAINS[name]}; set {name} on the "
                                   "controller yourself and tune its gains")
        value = getattr(controller, name, None) if isinstance(name, str) else None
        # a leaf of the controller's pytree with a real (floating-point or integer) dtype: a sub-model ("model") or
        # a static field ("seed", which no gradient reaches) has no log to descend on
        real = (name not in static and isinstance(value, (int, float, np.ndarray, jax.Array))
                and not isinstance(value, (bool, jax.core.Tracer))
                and (np.issubdtype(np.asarray(value).dtype, np.floating)
                     or np.issubdtype(np.asarray(value).dtype, np.integer)))
        if not real or not np.all(np.asarray(value) > 0) or not np.all(np.isfinite(np.asarray(value))):
            raise PamjaxInputError(f"tune_controller: gain {name!r} must name a positive, real-valued parameter of "
                                   f"the {type(controller).__name__}, got {_describe(value)}")
    repeated = sorted({name for name in gains if list(gains).count(name) > 1})
    if repeated:  # ("proportional_gain", "proportional_gain") ran with two values reported for one gain
        raise PamjaxInputError(f"tune_controller: gains names {', '.join(map(repr, repeated))} more than once; name "
                               "each gain once")
    if not (isinstance(steps, (int, np.integer)) and not isinstance(steps, bool) and steps >= 0):
        raise PamjaxInputError(f"tune_controller: steps must be an int >= 0 (Adam steps), got {steps!r}")
    number = (isinstance(learning_rate, (int, float, np.number, np.ndarray, jax.Array))
              and not isinstance(learning_rate, (bool, np.bool_)))
    rate = np.asarray(learning_rate, dtype=float) if number else None
    if rate is None or rate.ndim != 0 or not (np.isfinite(rate) and rate > 0):
        raise PamjaxInputError(f"tune_controller: learning_rate must be a finite number > 0 (log-gain units), got "
                               f"{learning_rate!r}")
    if not (isinstance(samples_per_period, (int, np.integer)) and not isinstance(samples_per_period, bool)
            and samples_per_period >= 1):
        raise PamjaxInputError(f"tune_controller: samples_per_period must be an int >= 1, got "
                               f"{samples_per_period!r}")


def _describe(value):
    """A refused gain's value, briefly: a number as it is, anything else by its type."""
    if value is None:
        return "None (no such field, or unset)"
    if isinstance(value, (int, float, np.ndarray, jax.Array)):
        return repr(np.asarray(value)) if np.size(value) <= 6 else f"an array of shape {np.shape(value)}"
    return type(value).__name__


def _getter(gains):
    return lambda ctl: tuple(getattr(ctl, n) for n in gains)


# One program per loop structure, gains, length and window (module level, the loop an argument): a closure jitted per
# call compiled anew at every `tune_controller` call (~3.7 s for a 1 s loop of the MAS-10).
@eqx.filter_jit
def _rmse_and_gradient(log_gains, loop, gains, num_periods, start, samples_per_period):
    def loss(log_gains):
        controller = eqx.tree_at(_getter(gains), loop.controller, tuple(jnp.exp(g) for g in log_gains))
        tuned = eqx.tree_at(lambda lp: lp.controller, loop, controller)
        return tracking_rmse(tuned, num_periods, start, samples_per_period=samples_per_period)

    return jax.value_and_grad(loss)(log_gains)
