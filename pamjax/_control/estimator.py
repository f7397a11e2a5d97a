"""State estimation in the closed loop: the bench's noisy sensors and an extended Kalman filter on paper 000's
discrete-time model (eq. 17-21), which feeds a state-feedback controller (the sliding mode controller needs the
velocity, which no sensor measures; paper 000 estimates it with an SVSF filter, ref. [29]).

The filter steps the model's own discrete-time model (`discrete_step`: eq. 18 pressure, eq. 20 velocity, eq. 19
position from the new velocity; eq. 21's acceleration is the velocity's difference quotient and adds no state):

    z_{k+1} = f(t_k, z_k, u_k) + w_k,   w_k ~ N(0, Q T_s)     (Q: white noise on each state's rate, per √s)
    y_k     = h(z_k) + v_k,             v_k ~ N(0, R)         (R: the sensors' noise, diagonal)

with the extended Kalman filter's first-order propagation (Jacobians by forward-mode autodiff) and the Joseph form of
the covariance update. It runs in the solvers' scaled coordinates (`system.state_scale()`) with each measurement
divided by its noise, so that pressures [Pa] and positions [m] meet in one well-conditioned matrix; on a linear model
it is the textbook Kalman filter (tests/test_estimator.py). Everything is JAX: the loop is differentiable
through the filter (gains, noise settings, plant and model parameters).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.arrays import as_array
from .._core.custom_types import Array, ArrayLike, Float, Int, IntScalarLike, Real, RealArrayLike
from .._core.errors import PamjaxInputError, check_finite, check_nonnegative, check_positive, concrete_values
from .._core.units import MIN_PRESSURE_NOISE, check_absolute_pressure
from .._physics.signals import Step
from .._solve.checks import START_STROKE_MARGIN, check_start_state
from .._solve.scaled import scaled
from .._solve.simulate import validate
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from .controllers import fold_seed

# The hybrid reference bench's sensors (`shared/data/hybrid-reference-bench/meta.json`, "noise": p_std_Pa 2000,
# x_std_m 1e-4; "sampling_hz": 1000): the pressure sensor (Festo SDE1) and the potentiometer of paper 000's Fig. 1.
BENCH_PRESSURE_NOISE = 2e3  # Pa
BENCH_POSITION_NOISE = 1e-4  # m
BENCH_SAMPLES_PER_PERIOD = 20  # 1 kHz at 50 Hz PWM
COVARIANCE_RTOL = 1e-9  # of the largest eigenvalue: how negative an initial covariance's may be (round-off), or
# how far from symmetric its entries


def _state_fields(state):
    """Names of the non-None fields of a named state (e.g. pressure, position, velocity of a `MuscleState`)."""
    return tuple(k for k, v in vars(state).items() if v is not None)


def _as_seed(seed: IntScalarLike) -> Int[Array, ""]:
    """A whole number (an int, or a whole-valued number or array: a model file's); 1.5 was truncated to 1 and "a"
    failed with a raw ValueError; one outside int32 folded into it (`fold_seed`). A traced seed (vmapped) as it is."""
    if not isinstance(seed, jax.core.Tracer):
        value = None if isinstance(seed, (bool, np.bool_, str, bytes)) else concrete_values(seed)
        if value is None or value.ndim != 0 or not np.isfinite(value) or value != np.round(value):
            raise PamjaxInputError(f"LoopSensors.seed must be an integer (the sensors' noise seed), got {seed!r}")
        seed = fold_seed(seed if isinstance(seed, (int, np.integer)) else int(value))  # (a float: whole-valued)
    return jnp.asarray(seed, dtype=jnp.int32)


def _floats(values, name):
    """`values` as a float array, or a `PamjaxInputError` naming `name` (a string was a raw ValueError)."""
    try:
        return jnp.asarray(values, float)
    except (TypeError, ValueError) as err:
        raise PamjaxInputError(f"{name} must be numbers, got {values!r}") from err


def _as_optional_floats(values: RealArrayLike | None) -> Float[Array, "..."] | None:
    return values if values is None else _floats(values, "ExtendedKalmanFilter.measurement_noise")


def check_noise_scale(system, noise, name):
    """A sensor noise level {channel: σ} no sensor of `system` can have (None: no system, only the rules that need
    none): a pressure noise in (0, `MIN_PRESSURE_NOISE`) Pa (a unit slip: 0.02 meant in bar, 2 in kPa), a position
    noise of a tenth of the muscle's whole stroke or more (0.1 meant in mm), a pressure noise of a tenth of the
    supply's range or more. `name` names the table ("noise", "LoopSensors.noise"); traced values are not checked.
    `design_experiment`'s check of its noise, the filter's of its `noise`."""
    values = {c: concrete_values(v) for c, v in noise.items()}
    p = values.get("pressure")
    if p is not None and 0.0 < float(p) < MIN_PRESSURE_NOISE:
        raise PamjaxInputError(f"{name}['pressure'] = {float(p)!r} Pa is below {MIN_PRESSURE_NOISE:g} Pa, no "
                               "pressure transducer's noise: that looks like bar (0.02 bar = 2e3 Pa) or kPa (2 kPa = "
                               "2e3 Pa); the noise is a standard deviation in Pa")
    x = values.get("position")
    if x is not None and isinstance(system, AbstractMuscleSystem):
        stroke = float(system.muscle.max_position) - float(system.muscle.min_position)
        if float(x) >= 0.1 * stroke:
            raise PamjaxInputError(f"{name}['position'] = {float(x)!r} m is {float(x) / stroke:.2g} of the muscle's "
                                   f"whole stroke ({1e3 * stroke:.0f} mm): the noise is a standard deviation in metres "
                                   "(0.1 mm = 1e-4)")
    if p is None or system is None:
        return
    try:
        span = float(system.valve.supply()) - float(system.air.atmospheric_pressure)
    except PamjaxInputError:  # a valve without a supply pressure of its own (the averaged valve)
        return
    if float(p) >= 0.1 * span:
        raise PamjaxInputError(f"{name}['pressure'] = {float(p)!r} Pa is {float(p) / span:.2g} of the valve's whole "
                               f"range (supply − atmosphere, {span / 1e5:.2f} bar): the noise is a standard deviation "
                               "in Pa (2 kPa = 2e3)")


class LoopSensors(eqx.Module):
    """The loop's sensors: the plant states `channels` sampled `samples_per_period` times per control period, at
    t_k + jT/N (j = 1 … N), each with independent Gaussian noise of standard deviation `noise` (per channel, in the
    channel's unit), seeded (`seed`, drawn per period: a run is reproducible and differentiable).

    **Arguments:** `channels` (static; state fields, default ("pressure", "position")); `noise` (2e3 Pa, 1e-4 m: the
    hybrid bench's `meta.json`); `samples_per_period` N (static int, 20: the bench's 1 kHz at 50 Hz); `seed` (an
    integer of any size: one outside int32 is folded into it, deterministically, by `fold_seed`)."""

    channels: tuple[str, ...] = eqx.field(static=True, default=("pressure", "position"))
    noise: Real[Array, " channels"] = eqx.field(converter=as_array,
                                                default=(BENCH_PRESSURE_NOISE, BENCH_POSITION_NOISE))
    samples_per_period: int = eqx.field(static=True, default=BENCH_SAMPLES_PER_PERIOD)
    seed: Int[Array, ""] = eqx.field(converter=_as_seed, default=0)  # an array: a new seed, same program; vmaps

    def __check_init__(self):
        channels = self.channels
        if not (isinstance(channels, tuple) and channels and all(isinstance(c, str) for c in channels)
                and len(set(channels)) == len(channels)):
            raise PamjaxInputError(
                f"LoopSensors.channels must be a non-empty tuple of distinct state names, got {channels!r}")
        if jnp.shape(self.noise) != (len(channels),):
            raise PamjaxInputError(f"LoopSensors.noise must have one standard deviation per channel {channels}, got "
                                   f"shape {jnp.shape(self.noise)}")
        check_nonnegative(self.noise, "LoopSensors.noise")
        check_noise_scale(None, dict(zip(channels, self.noise)), "LoopSensors.noise")  # the plant's: ClosedLoop
        n = self.samples_per_period
        if not (isinstance(n, int) and not isinstance(n, bool) and n >= 1):
            raise PamjaxInputError(f"LoopSensors.samples_per_period must be an int >= 1, got {n!r}")

    def offsets(self, period):
        """Sample times after the period start [s]: jT/N, j = 1 … N (the last at the period's end)."""
        n = self.samples_per_period
        return period * jnp.arange(1, n + 1) / n

    def read(self, states, period_index):
        """Noisy readings (N, channels) of the true `states` (a named state with a leading axis of N samples) in the
        period `period_index`."""
        values = jnp.stack([getattr(states, c) for c in self.channels], axis=-1)
        key = jax.random.fold_in(jax.random.key(self.seed), period_index)
        return values + self.noise * jax.random.normal(key, values.shape, dtype=values.dtype)


class KalmanState(eqx.Module):
    """The filter's belief: `mean` (n,) and `covariance` (n, n) of the model's state in scaled units (state /
    `system.state_scale()`, flattened in the state's field order); `ExtendedKalmanFilter.estimate` and `.covariance`
    give them in SI units."""

    mean: Float[ArrayLike, " *batch n"]
    covariance: Float[ArrayLike, " *batch n n"]


def _per_state(name, defaults):
    """Converter of a {state: value} dict to float arrays (a string named), omitted states at `defaults`, not 0."""
    def convert(values: dict[str, RealArrayLike]) -> dict[str, Float[Array, "..."]]:  # annotated: __init__'s type
        merged = {**defaults, **values} if isinstance(values, dict) else {}  # not a dict: __check_init__ names it
        return {k: _floats(v, f"ExtendedKalmanFilter.{name}[{k!r}]") for k, v in merged.items()} if merged else values
    return convert


def _named(template, values, name):
    """A state-shaped pytree from a {field: value} dict (missing fields 0), e.g. process noise per state."""
    fields = _state_fields(template)
    unknown = set(values) - set(fields)
    if unknown:
        raise PamjaxInputError(f"{name}: unknown state(s) {sorted(unknown)}; the model's states are {fields}")
    out = template
    for k in fields:
        value = jnp.broadcast_to(jnp.asarray(values.get(k, 0.0), float), jnp.shape(getattr(template, k)))
        out = eqx.tree_at(lambda s, k=k: getattr(s, k), out, value)
    return out


class ExtendedKalmanFilter(eqx.Module):
    """Extended Kalman filter on a system's discrete-time model (paper 000 eq. 18-21, `discrete_step`).

    Each sensor sample: predict z ← f(z), P ← F P Fᵀ + Q T_s (F = ∂f/∂z by forward-mode autodiff), then update with
    the readings y (noise σ_R): S = H P Hᵀ + R, K = P Hᵀ S⁻¹, z ← z + K (y − h(z)), P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ.

    **Arguments:**

    - `model`: the filter's model, a smooth system (not hybrid: Euler steps cannot switch a stick-slip mode), e.g.
      paper 000's choice `presets.mas10_system("averaged")` (eq. 13 valve) or the identified plant's parameters with
      `CoulombViscousFriction` (eq. 20's sign smoothed). Its discrete step at the sample time T_s = T / N must be
      stable: with the smooth sign that needs T_s below ≈ 2 w M / F_c (1.2 ms at w = 1 mm/s, 9.6 kg, 16 N).
    - `process_noise`: {state: q} the white noise on each state's rate [state unit per √s] that covers the model's
      errors (Q = q² T_s per sample). Default, for paper 000's plant under the averaged model: pressure 1.5e5 Pa/√s
      (4.7 kPa per 1 ms sample: the averaged valve does not know the switching valve's ±7 kPa ripple, so the filter
      follows the pressure readings), position 1e-4 m/√s, velocity 0.02 m/s/√s (0.63 mm/s per sample, an
      acceleration error of 0.6 m/s²: 6 N on 9.6 kg, where the smooth sign misplaces stick-slip). Chosen on a grid
      (pressure 3e4-4e5, position 1e-5-1e-3, velocity 0.005-0.5) as the smallest estimation error of the SMC's loop
      on `presets.mas10_system("pwm", friction="karnopp")` with the bench's noise (docs/control.md).
    - `measurement_noise`: σ_R per sensor channel (a 1-D array, one value > 0 per channel, in the channel's unit; a
      `ClosedLoop` checks it against its sensors' channels); None (default): the loop's `LoopSensors.noise`.
    - `initial_std`: {state: σ} of the initial belief about the model's state at rest (pressure 1e4 Pa, position
      5e-3 m, velocity 1e-2 m/s). A dict naming some states keeps the others' defaults, here and in `process_noise`.
    - `substeps` (static int >= 1, 1): Euler steps of the model per sample. Paper 000's averaged model runs at 1 kHz in
      one; a switching-valve model (`presets.mas10_system("pwm")`, smoothed edges of 0.1 ms) needs ≥ 10, and then
      predicts the PWM ripple (with pressure process noise 3e4 Pa/√s its pressure error halves, docs/control.md).
    """

    model: AbstractSystem
    process_noise: dict[str, Float[Array, "..."]] = eqx.field(
        converter=_per_state("process_noise", dict(pressure=1.5e5, position=1e-4, velocity=0.02)), default_factory=dict)
    measurement_noise: Float[Array, " channels"] | None = eqx.field(converter=_as_optional_floats, default=None)
    initial_std: dict[str, Float[Array, "..."]] = eqx.field(
        converter=_per_state("initial_std", dict(pressure=1e4, position=5e-3, velocity=1e-2)), default_factory=dict)
    substeps: int = eqx.field(static=True, default=1)

    def __check_init__(self):
        model = self.model
        if not isinstance(model, AbstractSystem):
            raise PamjaxInputError(f"ExtendedKalmanFilter.model must be a pamjax system, got {type(model).__name__}")
        if model.hybrid:
            raise PamjaxInputError(
                "ExtendedKalmanFilter.model must be smooth, not hybrid: its discrete-time model (eq. 18-21) steps by "
                "Euler and cannot switch a stick-slip mode; give the filter CoulombViscousFriction (eq. 20's sign "
                "smoothed), e.g. presets.mas10_system('averaged')"
            )
        template = jax.eval_shape(model.initial_state)
        for name in ("process_noise", "initial_std"):
            values = getattr(self, name)
            if not isinstance(values, dict):
                raise PamjaxInputError(f"ExtendedKalmanFilter.{name} must be a dict {{state: value}}, got {values!r}")
            unknown = set(values) - set(_state_fields(template))
            if unknown:
                raise PamjaxInputError(
                    f"ExtendedKalmanFilter.{name}: unknown state(s) {sorted(unknown)}; the model's states are "
                    f"{_state_fields(template)}"
                )
            for k, v in values.items():
                check_nonnegative(v, f"ExtendedKalmanFilter.{name}[{k!r}]")
                want = getattr(template, k).shape
                if not _broadcasts(jnp.shape(v), want):  # [1e5, 2e5] failed in filter with a broadcast ValueError
                    raise PamjaxInputError(f"ExtendedKalmanFilter.{name}[{k!r}] must be one value per entry of the "
                                           f"state {k!r} (shape {want}: a single number), got shape {jnp.shape(v)}")
        if self.measurement_noise is not None:
            if jnp.ndim(self.measurement_noise) != 1 or jnp.size(self.measurement_noise) == 0:
                raise PamjaxInputError(
                    "ExtendedKalmanFilter.measurement_noise must be a 1-D array of σ_R, one per sensor channel, got "
                    f"shape {jnp.shape(self.measurement_noise)}")
            check_positive(self.measurement_noise, "ExtendedKalmanFilter.measurement_noise")
        if not (isinstance(self.substeps, int) and not isinstance(self.substeps, bool) and self.substeps >= 1):
            raise PamjaxInputError(
                f"ExtendedKalmanFilter.substeps must be an int >= 1 (Euler steps per sample), got {self.substeps!r}")

    # --- the state map -------------------------------------------------------------------------------------------
    def _template(self):
        shapes = jax.eval_shape(self.model.initial_state)
        return jtu.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)

    def _scaled(self):
        return scaled(self.model, self._template())[1]

    def estimate(self, state: KalmanState):
        """The estimated model state (named, SI units, absolute pressure)."""
        return self._scaled().state(state.mean)

    def covariance(self, state: KalmanState):
        """The covariance (n, n) in SI units, in the flat order of the state's fields."""
        scale = self._scaled().scale
        return state.covariance * scale[:, None] * scale[None, :]

    def std(self, state: KalmanState):
        """The estimate's standard deviations as a named state (SI units)."""
        sc = self._scaled()
        return sc.unravel(jnp.sqrt(jnp.diag(state.covariance)) * sc.scale)

    def initial_state(self, mean=None):
        """The belief at the start: `mean` (a model state; default the model at rest, `model.initial_state()`) with
        the standard deviations `initial_std`.

        **Raises:** `PamjaxInputError` for a `mean` that is not a state of the model (a dict, another model's state)
        or one `simulate` would refuse as a start (a leaf not finite, a pressure not absolute pascal, a position
        outside the stroke)."""
        mean = self.model.initial_state() if mean is None else mean
        _check_state_like(self._template(), mean, "ExtendedKalmanFilter.initial_state: mean")
        check_start_state(self.model, mean, "ExtendedKalmanFilter.initial_state: mean")
        z0, sc = scaled(self.model, mean)
        std = sc.vector(_named(self._template(), self.initial_std, "initial_std"))
        return KalmanState(mean=z0, covariance=jnp.diag(std**2))

    # --- the two steps -------------------------------------------------------------------------------------------
    def predict(self, state: KalmanState, t, command, sample_time):
        """Propagate the belief over one sample time T_s [s] from `t` with `command` (what the model's valve acts
        on, `valve.read_command`) held: the model's `discrete_step`, linearised."""
        sc = self._scaled()
        h = sample_time / self.substeps

        def transition(z):
            y = sc.state(z)
            for i in range(self.substeps):
                y = self.model.discrete_step(t + i * h, y, command, h)
            return sc.vector(y)

        mean, jac = transition(state.mean), jax.jacfwd(transition)(state.mean)
        q = sc.vector(_named(self._template(), self.process_noise, "process_noise"))
        covariance = jac @ state.covariance @ jac.T + jnp.diag(q**2 * sample_time)
        return KalmanState(mean=mean, covariance=0.5 * (covariance + covariance.T))

    def update(self, state: KalmanState, readings, channels, noise):
        """Correct the belief with `readings` (m,) of the state fields `channels`, whose noise σ_R per channel the
        filter takes as `noise` (the callers choose it: `run_period` the filter's `measurement_noise`, or the sensors'
        own where that is None; `filter` its `noise` argument, or `measurement_noise` where that is None). A reading
        that is not finite (NaN: a dropped sample) is missing: that channel is not updated at that sample. Returns
        (belief, normalised innovation (y − h(z))/σ_R, 0 for a missing reading)."""
        sc = self._scaled()
        sigma = jnp.asarray(noise, dtype=float)

        def measure(z):
            named = sc.state(z)
            return jnp.stack([getattr(named, c) for c in channels]) / sigma

        predicted, h = measure(state.mean), jax.jacfwd(measure)(state.mean)
        # A NaN reading is a missing one (a dropped sample): its row of H and its innovation are 0, so its gain is 0
        # and the other channels update as without it (the readings made finite first: a NaN in the branch not taken
        # would still reach the gradient)
        present = jnp.isfinite(readings)
        h = jnp.where(present[:, None], h, 0.0)
        p = state.covariance
        s = h @ p @ h.T + jnp.eye(len(channels))
        gain = jnp.linalg.solve(s, h @ p).T  # P Hᵀ S⁻¹ (S, P symmetric)
        innovation = jnp.where(present, jnp.where(present, readings, 0.0) / sigma - predicted, 0.0)
        mean = state.mean + gain @ innovation
        joseph = jnp.eye(p.shape[0]) - gain @ h
        covariance = joseph @ p @ joseph.T + gain @ gain.T
        return KalmanState(mean=mean, covariance=0.5 * (covariance + covariance.T)), innovation

    # --- the loop's period and an offline run ----------------------------------------------------------------------
    def run_period(self, state: KalmanState, start, duty, previous_duty, period, readings, sensors):
        """One control period from `start` [s] with `duty` (the period before: `previous_duty`): predict and update
        at each of the sensors' N samples t_k + jT/N. `readings` (N, channels)."""
        signal = Step(previous_duty, duty, start)
        sample_time = period / sensors.samples_per_period
        noise = sensors.noise if self.measurement_noise is None else self.measurement_noise

        def body(belief, xs):
            j, y = xs
            t = start + j * sample_time
            belief = self.predict(belief, t, self.model.valve.read_command(signal, t), sample_time)
            belief, _ = self.update(belief, y, sensors.channels, noise)
            return belief, None

        state, _ = jax.lax.scan(body, state, (jnp.arange(readings.shape[0], dtype=float), readings))
        return state

    def filter(self, signal, readings, sample_time, channels, noise=None, *, t0=0.0, initial=None):
        """Filter a recording offline: `readings` (N, channels) of the state fields `channels` (a tuple of the
        model's state names) at t0 + k T_s (k = 1 … N, `sample_time` T_s > 0 [s]), the model driven by the command
        `signal` (a pamjax signal within the valve's `command_range`, read as the valve reads it). `noise` σ_R per
        channel (> 0, in the channel's unit): given, it is the one used, whatever `measurement_noise`; None
        (default): `measurement_noise`. A NaN reading is a missing one (a dropped sample): that channel is not
        updated at that sample, and the estimate's standard deviation grows over the gap. `initial`: the belief at
        t0 (a `KalmanState`, e.g. `initial_state(mean)`; default `initial_state()`). Returns (estimates: a named
        state with a leading axis of N, their standard deviations alike, the final `KalmanState`).

        **Raises:** `PamjaxInputError`, before filtering, for an unknown channel, a `noise` (or `measurement_noise`)
        not one value > 0 per channel or in another unit by its magnitude (`check_noise_scale`), a `sample_time` not
        one number > 0, a `t0` not finite, `readings` not (N, channels) with N >= 1, with an infinite value (its
        index named) or in another unit (gauge pressures, positions past the stroke), a `signal` `simulate` would
        refuse (not a signal, outside the valve's command range: a duty of 20-80 meant in percent), or an `initial`
        belief not of the model's shape, not finite or whose covariance is not symmetric positive semi-definite."""
        readings, channels, noise, belief = self._filter_inputs(signal, readings, sample_time, channels, noise, t0,
                                                                initial)

        def body(b, xs):
            k, y = xs
            t = t0 + k * sample_time
            b = self.predict(b, t, self.model.valve.read_command(signal, t), sample_time)
            b, _ = self.update(b, y, channels, noise)
            return b, (self.estimate(b), self.std(b))

        final, (means, stds) = jax.lax.scan(body, belief, (jnp.arange(readings.shape[0], dtype=float), readings))
        return means, stds, final

    def _filter_inputs(self, signal, readings, sample_time, channels, noise, t0, initial):
        """`filter`'s checks, in its arguments' order of importance: (readings, channels, noise, initial belief)."""
        where = "ExtendedKalmanFilter.filter"
        if noise is None and self.measurement_noise is None:
            raise PamjaxInputError(f"{where} needs `noise` (σ per channel) or measurement_noise")
        if not (isinstance(channels, (tuple, list)) and channels and all(isinstance(c, str) for c in channels)):
            raise PamjaxInputError(f"{where}: channels must be a non-empty tuple of state names, got {channels!r}")
        channels = tuple(channels)
        check_channels(self.model, channels, "estimator's model", name=f"{where}: channels")
        name = f"{where}: noise" if noise is not None else "ExtendedKalmanFilter.measurement_noise"
        noise = self.measurement_noise if noise is None else _floats(noise, name)
        check_noise_channels(noise, channels, name)
        check_positive(noise, name)
        check_noise_scale(self.model, dict(zip(channels, noise)), name)
        if not _one_number(sample_time):
            raise PamjaxInputError(f"{where}: sample_time must be one number T_s [s] (the readings' spacing), got "
                                   f"{sample_time!r}")
        check_positive(sample_time, f"{where}: sample_time")
        if not _one_number(t0):
            raise PamjaxInputError(f"{where}: t0 must be one time [s], got {t0!r}")
        check_finite(t0, f"{where}: t0")
        readings = _floats(readings, f"{where}: readings")
        if readings.ndim != 2 or readings.shape[1] != len(channels) or readings.shape[0] == 0:
            raise PamjaxInputError(
                f"{where}: readings must be (N, {len(channels)}) for channels {channels}, N >= 1, got "
                f"{readings.shape}")
        values = concrete_values(readings)
        if values is not None and np.any(np.isinf(values)):
            k, c = np.argwhere(np.isinf(values))[0]
            raise PamjaxInputError(f"{where}: readings[{k}, {c}] ({channels[c]}) is {values[k, c]}: a reading must be "
                                   "finite, or NaN where it is missing (a dropped sample, skipped)")
        sigma, strokes = concrete_values(noise), self.model.start_positions(self._template())
        for c, v, s in [] if values is None or sigma is None else zip(channels, values.T, sigma):
            v, stroke = v[np.isfinite(v)], strokes.get(c, (None, None))[1]
            if c in self.model.start_pressures(self._template()):  # gauge readings gave estimates 1 atm off
                check_absolute_pressure(v, f"{where}: channel {c!r} of readings")
            elif stroke is not None:  # mm readings gave x = 52 m, µm NaN; the end stops' give and 6 σ_R admitted
                lo, hi = (np.asarray(concrete_values(b), float) for b in stroke)  # NaN where traced: unchecked
                pad = START_STROKE_MARGIN * (hi - lo) + 6 * s
                if np.any((v < lo - pad) | (v > hi + pad)):
                    raise PamjaxInputError(f"{where}: channel {c!r} of readings spans [{v.min():.4g}, {v.max():.4g}] "
                                           f"m, past the stroke [{lo:.4g}, {hi:.4g}] m ± {pad:.2g}: metres, not mm, µm")
        try:  # simulate's checks of the signal against the model's valve (ts: the readings' times)
            validate(self.model, signal, t0 + sample_time * np.arange(1, readings.shape[0] + 1), t0=t0)
        except PamjaxInputError as err:
            raise PamjaxInputError(f"{where}: {err}") from None
        belief = self.initial_state() if initial is None else initial
        _check_belief(self._template(), belief, f"{where}: initial")
        return readings, channels, noise, belief


def check_channels(system, channels, what, name="LoopSensors.channels"):
    """Every sensor channel must be a state field of `system` (the plant, or the filter's model); `name` names the
    argument that holds them."""
    fields = _state_fields(jax.eval_shape(system.initial_state))
    missing = [c for c in channels if c not in fields]
    if missing:
        raise PamjaxInputError(f"{name} {missing} are not states of the {what} (its states: {fields})")


def check_noise_channels(noise, channels, name):
    """`noise` (σ_R per channel; None: not set, nothing to check) must hold one value per channel of `channels`: a
    single value was broadcast to every channel (2 kPa taken as the position's σ) and a longer one failed at run
    time. The shape is known even under jit, so this never waits for the values."""
    if noise is not None and jnp.shape(noise) != (len(channels),):
        raise PamjaxInputError(
            f"{name} must have one σ_R per sensor channel {tuple(channels)} (shape ({len(channels)},)), got shape "
            f"{jnp.shape(noise)}")


def _one_number(x):
    """Whether `x` is one real number (a Python or NumPy number, a 0-d array, a traced scalar; not a bool or a
    string)."""
    if isinstance(x, jax.core.Tracer):
        return x.ndim == 0
    if isinstance(x, (bool, np.bool_, str, bytes)):
        return False
    value = concrete_values(x)
    return value is not None and value.ndim == 0


def _broadcasts(shape, want):
    """Whether an array of `shape` broadcasts to `want` without changing it."""
    try:
        return np.broadcast_shapes(tuple(shape), tuple(want)) == tuple(want)
    except ValueError:
        return False


def _check_state_like(template, state, name):
    """`state` must be a state of the model whose shapes `template` has (its type, fields and shapes): a dict or
    another model's state failed with a raw pytree error."""
    ok = jtu.tree_structure(state) == jtu.tree_structure(template)
    if ok:
        ok = all(jnp.shape(a) == jnp.shape(b) for a, b in zip(jtu.tree_leaves(state), jtu.tree_leaves(template)))
    if not ok:
        raise PamjaxInputError(f"{name} must be a state of the filter's model (a {type(template).__name__} with "
                               f"fields {_state_fields(template)}, as model.initial_state() gives), got "
                               f"{type(state).__name__}")


def _check_belief(template, belief, name):
    """A belief the filter can start from: a `KalmanState` whose mean is (n,) and covariance (n, n) (n: the model's
    state size), finite, the covariance symmetric positive semi-definite (concrete values only). A covariance of
    another size failed with a raw TypeError, a negative-definite one gave estimates that meant nothing."""
    n = sum(int(np.prod(jnp.shape(x))) for x in jtu.tree_leaves(template))
    if not isinstance(belief, KalmanState):
        raise PamjaxInputError(f"{name} must be a KalmanState (e.g. the filter's initial_state(mean)), got "
                               f"{type(belief).__name__}")
    for field, want in (("mean", (n,)), ("covariance", (n, n))):
        shape = jnp.shape(getattr(belief, field))
        if shape != want:
            raise PamjaxInputError(f"{name}.{field} must have shape {want} (the model's {n} states, scaled: "
                                   f"initial_state(mean) makes it), got {shape}")
        check_finite(getattr(belief, field), f"{name}.{field}")
    p = concrete_values(belief.covariance)
    if p is None:
        return
    size = max(float(np.max(np.abs(p))), 1e-300)
    eigenvalues = np.linalg.eigvalsh(0.5 * (p + p.T))
    if np.max(np.abs(p - p.T)) > COVARIANCE_RTOL * size or eigenvalues.min() < -COVARIANCE_RTOL * size:
        raise PamjaxInputError(f"{name}.covariance must be symmetric positive semi-definite, its eigenvalues run "
                               f"from {eigenvalues.min():.3g} to {eigenvalues.max():.3g}")
