"""A rig: the plant seen through its sensors and driven under the conditions of each run.

A recording is not the plant's state: a real rig's pressure sensor has an offset and a gain error, its position sensor
an offset, its acquisition lags the command by a fraction of a millisecond to a few milliseconds, the supply pressure
drifts from run to run, and a run logged from the middle starts in an unknown state. These are parameters of the
experiments, not of the plant (design.md, "What a rig adds"; as PEtab's observables separate measurement offsets and
scalings from the model, and as SDO estimates initial states beside the parameters):

- `Sensors`: pressure offset [Pa] (added to the gauge pressure) and gain [-] (multiplies it), position offset [m],
  acquisition delay [s] (every channel's samples are `delay` late: fractional, differentiable — the model is read
  at t − delay on its own continuous interpolant, not shifted by whole samples). One `Sensors` per group of
  experiments that share the same sensors (default group "rig": one set for the whole rig); an experiment names
  its group with `Experiment(..., sensors="left")`.
- `RunConditions`: one run's supply pressure [Pa abs] and its start state (`StartState`: pressure, position,
  velocity; for stick-slip friction the mode follows the velocity — stuck at 0, sliding in its direction
  otherwise — or is declared "stuck").
- `Rig(plant, sensors, runs)`: the object `pamjax.fit` fits when nuisances are free. Its parameter paths are the
  plant's under `plant.` (`plant.valve.inflate.discharge_coefficient`), `sensors[rig].delay`,
  `runs[E4].supply_pressure`, `runs[E4].start.position`. An `Experiment` asked for its predictions of a `Rig`
  simulates the plant under its run's conditions and reads it through its group's sensors; given a plain plant, it
  assumes ideal sensors, the plant's nominal supply and its own start state, exactly as before.

Which nuisances to free, and why, is in docs/fitting.md ("Identifying your own rig").
"""

from collections.abc import Mapping
from typing import TYPE_CHECKING, Literal

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import RealScalar
from .._core.errors import PamjaxInputError, check_finite, check_positive, concrete_values
from .._core.fitting import positive, signed
from .._core.units import check_absolute_pressure
from .._systems.base import AbstractSystem

if TYPE_CHECKING:  # annotations only: the fit imports this module
    from .fit import FitResult

DEFAULT_GROUP = "rig"
NUISANCE_ROOTS = ("sensors", "runs")
# What a working sensor can be off by (beyond: a unit slip, named with its fix): a pressure sensor's gain within a
# factor 2 (a gain written in percent reads 101), its offset within 1 bar (the MAS-10's 6 bar gauge range: an offset
# of a sixth of it is a broken sensor, not a calibration), a position offset within 0.1 m (the MAS-10-300's 75 mm
# stroke, paper 000: mm written as m), an acquisition delay within 0.1 s (five 50 Hz PWM periods: ms written as s).
SENSOR_LIMITS = {"pressure_gain": ((0.5, 2.0), "a gain in percent? 1.0 reads true, 1.01 is 1 % high"),
                 "pressure_offset": ((-1e5, 1e5), "Pa: an offset in kPa or bar? 1.5 kPa is 1500.0"),
                 "position_offset": ((-0.1, 0.1), "m: an offset in mm? 0.2 mm is 0.0002"),
                 "delay": ((-0.1, 0.1), "s: a delay in ms? 2 ms is 0.002")}


class Sensors(eqx.Module):
    """What a rig's sensors add to the plant's true channels (model → measured):

    pressure [Pa abs] = p_atm + `pressure_gain` (p − p_atm) + `pressure_offset`; position [m] = x + `position_offset`;
    every channel read `delay` [s] late: measured(t) = model(t − delay).

    Defaults are ideal sensors (offsets 0, gain 1, no delay). Fitted linearly in units of their natural size
    (`signed`: 1 kPa, 0.1 mm, 1 ms — the scale of a bench's noise and sampling interval), the gain in log space."""

    pressure_offset: RealScalar = signed(0.0, scale=1e3, unit="Pa")  # added to the gauge pressure
    pressure_gain: RealScalar = positive(1.0, unit="-")  # multiplies the gauge pressure
    position_offset: RealScalar = signed(0.0, scale=1e-4, unit="m")
    delay: RealScalar = signed(0.0, scale=1e-3, unit="s")  # the samples lag the command

    def __check_init__(self):
        for name, ((lo, hi), hint) in SENSOR_LIMITS.items():
            v = concrete_values(getattr(self, name))  # traced values (inside a fit's program) are not checked
            if v is not None and not np.all((v >= lo) & (v <= hi)):
                worst = float(v.flat[np.argmax(np.abs(v))])
                raise PamjaxInputError(f"Sensors.{name} = {worst:g} is outside [{lo:g}, {hi:g}] ({hint})")

    def observe(self, channel, values, atmosphere):
        """The measured `channel` from the model's `values` (the delay is applied where the model is read)."""
        if channel == "pressure":
            return atmosphere + self.pressure_gain * (values - atmosphere) + self.pressure_offset
        if channel == "position":
            return values + self.position_offset
        return values

    @staticmethod
    def channel_parameters(channel):
        """The fields that act on `channel` (besides the delay, which acts on all)."""
        return {"pressure": ("pressure_offset", "pressure_gain"), "position": ("position_offset",)}.get(channel, ())


START_MODES = ("auto", "stuck")


class StartState(eqx.Module):
    """A run's start state where it is not "at rest" (a recording started mid-run): `pressure` [Pa abs],
    `position` [m], `velocity` [m/s]; None keeps the system's default (at rest, in equilibrium). `mode`: "auto" (stick-
    slip friction sliding in the direction of the velocity, stuck where it is 0) or "stuck" (the velocity is 0)."""

    pressure: RealScalar | None = positive(None, unit="Pa abs")
    position: RealScalar | None = signed(None, scale=1e-3, unit="m")
    velocity: RealScalar | None = signed(None, scale=1e-2, unit="m/s")
    mode: Literal["auto", "stuck"] = eqx.field(static=True, default="auto")

    def __check_init__(self):
        if self.mode not in START_MODES:
            raise PamjaxInputError(f"StartState.mode must be one of {START_MODES}, got {self.mode!r}")
        if self.mode == "stuck" and self.velocity is not None:
            raise PamjaxInputError("StartState: a start declared 'stuck' has no velocity (it is 0)")
        # NaN or a negative (gauge) pressure reached the solve, which failed without naming the field
        _check_pressure(self.pressure, "StartState.pressure")
        for name in ("position", "velocity"):
            if getattr(self, name) is not None:
                check_finite(getattr(self, name), f"StartState.{name}")

    def keywords(self):
        """The `initial_state` keyword arguments this start sets."""
        out = {k: v for k, v in (("pressure", self.pressure), ("position", self.position),
                                 ("velocity", self.velocity)) if v is not None}
        if self.mode == "stuck":
            out["velocity"] = jnp.zeros(())
        return out


class RunConditions(eqx.Module):
    """One run's conditions: `supply_pressure` [Pa abs] (None: the plant's own), `start` (a `StartState`; None: the
    experiment's own start, at rest by default)."""

    supply_pressure: RealScalar | None = positive(None, unit="Pa abs")
    start: StartState | None = None

    def __check_init__(self):
        _check_pressure(self.supply_pressure, "RunConditions.supply_pressure")
        if self.start is not None and not isinstance(self.start, StartState):
            raise PamjaxInputError(f"RunConditions.start must be a pamjax.StartState (or None), got "
                                   f"{type(self.start).__name__}")


def _check_pressure(value, name):
    """An absolute pressure [Pa] a run sets: finite, positive, and of an absolute pressure's magnitude (a gauge value
    or another unit named). None (the plant's or the experiment's own) passes."""
    if value is not None:
        check_positive(value, f"{name} [Pa abs]")
        check_absolute_pressure(value, name)


class Rig(eqx.Module):
    """A plant with the nuisances of the rig it was recorded on (module docstring): `plant` (a system), `sensors`
    (group name → `Sensors`), `runs` (experiment name → `RunConditions`)."""

    plant: AbstractSystem
    sensors: dict[str, Sensors]
    runs: dict[str, RunConditions]

    def __init__(self, plant: AbstractSystem, sensors: Sensors | Mapping[str, Sensors] | None = None,
                 runs: Mapping[str, RunConditions] | None = None):
        if isinstance(plant, Rig):
            raise PamjaxInputError("Rig(plant=...): the plant is a Rig already")
        sensors = {DEFAULT_GROUP: Sensors()} if sensors is None else sensors
        if isinstance(sensors, Sensors):
            sensors = {DEFAULT_GROUP: sensors}
        for name, s in dict(sensors).items():
            if not isinstance(s, Sensors):
                raise PamjaxInputError(f"Rig sensors[{name!r}] must be a pamjax.Sensors, got {type(s).__name__}")
        for name, r in dict(runs or {}).items():
            if not isinstance(r, RunConditions):
                raise PamjaxInputError(f"Rig runs[{name!r}] must be a pamjax.RunConditions, got {type(r).__name__}")
        self.plant = plant
        self.sensors = {str(k): v for k, v in dict(sensors).items()}
        self.runs = {str(k): v for k, v in dict(runs or {}).items()}


def split(model, name, group):
    """(plant, sensors or None, run conditions or None) of experiment `name` in sensor group `group`: a `Rig`'s, or
    the plain plant with ideal sensors and its own conditions."""
    if isinstance(model, Rig):
        return model.plant, model.sensors.get(group), model.runs.get(name)
    return model, None, None


def check_group(model, name, group):
    """A `Rig` must hold the sensors of experiment `name`'s group: one it lacks (a typo: `sensors={"Rig": ...}`) would
    read the experiment through ideal sensors, its calibration unused."""
    if isinstance(model, Rig) and group not in model.sensors:
        example = min(model.sensors, default="left")  # the keyword is `sensors=` (it said `sensor_group=`: a TypeError)
        raise PamjaxInputError(f"experiment {name!r} reads sensor group {group!r}, which the Rig has none of (its "
                               f"groups: {sorted(model.sensors)}); name the group as the experiment does "
                               f"(Experiment(..., sensors={example!r}), {DEFAULT_GROUP!r} by default), or give it "
                               "Sensors() for ideal sensors")


PLANT_PREFIX = "plant."  # how a `Rig` labels its plant's parameters (`plant.valve.inflate.discharge_coefficient`)


def plant_label(label):
    """A rig fit's label of a plant parameter as the plant's own (`plant.` taken off; other labels as they are)."""
    return label.removeprefix(PLANT_PREFIX)


def is_nuisance(path):
    """Whether a parameter path (or label) names a rig's nuisance rather than the plant."""
    head = str(path).split(".")[0].split("[")[0]
    return head in NUISANCE_ROOTS


def nuisance_report(result: "FitResult") -> dict[str, dict[str, dict[str, tuple[float, float]]]]:
    """A fit result's nuisances apart from the plant: {"sensors": {group: {field: (value, std err)}},
    "runs": {run: {"supply_pressure" | "start.position" | ...: (value, std err)}}}."""
    from .fit import FitResult
    from .parameters import Key, split_path

    if not isinstance(result, FitResult):
        raise PamjaxInputError(f"nuisance_report: result must be a fit result (pamjax.fit(...) of a pamjax.Rig), got "
                               f"{type(result).__name__}")
    out = {"sensors": {}, "runs": {}}
    for label, value, se in zip(result.labels, result.values, result.standard_errors):
        if not is_nuisance(label):
            continue
        steps, _ = split_path(label)
        root, key, rest = steps[0], steps[1], [s for s in steps[2:] if not isinstance(s, Key)]
        out[root].setdefault(str(key), {})[".".join(rest)] = (float(value), float(se))
    return out
