"""Experiments: what a fit compares. Each one turns a model (the object whose parameters are fitted, e.g. a
`MuscleSystem`) into predictions of recorded channels, and its residuals (model − data) / scale.

- `Experiment`: a dynamic test: the system built from the model (the model itself, or a `TankFromModel` for a
  constant-volume valve test sharing the model's valve), a command signal, a `Recording`, the channels to compare and
  their scales (noise level, in the channel's unit), and the initial state.
- The static experiments (no time axis) of `pamjax._fit.static_experiments`: force maps, friction and flow
  curves.

Every experiment keeps the contract of `AbstractExperiment`, the one thing `fit` knows of them. Experiments of
different systems share parameters through the model (all valve tests use `model.valve`).
"""

import abc
import copy
import hashlib
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import device_array
from .._core.cache import structural
from .._core.custom_types import RealArrayLike, RealScalarLike
from .._core.errors import PamjaxInputError, check_count
from .._core.fastjit import keyed_by_code
from .._core.units import MIN_PRESSURE_NOISE, check_absolute_pressure
from .._physics.signals import AbstractSignal
from .._solve.checks import check_start_state
from .._solve.simulate import Stepping, fixed_grid_size, resolve_stepping, solve, validate
from .._solve.synchronous import num_periods
from .._systems.base import AbstractSystem
from .builds import SameSystem
from .recording import Recording, warn_filtered
from .rig import DEFAULT_GROUP, check_group, split


class AbstractExperiment(eqx.Module):
    """What a fit compares: an experiment turns a model (the object whose parameters are fitted) into predictions
    of measured channels and their residuals (model − data) / scale. `fit`, `evaluate` and `predictions` know
    experiments only through this contract.

    - `name`: unique among a fit's experiments; `channels`: the compared channels, in residual order.
    - `noise_channels`: the channels whose scale is their noise level as the user gave it (the diagnostics then
      measure the residuals against it; elsewhere they estimate the noise from the residuals).
    - `split_time`: the time [s] after which the samples are held out for validation (the first sample's time or
      later; after the last: none held out); None for an experiment without a time axis.
    - `check(model)`, `predict(model)`, `layout()`, `residuals_of(pred, part)` (abstract, below).
    - `bind(model)`: the experiment ready for tracing with `model` (e.g. its fixed grid sized); itself by default.
    - `sees(model)`: the parameter paths its predictions depend on (None, the default: all).
    - `batch_key(model)`: experiments with equal keys are integrated in one compiled loop (`predict_all`); None (the
      default): predicted on its own.
    - `residuals(model, part)`: `residuals_of(predict(model), part)`.
    """

    name: eqx.AbstractVar[str]
    channels: eqx.AbstractVar[tuple]
    noise_channels: eqx.AbstractVar[tuple]
    split_time: eqx.AbstractVar[jax.Array | None]

    @abc.abstractmethod
    def check(self, model):
        """Concrete validation against `model` before any traced solve: a `PamjaxInputError` naming the experiment
        for anything it cannot compare (a channel the model lacks, a command outside its range, ...)."""

    @abc.abstractmethod
    def predict(self, model):
        """{channel: the model's values at the data points} (traceable)."""

    @abc.abstractmethod
    def layout(self):
        """The residual vector's blocks, in order: per channel (name, scale, data, used, identification), the data
        and two boolean masks over its samples (used: not masked; identification: not held out for validation)."""

    @abc.abstractmethod
    def residuals_of(self, pred, part="identification"):
        """(pred − data) / scale, flat, in `layout` order, 0 where a sample is masked or belongs to the other part
        ("identification", "validation", "all")."""

    def bind(self, model):
        return self

    def batch_key(self, model):
        return None

    def sees(self, model):
        """The parameter paths of `model` (as `pamjax.parameter_paths` names them) that this experiment's predictions
        depend on, from the model's structure; None (the default): all of them. `staged_start` chooses its stages
        from this."""
        return None

    def residuals(self, model, part="identification"):
        check_part(part)
        return self.residuals_of(self.predict(model), part)


PARTS = ("identification", "validation", "all")  # the parts of an experiment's residuals


def check_part(part):
    """`residuals`' `part`, one of `PARTS` (an unknown one, "validaton", was taken as "all")."""
    if not (isinstance(part, str) and part in PARTS):
        raise PamjaxInputError(f"part must be one of {', '.join(map(repr, PARTS))}, got {part!r}")


# What `fit`, `evaluate` and `predictions` take as their experiments: a list (or tuple) of them, or one
Experiments = AbstractExperiment | Sequence[AbstractExperiment]


class _Constant:
    """A NumPy array held as a static (compile-time) value: hashed and compared by content."""

    def __init__(self, array):
        self.array = np.array(array, copy=True)
        self.array.setflags(write=False)
        self._hash = hash((self.array.shape, self.array.tobytes()))

    def __hash__(self):
        return self._hash

    def __eq__(self, other):
        return isinstance(other, _Constant) and np.array_equal(self.array, other.array)

    def __repr__(self):  # process-independent (fingerprints of resumed fits compare it)
        digest = hashlib.sha256(np.ascontiguousarray(self.array).tobytes()).hexdigest()[:16]
        return f"_Constant(shape={self.array.shape}, sha256={digest})"


def _default_scale(values):
    """1 % of the channel's range (so a residual of 1 is 1 % of range), or 1 for a flat channel."""
    span = float(np.ptp(values)) if values.size else 0.0
    return 0.01 * span if span > 0 else 1.0


# Fewer recorded samples than this and a channel's range says little about its noise: not checked against it
# (the range of n normal samples is ~4 σ at n = 20, ~6.5 σ at 1,000).
MIN_SAMPLES_FOR_SCALE_CHECK = 20


def check_scale_against_data(channel, scale, values, name="scales"):
    """Refuse a given noise level (`name[channel]`, a standard deviation in the channel's SI unit) that the
    recorded `values` contradict: larger than their whole range (0.1 meant in mm weighted the position 1,000× too
    little, silently), or a pressure noise below `MIN_PRESSURE_NOISE` Pa (0.02 meant in bar: weighted 1e5× too much)."""
    if channel.startswith("pressure") and scale < MIN_PRESSURE_NOISE:
        raise PamjaxInputError(f"{name}[{channel!r}] = {scale:g} Pa is below {MIN_PRESSURE_NOISE:g} Pa, no pressure "
                               "sensor's noise: that looks like kPa or bar (0.02 bar = 2 kPa = 2e3 Pa); the scale "
                               "is the channel's noise standard deviation in Pa")
    span = float(np.ptp(values)) if values.size >= MIN_SAMPLES_FOR_SCALE_CHECK else 0.0
    if span > 0 and scale > span:
        hint = " (0.1 mm = 1e-4 m)" if channel.startswith("position") else ""
        raise PamjaxInputError(f"{name}[{channel!r}] = {scale:g} exceeds the whole range of the recorded {channel} "
                               f"({span:.4g}): a noise standard deviation is a fraction of it; is it in another unit"
                               f"{hint}? Scales are in the channel's SI unit")


def _compared_channels(recording, channels, name):
    """The checked tuple of an `Experiment`'s compared channels (default: the recording's pressure, position,
    velocity and force): recorded, and each named once."""
    if channels is None:
        channels = [c for c in recording.channels if c in ("pressure", "position", "velocity", "force")]
    if isinstance(channels, str):
        raise PamjaxInputError(f"experiment {name!r}: channels must be a list of channel names, got {channels!r} "
                               "(a single one: put it in brackets)")
    channels = tuple(channels)
    if not channels:
        raise PamjaxInputError(f"experiment {name!r}: no channels to compare; recording has "
                               f"{sorted(recording.channels)}")
    twice = sorted({c for c in channels if channels.count(c) > 1}, key=str)
    if twice:  # every sample of it would be fitted twice: the cost doubled, the standard errors shrunk by √2
        raise PamjaxInputError(f"experiment {name!r}: channels names {', '.join(map(repr, twice))} more than once "
                               f"({list(channels)}); name each channel once")
    for c in channels:
        recording[c]  # error naming the valid channels
        if not np.any(recording.mask[c]):
            raise PamjaxInputError(f"experiment {name!r}: channel {c!r} has no valid sample (all masked: NaN), so it "
                                   f"would drop out of the fit unseen; compare other channels than {list(channels)}")
    return channels


class Experiment(AbstractExperiment):
    """A dynamic experiment: simulate `build(model)` driven by `signal` and compare `channels` with `recording`.

    **Arguments:**

    - `recording`: a `Recording` (times [s], channels in SI, ABSOLUTE pressure).
    - `signal`: the command (e.g. `Constant(0.25)`, `Triangle(0.05, 0.95, 0.08)`, `Sampled(...)`).
    - `channels`: names compared (default: the recording's channels the system outputs, command excluded).
    - `scales`: dict channel → scale in the channel's unit (the noise standard deviation, if known); default 1 % of
      the channel's range.
    - `build`: model → system (`SameSystem()` by default; `TankFromModel(volume)` for valve tests).
    - `initial`: keyword arguments of `system.initial_state` (e.g. `dict(pressure=6.5e5)`); default: its default
      (atmospheric, at rest in equilibrium). `t0`: start time [s] (default the first sample).
    - `name`; `rtol`, `atol`, `max_steps`, `dt0`: solver settings of the adaptive solve (see `simulate`); the
      tolerances default to 1e-9 (tighter than `simulate`'s 1e-6, so that the residuals are smooth enough for
      Levenberg-Marquardt near the optimum; see the comment at the default).
    - `stepping`: "auto" (default: "pwm" when the system's valve switches; "grid", fixed RK4 steps of 1 ms with
      events located inside the step, for stick-slip friction with a continuous valve; else "adaptive", diffrax at
      `rtol`/`atol`), or one of "adaptive", "pwm", "grid". "pwm" integrates on the PWM-synchronous fixed RK4 grid
      (`simulate(stepping="pwm")`: exact edges, `substeps` nodes per period plus the edges), so the residuals are
      smooth, deterministic functions of every parameter; an adaptive solve of a switching valve changes its step
      pattern with the parameters, and the cost jumps by O(1) between neighbouring trial points (docs/fitting.md),
      which stalls Levenberg-Marquardt. The grid is sized from the valve's PWM frequency in the model the
      experiment is first used with.
    - `validation_fraction`: the last fraction of the recording's DURATION kept out of the fit (paper 001: 0.4), the
      samples after t_first + (1 − fraction)·(t_last − t_first), reported as validation error (by time, not by sample
      count: the two differ for a recording not sampled uniformly).
    - `sensors`: the sensor group whose `pamjax.Sensors` read this experiment when it is predicted from a
      `pamjax.Rig` (default "rig": one set of sensors for the whole rig); its run conditions are the rig's
      `runs[name]`. `initial={"pressure": "supply"}` starts a tank at its run's supply pressure.
    """

    times: jax.Array
    data: dict
    weights: dict  # 1/scale where the sample is used, 0 where masked (NaN)
    # channel -> scale, NumPy float64 scalars: leaves of the pytree (read on the host only), not static, so that a
    # fit of other data of the same layout reuses the compiled residuals (a default scale follows the data)
    scales: dict
    noise_channels: tuple = eqx.field(static=True)  # channels whose scale the user gave (their noise level)
    signal: AbstractSignal
    build: Callable[[eqx.Module], AbstractSystem]
    initial: dict
    t0: jax.Array
    split_time: jax.Array
    name: str = eqx.field(static=True)
    channels: tuple = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    dt0: float | None = eqx.field(static=True)
    stepping: Stepping = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
    span: tuple = eqx.field(static=True)  # (t0, t_end) [s] as floats, to size the PWM grid
    host_times: "_Constant" = eqx.field(static=True)  # the times as a NumPy array (`predict`)
    num_periods: int | None = eqx.field(static=True)
    lowpass_hz: float | None = eqx.field(static=True)  # the recording's low-pass cut-off, if it was filtered
    sensor_group: str = eqx.field(static=True)  # which `Sensors` of a `Rig` read this experiment
    start_at_supply: bool = eqx.field(static=True)  # initial pressure = the run's supply pressure

    def __init__(
        self,
        recording: Recording,
        signal: AbstractSignal,
        channels: Sequence[str] | None = None,
        scales: Mapping[str, RealScalarLike] | None = None,
        build: Callable[[eqx.Module], AbstractSystem] | None = None,
        initial: Mapping[str, RealArrayLike | str] | None = None,
        t0: RealScalarLike | None = None,
        name: str | None = None,
        # 1e-9, not simulate's 1e-6: an adaptive solve's cost jumps at the tolerance level wherever its step pattern
        # changes with the parameters; in the ill-conditioned valleys of a joint fit (force law, friction and volume
        # trade off) that noise outweighs the decrease Levenberg-Marquardt can still make, and the fit stalls. The
        # averaged-valve benchmark fit (benchmarks/fit.py) stalls at 1e-6 and 1e-8 with F_c 35 % off (cost 1137 and
        # 1148) and converges at 1e-9 (cost 1110, every parameter within 1.6 standard errors of the truth).
        rtol: RealScalarLike = 1e-9,
        atol: RealScalarLike = 1e-9,
        max_steps: int = 100_000,
        dt0: RealScalarLike | None = None,
        validation_fraction: RealScalarLike = 0.0,
        stepping: Stepping = "auto", substeps: int = 16, sensors: str = DEFAULT_GROUP,
    ):
        if not isinstance(recording, Recording):
            raise PamjaxInputError(f"recording must be a pamjax.Recording, got {type(recording)}")
        if not isinstance(signal, AbstractSignal):
            raise PamjaxInputError(f"signal must be a pamjax signal (Constant, Triangle, ...), got {type(signal)}")
        channels = _compared_channels(recording, channels, recording.name if name is None else str(name))
        scales = dict(scales or {})
        for c in scales:
            if c not in channels:
                raise PamjaxInputError(f"scales names channel {c!r}, which is not compared; channels are {channels}")
        self.scales = {c: np.float64(scales.get(c, _default_scale(recording[c][recording.mask[c]]))) for c in channels}
        self.noise_channels = tuple(c for c in channels if c in scales)
        for c, s in self.scales.items():
            if not (np.isfinite(s) and s > 0):
                raise PamjaxInputError(f"scales[{c!r}] must be > 0 (the channel's noise level), got {s}")
        for c in self.noise_channels:
            check_scale_against_data(c, self.scales[c], recording[c][recording.mask[c]])
        if not 0.0 <= float(validation_fraction) < 1.0:
            raise PamjaxInputError(f"validation_fraction must be in [0, 1), got {validation_fraction}")
        t = recording.t
        self.times = device_array(t)  # (jnp.asarray compiles a small program per shape)
        self.data = {c: device_array(np.where(recording.mask[c], recording[c], 0.0)) for c in channels}
        self.weights = {c: device_array(recording.mask[c] / self.scales[c]) for c in channels}
        self.signal = signal
        self.build = SameSystem() if build is None else keyed_by_code(build)  # an inline lambda: one program
        initial = dict(initial or {})
        self.start_at_supply = isinstance(initial.get("pressure"), str)
        if self.start_at_supply:
            if initial["pressure"] != "supply":
                raise PamjaxInputError(f"experiment {name!r}: initial pressure must be a number [Pa abs] or "
                                       f"'supply', got {initial['pressure']!r}")
            del initial["pressure"]
        self.initial = {k: device_array(v, dtype=float) for k, v in initial.items()}
        if not isinstance(sensors, str) or not sensors:
            raise PamjaxInputError(f"experiment {name!r}: sensors must be a sensor group name (str), got {sensors!r}")
        self.sensor_group = sensors
        self.t0 = device_array(t[0] if t0 is None else t0, dtype=float)
        self.split_time = device_array(t[0] + (1.0 - float(validation_fraction)) * (t[-1] - t[0]) + 1e-12,
                                       dtype=float)
        self.name = recording.name if name is None else str(name)
        self.channels = channels
        check_count(max_steps, "max_steps")
        self.rtol, self.atol, self.max_steps = float(rtol), float(atol), int(max_steps)
        self.dt0 = None if dt0 is None else float(dt0)
        if stepping not in ("auto", "adaptive", "pwm", "grid"):
            raise PamjaxInputError(f"stepping must be 'auto', 'adaptive', 'pwm' or 'grid', got {stepping!r}")
        if not (isinstance(substeps, (int, np.integer)) and not isinstance(substeps, (bool, np.bool_))
                and substeps >= 2):  # a NumPy integer too (np.int64(16)), never a bool
            raise PamjaxInputError(f"substeps must be an int >= 2 (RK4 nodes per PWM period), got {substeps!r}")
        self.stepping, self.substeps = stepping, int(substeps)
        self.lowpass_hz = recording.lowpass_hz
        self.span = (float(self.t0), float(t[-1]))
        self.host_times = _Constant(np.asarray(t, dtype=float))
        self.num_periods = None

    # -- the plant under this run's conditions, read through its sensors (a `Rig`; a plain plant: ideal) ---------
    def system_for(self, model):
        """The system this experiment simulates: `build` of the plant, fed at the run's supply pressure."""
        plant, _, run = split(model, self.name, self.sensor_group)
        system = self.build(plant)
        if run is not None and run.supply_pressure is not None:
            system = system.with_supply_pressure(run.supply_pressure)
        return system

    def start_for(self, system, model):
        """The start state: the experiment's `initial` (at the supply pressure if it says so), with the run's
        `StartState` where the rig gives one."""
        _, _, run = split(model, self.name, self.sensor_group)
        initial = dict(self.initial)
        if self.start_at_supply:
            initial["pressure"] = system.valve.supply()
        if run is not None and run.start is not None:
            initial.update(run.start.keywords())
        return system.initial_state(**initial)

    def sample_times(self, model):
        """Where the model is read: the recording's times less the sensors' delay, within the run."""
        _, sensors, _ = split(model, self.name, self.sensor_group)
        if sensors is None:
            return self.times
        return jnp.clip(self.times - sensors.delay, self.t0, self.times[-1])

    def observe(self, model, channels):
        """The measured channels from the model's (the sensors' offsets and gain; see `pamjax.Sensors`)."""
        plant, sensors, _ = split(model, self.name, self.sensor_group)
        if sensors is None:
            return channels
        atmosphere = plant.air.atmospheric_pressure
        return {c: sensors.observe(c, v, atmosphere) for c, v in channels.items()}

    def sees(self, model):
        """The model's parameter paths this experiment depends on: those of the system `build` makes of the plant
        (prefixed `plant.` in a `Rig`), its sensor group's fields that act on its channels, and its own run's
        conditions."""
        from .parameters import parameter_paths

        plant, sensors, run = split(model, self.name, self.sensor_group)
        system = parameter_paths(self.build(plant))
        if plant is model:
            return set(system)
        paths = {f"plant.{p}" for p in system}
        if sensors is not None:
            fields = {"delay"} | {f for c in self.channels for f in sensors.channel_parameters(c)}
            paths |= {f"sensors[{self.sensor_group}].{f}" for f in fields}
        if run is not None:
            paths |= {f"runs[{self.name}].{p}" for p in parameter_paths(run)}
        return paths

    def _stepping(self, system):
        """The stepping of this experiment's solve. "auto": the PWM-synchronous grid for a switching valve (smooth,
        deterministic residuals in every parameter, where an adaptive solve's step pattern changes with them and its
        cost jumps at the tolerance level), the uniform grid for a hybrid system (stick-slip friction) fed by a
        continuous valve, and the adaptive solver otherwise: a smooth system can be stiff (a smooth Coulomb sign
        under a large F_c) beyond what a fixed 1 ms RK4 step holds. "grid" asks for the uniform grid anyway (small
        programs, smooth residuals: a tank test with the averaged valve)."""
        if self.stepping == "auto" and system.valve.switches:
            return "pwm"
        try:
            return resolve_stepping(system, self.stepping)
        except PamjaxInputError as err:
            raise PamjaxInputError(f"experiment {self.name!r}: {err}") from None

    def grid_size(self, system, stepping):
        """The number of fixed-grid steps (PWM periods for "pwm") covering the recording: as bound (`bind`), else
        sized for this concrete `system`."""
        if self.num_periods is not None:
            return self.num_periods
        return fixed_grid_size(system, stepping, *self.span)  # concrete model; traced: bind(model) first

    def bind(self, model):
        """This experiment with its fixed grid sized for `model` (concrete): the number of PWM periods (or grid
        steps) covering the recording. A no-op for adaptive stepping or when already sized."""
        system = self.system_for(model)
        stepping = self._stepping(system)
        if self.num_periods is not None or stepping == "adaptive":
            return self
        bound = copy.copy(self)
        object.__setattr__(bound, "num_periods", fixed_grid_size(system, stepping, *self.span))
        return bound

    def check(self, model):
        """Concrete validation (signal range, times, initial state) before any traced solve."""
        check_group(model, self.name, self.sensor_group)
        plant, _, _ = split(model, self.name, self.sensor_group)
        system = self.build(plant)
        if not isinstance(system, AbstractSystem):
            raise PamjaxInputError(f"experiment {self.name!r}: build(model) must give a pamjax system, got "
                                   f"{type(system)}")
        system = self.system_for(model)
        validate(system, self.signal, self.times, None, self.t0)
        self._stepping(system)  # a stepping this system cannot take is named here
        for key, value in self.initial.items():
            if not np.all(np.isfinite(np.asarray(value))):
                raise PamjaxInputError(f"experiment {self.name!r}: initial {key} must be finite, got {value}")
            if key == "pressure":
                if not np.all(np.asarray(value) > 0):
                    raise PamjaxInputError(f"experiment {self.name!r}: initial pressure must be an ABSOLUTE "
                                           f"pressure > 0 [Pa], got {value}")
                check_absolute_pressure(value, f"experiment {self.name!r}: initial pressure")
        period = system.valve.period if self.lowpass_hz is not None else None  # (an eager division: only if needed)
        if period is not None and self.lowpass_hz < 1.0 / float(period):
            warn_filtered(self.name, self.lowpass_hz, 1.0 / float(period), stacklevel=4)
        # Which channels the system has: its outputs, traced (not solved, not compiled); kept per structure by the
        # CLI's program cache (a warm `pamjax fit` traces nothing)
        outputs = structural("experiment_outputs", Experiment._output_names, self, system, model)
        for c in self.channels:
            if c not in outputs and c != "command":
                raise PamjaxInputError(f"experiment {self.name!r}: the system has no output {c!r}")
        try:  # as `simulate` checks y0.position: metres (not 20 for 20 mm), inside the stroke
            check_start_state(system, self.start_for(system, model) if "position" in self.initial else None, "initial")
        except PamjaxInputError as err:
            raise PamjaxInputError(f"experiment {self.name!r}: {err}") from None

    def _output_names(self, system, model):
        """The names of `system`'s outputs, by shape inference of the start state (computed inside the compiled
        solve) and of the outputs there; bad `initial` keys are named."""
        try:
            y0 = jax.eval_shape(lambda s: self.start_for(s, model), system)
        except TypeError as err:
            raise PamjaxInputError(f"experiment {self.name!r}: bad `initial` keys {sorted(self.initial)}: "
                                   f"{err}") from err
        return sorted(jax.eval_shape(lambda s, y: s.outputs(self.t0, y, self.signal(self.t0)), system, y0))

    def predict(self, model):
        """Model channels at the recording's times (traceable): dict channel → array."""
        system = self.system_for(model)
        y0 = self.start_for(system, model)
        stepping = self._stepping(system)
        times = self.sample_times(model)
        if stepping != "adaptive":
            traj = solve(system, self.signal, times, y0, self.t0, stepping=stepping, substeps=self.substeps,
                         num_periods=self.grid_size(system, stepping))
            return self.observe(model, {c: traj.channel(c) for c in traj.channels()})
        # The output times and start as compile-time constants (the recording's own, exactly): diffrax then checks
        # them at trace time instead of with a run-time host callback, and a program with a host callback cannot be
        # kept in JAX's persistent compilation cache.
        traj = solve(system, self.signal, jnp.asarray(self.host_times.array) if times is self.times else times, y0,
                     jnp.asarray(self.span[0]), rtol=self.rtol, atol=self.atol, max_steps=self.max_steps, dt0=self.dt0,
                     adjoint="forward", num_periods=self._edge_periods(system))
        return self.observe(model, {c: traj.channel(c) for c in traj.channels()})

    def _edge_periods(self, system):
        """PWM periods of the recording for a smoothed switching valve (its edges get step boundaries), else None."""
        valve = system.valve
        if not valve.smooth_edges:
            return None
        try:
            return num_periods(valve, self.span[0], self.span[1])
        except PamjaxInputError:  # a traced PWM frequency (fitted): no edge steps
            return None

    def batch_key(self, model):
        """Experiments with equal keys are integrated in one compiled loop (`predict_all`): fixed-grid stepping of
        systems of one structure. None: solved on its own (adaptive stepping)."""
        system = self.system_for(model)
        stepping = self._stepping(system)
        if stepping == "adaptive":
            return None
        return (stepping, self.substeps, jax.tree_util.tree_structure(system))

    def residuals(self, model, part="identification"):
        """(model − data) / scale for the compared channels, flattened; 0 at masked samples and at the samples of
        the other part ("identification": t before the split, "validation": after it, "all")."""
        return self.residuals_of(self.predict(model), part)

    def layout(self):
        """The residual vector's blocks, in order: per channel (name, scale, data, used, identification) with the
        data and two masks over its samples (used: not masked; identification: before the validation split)."""
        ident = np.asarray(self.times) <= float(self.split_time)
        return [(c, self.scales[c], np.asarray(self.data[c]), np.asarray(self.weights[c]) > 0, ident)
                for c in self.channels]

    def residuals_of(self, pred, part="identification"):
        """`residuals` from this experiment's predictions `pred` (dict channel → array at `times`)."""
        check_part(part)
        keep = {"identification": self.times <= self.split_time, "validation": self.times > self.split_time}.get(
            part, jnp.ones_like(self.times, dtype=bool))
        return jnp.concatenate([(pred[c] - self.data[c]) * self.weights[c] * keep for c in self.channels])
