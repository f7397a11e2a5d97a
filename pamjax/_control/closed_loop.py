"""The sampled-data closed loop: plant, controller and position reference (and optionally noisy sensors and a state
estimator), run as a `lax.scan` over PWM periods with one solve of the plant per period, so the whole loop is
differentiable with respect to controller gains and plant parameters and vmaps over perturbed plants.

Per period the plant is solved adaptively (diffrax; a smooth plant: smoothed valve edges, smooth friction) or on the
fixed grid with events located inside the step (`pamjax._control.fixed_grid`: exact PWM edges, exact stick-slip),
which the loop chooses from the plant (`stepping="auto"`)."""

import dataclasses
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.custom_types import (
    Array,
    ArrayLike,
    Bool,
    Float,
    Int,
    PyTreeLike,
    RealScalar,
    RealScalarLike,
    Series,
    StateLike,
)
from .._core.errors import PamjaxInputError, PamjaxSolveError, check_count, check_in_closed_interval, check_positive
from .._core.fitting import parameter
from .._papers import paper000
from .._physics.signals import AbstractSignal, Step
from .._solve.checks import check_finite_state, check_parameters, check_positive_number, check_start_state, prepared
from .._solve.simulate import solve
from .._solve.trajectory import RESULT_NONFINITE, result_message
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from .controllers import MAX_PERIOD, AbstractController, reference_derivatives
from .estimator import ExtendedKalmanFilter, LoopSensors, check_channels, check_noise_channels, check_noise_scale
from .fixed_grid import period_on_grid

_DEFAULT_SUBSTEPS = 16  # RK4 nodes per period on the fixed grids: ≤ 1.25 ms at 50 Hz, as `simulate`'s PWM grid


class ClosedLoopState(eqx.Module):
    """State of the closed loop at a period start: `plant` (the plant's state, absolute pressure), `controller`
    (the controller's own state, e.g. the PI integrator [m s]), `duty`, the duty of the period before, `valve_open`
    whether a switching valve is open at the period start (its state carries across periods: after a period above
    ~90 % it is still open), and `estimator` the state estimator's belief (a `KalmanState`; None without one)."""

    plant: eqx.Module
    controller: PyTreeLike
    duty: StateLike = eqx.field(default_factory=lambda: jnp.zeros(()))
    valve_open: Bool[ArrayLike, "*batch"] = eqx.field(default_factory=lambda: jnp.zeros((), dtype=bool))
    estimator: PyTreeLike = None


def _check_plant(plant):
    if not (isinstance(plant, AbstractMuscleSystem) and plant.command_range == (0.0, 1.0)
            and {"position", "velocity", "pressure"} <= set(plant.output_names)):
        raise PamjaxInputError(
            "ClosedLoop.plant must be a muscle driven by a duty ratio through a valve (position, velocity and "
            f"pressure outputs, e.g. MuscleSystem), got {type(plant).__name__}"
        )


def _resolve_stepping(plant, stepping):
    """"auto": the fixed grid where an adaptive solve cannot go (exact edges or a hybrid plant), "pwm" for a switching
    valve and "grid" for a continuous one; else "adaptive" (diffrax per period, the smoothed plant)."""
    if stepping not in ("auto", "adaptive", "pwm", "grid"):
        raise PamjaxInputError(f"ClosedLoop.stepping must be 'auto', 'adaptive', 'pwm' or 'grid', got {stepping!r}")
    valve = plant.valve
    exact = plant.hybrid or valve.exact_edges
    if stepping == "auto":
        return ("pwm" if valve.switches else "grid") if exact else "adaptive"
    if stepping == "adaptive" and exact:
        raise PamjaxInputError(
            "ClosedLoop(stepping='adaptive') needs a smooth plant: smoothed valve edges (OnOffValve(mode='smooth'), "
            "presets.mas10_system('pwm')) and smooth friction; exact edges and stick-slip (KarnoppFriction) run on "
            "the fixed grid: stepping='auto' or 'pwm'"
        )
    if stepping == "pwm" and not valve.switches:
        raise PamjaxInputError(
            f"ClosedLoop(stepping='pwm') needs a switching valve, got {type(valve).__name__}; use 'grid' or 'auto'"
        )
    if stepping == "grid" and valve.switches:
        raise PamjaxInputError(
            "ClosedLoop(stepping='grid') is for continuous valves; a switching valve's fixed grid is 'pwm' (its edges "
            "are nodes of the grid)"
        )
    return stepping


class ClosedLoop(eqx.Module):
    """A muscle plant under sampled-data position control: plant, controller and position reference [m], and
    optionally noisy sensors with a state estimator between the plant and the controller.

    The controller runs once per PWM period T = 1/f of the plant's valve (1/50 s for paper 000's MHE2); an
    `AveragedValve` plant uses `period` [s] (default 0.02 s); with a switching valve a `period` other than its PWM
    period is refused, whatever the stepping (the valve latches one duty per PWM period). Without an estimator the
    controller reads the plant's true state at each period start; with one (`estimator`, e.g.
    `ExtendedKalmanFilter`) it reads the estimate, which the estimator forms from the `sensors`' noisy readings
    (default `LoopSensors()`: pressure and position at 1 kHz with the bench's 2 kPa and 0.1 mm noise).

    `stepping`: how each period's plant is solved. "auto" (default): "adaptive" (diffrax, `rtol`/`atol` of
    `simulate_closed_loop`) for a smooth plant (smoothed valve edges, smooth friction); the fixed grid with events
    located inside the step for a plant an adaptive solve cannot take: "pwm" for a switching valve (exact edges,
    whatever the valve's `mode`: the PWM-synchronous grid, `substeps` uniform RK4 nodes per period plus the two
    edges) and "grid" for a continuous one (`substeps` uniform RK4 steps), both with exact stick-slip
    (`KarnoppFriction`). So `presets.mas10_system(valve="pwm", friction="karnopp")`, the plant identification
    produces, runs with exact edges and stick-slip. "pwm" also runs a smoothed-valve plant with exact edges.
    """

    plant: AbstractSystem
    controller: AbstractController
    reference: AbstractSignal
    period: RealScalar = parameter(unit="s")  # set by __init__ (the valve's PWM period by default)
    estimator: ExtendedKalmanFilter | None
    sensors: LoopSensors | None
    stepping: str = eqx.field(static=True)
    substeps: int = eqx.field(static=True)

    def __init__(self, plant: AbstractSystem, controller: AbstractController, reference: AbstractSignal,
                 period: RealScalarLike | None = None, *, estimator: ExtendedKalmanFilter | None = None,
                 sensors: LoopSensors | None = None, stepping: Literal["auto", "adaptive", "pwm", "grid"] = "auto",
                 substeps: int = _DEFAULT_SUBSTEPS):
        _check_plant(plant)
        self.plant = plant
        self.controller = controller
        self.reference = reference
        if period is None:
            period = plant.valve.period if plant.valve.switches else 1.0 / paper000.PWM_FREQUENCY
        self.period = jnp.asarray(period, dtype=float)
        self.estimator = estimator
        self.sensors = LoopSensors() if (sensors is None and estimator is not None) else sensors
        self.stepping = _resolve_stepping(plant, stepping)
        self.substeps = substeps

    def __check_init__(self):
        if not isinstance(self.controller, AbstractController):
            raise PamjaxInputError(
                f"ClosedLoop.controller must be a pamjax controller, got {type(self.controller).__name__}"
            )
        if not isinstance(self.reference, AbstractSignal):
            raise PamjaxInputError(
                f"ClosedLoop.reference must be a pamjax signal (e.g. Sine), got {type(self.reference).__name__}"
            )
        if np.ndim(self.period) != 0:  # [0.02, 0.01] ran, its controller then blamed for giving several duties
            raise PamjaxInputError(f"ClosedLoop.period must be one number [s] (e.g. 0.02), got shape "
                                   f"{np.shape(self.period)}: one loop per period (several are a jax.vmap)")
        check_positive(self.period, "ClosedLoop.period")
        period = _concrete(self.period)
        if period is not None and period > MAX_PERIOD:
            raise PamjaxInputError(
                f"ClosedLoop.period is {period} s, longer than {MAX_PERIOD} s: that looks like milliseconds (a 20 ms "
                "period, paper 000's 50 Hz PWM, is written 0.02); the controller holds one duty per period [s]")
        self.controller.check_loop(self.plant, self.period)  # e.g. a PID's sensor noise against the stroke
        if not (isinstance(self.substeps, int) and self.substeps >= 2):
            raise PamjaxInputError(f"ClosedLoop.substeps must be an int >= 2 (RK4 nodes per period), got "
                                   f"{self.substeps!r}")
        if self.plant.valve.switches:  # whatever the stepping: the valve latches one duty per PWM period
            period, valve_period = _concrete(self.period), _concrete(self.plant.valve.period)
            if period is not None and valve_period is not None and not np.isclose(period, valve_period, rtol=1e-12):
                raise PamjaxInputError(
                    f"ClosedLoop.period ({period} s) must be the valve's PWM period ({valve_period} s) on the PWM "
                    "grid: a PWM controller sets one duty per period"
                )
        if self.estimator is not None and not isinstance(self.estimator, ExtendedKalmanFilter):
            raise PamjaxInputError(
                f"ClosedLoop.estimator must be a pamjax estimator (ExtendedKalmanFilter), got "
                f"{type(self.estimator).__name__}"
            )
        if self.sensors is not None:
            if not isinstance(self.sensors, LoopSensors):
                raise PamjaxInputError(f"ClosedLoop.sensors must be LoopSensors, got {type(self.sensors).__name__}")
            if self.estimator is None:
                raise PamjaxInputError(
                    "ClosedLoop.sensors need an estimator between them and the controller (e.g. "
                    "ExtendedKalmanFilter(model)); a controller with a noisy sensor of its own is PIDController("
                    "measurement_noise=...)"
                )
            check_channels(self.plant, self.sensors.channels, "plant")
            check_channels(self.estimator.model, self.sensors.channels, "estimator's model")
            check_noise_channels(self.estimator.measurement_noise, self.sensors.channels,
                                 "ExtendedKalmanFilter.measurement_noise")
            # in bar or mm by their magnitude (0.1 m of position noise on a 95 mm stroke was run)
            check_noise_scale(self.plant, dict(zip(self.sensors.channels, self.sensors.noise)), "LoopSensors.noise")
            if self.estimator.measurement_noise is not None:
                check_noise_scale(self.estimator.model, dict(zip(self.sensors.channels,
                                                                 self.estimator.measurement_noise)),
                                  "ExtendedKalmanFilter.measurement_noise")
            noise = self.sensors.noise
            if (self.estimator.measurement_noise is None and not isinstance(noise, jax.core.Tracer)
                    and not np.all(np.asarray(noise) > 0)):
                raise PamjaxInputError(
                    "ExtendedKalmanFilter.measurement_noise must be given (> 0) where the sensors are noise-free "
                    f"(LoopSensors.noise {noise})"
                )

    def initial_state(self, plant_state=None, estimate=None):
        """Plant at rest in equilibrium at atmospheric pressure, valve off (the bench's E5 start), controller reset;
        an estimator starts from `estimate` (a model state; default its model at rest) with its `initial_std`."""
        plant_state = self.plant.initial_state() if plant_state is None else plant_state
        belief = None if self.estimator is None else self.estimator.initial_state(estimate)
        return ClosedLoopState(plant=plant_state, controller=self.controller.initial_state(), duty=jnp.zeros(()),
                               valve_open=jnp.zeros((), dtype=bool), estimator=belief)

    def step(self, t, state, sample_offsets, *, rtol, atol, max_steps, adjoint=None):
        """One PWM period from `t`: the controller picks the duty from the plant's state (or its estimate), the plant
        runs with it held, the estimator takes the period's readings. Returns the next state, the duty and the
        samples: the plant's position, pressure and velocity at `t + sample_offsets` (the last offset is the period's
        end), what the controller read and the plant's true state at `t`."""
        reference = reference_derivatives(self.reference, t)
        observed = state.plant if self.estimator is None else self.estimator.estimate(state.estimator)
        duty, controller_state = self.controller.update(t, reference, observed, state.controller, self.period)
        sensor_offsets = jnp.zeros((0,)) if self.sensors is None else self.sensors.offsets(self.period)
        offsets = jnp.concatenate([sample_offsets, sensor_offsets])
        n = sample_offsets.shape[0]
        valve = self.plant.valve
        if self.stepping == "adaptive":
            order = jnp.argsort(offsets)  # diffrax saves at non-decreasing times
            # this period's duty from t, the last period's before it: a switching valve latches both (`read_command`)
            # num_periods=1: a smoothed valve's edges get step boundaries of their own
            traj = solve(self.plant, Step(state.duty, duty, t), t + offsets[order], state.plant, t, rtol=rtol,
                         atol=atol, max_steps=max_steps, adjoint=adjoint, starts_off=False, num_periods=1)
            states = jtu.tree_map(lambda a: a[jnp.argsort(order)], traj.state)
            result = traj.result
        else:
            states, finite = period_on_grid(self.plant, duty, state.valve_open, state.plant, t, self.period,
                                            t + offsets, stepping=self.stepping, substeps=self.substeps)
            result = jnp.where(finite, 0, RESULT_NONFINITE)
        samples = jtu.tree_map(lambda a: a[:n], states)
        plant_state = jtu.tree_map(lambda a: a[n - 1], states)  # the period's end
        valve_open = valve.open_at_period_end(duty, state.valve_open) if valve.switches else state.valve_open
        belief = state.estimator
        if self.estimator is not None:
            k = jnp.round(t / self.period).astype(jnp.int32)
            readings = self.sensors.read(jtu.tree_map(lambda a: a[n:], states), k)
            belief = self.estimator.run_period(belief, t, duty, state.duty, self.period, readings, self.sensors)
        out = dict(position=samples.position, pressure=samples.pressure, velocity=samples.velocity, result=result,
                   observed=observed, start=state.plant)
        next_state = ClosedLoopState(plant=plant_state, controller=controller_state, duty=duty, valve_open=valve_open,
                                     estimator=belief)
        return next_state, duty, out


def _concrete(x):
    try:
        return float(x)
    except (TypeError, jax.errors.ConcretizationTypeError):
        return None


class ClosedLoopTrajectory(eqx.Module):
    """Result of `simulate_closed_loop`: `t` [s], `position` [m], `reference` [m], `pressure` [Pa abs], `velocity`
    [m/s] at the sample times; `period_start` [s] and `duty` [-] per PWM period; `final` the last `ClosedLoopState`;
    `result` 0 where every period's solve succeeded. Per period also `observed`, the plant state the controller read
    at the period start (the true state, or the estimator's estimate), and `period_start_state`, the plant's true
    state there (named states with a leading axis of periods)."""

    t: Series
    position: Series
    reference: Series
    pressure: Series
    velocity: Series
    period_start: Float[Array, " periods"]
    duty: Float[Array, " periods"]
    final: ClosedLoopState
    result: Int[Array, ""]
    observed: eqx.Module | None = None
    period_start_state: eqx.Module | None = None

    def estimation_error(self, start=0.0):
        """RMS of (what the controller read − the true state) at the period starts t ≥ `start` [s], per state:
        {"pressure" [Pa], "position" [m], "velocity" [m/s]} (zeros without an estimator; traceable).

        **Raises:** `PamjaxInputError` where `start` and the run are concrete and no period starts at or after
        `start` (an empty window: the RMS would be 0/0 = NaN)."""
        check_window(start, self.period_start, self.t, "estimation_error", "its last period starts")
        weight = window_weight(self.period_start, start)
        return {name: jnp.sqrt(jnp.sum(weight * (getattr(self.observed, name) - getattr(self.period_start_state, name))
                                       ** 2) / jnp.sum(weight))
                for name in ("pressure", "position", "velocity")}

    def tracking_error(self, start=0.0):
        """(RMSE, peak |e|) [m] of e = r − x over samples with t ≥ `start` [s] (traceable; a sample on `start` to
        round-off is in the window: `window_weight`).

        **Raises:** `PamjaxInputError` where `start` and the run are concrete and `start` is at or after the run's end
        (an empty window: the RMSE would be 0/0 = NaN and the peak 0)."""
        check_window(start, self.t, self.t, "tracking_error", "its last sample is")
        weight = window_weight(self.t, start)
        error = (self.reference - self.position) * weight
        rmse = jnp.sqrt(jnp.sum(error**2) / jnp.sum(weight))
        return rmse, jnp.max(jnp.abs(error))


# A time counts as in the window t ≥ start from this fraction of a sample interval before `start`. The sample times
# are period starts plus offsets, a sum XLA fuses into an FMA in one program and not in another (0.18 + 0.02 =
# 0.19999999999999998, fused 0.2): the sample on start = 0.2 s was in the value's window and not in the reverse-mode
# gradient's (tune_controller's gradient 0.29 % off forward mode at 25 periods of 20 ms). Round-off is ~1e-16 of t.
WINDOW_TOLERANCE = 1e-6


def window_weight(times, start):
    """1.0 where `times` [s] (increasing) are at or after `start` [s], else 0.0, a time within `WINDOW_TOLERANCE` of
    the mean sample interval before `start` counted as on it: every program that computes the times (forward, reverse
    mode, fused or not) then makes the same window. Traceable."""
    times = jnp.asarray(times)
    n = times.shape[0]
    interval = (times[-1] - times[0]) / (n - 1) if n > 1 else jnp.abs(times[0])
    return (times >= start - WINDOW_TOLERANCE * interval).astype(float)


def check_window(start, times, samples, method, last_is):
    """Refuse a window start `start` [s] after every time of `times` (the times the window averages over; `last_is`
    names the last of them) or at or after the run's end (the last of `samples`), where both are concrete: the window
    would be empty and the RMS 0/0 = NaN. Inside jit, grad or vmap they are traced and the check is left to the caller
    (`tune_controller` checks its `start` before solving). Shared by the closed loops' trajectories
    (`ClosedLoopTrajectory`, `JointControlTrajectory`)."""
    if isinstance(start, jax.core.Tracer) or isinstance(times, jax.core.Tracer) or np.size(times) == 0:
        return
    start_value = _concrete(start)
    if start_value is None:
        return
    last, end = float(np.max(np.asarray(times))), float(np.max(np.asarray(samples)))
    if not (start_value <= last and start_value < end):  # also refuses a NaN start
        raise PamjaxInputError(
            f"{method}: start = {start_value} s leaves an empty window: the run ends at {end} s ({last_is} at "
            f"{last} s); give a start before that, or run longer"
        )


def check_solver_settings(rtol, atol, max_steps, steps="solver steps per period"):
    """`rtol` and `atol` finite numbers > 0 and `max_steps` an int >= 1 (`steps`: what it counts), as `simulate`
    refuses them: a tolerance of 0 or a step budget of 0 failed every period's solve (inf positions, `result` 1), a
    negative `rtol` ran silently. `simulate_closed_loop`'s check, and `simulate_joint_control`'s."""
    for name, value in (("rtol", rtol), ("atol", atol)):
        check_positive_number(value, name)
    check_count(max_steps, "max_steps", f"an int >= 1 ({steps})")


def _run(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps, adjoint=None):
    period = loop.period
    offsets = period * jnp.arange(1, samples_per_period + 1) / samples_per_period
    state = loop.initial_state() if y0 is None else y0

    # Period starts are computed outside the loop: inside, XLA may fuse k·T + offset into an FMA in one place and not
    # another, and diffrax's check that the save times lie in [t0, t1] then fails by one rounding.
    starts = period * jnp.arange(num_periods, dtype=float)

    def body(state, t):
        state, duty, samples = loop.step(t, state, offsets, rtol=rtol, atol=atol, max_steps=max_steps,
                                         adjoint=adjoint)
        return state, (t, duty, samples)

    final, (starts, duties, samples) = jax.lax.scan(body, state, starts)
    t = (starts[:, None] + offsets[None, :]).reshape(-1)
    flat = {k: samples[k].reshape(-1) for k in ("position", "pressure", "velocity")}
    return ClosedLoopTrajectory(
        t=t,
        position=flat["position"],
        reference=jax.vmap(loop.reference)(t),
        pressure=flat["pressure"],
        velocity=flat["velocity"],
        period_start=starts,
        duty=duties,
        final=final,
        result=jnp.max(jnp.abs(samples["result"])),
        observed=samples["observed"],
        period_start_state=samples["start"],
    )


def run_closed_loop(loop: ClosedLoop, num_periods: int, samples_per_period: int = 10, y0: ClosedLoopState | None = None,
                    rtol: RealScalarLike = 1e-6, atol: RealScalarLike = 1e-6,
                    max_steps: int = 2000, adjoint: str | None = None) -> ClosedLoopTrajectory:
    """The unchecked, traceable core of `simulate_closed_loop` (for use inside grad / vmap); `adjoint` as for
    `simulate` (reverse mode by default; `simulate_closed_loop`, whose result nothing differentiates, asks for
    forward mode: diffrax's plain loop, the lighter trace)."""
    return _run(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps, adjoint)


_run_jit = eqx.filter_jit(_run)


def simulate_closed_loop(
    loop: ClosedLoop,
    duration: RealScalarLike,
    *,
    samples_per_period: int = 10,
    y0: ClosedLoopState | None = None,
    rtol: RealScalarLike = 1e-6,
    atol: RealScalarLike = 1e-6,
    max_steps: int = 2000,
    throw: bool = True,
) -> ClosedLoopTrajectory:
    """Simulate a sampled-data closed loop for `duration` [s] (rounded up to whole PWM periods).

    Each PWM period the controller reads the plant state (or the estimator's estimate of it) and the reference at
    the period start and sets the duty, which the plant holds for the period (one solve of the plant per period,
    `lax.scan` over periods: diffrax for a smooth plant, the fixed grid with exact edges and stick-slip events for the
    identified plant, `ClosedLoop.stepping`). Differentiable with respect to controller gains and plant parameters
    (use `run_closed_loop` inside `jax.grad` / `eqx.filter_vmap`).

    **Arguments:** `loop` a `ClosedLoop`; `duration` [s]; `samples_per_period` output samples per period (10: 2 ms
    at 50 Hz, the position ripple resolved); `y0` initial `ClosedLoopState` (default: plant at rest in equilibrium
    at atmospheric pressure, valve off; another plant state: `loop.initial_state(plant_state=...)`); `rtol`, `atol`
    as for `simulate` (scaled states) and `max_steps` per period, for adaptive stepping (the fixed grid's size is
    `ClosedLoop.substeps`); `throw`: raise `PamjaxSolveError` where a period's solve fails (default), as `simulate`
    does; with `throw=False` the trajectory comes back with `result` non-zero and non-finite samples from there.

    **Raises:** `PamjaxInputError`, before any solve, for what `simulate` refuses in the plant or a start state
    (parameters set with `eqx.tree_at`, such as `payload_mass` ≤ 0, are checked as the constructors check them, the
    controller's duty limits too; `y0.plant`'s pressures ABSOLUTE pascal, its position in metres inside the stroke,
    every leaf finite), a `y0` that is no `ClosedLoopState`, a controller whose duty is not one number, a reference
    outside the muscle's stroke, a bad duration, `rtol` or `atol` not a finite number > 0 or `max_steps` not an int
    >= 1; `PamjaxSolveError` where a period's solve fails and `throw` is True.
    """
    loop = checked_loop(loop, y0)
    check_solver_settings(rtol, atol, max_steps)
    duration = float(check_positive_number(duration, "duration"))
    if not (isinstance(samples_per_period, int) and samples_per_period >= 1):
        raise PamjaxInputError(f"samples_per_period must be a positive int, got {samples_per_period!r}")
    num_periods = int(np.ceil(duration / float(loop.period) - 1e-9))
    traj = _run_jit(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps, "forward")
    if throw and not isinstance(traj.result, jax.core.Tracer) and int(traj.result) != 0:
        raise PamjaxSolveError(_failure(loop, traj, max_steps))
    return traj


def checked_loop(loop: ClosedLoop, y0: ClosedLoopState | None = None) -> ClosedLoop:
    """`loop` checked as `simulate_closed_loop` and `tune_controller` check it before any solve, `prepared` (a float
    set with eqx.tree_at as an array: checked, and no constant of the program): its components' parameters (which
    eqx.tree_at skipped), its reference inside the muscle's stroke (a reference in mm, or 0.5 m, was tuned on
    silently: an RMSE of metres, a zero gradient), `y0` a `ClosedLoopState` whose plant state passes `simulate`'s
    start-state checks (named "y0.plant...") and whose other leaves are finite, and the controller's duty one number
    (`jax.eval_shape` of its update: tracing only, nothing compiled), else the solve failed deep inside JAX (a gain
    of two values: "incompatible shapes"). Raises `PamjaxInputError`."""
    if not isinstance(loop, ClosedLoop):
        raise PamjaxInputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    loop, _ = prepared(loop)
    check_parameters(loop, "loop")
    lo, hi = loop.reference.bounds()
    x_min, x_max = float(loop.plant.muscle.min_position), float(loop.plant.muscle.max_position)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo >= x_min and hi <= x_max):
        raise PamjaxInputError(
            f"reference must stay inside the muscle's stroke [{x_min}, {x_max}] m, but spans [{lo}, {hi}] m")
    if y0 is not None:
        if not isinstance(y0, ClosedLoopState):
            raise PamjaxInputError(
                f"y0 must be a ClosedLoopState (plant, controller, duty, ...), got {type(y0).__name__}: start the loop "
                "from a plant state with y0=loop.initial_state(plant_state=...)")
        check_start_state(loop.plant, y0.plant, "y0.plant")
        check_finite_state(y0.controller, "y0.controller")
        check_finite_state(y0.duty, "y0.duty")
        check_finite_state(y0.estimator, "y0.estimator")
        check_in_closed_interval(y0.duty, 0.0, 1.0, "y0.duty (the duty of the period before the start)")

    def duty(lp, y):
        state = lp.initial_state() if y is None else y
        observed = state.plant if lp.estimator is None else lp.estimator.estimate(state.estimator)
        t = jnp.zeros(())
        return lp.controller.update(t, reference_derivatives(lp.reference, t), observed, state.controller,
                                    lp.period)[0]

    several = [f"{f.name} (shape {np.shape(leaf)})" for f in dataclasses.fields(loop.controller)
               if eqx.is_array(leaf := getattr(loop.controller, f.name)) and np.ndim(leaf) > 0]
    try:
        shape = jax.eval_shape(duty, loop, y0).shape
    except (TypeError, ValueError):
        if not several:
            raise
        shape = None
    if shape != ():
        raise PamjaxInputError(
            f"ClosedLoop.controller ({type(loop.controller).__name__}) must give one duty per period, "
            + (f"its parameters {', '.join(several)} hold several values: give one value each"
               if several else f"it gives shape {shape}")
            + " (a batch of controllers is jax.vmap over pamjax.unchecked.run_closed_loop)")
    return loop


def _failure(loop, traj, max_steps):
    """The message of a failed closed-loop solve: the first period whose samples are not finite, the cause, the fix."""
    code = int(traj.result)
    bad = ~np.isfinite(np.asarray(traj.position).reshape(len(np.asarray(traj.period_start)), -1)).all(axis=1)
    when = (f"in the period starting at t = {float(np.asarray(traj.period_start)[int(np.argmax(bad))]):.6g} s"
            if bad.any() else "in a period")
    fix = (f"Raise max_steps (now {max_steps} solver steps per period) or loosen rtol/atol"
           if loop.stepping == "adaptive" else f"Raise ClosedLoop(substeps=...) (now {loop.substeps} per period)")
    cause = result_message(code).split(" Try increasing")[0].rstrip(".")  # the fix follows
    return (f"simulate_closed_loop: the plant's solve failed {when}: {cause} (result code {code}). "
            f"{fix}, or check the plant's parameters and start state. (throw=False returns the trajectory with its "
            "status instead: its samples are not finite from there.)")
