"""Gradient-based tuning of a closed loop's controller gains (Adam on their logarithms, reverse mode through the
whole sampled-data simulation)."""

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError
from .closed_loop import ClosedLoop, run_closed_loop


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
    of its controller (e.g. `("proportional_gain", "integral_gain")`); `duration` [s]; `start` [s] the RMSE window's
    start; `steps` Adam steps; `learning_rate` in log-gain units; `callback(step, rmse, gains)` for progress.

    **Returns:** `(tuned_loop, history)`: the loop with the best gains met and a list of (rmse [m], gains) per step.

    **Raises:** `PamjaxInputError`, before any solve, for a gain that is no positive controller field, a duration
    that is not > 0 or a `start` at or after the run's end (`duration` rounded up to whole PWM periods).
    """
    if not isinstance(loop, ClosedLoop):
        raise PamjaxInputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    for name in gains:
        value = getattr(loop.controller, name, None)
        if value is None or not np.all(np.asarray(value) > 0):
            raise PamjaxInputError(f"tune_controller: gain {name!r} must be a positive controller field, got {value}")
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
