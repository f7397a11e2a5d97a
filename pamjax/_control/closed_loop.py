"""The sampled-data closed loop: plant, controller and position reference, run as a `lax.scan` over PWM periods,
one diffrax solve of the plant per period, so the whole loop is differentiable with respect to controller gains and
plant parameters and vmaps over perturbed plants."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.errors import PamjaxInputError, check_positive
from .._papers import paper000
from .._physics.signals import AbstractSignal, Step
from .._solve.simulate import solve
from .._systems.base import AbstractSystem
from .controllers import AbstractController, reference_derivatives


class ClosedLoopState(eqx.Module):
    """State of the closed loop at a period start: `plant` (the plant's state, absolute pressure), `controller`
    (the controller's own state, e.g. the PI integrator [m s]) and `duty`, the duty of the period before (a PWM
    valve's state carries across periods: after a period above ~90 % it is still open)."""

    plant: eqx.Module
    controller: object
    duty: jax.Array = eqx.field(default_factory=lambda: jnp.zeros(()))


class ClosedLoop(eqx.Module):
    """A muscle plant under sampled-data position control: plant, controller and position reference [m].

    The controller runs once per PWM period T = 1/f of the plant's valve (1/50 s for paper 000's MHE2); an
    `AveragedValve` plant uses `period` [s] (default 0.02 s).
    """

    plant: AbstractSystem
    controller: AbstractController
    reference: AbstractSignal
    period: jax.Array  # s

    def __init__(self, plant, controller, reference, period=None):
        self.plant = plant
        self.controller = controller
        self.reference = reference
        if period is None:
            period = plant.valve.period if plant.valve.switches else 1.0 / paper000.PWM_FREQUENCY
        self.period = jnp.asarray(period, dtype=float)

    def __check_init__(self):
        plant = self.plant
        if not (isinstance(plant, AbstractSystem) and hasattr(plant, "muscle") and plant.command_range == (0.0, 1.0)
                and {"position", "velocity", "pressure"} <= set(plant.output_names)):
            raise PamjaxInputError(
                "ClosedLoop.plant must be a muscle driven by a duty ratio through a valve (position, velocity and "
                f"pressure outputs, e.g. MuscleSystem), got {type(plant).__name__}"
            )
        if not isinstance(self.controller, AbstractController):
            raise PamjaxInputError(
                f"ClosedLoop.controller must be a pamjax controller, got {type(self.controller).__name__}"
            )
        if not isinstance(self.reference, AbstractSignal):
            raise PamjaxInputError(
                f"ClosedLoop.reference must be a pamjax signal (e.g. Sine), got {type(self.reference).__name__}"
            )
        if self.plant.valve.exact_edges:
            raise PamjaxInputError(
                "ClosedLoop needs a differentiable plant: use OnOffValve(mode='smooth') (presets.mas10_system('pwm'))"
            )
        check_positive(self.period, "ClosedLoop.period")

    def initial_state(self, plant_state=None):
        """Plant at rest in equilibrium at atmospheric pressure, valve off (the bench's E5 start), controller reset."""
        plant_state = self.plant.initial_state() if plant_state is None else plant_state
        return ClosedLoopState(plant=plant_state, controller=self.controller.initial_state(), duty=jnp.zeros(()))

    def step(self, t, state, sample_offsets, *, rtol, atol, max_steps):
        """One PWM period from `t`: the controller picks the duty, the plant runs with it held. Returns the next state
        and the plant's position and pressure at `t + sample_offsets` and the duty."""
        reference = reference_derivatives(self.reference, t)
        duty, controller_state = self.controller.update(t, reference, state.plant, state.controller, self.period)
        times = t + sample_offsets
        # this period's duty from t, the last period's before it: a switching valve latches both (`read_command`)
        traj = solve(
            self.plant,
            Step(state.duty, duty, t),
            times,
            state.plant,
            t,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            starts_off=False,
            num_periods=1,  # a smoothed valve's edges get step boundaries of their own
        )
        plant_state = jtu.tree_map(lambda a: a[-1], traj.state)
        samples = dict(position=traj.position, pressure=traj.pressure, velocity=traj.velocity, result=traj.result)
        return ClosedLoopState(plant=plant_state, controller=controller_state, duty=duty), duty, samples


class ClosedLoopTrajectory(eqx.Module):
    """Result of `simulate_closed_loop`: `t` [s], `position` [m], `reference` [m], `pressure` [Pa abs], `velocity`
    [m/s] at the sample times; `period_start` [s] and `duty` [-] per PWM period; `final` the last `ClosedLoopState`;
    `result` 0 where every period's solve succeeded."""

    t: jax.Array
    position: jax.Array
    reference: jax.Array
    pressure: jax.Array
    velocity: jax.Array
    period_start: jax.Array
    duty: jax.Array
    final: ClosedLoopState
    result: jax.Array

    def tracking_error(self, start=0.0):
        """(RMSE, peak |e|) [m] of e = r − x over samples with t ≥ `start` [s] (traceable)."""
        weight = (self.t >= start).astype(float)
        error = (self.reference - self.position) * weight
        rmse = jnp.sqrt(jnp.sum(error**2) / jnp.sum(weight))
        return rmse, jnp.max(jnp.abs(error))


def _run(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps):
    period = loop.period
    offsets = period * jnp.arange(1, samples_per_period + 1) / samples_per_period
    state = loop.initial_state() if y0 is None else y0

    # Period starts are computed outside the loop: inside, XLA may fuse k·T + offset into an FMA in one place and not
    # another, and diffrax's check that the save times lie in [t0, t1] then fails by one rounding.
    starts = period * jnp.arange(num_periods, dtype=float)

    def body(state, t):
        state, duty, samples = loop.step(t, state, offsets, rtol=rtol, atol=atol, max_steps=max_steps)
        return state, (t, duty, samples)

    final, (starts, duties, samples) = jax.lax.scan(body, state, starts)
    t = (starts[:, None] + offsets[None, :]).reshape(-1)
    flat = {k: v.reshape(-1) for k, v in samples.items() if k != "result"}
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
    )


def run_closed_loop(loop, num_periods, samples_per_period=10, y0=None, rtol=1e-6, atol=1e-6, max_steps=2000):
    """The unchecked, traceable core of `simulate_closed_loop` (for use inside grad / vmap)."""
    return _run(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps)


_run_jit = eqx.filter_jit(_run)


def simulate_closed_loop(
    loop: ClosedLoop,
    duration,
    *,
    samples_per_period: int = 10,
    y0: ClosedLoopState | None = None,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    max_steps: int = 2000,
) -> ClosedLoopTrajectory:
    """Simulate a sampled-data closed loop for `duration` [s] (rounded up to whole PWM periods).

    Each PWM period the controller reads the plant state and the reference at the period start and sets the duty,
    which the plant holds for the period (one diffrax solve of the plant per period, `lax.scan` over periods).
    Differentiable with respect to controller gains and plant parameters (use `run_closed_loop` inside `jax.grad` /
    `eqx.filter_vmap`).

    **Arguments:** `loop` a `ClosedLoop`; `duration` [s]; `samples_per_period` output samples per period (10: 2 ms
    at 50 Hz, the position ripple resolved); `y0` initial `ClosedLoopState` (default: plant at rest in equilibrium
    at atmospheric pressure, valve off); `rtol`, `atol` as for `simulate` (scaled states); `max_steps` per period.

    **Raises:** `PamjaxInputError` for a reference outside the muscle's stroke or a bad duration, before any solve.
    """
    if not isinstance(loop, ClosedLoop):
        raise PamjaxInputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    duration = float(duration)
    if not np.isfinite(duration) or duration <= 0:
        raise PamjaxInputError(f"duration must be > 0 [s], got {duration}")
    if not (isinstance(samples_per_period, int) and samples_per_period >= 1):
        raise PamjaxInputError(f"samples_per_period must be a positive int, got {samples_per_period!r}")
    lo, hi = loop.reference.bounds()
    x_min, x_max = float(loop.plant.muscle.min_position), float(loop.plant.muscle.max_position)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo >= x_min and hi <= x_max):
        raise PamjaxInputError(
            f"reference must stay inside the muscle's stroke [{x_min}, {x_max}] m, but spans [{lo}, {hi}] m"
        )
    num_periods = int(np.ceil(duration / float(loop.period) - 1e-9))
    return _run_jit(loop, num_periods, samples_per_period, y0, rtol, atol, max_steps)
