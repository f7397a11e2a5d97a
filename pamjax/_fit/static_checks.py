"""The input checks of the bench tests without a time axis (`static_experiments.py`): their columns (numbers, and
in SI by magnitude as `Recording` checks its channels: m, m/s, kg/s, ABSOLUTE pascal), a force map's positions
against the muscle's stroke and its loaded points, the velocities and path of a loop, the scale and the slack
threshold, the data an experiment keeps (`set_data`), and the arguments of the reductions (`flow_curve`,
`loop_average`). Each refusal is a `PamjaxInputError` naming the argument (and the experiment, where the model is
needed to decide)."""

import re

import jax
import jax.numpy as jnp
import numpy as np

from .._core.errors import PamjaxInputError, check_count, concrete_values
from .._core.units import ATMOSPHERE, MIN_ABSOLUTE_PA, check_absolute_pressure, check_magnitude
from .._solve.checks import START_STROKE_MARGIN


def columns(names, arrays):
    """`arrays` as float NumPy arrays: 1-D, of one length > 0, finite; else a `PamjaxInputError` naming the column
    (text too: a CSV column read with its header cell gave NumPy's raw "could not convert string to float")."""
    arrays = [numbers(name, a) for name, a in zip(names, arrays)]
    shapes = [a.shape for a in arrays]
    if not (all(s == shapes[0] for s in shapes) and arrays[0].ndim == 1 and arrays[0].size > 0):
        raise PamjaxInputError(f"{', '.join(names)} must be 1-D arrays of one length, got shapes {shapes}")
    for name, a in zip(names, arrays):
        if not np.all(np.isfinite(a)):
            raise PamjaxInputError(f"{name} is NaN/inf at row {int(np.argmin(np.isfinite(a)))}")
    return arrays


def numbers(name, a):
    """`a` as a float NumPy array, else a `PamjaxInputError` naming `name` (text: NumPy's raw ValueError)."""
    try:
        return np.asarray(a, dtype=float)
    except (TypeError, ValueError) as err:
        raise PamjaxInputError(f"{name} must be numbers (a column read as text? its header cell left in?): "
                               f"{err}") from None


def check_unit(dimension, values, name):
    """`check_magnitude` (what `Recording` refuses: m/s above 20 look like mm/s, kg/s above 1 like g/s) of the
    argument `name` (`dimension`: "velocity", "mass_flow"), its advice to write the unit in a CSV header turned into
    the conversion to SI. Traced values are not checked."""
    v = concrete_values(values)
    if v is None:
        return
    try:
        check_magnitude(dimension, v, "", name)
    except PamjaxInputError as err:
        said = str(err).replace(f": channel {name!r}", name, 1)
        raise PamjaxInputError(re.sub(r": write '[^']*' in the header", "; pamjax takes SI units (divide them by "
                                      "1000)", said)) from None


def check_map(x, p, v=None):
    """A force map's positions [m] (not mm), ABSOLUTE pressures [Pa] and velocities (≠ 0; none for a static map)."""
    if np.max(np.abs(x)) > 1.0:  # (as `pamjax._core.units.check_magnitude` refuses a length channel's mm)
        raise PamjaxInputError(f"positions reach {np.max(np.abs(x)):g} m, but no muscle contracts by a metre (the "
                               "MAS-10's stroke is 75 mm): these look like mm; pamjax takes m")
    check_absolute("pressures", p)
    if v is not None:
        check_moving(v, "the direction of motion")


def check_moving(v, why):
    """Concrete velocities all ≠ 0 (`why` they must be), else `PamjaxInputError` naming the first 0, and in m/s, not
    mm/s (`check_unit`); traced: none."""
    v = concrete_values(v)
    if v is not None and np.any(v == 0):
        raise PamjaxInputError(f"velocities must be non-zero ({why}), row {int(np.argmin(v != 0))} is 0")
    if v is not None:
        check_unit("velocity", v, "velocities")  # mm/s: a friction curve fitted C_f = 0.25 for 250 N s/m


def check_absolute(name, p):
    """Pressures `name` ABSOLUTE [Pa]: none below half an atmosphere (gauge or bar), none above 50 bar
    (`check_absolute_pressure`, as every other pressure pamjax takes: 5e7 Pa was fitted as it came)."""
    if np.min(p) < MIN_ABSOLUTE_PA:
        raise PamjaxInputError(f"{name} must be ABSOLUTE [Pa]; the lowest is {np.min(p):.4g} Pa (row "
                               f"{int(np.argmin(p))}), below half an atmosphere: these look like gauge or bar (add "
                               "101325 Pa to gauge readings)")
    check_absolute_pressure(p, name)


def check_scale(values, scale, unit):
    """The residuals' scale [`unit`]: `scale`, or 1 % of the range of `values` where None; a finite number > 0 (an
    infinite one would make every residual 0, a fit of nothing), else a `PamjaxInputError` naming it."""
    if scale is not None and (isinstance(scale, (str, bool, np.bool_)) or np.ndim(scale) != 0):
        raise PamjaxInputError(f"scale must be one number [{unit}] (the measurement's noise level, one for all "
                               f"points), got {scale!r}")
    s = float(0.01 * np.ptp(values) if scale is None else scale)
    if not (np.isfinite(s) and s > 0):
        raise PamjaxInputError(f"scale must be > 0 and finite [{unit}] (the measurement's noise level), got {s}")
    return s


def component_path(path, name, example):
    """A component's path (`Component`): a string, e.g. `example` ("" for the model itself). None was accepted and
    failed in the fit with a raw AttributeError."""
    if not isinstance(path, str):
        raise PamjaxInputError(f"{name} must be the component's path as a string (e.g. {example!r}; \"\" when the "
                               f"model is the component itself), got {path!r}")
    return path


def check_kind(value, kind, name, what):
    """`value` an instance of `kind` (`what`, in words), else a `PamjaxInputError` naming the argument `name`."""
    if not isinstance(value, kind):
        raise PamjaxInputError(f"{name} must be {what} (a {kind.__module__.split('.')[0]} {kind.__name__}), got "
                               f"{type(value).__name__} {value!r}")


def check_flow_curve(upstream_pressure, ratios):
    """`flow_curve`'s pressures: the upstream one ABSOLUTE [Pa] (6 for 6 bar gave flows 1e5 times too small), the
    ratios p_down/p_up in [0, 1] (downstream pressures in Pa passed for them gave −1011 kg/s; a negative one was
    silently clipped to 0). Traced values are not checked."""
    p1, r = concrete_values(upstream_pressure), concrete_values(ratios)
    if p1 is not None:
        if p1.ndim:
            raise PamjaxInputError(f"upstream_pressure must be one number [Pa abs], got shape {p1.shape}")
        check_absolute_pressure(p1, "upstream_pressure")
    if r is not None and not np.all((r >= 0) & (r <= 1)):
        bad = r.ravel()[int(np.argmax(~((r.ravel() >= 0) & (r.ravel() <= 1))))]
        hint = " (these look like downstream pressures in Pa: divide them by upstream_pressure)" if bad > 1 else ""
        raise PamjaxInputError(f"ratios must be pressure ratios p_down/p_up in [0, 1], got {bad:g}{hint}")


def check_decimals(decimals):
    """`loop_average`'s `decimals`: an integer (NumPy's `round` takes no other)."""
    if isinstance(decimals, (bool, np.bool_)) or not isinstance(decimals, (int, np.integer)):
        raise PamjaxInputError(f"decimals must be an integer (the positions are rounded to it to pair the branches), "
                               f"got {decimals!r}")


def set_data(experiment, channel, values, scale, unit, name):
    """Inside an experiment's `__init__`: the measured `channel`, its scale [`unit`] (`check_scale`: default 1 % of
    the range; the noise level if known) and the name."""
    experiment.scale = check_scale(values, scale, unit)
    experiment.data = {channel: jnp.asarray(values)}
    experiment.name = str(name)
    experiment.channels = (channel,)


def slack_points(forces, slack_force):
    """The slack points of a force map: measured forces [N] ≤ `slack_force` (one number; −inf: none is slack). NaN
    (every comparison false: each slack point silently an ordinary 0 N) and +inf (every point slack) are refused, and
    so is a map with no loaded point left: forces read with the opposite sign (a load cell reading tension negative)
    made all 126 points of the DMSP-20-300 map inequalities, which a pushing muscle met at cost 5e-25."""
    s = concrete_values(slack_force)
    if s is None or s.ndim != 0 or np.isnan(s) or s == np.inf:
        raise PamjaxInputError(f"slack_force must be one number [N] (measured forces at or below it are slack: the "
                               f"muscle cannot push; default 0.0, -inf for none), got {slack_force!r}")
    slack = np.asarray(forces) <= s
    if np.all(slack):  # an inequality at every point: nothing measured is left, any slack model fits it at cost 0
        negative, positive = int(np.sum(np.asarray(forces) < 0)), int(np.sum(np.asarray(forces) > 0))
        flipped = (f" {negative} of the {np.size(forces)} are negative (and {positive} positive): these look "
                   "sign-flipped (a load cell that reads tension negative); pass -forces (pamjax takes the muscle's "
                   "tension positive)") if negative > positive else ""
        raise PamjaxInputError(f"forces: every point is at or below slack_force = {float(s):g} N (slack: only a "
                               f"push of the model is penalised there), so no measured (loaded) force is left to "
                               f"fit.{flipped}")
    return jnp.asarray(slack)


def check_loaded_above_atmosphere(pressures, forces, slack):
    """No loaded point of a static map (measured F above `slack_force`) at an ABSOLUTE pressure at or below one
    atmosphere, where a muscle is vented and pulls nothing (eq. 7's force is ∝ the GAUGE pressure): the Festo map's
    gauge pressures from 65 kPa up passed `check_absolute` once its all-zero 35 kPa row was dropped, and the fit of
    eq. 7 was 264 N off at 6 bar (1718.8 N for 1454.8 N)."""
    low = ~np.asarray(slack) & (np.asarray(pressures) <= ATMOSPHERE)
    if np.any(low):
        row = int(np.argmax(low))
        raise PamjaxInputError(
            f"pressures must be ABSOLUTE [Pa]: {int(np.sum(low))} loaded point(s) lie at or below one atmosphere "
            f"({ATMOSPHERE:g} Pa abs), e.g. row {row}: {float(forces[row]):.4g} N at {float(pressures[row]):.6g} Pa, "
            f"where a vented muscle pulls nothing: these look like GAUGE pressures (add {ATMOSPHERE:g} Pa); if "
            "those forces are a vented muscle's noise, raise slack_force above them")


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


def check_path(positions, velocities, starts, substeps):
    """The checks of a loop read as a path (`path_friction_force`, `HysteresisLoopExperiment`), each a
    `PamjaxInputError` naming the argument: `substeps` an int >= 1 (0 RK4 steps carry no state: the force stays on
    the branch it started on past every reversal); `positions`, `velocities`, `starts` 1-D of one length; `starts`
    bool with `starts[0]` True (the first sample begins a sweep, on the branch of its velocity; without it the state
    starts virgin, z = 0, halfway between the branches); concrete positions and velocities finite (one NaN makes every
    force after it NaN: the state is carried), positions in m (not mm) and velocities ≠ 0. Traced values (jit, vmap,
    grad): their shapes and dtype only."""
    check_count(substeps, "substeps", "an integer >= 1")
    shapes = [jnp.shape(a) for a in (positions, velocities)]
    if not (len(shapes[0]) == 1 and shapes[0][0] > 0 and shapes[1] == shapes[0]):
        raise PamjaxInputError(f"positions, velocities must be 1-D arrays of one length, got shapes {shapes}")
    traced = isinstance(starts, jax.core.Tracer)
    dtype = starts.dtype if traced else np.asarray(starts).dtype
    if jnp.shape(starts) != shapes[0] or dtype != np.bool_:
        raise PamjaxInputError(f"starts must be a bool array of the positions' shape {shapes[0]}, got "
                               f"{dtype} {jnp.shape(starts)}")
    if not traced and not np.asarray(starts)[0]:
        raise PamjaxInputError("starts[0] must be True: the first sample begins a sweep")
    if concrete_values(positions) is not None and concrete_values(velocities) is not None:
        x, _ = columns(("positions", "velocities"), (positions, velocities))
        if np.max(np.abs(x)) > 1.0:  # as `check_map`: no muscle contracts by a metre
            raise PamjaxInputError(f"positions reach {np.max(np.abs(x)):g} m: these look like mm; pamjax takes m")
    check_moving(velocities, "the direction of motion")
