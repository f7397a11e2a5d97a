"""Bands on the maps users draw of a fitted model: the steady state against duty, the frequency response (gain and
phase), the valve's averaged flow surface.

The steady-state map and the frequency response run on `pamjax.sweep`'s batch engine (per-lane error control, many
lanes per compiled call), which is not traced end to end; their bands put the parameter points into the sweep as
one more batch axis, so every point of the band is one more lane of ONE sweep:

- "linear": the 2n + 1 points θ̂, θ̂ ± sₖ (the covariance's principal axes at 1 σ; `band.sigma_points`), and
  σ² = Σₖ ((y(θ̂+sₖ) − y(θ̂−sₖ))/2)²: the delta method with central differences at ±1 σ instead of a traced
  Jacobian (exact for a prediction linear in θ, like the forward-mode one; its step is the uncertainty itself, far
  above the solver's tolerance), with the curvature index from the same points;
- "samples": θ̂ and the draws, quantiles as `prediction_band`'s.

The flow surface is a traced function of the valve, so its band is `prediction_band`'s (forward-mode Jacobian).
"""

import inspect
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .._core.arrays import device_array
from .._core.custom_types import RealVectorLike
from .._core.errors import PamjaxInputError, PamjaxSolveError
from .._fit.parameters import Key, getter, join_path
from .._physics.valves.averaged import cycle_averaged_flow
from .._sweep.maps import check_flow_surface, frequency_response, steady_state_map
from .._sweep.sweep import channel_names, sweep
from .._systems.base import AbstractSystem
from .band import (
    Method,
    PredictionBand,
    check_method,
    draws,
    linear_from_points,
    nonlinearity_warning,
    prediction_band,
    propagated_band,
    quantile_band,
    sigma_points,
    z_of,
)
from .uncertainty import ResultLike, propagation

PHASE_PERIOD = 360.0  # deg: phase differences between parameter points are taken modulo a turn
# the flow surface's band: `prediction_band`'s own batch and linearity check (its defaults)
SURFACE_BAND = tuple(inspect.signature(prediction_band).parameters[k].default for k in ("batch", "check_linearity"))


@eqx.filter_jit
def _leaves(space, thetas, attrs):
    return jax.vmap(lambda t: tuple(getter(a)(space.model(t)) for a in attrs))(thetas)


def swept_values(prop, thetas, extra_axes=1):
    """`over` for a sweep of the models at `thetas` (P, n): {leaf path: values of shape (P, 1, ..., leaf shape)},
    with `extra_axes` unit axes for the map's own axes to broadcast against."""
    attrs = tuple(dict.fromkeys(g.attrs for g in prop.space.groups))
    for a in attrs:
        if any(isinstance(s, Key) for s in a):
            raise PamjaxInputError(f"{join_path(a)}: a band on a map propagates the model's own parameters, not a "
                                   "rig's run conditions")
    values = _leaves(prop.space, device_array(np.asarray(thetas, dtype=float)), attrs)
    out = {}
    for a, v in zip(attrs, values):
        v = np.asarray(v)
        out[join_path(a)] = v.reshape(v.shape[:1] + (1,) * extra_axes + v.shape[1:])
    return out


def parameter_points(prop, method, samples, seed):
    """The parameter points a map's band sweeps: θ̂ first, then θ̂ ± sₖ (linear) or the draws (samples)."""
    if method == "linear":
        return sigma_points(prop.theta, prop.covariance)
    return np.concatenate([prop.theta[None], draws(prop.theta, prop.covariance, samples, seed)])


def band_of_points(outputs, method, level, n, periods=None):
    """A `PredictionBand`'s arrays from each output's values at the parameter points (a dict name → (P, ...), θ̂
    first): (prediction, lower, upper, std, nonlinearity or None, failed points)."""
    z = z_of(level)
    pred, lower, upper, std, index = {}, {}, {}, {}, {}
    rows = next(iter(outputs.values())).shape[0]
    ok = np.ones(rows, dtype=bool)
    for y in outputs.values():
        ok &= np.all(np.isfinite(y.reshape(rows, -1)), axis=1)
    for name, y in outputs.items():
        pred[name] = y[0]
        if method == "linear":
            period = (periods or {}).get(name)
            std[name], index[name] = linear_from_points(y[0], y[1 : n + 1], y[n + 1 :], period)
            lower[name], upper[name] = y[0] - z * std[name], y[0] + z * std[name]
        else:
            period = (periods or {}).get(name)  # a phase: the draws differenced modulo a turn about ŷ
            lower[name], upper[name], std[name] = quantile_band(y[1:][ok[1:]], level, y[0], period)
    return pred, lower, upper, std, (index if method == "linear" else None), int(np.count_nonzero(~ok[1:]))


def map_options(kwargs, band, target):
    """The keyword arguments the map's band `band` (the function) passes on to the map `target` (its `scheme` as the
    map's `method`), refusing by name those the band sets itself: `over` is its batch axis of parameter points (a
    user's `over` gave a raw "multiple values for keyword argument" TypeError), `system` the fitted model; and any
    other that neither the map nor `pamjax.sweep` takes, naming the band and listing what it takes (`horizn=3` was
    refused naming steady_state_map, or sweep(), and listed `over`), before the fitted model is read."""
    kwargs = dict(kwargs)
    band_name, target_name = band.__name__, target.__name__
    own = [p for p, spec in inspect.signature(band).parameters.items() if spec.kind is spec.KEYWORD_ONLY]
    of_map = [p for p, spec in inspect.signature(target).parameters.items()
              if spec.kind is spec.KEYWORD_ONLY and p not in ("over", *own)]
    of_sweep = ["scheme" if p == "method" else p for p, spec in inspect.signature(sweep).parameters.items()
                if spec.kind is spec.KEYWORD_ONLY and (p == "method" or p not in ("reduce", *of_map, *own))]
    unknown = [k for k in kwargs if k not in (*of_map, *of_sweep, "over", "system")]
    if unknown:
        raise PamjaxInputError(f"{band_name} got the keyword {unknown[0]}=, which it does not take; its own: "
                               f"{', '.join(own)}; passed on to {target_name}: {', '.join(of_map)}; and to its "
                               f"pamjax.sweep: {', '.join(of_sweep)} (scheme: the sweep's method)")
    band = band_name
    if "over" in kwargs:
        raise PamjaxInputError(f"over: {band} sweeps the fitted parameters' points along its own batch axis and takes "
                               "no `over`; for the band at other values of a parameter the fit did not determine, set "
                               f"them on the model (model=eqx.tree_at(...)) and call {band} once per value (as pamjax "
                               "sweep --band does per point of [sweep] over)")
    if "system" in kwargs:
        raise PamjaxInputError(f"system: {band} maps the fitted model (`result`, or `model=`), not a `system` of "
                               f"{target_name}'s")
    if "scheme" in kwargs:
        kwargs["method"] = kwargs.pop("scheme")
    return kwargs


def _map_band(prop, outputs, method, level, samples, seed, how, periods=None):
    n = prop.theta.size
    notes = list(prop.notes)
    if not all(np.any(np.isfinite(y[0])) for y in outputs.values()):
        raise PamjaxSolveError("the map of the fitted model failed at every point: see the sweep's status")
    pred, lower, upper, std, index, failed = band_of_points(outputs, method, level, n, periods)
    if index is not None:
        nonlinearity_warning(index, notes)
    if failed:
        notes.append(f"{failed} of {2 * n if method == 'linear' else samples} parameter points failed at some map "
                     "point (NaN there" + (")" if method == "linear" else "; left out of the quantiles)"))
    count = 2 * n + 1 if method == "linear" else samples + 1
    if method == "linear":
        how = f"delta method, central differences at ±1 σ along the {n} principal axes of the covariance ({how})"
    else:
        how = (f"{samples} draws of the parameters from N(θ̂, Σθ) in the fit's unconstrained space (seed {seed}), "
               f"band = their quantiles ({how})")
    return PredictionBand(prediction=pred, lower=lower, upper=upper, std=std, level=float(level), method=method,
                          how=how, parameters=list(prop.labels), marginalised=list(prop.marginalised), draws=count,
                          failed=failed, nonlinearity=index, notes=notes)


def steady_state_band(result: ResultLike, commands: RealVectorLike, *, model: eqx.Module | None = None,
                      level: float = 0.95, method: Method = "linear", samples: int = 200, seed: int = 0,
                      **map_kwargs: Any) -> PredictionBand:
    """A confidence band on `pamjax.steady_state_map(model, commands, ...)` of a fitted model: every output channel
    (pressure, position, ...) against the command, from the fit's covariance. The parameter points are one more
    batch axis of one sweep (module docstring). `result`, `model`, `level`, `method`, `samples`, `seed` as for
    `prediction_band`; `map_kwargs` go to `steady_state_map` (`horizon`, `window`, `method` → `scheme`, ...)."""
    z_of(level)
    check_method(method, samples, seed)
    kwargs = map_options(map_kwargs, steady_state_band, steady_state_map)
    prop = propagation(result, model)
    points = parameter_points(prop, method, samples, seed)
    r = steady_state_map(prop.space.base, commands, over=swept_values(prop, points), **kwargs)
    outputs = {c: np.asarray(r[c]) for c in r.channels if c != "command"}
    return _map_band(prop, outputs, method, level, samples, seed, f"{len(points)} x {np.size(commands)} lanes of "
                     f"one sweep, {r.method}")


def frequency_response_band(result: ResultLike, frequencies: RealVectorLike, *, model: eqx.Module | None = None,
                            level: float = 0.95, method: Method = "linear", samples: int = 200, seed: int = 0,
                            channels: Sequence[str] | None = None, **response_kwargs: Any) -> PredictionBand:
    """A confidence band on `pamjax.frequency_response(model, frequencies, ...)` of a fitted model: per channel
    `"<channel>_gain"` (|Y|/|U|) and `"<channel>_phase"` [deg], from the fit's covariance (phases differenced
    modulo 360°). `channels`: default position and pressure, those the system has. The parameter points are one more
    batch axis of one sweep (module docstring); arguments as for `steady_state_band`, `response_kwargs` to
    `frequency_response` (`offset`, `amplitude`, `periods`, ...)."""
    z_of(level)
    check_method(method, samples, seed)
    channels = channel_names(channels)  # sweep's check: a bare string was read letter by letter ("unknown channel 'p'")
    kwargs = map_options(response_kwargs, frequency_response_band, frequency_response)
    prop = propagation(result, model)
    if channels is None:
        channels = tuple(c for c in ("position", "pressure") if c in prop.space.base.output_names)
    points = parameter_points(prop, method, samples, seed)
    fr = frequency_response(prop.space.base, frequencies, channels=tuple(channels), over=swept_values(prop, points),
                            **kwargs)
    outputs, periods = {}, {}
    for c in channels:
        outputs[f"{c}_gain"] = np.asarray(fr[c]["gain"])
        outputs[f"{c}_phase"] = np.asarray(fr[c]["phase"])
        periods[f"{c}_phase"] = PHASE_PERIOD
    return _map_band(prop, outputs, method, level, samples, seed, f"{len(points)} x {np.size(frequencies)} lanes of "
                     f"one sweep, {fr['result'].method}", periods)


@eqx.filter_jit
def _surface(valve, air, commands, pressures, samples):
    per_pressure = jax.vmap(lambda u, p: cycle_averaged_flow(valve, u, p, air, samples), (None, 0))
    return jax.vmap(per_pressure, (0, None))(commands, pressures)


class _Surface(eqx.Module):
    """The flow surface as a traced prediction of a model (its valve and air), for `prediction_band`."""

    commands: jax.Array
    pressures: jax.Array
    samples: int = eqx.field(static=True)

    def __call__(self, model):
        return {"mass_flow": _surface(model.valve, model.air, self.commands, self.pressures, self.samples)}


def flow_surface_band(result: ResultLike, commands: RealVectorLike, pressures: RealVectorLike, *,
                      model: eqx.Module | None = None, level: float = 0.95, method: Method = "linear",
                      samples: int = 200, seed: int = 0, phases: int = 400) -> PredictionBand:
    """A confidence band on `pamjax.flow_surface(model.valve, commands, pressures, model.air)` of a fitted model
    (a switching valve's cycle-averaged mass flow [kg/s], shape (commands, pressures)): `prediction_band` of the
    traced surface (forward-mode Jacobian, or draws), `phases` per PWM period as `flow_surface`'s `samples`."""
    z_of(level)
    check_method(method, samples, seed)
    prop = propagation(result, model)
    if not isinstance(prop.space.base, AbstractSystem):
        raise PamjaxInputError(f"model: flow_surface_band needs a system with a valve and air (e.g. "
                               f"presets.mas10_system(valve='pwm')), got {type(prop.space.base).__name__}")
    commands, pressures = check_flow_surface(prop.space.base.valve, commands, pressures, phases, "phases")
    predict = _Surface(device_array(commands), device_array(pressures), int(phases))
    return propagated_band(predict, prop, level, method, samples, seed, *SURFACE_BAND)
