"""Antagonistic joint control runs: `simulate_joint_control` solves a `JointControlLoop` (angle through the pressure
difference, stiffness through the pressure sum; `pamjax._systems.joint_control`) and reports angle, stiffness and
pressure sum against their references."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import Array, Float, Int, RealScalarLike, Series, TimesLike
from .._core.errors import PamjaxInputError, PamjaxSolveError, concrete_values
from .._physics.signals import Constant
from .._solve.checks import START_STROKE_MARGIN, check_parameters, check_start_state, prepared
from .._solve.simulate import solve
from .._solve.trajectory import result_message
from .._systems.joint import MIN_GAUGE_SUM
from .._systems.joint_control import (
    JointControlLoop,
    JointControlState,
    check_joint_control_loop,
    held_stiffness,
    hold_pressures,
    joint_angle_range,
    max_gauge_pressure,
    regulated_stiffness,
    stiffness_range,
)
from .closed_loop import check_solver_settings, check_window


class JointControlTrajectory(eqx.Module):
    """Result of `simulate_joint_control` at times `t` [s]: `angle`, `angle_reference` [rad]; `stiffness` (regulated,
    at the measured angle and pressures), `stiffness_reference` [N m/rad] (in pressure-sum mode: the stiffness the
    sum gives at θ_r); `pressure_sum`, `pressure_sum_reference` [Pa gauge]; `pressure` (p_f, p_e) [Pa abs];
    `voltage` (V_f, V_e) [V]; `result` 0 on success."""

    t: Series
    angle: Series
    angle_reference: Series
    stiffness: Series
    stiffness_reference: Series
    pressure_sum: Series
    pressure_sum_reference: Series
    pressure: Float[Array, " times 2"]
    voltage: Float[Array, " times 2"]
    result: Int[Array, ""]

    def rmse(self, start=0.0):
        """(angle RMSE [rad], stiffness RMSE [N m/rad]) over t ≥ `start` [s] (traceable).

        **Raises:** `PamjaxInputError` where `start` and the run are concrete and `start` is at or after the run's end
        (an empty window, or a NaN start: the RMSE would be 0/0 = NaN)."""
        check_window(start, self.t, self.t, "rmse", "its last sample is")
        w = (self.t >= start).astype(float)
        n = jnp.sum(w)
        return (
            jnp.sqrt(jnp.sum(w * (self.angle - self.angle_reference) ** 2) / n),
            jnp.sqrt(jnp.sum(w * (self.stiffness - self.stiffness_reference) ** 2) / n),
        )


def run_joint_control(loop: JointControlLoop, ts: TimesLike, y0: JointControlState | None = None,
                      rtol: RealScalarLike = 1e-7, atol: RealScalarLike = 1e-7,
                      max_steps: int = 100_000, adjoint: str | None = None) -> JointControlTrajectory:
    """The unchecked, traceable core of `simulate_joint_control` (for use inside grad / vmap); `adjoint` as for
    `simulate` (reverse mode by default; `simulate_joint_control`, whose result nothing differentiates, asks for
    forward mode: diffrax's plain loop, the lighter trace)."""
    ts = jnp.asarray(ts, dtype=float)
    y0 = loop.initial_state(ts[0]) if y0 is None else y0
    traj = solve(loop, Constant(0.0), ts, y0, ts[0], rtol=rtol, atol=atol, max_steps=max_steps, adjoint=adjoint)
    joint, p_atm = loop.joint, loop.air.atmospheric_pressure
    pressure, angle = traj.pressure, traj.angle
    theta_r, sum_r = jax.vmap(loop.targets)(ts)
    stiffness = jax.vmap(lambda a, p: regulated_stiffness(joint, a, p[0], p[1]))(angle, pressure)
    if loop.target_kind == "stiffness":
        stiffness_r = jax.vmap(loop.target)(ts)
    else:
        stiffness_r = jax.vmap(lambda a, s: held_stiffness(joint, a, s))(theta_r, sum_r)
    # the loop's outputs already hold the command voltages at `ts` (`JointControlLoop.outputs`): recomputing them here
    # would trace and compile a second copy of the controller (its Newton solves) for the same numbers
    volts = traj.voltage
    return JointControlTrajectory(
        t=ts,
        angle=angle,
        angle_reference=theta_r,
        stiffness=stiffness,
        stiffness_reference=stiffness_r + 0.0 * ts,
        pressure_sum=pressure[:, 0] + pressure[:, 1] - 2 * p_atm,
        pressure_sum_reference=sum_r + 0.0 * ts,
        pressure=pressure,
        voltage=volts,
        result=traj.result,
    )


_run_jit = eqx.filter_jit(run_joint_control)


@eqx.filter_jit
def _static_targets(loop, grid):
    """On `grid` [s]: θ_r, Σ_r, the held pressures, the static torque left at them [N m] and, for a stiffness target,
    the stiffness reached minus the target's and the stiffness range at θ_r (`stiffness_range`) [N m/rad]."""
    joint = loop.joint
    theta, total = jax.vmap(loop.targets)(grid)
    pf, pe = jax.vmap(lambda a, s: hold_pressures(joint, a, s))(theta, total)
    torque = jax.vmap(joint.torque)(theta, pf, pe)
    if loop.target_kind != "stiffness":
        return theta, total, pf, pe, torque, None
    missed = jax.vmap(lambda a, s: held_stiffness(joint, a, s))(theta, total) - jax.vmap(loop.target)(grid)
    return theta, total, pf, pe, torque, (missed, jax.vmap(lambda a: stiffness_range(joint, a))(theta))


def check_joint_control(loop: JointControlLoop, ts, samples=401):
    """Concrete feasibility checks before any solve (`PamjaxInputError` naming the argument): the angle reference
    inside the joint's range; at `samples` times over `ts`, a pressure-sum target a GAUGE sum ≥ `MIN_GAUGE_SUM` Pa (not
    bar), a stiffness target inside the stiffness the joint reaches at θ_r (`stiffness_range`), and the target held
    statically with both gauge pressures in [0, `max_gauge_pressure`]: each failure says which of these it is."""
    given = ts
    ts = concrete_values(ts)  # None for what is no array of numbers ("0 1 2" was a raw ValueError)
    if ts is None or ts.ndim != 1 or ts.size < 2 or not np.all(np.isfinite(ts)) or not np.all(np.diff(ts) > 0):
        raise PamjaxInputError(f"ts must be a finite, strictly increasing 1-D time grid [s] of ≥ 2 times, got "
                               f"{given!r}")
    lo, hi = loop.angle_reference.bounds()
    a_lo, a_hi = joint_angle_range(loop.joint)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo >= a_lo and hi <= a_hi):
        raise PamjaxInputError(
            f"angle_reference must stay inside the joint's range [{a_lo:.3f}, {a_hi:.3f}] rad (both muscles within "
            f"their strokes), but spans [{lo}, {hi}] rad"
        )
    grid = np.linspace(ts[0], ts[-1], samples)
    theta, total, pf, pe, torque, stiffness = jax.tree_util.tree_map(
        np.asarray, _static_targets(loop, jnp.asarray(grid)))
    p_atm, p_max = float(loop.joint.air.atmospheric_pressure), float(max_gauge_pressure(loop.joint))
    gauge = np.stack([pf, pe]) - p_atm

    def at(k):
        return f"at t = {grid[k]:.3f} s (θ_r = {theta[k]:.3f} rad)"

    if loop.target_kind == "pressure_sum":
        small = ~(total >= MIN_GAUGE_SUM)
        if np.any(small):
            k = int(np.argmax(small))
            why = ("negative" if total[k] < 0 else "0 vents both muscles and holds no angle" if total[k] == 0 else
                   "not finite" if not np.isfinite(total[k]) else "that looks like bar or MPa (5 bar = 5e5 Pa)")
            raise PamjaxInputError(f"pressure-sum target must be a GAUGE pressure sum >= {MIN_GAUGE_SUM:g} Pa, got "
                                   f"{total[k]:g} {at(k)}: {why}")
    else:
        missed, (k_lo, k_hi) = stiffness
        bad = ~(np.abs(missed) < 1e-6)
        if np.any(bad):
            k = int(np.argmax(bad))
            target = float(np.asarray(loop.target(grid[k])))
            raise PamjaxInputError(
                f"stiffness target {target:g} N m/rad {at(k)} is not reached: the joint's regulated stiffness there "
                f"spans [{k_lo[k]:.4g}, {k_hi[k]:.4g}] N m/rad (gauge pressure sums 0 to {2 * p_max:.4g} Pa)")
    name = "stiffness target" if loop.target_kind == "stiffness" else "pressure-sum target"
    if not np.all(np.abs(torque) < 1e-6):
        k = int(np.argmax(~(np.abs(torque) < 1e-6)))
        raise PamjaxInputError(f"{name} {at(k)}: no pressure pair with gauge sum {total[k]:.4g} Pa holds θ_r (a "
                               f"static torque of {torque[k]:.4g} N m is left)")
    for failed, why in ((gauge.min(0) < 0, "one below 0: the sum {:.4g} Pa is too small to hold θ_r (a larger sum, "
                                           "or stiffness, holds it)"),
                        (gauge.max(0) > p_max, f"one above the regulators' {p_max:.4g} Pa (supply / 10 V)")):
        if np.any(failed):
            k = int(np.argmax(failed))
            raise PamjaxInputError(f"{name} is infeasible {at(k)}: holding it needs gauge pressures "
                                   f"({gauge[0, k]:.4g}, {gauge[1, k]:.4g}) Pa, " + why.format(total[k]))


def _check_start_angle(loop, y0):
    """`y0`'s angle inside the joint's range (both muscles within their strokes), give or take `START_STROKE_MARGIN`
    of it as `simulate` admits a start position beyond the stroke: 5 rad ran ~6 s of solve before failing."""
    angle = None if y0 is None else concrete_values(y0.plant.angle)
    bounds = joint_angle_range(loop.joint)  # None where a joint parameter is traced
    if angle is None or bounds is None:
        return
    a_lo, a_hi = bounds
    margin = START_STROKE_MARGIN * (a_hi - a_lo)
    if np.any((angle < a_lo - margin) | (angle > a_hi + margin)):
        raise PamjaxInputError(f"y0.plant.angle = {angle} rad lies outside the joint's range [{a_lo:.3f}, {a_hi:.3f}] "
                               "rad (both muscles within their strokes): start inside it (angle in radians)")


def simulate_joint_control(
    loop: JointControlLoop,
    ts: TimesLike,
    *,
    y0: JointControlState | None = None,
    rtol: RealScalarLike = 1e-7,
    atol: RealScalarLike = 1e-7,
    max_steps: int = 100_000,
    throw: bool = True,
) -> JointControlTrajectory:
    """Simulate angle and stiffness (or pressure-sum) control of an antagonistic joint over the times `ts` [s].

    One continuous-time diffrax solve of joint, regulators and controller integrators (the controller reads θ and
    the pressures continuously). Differentiable with respect to gains and joint parameters (use `run_joint_control`
    inside `jax.grad` / `eqx.filter_vmap`).

    **Arguments:** `loop` a `JointControlLoop`; `ts` save times [s] (the solve starts at ts[0]); `y0` initial
    `JointControlState` (default: at rest holding the references at ts[0]); `rtol`, `atol` on the scaled state
    (pressures in bar, angle in 0.1 rad); `max_steps`; `throw`: raise `PamjaxSolveError` on a failed solve (default),
    as `simulate` does; with `throw=False` the trajectory comes back with `result` non-zero and NaN channels.

    **Raises:** `PamjaxInputError` for what `simulate` refuses in the loop (parameters set with `eqx.tree_at`, such
    as a joint inertia ≤ 0, are checked as the constructors check them), a `y0` that is no `JointControlState` or
    holds a non-finite value, an angle reference outside the joint's range or an infeasible stiffness or
    pressure-sum target (see `check_joint_control`), a `y0` angle outside the joint's range (give or take
    `START_STROKE_MARGIN` of it, the end stops' give), `rtol` or `atol` not a finite number > 0 or `max_steps` not an
    int >= 1 (a negative `rtol` ran silently to results far off with `result` 0), before any solve;
    `PamjaxSolveError` where the solve fails and `throw` is True.
    """
    check_joint_control_loop(loop)
    check_solver_settings(rtol, atol, max_steps, "solver steps")
    loop, _ = prepared(loop)  # a float set with eqx.tree_at as an array: checked, and no constant of the program
    check_parameters(loop, "loop")  # the components' own checks, which eqx.tree_at skipped (inertia < 0: NaN)
    # the loop's state structure from its `state_scale` (a state of constants; shapes only, nothing computed), not
    # a class test across layers
    if y0 is not None and (jax.tree_util.tree_structure(y0)
                           != jax.tree_util.tree_structure(jax.eval_shape(loop.state_scale))):
        raise PamjaxInputError(f"y0 must be a JointControlState (plant, integrals) of this loop, got "
                               f"{type(y0).__name__}: loop.initial_state(t0) is one")
    check_start_state(loop, y0)
    _check_start_angle(loop, y0)
    check_joint_control(loop, ts)
    traj = _run_jit(loop, jnp.asarray(ts, dtype=float), y0, rtol, atol, max_steps, "forward")
    if throw and not isinstance(traj.result, jax.core.Tracer) and int(traj.result) != 0:
        code = int(traj.result)
        cause = result_message(code).split(" Try increasing")[0].rstrip(".")  # the fix follows
        raise PamjaxSolveError(
            f"simulate_joint_control: the solve failed: {cause} (result code {code}, max_steps={max_steps}). Raise "
            "max_steps or loosen rtol/atol, or check the joint's parameters, gains and start state. (throw=False "
            "returns the trajectory with its status instead.)")
    return traj
