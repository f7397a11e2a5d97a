"""`Measurement`: an independent measurement of one model parameter, with its standard uncertainty, fitted beside the
recordings.

A rig carries knowledge that its recordings hold only weakly: a calibration certificate gives the pressure sensor's
gain to 0.05 %, a reference gauge reads each run's supply pressure to 1 kPa. Holding such a value fixed trusts it
beyond its uncertainty: where the recordings pin a combination of parameters more tightly than the measurement, a
held value that is off by its own error pushes that error into the plant (benchmarks/RESULTS.md, identify: a supply
held at a gauge reading 1 kPa off moved k0, k1, F_c and C_f of an unseen rig by 4 %). Freeing it ignores the
knowledge. A `Measurement` puts it into the fit as what it is, one more datum: the residual

    r = (θ − value) / sd

beside the recordings' (model − data) / noise, so that the least-squares solution weighs the measurement and the
recordings by their uncertainties (a Gaussian prior on θ, in Bayesian terms; the maximum a posteriori estimate), and
the standard errors of every parameter include what the measurement adds. `θ` is the parameter as `pamjax.fit`'s
paths name it, in SI units (a `pamjax.Rig`'s `sensors[rig].pressure_gain`, `runs[E1].supply_pressure`, or a plant
parameter such as `plant.valve.inflate.area`).

The fit reports a measurement apart from the recordings' channels: its `channel_errors` entry gives the measured
value, its uncertainty, the fitted value and z = (fitted − measured) / sd; `|z| > 3` is a contradiction between the
measurement and the recordings (a wrong calibration, a misread gauge, or a model that cannot follow the data), which
the fit names in its warnings. A measurement takes no part in the residual-noise diagnostics (one datum is not a
noise sample).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError
from .experiment import AbstractExperiment
from .parameters import getter, join_path, parameter_paths, split_path

CONTRADICTION_Z = 3.0  # |fitted − measured| / sd above which a measurement contradicts the recordings (3σ: 0.27 %)


class Measurement(AbstractExperiment):
    """An independent measurement of the parameter at `path`: `value` (SI units, as the model holds it) with standard
    uncertainty `sd` (> 0, same unit), fitted as the residual (θ − value)/sd (module docstring).

    **Arguments:** `path` (a parameter path of the fitted model, e.g. `"sensors[rig].pressure_gain"`,
    `"runs[E1_u0.25].supply_pressure"`, `"plant.valve.inflate.area"`; an array element as `"…coefficients[2]"`),
    `value`, `sd`, `name` (default `"measured <path>"`; unique among the fit's experiments).

    The parameter should be free in the fit: a measurement of a held parameter only adds a constant to the cost.
    """

    measured: jax.Array  # (1,): the value (arrays, not compile-time constants: another reading compiles nothing)
    uncertainty: jax.Array  # (): sd
    path: str = eqx.field(static=True)
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True, default=("value",))

    def __init__(self, path: str, value: RealScalarLike, sd: RealScalarLike, name: str | None = None):
        split_path(path)  # a malformed path is named here
        self.path = str(path)
        value = _finite(value, f"Measurement({path!r}) value")
        sd = _finite(sd, f"Measurement({path!r}) sd")
        if not sd > 0:
            raise PamjaxInputError(f"Measurement({path!r}) sd must be > 0 (the measurement's standard uncertainty, "
                                   f"in the parameter's unit), got {sd!r}")
        self.measured = device_array(np.array([value]))
        self.uncertainty = device_array(np.array(sd))
        self.name = f"measured {self.path}" if name is None else str(name)
        self.channels = ("value",)

    @property
    def value(self) -> float:
        return float(np.asarray(self.measured)[0])

    @property
    def sd(self) -> float:
        return float(np.asarray(self.uncertainty))

    @property
    def noise_channels(self):
        return ("value",)  # `sd` is the measurement's uncertainty as the user gave it

    @property
    def split_time(self):
        return None  # no time axis: fitted, never held out

    def _steps(self):
        steps, index = split_path(self.path)
        return steps, index

    def check(self, model):
        """The path must name a scalar parameter of `model` (or one element of an array parameter)."""
        steps, index = self._steps()
        leaf = join_path(steps)
        shapes = parameter_paths(model)
        if leaf not in shapes:
            near = sorted(p for p in shapes if p.split(".")[-1] == leaf.split(".")[-1])[:5]
            raise PamjaxInputError(f"{self.name}: the model has no parameter {leaf!r}"
                                   + (f"; did you mean one of {near}?" if near else
                                      " (pamjax.parameter_paths(model) lists them)"))
        shape = shapes[leaf]
        if index is None and shape != ():
            raise PamjaxInputError(f"{self.name}: {leaf!r} is an array of shape {shape}; measure one element "
                                   f"({leaf}[i])")
        if index is not None and (len(index) != len(shape) or any(not 0 <= i < n for i, n in zip(index, shape))):
            raise PamjaxInputError(f"{self.name}: index {list(index)} is outside {leaf!r} of shape {shape}")

    def sees(self, model):
        steps, _ = self._steps()
        return {join_path(steps)}

    def predict(self, model):
        steps, index = self._steps()
        theta = jnp.asarray(getter(steps)(model))
        if index is not None:
            theta = theta[index]
        return {"value": jnp.reshape(theta, (1,))}

    def layout(self):
        one = np.ones(1, dtype=bool)
        return [("value", self.sd, np.array([self.value]), one, one)]

    def residuals_of(self, pred, part="identification"):
        del part
        return (pred["value"] - self.measured) / self.uncertainty


def is_measurement(experiment) -> bool:
    """Whether a fit's experiment is a parameter `Measurement` (reported apart from the recordings' channels)."""
    return isinstance(experiment, Measurement)


def measurement_stats(experiment, residual):
    """The `channel_errors` entry of a measurement: measured value, its sd, the fitted value and z."""
    z = float(residual)
    return {"measured": experiment.value, "sd": experiment.sd, "fitted": experiment.value + z * experiment.sd,
            "z": z, "rmse": abs(z) * experiment.sd, "max_error": abs(z) * experiment.sd}


def contradictions(experiments, errors):
    """Sentences for the measurements whose fitted value is more than `CONTRADICTION_Z` uncertainties from the
    measured one."""
    out = []
    for e in experiments:
        if is_measurement(e):
            st = errors.get(e.name, {}).get("value", {})
            z = st.get("z", 0.0)
            if math.isfinite(z) and abs(z) > CONTRADICTION_Z:
                out.append(f"{e.name}: measured {e.value:.6g} ± {e.sd:.3g}, fitted {st['fitted']:.6g} ({z:+.1f} "
                           f"uncertainties): the measurement and the recordings disagree (a wrong calibration or "
                           f"reading, or a model that cannot follow the data)")
    return out


def check_measured_free(model, experiments, free):
    """Every `Measurement` among `experiments` measures a parameter that `free` frees (a measurement of a held
    parameter only adds a constant to the cost: a mistake, named before any solve)."""
    freed = set()
    for entry in free:
        path = entry if isinstance(entry, str) else entry.get("path") if isinstance(entry, dict) else None
        if isinstance(path, str):
            freed.add(join_path(split_path(path)[0]))
    for e in experiments:
        if is_measurement(e):
            e.check(model)
            if not e.sees(model) <= freed:
                raise PamjaxInputError(f"{e.name}: measures {e.path!r}, which `free` does not free (a measurement of "
                                       f"a held parameter only adds a constant to the cost): free it, or leave the "
                                       f"measurement out")


def _finite(x, what):
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise PamjaxInputError(f"{what} must be a real number, got {x!r}") from None
    if not math.isfinite(v):
        raise PamjaxInputError(f"{what} must be finite, got {x!r}")
    return v
