"""One sweep lane (a point's system, signal and initial state) integrated and observed, and the compiled call over a
chunk of lanes; the scheme and step a sweep chooses from the plant's stiffness and the valve's edges."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import PartitionSpec

from .._physics.signals import AbstractSignal
from .._solve import fixed_step as _fixed_step
from .._solve.scaled import scaled
from .._solve.simulate import solve
from .plan import lane_system, make_lane
from .result import NON_FINITE, NON_PHYSICAL, SOLVER_FAILED, SUCCESS

# Default step of the ROS2 scheme [s]: on paper 000's MAS-10 plant (averaged valve, 1,024 duties x 5 s) its
# final-state error against a tight adaptive reference is <= 0.5 um and <= 0.06 Pa (benchmarks/RESULTS.md, ## sweep).
ROS2_DEFAULT_STEP = 5e-3  # s
# A smoothed PWM edge needs steps no longer than ~2 edge widths: with RK4 at 2e-4 s (MHE2 preset, edge width 1e-4 s)
# the state after 2 s is within 0.2 um and 1.2 Pa of a tight reference at duties 0.105-0.88, at 5e-4 s off by up to
# 50 um and 285 Pa (the edges fall between RK4's samples; measured, docs/sweeps.md).
EDGE_WIDTHS_PER_STEP = 2.0
# A periodic command needs >= 100 steps per period for 2nd-order accuracy at the 1e-4 level.
STEPS_PER_SIGNAL_PERIOD = 100


def _observe(system, signal, t, state, channels):
    command = signal(system.valve.command_time(t))
    outs = dict(system.outputs(t, state, command), command=command)
    return jnp.stack([jnp.asarray(outs[c], dtype=float) for c in channels])


def _lane_fixed(system, signal, y0, ts, counts, steps, scheme, channels, reduction):
    z0, scaled_state = scaled(system, y0)
    state_of = scaled_state.state

    def field(t, z):
        return scaled_state.field(system, t, z, signal(system.valve.command_time(t)))

    n_out = ts.shape[0]
    if reduction is None:
        init = jnp.zeros((n_out, len(channels)))
    else:
        w = reduction.weights(ts, system, signal)
        init = jnp.zeros((len(channels),), dtype=w.dtype)

    def update(carry, k, t, z):
        acc, physical = carry
        state = state_of(z)
        obs = _observe(system, signal, t, state, channels)
        physical = physical & jnp.all(state.pressure > 0)
        if reduction is None:
            acc = acc.at[k].set(obs)
        else:
            acc = acc + w[k] * obs
        return acc, physical

    (acc, physical), _, finite = _fixed_step.integrate(
        field, z0, ts, counts, steps, scheme, (init, jnp.asarray(True)), update
    )
    finite = finite & jnp.all(jnp.isfinite(acc))
    status = jnp.where(finite, jnp.where(physical, SUCCESS, NON_PHYSICAL), NON_FINITE)
    return acc, status


def _lane_adaptive(system, signal, y0, ts, channels, reduction, solve_options):
    traj = solve(system, signal, ts, y0, ts[0], throw=False, **solve_options)
    obs = jnp.stack([jnp.asarray(traj.channel(c), dtype=float) for c in channels], axis=-1)
    finite = jnp.all(jnp.isfinite(obs))
    if reduction is not None:
        obs = reduction.weights(ts, system, signal) @ obs
    status = jnp.where(traj.result != 0, SOLVER_FAILED, jnp.where(finite, SUCCESS, NON_FINITE))
    return obs, status


@eqx.filter_jit
def run_chunk(system, signal, y0, values, ts, plan, config, mesh=None):
    """One compiled call over a chunk of lanes. With a `mesh` the lanes are split over its devices by `shard_map`:
    each device runs its own lanes' loop, so an error-controlled scheme's while loop ends per device when that
    device's slowest lane ends, with no cross-device agreement per iteration."""
    method, counts, channels, reduction, solve_options = config
    counts = np.asarray(counts)

    def lane(vals):
        sys_l, sig_l, y0_l = make_lane(system, signal, y0, plan, vals)
        if method == "adaptive":
            return _lane_adaptive(sys_l, sig_l, y0_l, ts, channels, reduction, dict(solve_options))
        steps = jnp.diff(ts) / counts
        return _lane_fixed(sys_l, sig_l, y0_l, ts, counts, steps, method, channels, reduction)

    if mesh is None:
        out, status = jax.vmap(lane)(values)
    else:
        batch = PartitionSpec("batch")
        out, status = jax.shard_map(jax.vmap(lane), mesh=mesh, in_specs=batch, out_specs=(batch, batch),
                                    check_vma=False)(values)
    failed = (status != SUCCESS).reshape(status.shape + (1,) * (out.ndim - 1))
    return jnp.where(failed, jnp.nan, out), status


def _signal_frequency(signal, values, plan):
    """The highest frequency [Hz] of the (possibly swept) signal, or None."""
    freqs = []
    if isinstance(signal, AbstractSignal) and hasattr(signal, "frequency"):
        freqs.append(float(np.max(np.asarray(signal.frequency))))
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if parts and parts[-1] == "frequency" and where in ("signal", "factory"):
            freqs.append(float(np.max(values[key])))
    return max(freqs) if freqs else None


def method_and_step(system, signal, values, flat, plan, method, dt, stiffness):
    """The scheme and step of a sweep: "auto" is RK4 for a switching valve and RODAS5 under error control
    otherwise; the default step is capped at 2 edge widths of the valve's smoothed edges (over every point), at
    1/100 of the signal's shortest period, and at RK4's stability limit on the plant's `stiffness()` (the largest
    |eigenvalue| over a sample of points) or ROS2's default step."""
    if method == "auto":  # see sweep's docstring
        method = "rk4" if system.valve.switches else "rodas5a"
    if method == "adaptive":
        return method, float("nan")
    if dt is not None:
        return method, float(dt)
    caps = []
    edge = _edge_time_scale(system, plan, flat)
    if edge is not None:
        caps.append(EDGE_WIDTHS_PER_STEP * edge)
    frequency = _signal_frequency(signal, values, plan)
    if frequency is not None:
        caps.append(1.0 / (STEPS_PER_SIGNAL_PERIOD * frequency))
    if method == "rk4":
        caps.append(_fixed_step.RK4_STABILITY_LIMIT / stiffness())
    else:
        caps.append(ROS2_DEFAULT_STEP)
    return method, min(caps)


def _edge_time_scale(system, plan, flat):
    """The smallest time scale [s] of the valve's switching edges over every point (None: a valve without edges)."""
    base = system.valve.switching_time_scale()
    if base is None:
        return None
    if not any(where == "system" for where, _ in plan.targets):
        return float(np.min(np.asarray(base)))
    lanes = jax.vmap(lambda vals: lane_system(system, plan, vals).valve.switching_time_scale())
    return float(np.min(np.asarray(lanes({k: jnp.asarray(v) for k, v in flat.items()}))))


@eqx.filter_jit
def jacobians(system, signal, y0, plan, values, t0):
    """Each lane's Jacobian of the scaled vector field at its initial state [1/s] (eigenvalues taken on the host,
    as not every backend has a non-symmetric eigensolver)."""

    def lane(vals):
        sys_l, sig_l, y0_l = make_lane(system, signal, y0, plan, vals)
        z0, scaled_state = scaled(sys_l, y0_l)
        command = sig_l(sys_l.valve.command_time(t0))
        return jax.jacfwd(lambda z: scaled_state.field(sys_l, t0, z, command))(z0)

    return jax.vmap(lane)(values)
