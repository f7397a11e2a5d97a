"""The input checks of the bench tests without a time axis (`static_experiments.py`): their columns, a force map's
units (metres, ABSOLUTE pascal) and its positions against the muscle's stroke, the velocities of a loop, the scale and
the slack threshold, and the data an experiment keeps (`set_data`). Each refusal is a `PamjaxInputError` naming the
argument (and the experiment, where the model is needed to decide)."""

import jax.numpy as jnp
import numpy as np

from .._core.errors import PamjaxInputError, concrete_values
from .._core.units import MIN_ABSOLUTE_PA
from .._solve.checks import START_STROKE_MARGIN


def columns(names, arrays):
    """`arrays` as float NumPy arrays: 1-D, of one length > 0, finite; else a `PamjaxInputError` naming the column."""
    arrays = [np.asarray(a, dtype=float) for a in arrays]
    shapes = [a.shape for a in arrays]
    if not (all(s == shapes[0] for s in shapes) and arrays[0].ndim == 1 and arrays[0].size > 0):
        raise PamjaxInputError(f"{', '.join(names)} must be 1-D arrays of one length, got shapes {shapes}")
    for name, a in zip(names, arrays):
        if not np.all(np.isfinite(a)):
            raise PamjaxInputError(f"{name} is NaN/inf at row {int(np.argmin(np.isfinite(a)))}")
    return arrays


def check_map(x, p, v=None):
    """A force map's positions [m] (not mm), ABSOLUTE pressures [Pa] and velocities (≠ 0; none for a static map)."""
    if np.max(np.abs(x)) > 1.0:  # (as `pamjax._core.units.check_magnitude` refuses a length channel's mm)
        raise PamjaxInputError(f"positions reach {np.max(np.abs(x)):g} m, but no muscle contracts by a metre (the "
                               "MAS-10's stroke is 75 mm): these look like mm; pamjax takes m")
    check_absolute("pressures", p)
    if v is not None:
        check_moving(v, "the direction of motion")


def check_moving(v, why):
    """Concrete velocities all ≠ 0 (`why` they must be), else `PamjaxInputError` naming the first 0; traced: none."""
    v = concrete_values(v)
    if v is not None and np.any(v == 0):
        raise PamjaxInputError(f"velocities must be non-zero ({why}), row {int(np.argmin(v != 0))} is 0")


def check_absolute(name, p):
    """Pressures `name` ABSOLUTE [Pa]: none below half an atmosphere (gauge or bar)."""
    if np.min(p) < MIN_ABSOLUTE_PA:
        raise PamjaxInputError(f"{name} must be ABSOLUTE [Pa]; the lowest is {np.min(p):.4g} Pa (row "
                               f"{int(np.argmin(p))}), below half an atmosphere: these look like gauge or bar (add "
                               "101325 Pa to gauge readings)")


def check_scale(values, scale, unit):
    """The residuals' scale [`unit`]: `scale`, or 1 % of the range of `values` where None; a finite number > 0 (an
    infinite one would make every residual 0, a fit of nothing), else a `PamjaxInputError` naming it."""
    s = float(0.01 * np.ptp(values) if scale is None else scale)
    if not (np.isfinite(s) and s > 0):
        raise PamjaxInputError(f"scale must be > 0 and finite [{unit}] (the measurement's noise level), got {s}")
    return s


def set_data(experiment, channel, values, scale, unit, name):
    """Inside an experiment's `__init__`: the measured `channel`, its scale [`unit`] (`check_scale`: default 1 % of
    the range; the noise level if known) and the name."""
    experiment.scale = check_scale(values, scale, unit)
    experiment.data = {channel: jnp.asarray(values)}
    experiment.name = str(name)
    experiment.channels = (channel,)


def slack_points(forces, slack_force):
    """The slack points of a force map: measured forces [N] ≤ `slack_force` (one number; −inf: none is slack). NaN
    (every comparison false: each slack point silently an ordinary 0 N) and +inf (every point slack) are refused."""
    s = concrete_values(slack_force)
    if s is None or s.ndim != 0 or np.isnan(s) or s == np.inf:
        raise PamjaxInputError(f"slack_force must be one number [N] (measured forces at or below it are slack: the "
                               f"muscle cannot push; default 0.0, -inf for none), got {slack_force!r}")
    return jnp.asarray(forces <= s)


def check_stroke(experiment, positions, muscle):
    """A force map's `positions` [m] inside `muscle`'s stroke [min_position, max_position], give or take
    `START_STROKE_MARGIN` of it (as `simulate` admits a start position: the end stops' give, a sensor's offset): a
    length L (0.22-0.30 m for a 300 mm muscle) passed for the contraction L0 − L is refused, naming `experiment`.
    Unchecked where the stroke is traced."""
    lo, hi = concrete_values(muscle.min_position), concrete_values(muscle.max_position)
    if lo is None or hi is None or lo.ndim or hi.ndim:
        return
    x = np.asarray(positions, dtype=float)
    margin = START_STROKE_MARGIN * float(hi - lo)
    outside = (x < lo - margin) | (x > hi + margin)
    if np.any(outside):
        row = int(np.argmax(outside))
        raise PamjaxInputError(
            f"{experiment}: positions[{row}] = {x[row]:.6g} m (they span {x.min():.6g} … {x.max():.6g} m) lies outside "
            f"the muscle's stroke [{float(lo):.6g}, {float(hi):.6g}] m (its min_position, max_position; "
            f"{START_STROKE_MARGIN:.0%} of it beyond either end is admitted): positions are contractions L0 − L [m] "
            "(positive = shorter than at rest), not the muscle's lengths L")
