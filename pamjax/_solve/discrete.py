"""Paper 000's discrete-time model (eq. 17-21): the plant stepped by explicit Euler at a sample time T_s.

State (eq. 17): x = [p, x, ẋ, ẍ] (pressure [Pa abs], position [m], velocity [m/s], acceleration [m/s²]).

    p_{k+1}  = p_k + T_s ṗ(t_k, x_k, u_k)              (eq. 18: eq. 15 at step k)
    ẋ_{k+1}  = ẋ_k + T_s ẍ(t_k, x_k, u_k)              (eq. 20: eq. 16 at step k)
    x_{k+1}  = x_k + T_s ẋ_{k+1}                        (eq. 19: the NEW velocity, semi-implicit Euler)
    ẍ_{k+1}  = (ẋ_{k+1} − ẋ_k) / T_s                   (eq. 21)

The rates come from the system's own vector field (the same valve flow, muscle force, friction, end stops and volume
as the continuous model), so the discrete model converges to `simulate` as T_s → 0 with error O(T_s). A friction
model with its own state (bristle) is stepped by explicit Euler too. For a `TankSystem` only eq. 18 applies.
A switching valve acts on the pair (u_k, u_{k-1}) of this PWM period's duty and the last one's (`read_command`: a
period above 90 % duty, whose off-pulse at 50 Hz is shorter than the 2 ms switch-off delay, leaves it open), the
period before t0 off, exactly as in `simulate`. A hybrid system (stick-slip, `KarnoppFriction`) is refused: Euler
steps cannot switch its mode.
Explicit Euler is stable only for T_s below ~2/(fastest rate): with the smooth Coulomb sign (16 N over 1e-3 m/s on
9.6 kg) that is ≈ 1 ms; paper 000 samples at 0.1 ms.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import floats_as_arrays
from .._core.custom_types import Array, ArrayLike, PyTreeLike, Real, RealScalarLike, Series
from .._core.errors import PamjaxInputError, PamjaxSolveError, check_positive, concrete_values
from .._physics.signals import AbstractSignal
from .._systems.base import AbstractSystem
from .edges import StartsOff
from .simulate import validate


class DiscreteTrajectory(eqx.Module):
    """Result of `simulate_discrete` at the sample times t_k = t0 + k T_s.

    `t` [s], `state` (the state pytree per sample), `command`, `pressure` [Pa abs], `mass_flow` [kg/s into the
    chamber]; for muscle systems also `position` [m], `velocity` [m/s], `acceleration` [m/s²] (eq. 21; 0 at k = 0),
    `force` [N] (muscle); None for a tank.
    """

    t: Series
    state: PyTreeLike
    command: Real[Array, " times *command"]
    pressure: Series
    mass_flow: Series
    position: Series | None
    velocity: Series | None
    acceleration: Series | None
    force: Series | None


def discrete_step(system: AbstractSystem, t: RealScalarLike, state: eqx.Module, command: Real[ArrayLike, "*command"],
                  sample_time: RealScalarLike) -> eqx.Module:
    """One step of eq. 18-21 from `state` at time `t` [s] with `command` held over [t, t + T_s]: the system's own
    discrete-time model (`system.discrete_step`: eq. 18-20 for a muscle, eq. 18 for a tank)."""
    return system.discrete_step(t, state, command, sample_time)


@eqx.filter_jit
def _run(system, signal, y0, t0, sample_time, num_steps: int):
    valve = system.valve
    if valve.switches:  # the valve is off in the PWM period before the run, as in `simulate` and the EKF's `filter`
        signal = StartsOff(signal, valve.command_time(t0))

    def acts_on(t):  # what the valve acts on at t: a switching valve's (u_k, u_{k-1}), its state carries over
        return valve.read_command(signal, t)

    def body(state, k):
        t = t0 + k * sample_time
        new = discrete_step(system, t, state, acts_on(t), sample_time)
        return new, new

    _, states = jax.lax.scan(body, y0, jnp.arange(num_steps, dtype=float))
    states = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), y0, states)
    ts = t0 + jnp.arange(num_steps + 1, dtype=float) * sample_time
    commands = jax.vmap(lambda t: signal(valve.command_time(t)))(ts)  # the latched duty, as `simulate`'s `command`
    outs = jax.vmap(lambda t, y: system.outputs(t, y, acts_on(t)))(ts, states)
    acceleration = None
    if "velocity" in outs:  # eq. 21
        acceleration = jnp.concatenate([jnp.zeros(1), jnp.diff(outs["velocity"]) / sample_time])
    return DiscreteTrajectory(
        t=ts,
        state=states,
        command=commands,
        pressure=outs["pressure"],
        mass_flow=outs["mass_flow"],
        position=outs.get("position"),
        velocity=outs.get("velocity"),
        acceleration=acceleration,
        force=outs.get("force"),
    )


def simulate_discrete(system: AbstractSystem, signal: AbstractSignal, sample_time: RealScalarLike,
                      t_end: RealScalarLike, *, y0: eqx.Module | None = None,
                      t0: RealScalarLike = 0.0) -> DiscreteTrajectory:
    """Paper 000's discrete-time model (eq. 18-21): step `system` by Euler at `sample_time` T_s [s] from `t0` to
    `t_end` [s] (⌈(t_end − t0)/T_s⌉ steps, the last sample at or just past `t_end`).

    **Arguments:** `system` (a smooth `MuscleSystem` or a `TankSystem`), `signal` (the command, read at each t_k as
    the valve reads it: a switching valve acts on this period's and the last period's duty, off in the period before
    `t0`, as in `simulate`), `sample_time` T_s [s] > 0, `t_end` [s] > `t0`, `y0` (default `system.initial_state()`),
    `t0` [s].

    **Returns:** a `DiscreteTrajectory`. Differentiable (reverse and forward mode) and jitted.

    **Raises:** `PamjaxInputError` for bad input, naming the argument (a `sample_time` longer than the run
    included), and for a hybrid `system` (stick-slip friction, `KarnoppFriction`): Euler steps cannot switch its
    mode (use `simulate`); `PamjaxSolveError` when a concrete run diverges (Euler above its stability limit).
    """
    # A hybrid system's Euler steps never evaluate the events that switch its mode: stuck for ever, silently.
    if isinstance(system, AbstractSystem) and system.hybrid:
        raise PamjaxInputError(
            "simulate_discrete: system must be smooth, not hybrid: the discrete-time model (eq. 18-21) steps by Euler "
            "and cannot switch a stick-slip mode (a payload stuck at the start would stay stuck); give the system "
            "CoulombViscousFriction (eq. 20's sign smoothed), e.g. presets.mas10_system('averaged'), or solve the "
            "hybrid system with pamjax.simulate (events located inside the step)"
        )
    sample_time, t_end, t0 = (_number(v, name) for v, name in ((sample_time, "sample_time"), (t_end, "t_end"),
                                                                  (t0, "t0")))
    check_positive(sample_time, "sample_time")
    check_positive(float(t_end) - float(t0), "t_end - t0")
    if float(sample_time) > float(t_end) - float(t0):  # one step far past t_end (1 s for a 10 ms run): a unit slip
        raise PamjaxInputError(f"sample_time ({sample_time} s) must not exceed the run, t_end - t0 = "
                               f"{float(t_end) - float(t0):g} s (paper 000 samples at 1e-4 s: seconds, not ms)")
    num_steps = int(np.ceil((float(t_end) - float(t0)) / float(sample_time) - 1e-9))
    if num_steps > 50_000_000:
        raise PamjaxInputError(f"sample_time {sample_time} gives {num_steps} steps up to t_end; use a larger one")
    system = floats_as_arrays(system)  # a value set with eqx.tree_at: an argument, not a constant of the program
    validate(system, signal, np.array([float(t0), float(t0) + num_steps * float(sample_time)]), y0, None)
    # as `simulate` takes it: a plain float leaf (MuscleState(3e5, 0.0, 0.0)) was a raw TypeError in the scan
    y0 = system.initial_state() if y0 is None else jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype=float), y0)
    traj = _run(system, signal, y0, jnp.asarray(t0, dtype=float), jnp.asarray(sample_time, dtype=float), num_steps)
    _check_stable(traj, sample_time)
    return traj


def _number(value, name):
    """`value` [s] as a float where it is one concrete real number, else `PamjaxInputError` naming `name` (it sets the
    number of steps: sample_time=[1e-4] was a raw TypeError from float())."""
    number = (isinstance(value, (int, float, np.ndarray, np.generic, jax.Array))
              and not isinstance(value, (bool, np.bool_, jax.core.Tracer)))
    v = np.asarray(value, dtype=float) if number else None
    if v is None or v.ndim != 0:
        raise PamjaxInputError(f"{name} must be one number [s], concrete (it sets the number of steps), got "
                               f"{value!r}")
    return float(v)


def _check_stable(traj, sample_time):
    """A concrete run whose Euler steps diverged (a state not finite, an absolute pressure <= 0) raises
    `PamjaxSolveError` naming the first such sample and the remedy; it returned NaN and negative pressures silently
    (T_s = 0.1 s, the paper's 0.1 ms typed as ms: NaN after a few steps)."""
    pressure = concrete_values(traj.pressure)
    leaves = [concrete_values(leaf) for leaf in jax.tree_util.tree_leaves(traj.state)]
    if pressure is None or any(v is None for v in leaves):
        return  # traced (under jit, grad, vmap): nothing to check on the host
    bad = ~(pressure > 0)
    for v in leaves:
        bad = bad | ~np.isfinite(v.reshape(v.shape[0], -1)).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise PamjaxSolveError(
            f"simulate_discrete diverged at t = {float(traj.t[k]):.6g} s (step {k}: a state not finite or an absolute "
            f"pressure <= 0): explicit Euler at sample_time = {float(sample_time):g} s is above its stability limit "
            "(about 2 / the fastest rate: ~1 ms for the MAS-10 with the smooth Coulomb sign); use a smaller "
            "sample_time (paper 000: 1e-4 s)")
