"""One sweep lane (a point's system, signal and initial state) integrated and observed, and the compiled call over a
chunk of lanes; the scheme and step a sweep chooses from the plant's stiffness and the valve's edges."""

import contextlib
import functools
import inspect

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import PartitionSpec

from .._core.errors import PamjaxInputError
from .._core.xla_cpu import batched_options, compiled_with
from .._physics.signals import AbstractSignal
from .._physics.smooth import batched_lanes
from .._solve import fixed_step as _fixed_step, synchronous as _sync
from .._solve.edges import StartsOff
from .._solve.scaled import scaled
from .._solve.simulate import solve
from .plan import lane_system, make_lane
from .result import NON_FINITE, NON_PHYSICAL, SOLVER_FAILED, SUCCESS

# Default step of the ROS2 scheme [s]: on paper 000's MAS-10 plant (averaged valve, 1,024 duties x 5 s) its
# final-state error against a tight adaptive reference is <= 0.5 um and <= 0.06 Pa (benchmarks/RESULTS.md, ## sweep).
ROS2_DEFAULT_STEP = 5e-3  # s
# First step of "rodas5a" [s] (its error control grows it up to 5x per step): from rest the valve's pressure rise
# rejected a 5 ms first step 2-4 times per lane on the MAS-10 map (error estimate ~100x the tolerance), 1 ms is
# accepted at once (1,024-duty map: the slowest lane 129 -> 126 iterations; benchmarks/RESULTS.md, ## sweep).
RODAS5A_FIRST_STEP = 1e-3  # s
# A smoothed PWM edge needs steps no longer than ~2 edge widths: with RK4 at 2e-4 s (MHE2 preset, edge width 1e-4 s)
# the state after 2 s is within 0.2 um and 1.2 Pa of a tight reference at duties 0.105-0.88, at 5e-4 s off by up to
# 50 um and 285 Pa (the edges fall between RK4's samples; measured, docs/sweeps.md).
EDGE_WIDTHS_PER_STEP = 2.0
# A periodic command needs >= 100 steps per period for 2nd-order accuracy at the 1e-4 level.
STEPS_PER_SIGNAL_PERIOD = 100
# `solve`'s fixed-grid defaults (RK4 nodes per PWM period; the uniform grid's step [s]), read from its signature
DEFAULT_SUBSTEPS = inspect.signature(solve).parameters["substeps"].default
DEFAULT_GRID_STEP = inspect.signature(solve).parameters["grid_step"].default


def _observe(system, signal, t, state, channels):
    """(the channels at `t`, stacked; whether every absolute pressure of the system is > 0: its outputs' "pressure",
    every system's, one chamber's or several, wherever its state keeps it). The outputs see the command the valve
    acts on (`read_command`: a switching valve's duty pair), the "command" channel the latched duty, as `simulate`."""
    command = signal(system.valve.command_time(t))
    outs = dict(system.outputs(t, state, system.valve.read_command(signal, t)), command=command)
    return jnp.stack([jnp.asarray(outs[c], dtype=float) for c in channels]), jnp.all(outs["pressure"] > 0)


def _lane_fixed(system, signal, y0, ts, counts, steps, scheme, channels, reduction):
    """A lane on a fixed scheme (RK4/ROS2/RODAS5: a continuous valve, or a smoothed PWM valve at ~2 edge widths a
    step). A switching valve reads its duty pair (`read_command`: this period's and the last one's) with the valve
    off before the run (`StartsOff`), as `simulate` does: with one duty read as held over both periods, a first
    period above 90 % started open, and a period after one above 90 % lost the open state carried from it (12 kPa
    off a tight `simulate` at Constant(0.95), 10-15 kPa along a 1 Hz triangle). A continuous valve reads
    `signal(t)` as before (`read_command`'s default: the same program)."""
    z0, scaled_state = scaled(system, y0)
    state_of = scaled_state.state
    drive = StartsOff(signal, system.valve.command_time(ts[0])) if system.valve.switches else signal

    def field(t, z):
        return scaled_state.field(system, t, z, system.valve.read_command(drive, t))

    n_out = ts.shape[0]
    if reduction is None:
        init = jnp.zeros((n_out, len(channels)))
    else:
        w = reduction.weights(ts, system, signal)
        init = jnp.zeros((len(channels),), dtype=w.dtype)

    def update(carry, k, t, z):
        acc, physical = carry
        state = state_of(z)
        obs, positive = _observe(system, drive, t, state, channels)
        physical = physical & positive
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


def _lane_hybrid(system, signal, y0, ts, grid, channels, reduction):
    """A hybrid lane (stick-slip friction; or an exact-edge valve's, on the PWM grid with no events): `simulate`'s
    fixed grid with the events located inside the step, the
    outputs observed on the fly (`pamjax._solve.synchronous.observe_run`), so each lane equals its own `simulate`."""
    stepping, size, substeps = grid
    z0, scaled_state = scaled(system, y0)
    t0 = ts[0]
    n_out = ts.shape[0]
    if reduction is None:
        init = jnp.zeros((n_out, len(channels)))
    else:
        w = reduction.weights(ts, system, signal)
        init = jnp.zeros((len(channels),), dtype=w.dtype)

    def observe(carry, k, t, state, command):
        acc, physical = carry
        if stepping == "pwm":  # the valve's exact-edge opening at t, as simulate's trajectory reports it
            outs = _sync.output_at(system, signal, t, state, command, t0)
        else:
            outs = system.outputs(t, state, command)
        outs = dict(outs, command=command)
        obs = jnp.stack([jnp.asarray(outs[c], dtype=float) for c in channels])
        physical = physical & jnp.all(outs["pressure"] > 0)  # every system's outputs have it (_observe)
        acc = acc.at[k].set(obs) if reduction is None else acc + w[k] * obs
        return acc, physical

    (acc, physical), finite = _sync.observe_run(system, signal, ts, z0, scaled_state, t0, stepping=stepping,
                                                substeps=substeps, size=size, observe=observe,
                                                init=(init, jnp.asarray(True)))
    finite = finite & jnp.all(jnp.isfinite(acc))
    status = jnp.where(finite, jnp.where(physical, SUCCESS, NON_PHYSICAL), NON_FINITE)
    return acc, status


def _lane_adaptive(system, signal, y0, ts, channels, reduction, solve_options):
    # a sweep's results are concrete (nothing differentiates them): diffrax's plain loop, as a concrete `simulate`
    traj = solve(system, signal, ts, y0, ts[0], throw=False, **{"adjoint": "forward", **solve_options})
    obs = jnp.stack([jnp.asarray(traj.channel(c), dtype=float) for c in channels], axis=-1)
    finite = jnp.all(jnp.isfinite(obs))
    if reduction is not None:
        obs = reduction.weights(ts, system, signal) @ obs
    status = jnp.where(traj.result != 0, SOLVER_FAILED, jnp.where(finite, SUCCESS, NON_FINITE))
    return obs, status


def _run_chunk(system, signal, y0, values, ts, plan, config, mesh=None, vector_log=False):
    """One compiled call over a chunk of lanes. With a `mesh` the lanes are split over its devices by `shard_map`:
    each device runs its own lanes' loop, so an error-controlled scheme's while loop ends per device when that
    device's slowest lane ends, with no cross-device agreement per iteration. `vector_log` (static; on a CPU): the
    fixed-scheme lanes' softplus takes its log from `smooth.log1p_exp` (`smooth.batched_lanes`), as XLA's CPU code
    for a float64 log is not vectorised (a GPU's is native: there, not measured, XLA's own is kept)."""
    method, counts, channels, reduction, solve_options, grid = config
    counts = np.asarray(counts)

    def lane(vals):
        sys_l, sig_l, y0_l = make_lane(system, signal, y0, plan, vals)
        if grid is not None:
            return _lane_hybrid(sys_l, sig_l, y0_l, ts, grid, channels, reduction)
        if method == "adaptive":
            return _lane_adaptive(sys_l, sig_l, y0_l, ts, channels, reduction, dict(solve_options))
        steps = jnp.diff(ts) / counts
        with batched_lanes() if vector_log else contextlib.nullcontext():  # the field is traced here, no nested jit
            return _lane_fixed(sys_l, sig_l, y0_l, ts, counts, steps, method, channels, reduction)

    if mesh is None:
        out, status = jax.vmap(lane)(values)
    else:
        batch = PartitionSpec("batch")
        out, status = jax.shard_map(jax.vmap(lane), mesh=mesh, in_specs=batch, out_specs=(batch, batch),
                                    check_vma=False)(values)
    failed = (status != SUCCESS).reshape(status.shape + (1,) * (out.ndim - 1))
    return jnp.where(failed, jnp.nan, out), status


run_chunk = eqx.filter_jit(_run_chunk)
_CHUNK_PROGRAMS = {}  # compile options (a sorted tuple) → `_run_chunk` jitted with them


def chunk_program(platform):
    """`run_chunk` as compiled for lanes on `platform`: with `pamjax._core.xla_cpu.batched_options` where they apply
    (512-bit vectors on an AVX-512 CPU: a 1,024-lane sweep 20-30 % faster), else the plain program; on a CPU with
    the softplus's vectorised log (`_run_chunk`'s `vector_log`)."""
    options = batched_options(platform)
    program = run_chunk if options is None else compiled_with(_CHUNK_PROGRAMS, eqx.filter_jit, _run_chunk, options)
    return functools.partial(program, vector_log=platform == "cpu")


def _signal_frequency(signal, values, plan):
    """The highest frequency [Hz] of the (possibly swept) signal, or None."""
    freqs = []
    frequency = signal.cycle_frequency() if isinstance(signal, AbstractSignal) else None
    if frequency is not None:
        freqs.append(float(np.max(np.asarray(frequency))))
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
    elif method == "rodas5a":
        caps.append(RODAS5A_FIRST_STEP)
    else:
        caps.append(ROS2_DEFAULT_STEP)
    return method, min(caps)


def hybrid_method_and_step(system, signal, values, flat, plan, method, dt, ts):
    """The scheme of a sweep of a hybrid system (stick-slip friction, `system.hybrid`): `simulate`'s fixed grid with
    the mode switches located inside the RK4 step, the only scheme of pamjax that integrates such a system; the
    error-controlled and implicit schemes would hold the payload stuck at its start (they do not see the events),
    so they are refused. Returns `(method, dt, grid)`: method "pwm" (a switching valve: the PWM-synchronous grid,
    `substeps` RK4 nodes per period, `simulate`'s default 16; `dt` given: period / dt of the shortest period, rounded
    up) or "grid" (a continuous valve: uniform RK4 steps of at most `dt`, default `simulate`'s 1 ms), the step no
    longer than 1/100 of the signal's shortest period; `grid` = (stepping, size, substeps), size the periods or
    steps covering `ts`."""
    if method not in ("auto", "rk4") and not system.hybrid:
        raise PamjaxInputError(
            f"method={method!r} cannot sweep this system: its valve switches at exact edges (mode='exact'), which "
            "only the PWM-synchronous RK4 grid has as nodes (the scheme of pamjax.simulate(..., stepping='pwm')); "
            "use method='auto' (or 'rk4', with dt its step), or the valve's mode 'smooth' for the other schemes")
    if method not in ("auto", "rk4"):
        raise PamjaxInputError(
            f"method={method!r} cannot sweep this system: it is hybrid (stick-slip friction, e.g. KarnoppFriction), "
            "its modes switch at events that only the fixed-grid RK4 with events located inside the step "
            "integrates (the scheme of pamjax.simulate); use method='auto' (or 'rk4', with dt its step), or "
            "CoulombViscousFriction (smooth) for the other schemes")
    t0, t1 = float(ts[0]), float(ts[-1])
    frequency = _signal_frequency(signal, values, plan)
    signal_cap = np.inf if frequency is None else 1.0 / (STEPS_PER_SIGNAL_PERIOD * frequency)
    if not system.valve.switches:
        step = min(DEFAULT_GRID_STEP if dt is None else float(dt), signal_cap)
        size = _sync.num_grid_steps(t0, t1, step)
        return "grid", (t1 - t0) / size, ("grid", size, DEFAULT_SUBSTEPS)
    pwm = np.asarray(_lane_valves(system, plan, flat, lambda v: v.pwm_frequency), dtype=float)
    shortest = 1.0 / float(np.max(pwm))
    substeps = DEFAULT_SUBSTEPS if dt is None else max(2, int(np.ceil(shortest / float(dt) - 1e-9)))
    substeps = max(substeps, int(np.ceil(shortest / signal_cap - 1e-9)))
    first = np.floor(t0 * pwm + 1e-9)  # as `pamjax._solve.synchronous.num_periods`, for every lane's frequency
    periods = int(np.max(np.maximum(np.ceil(t1 * pwm - first - 1e-9), 1)))
    return "pwm", shortest / substeps, ("pwm", periods, substeps)


def _lane_valves(system, plan, flat, read):
    """`read(valve)` of the base system's valve, or of every lane's where the sweep replaces system leaves."""
    if not any(where == "system" for where, _ in plan.targets):
        return read(system.valve)
    lanes = jax.vmap(lambda vals: read(lane_system(system, plan, vals).valve))
    return lanes({k: jnp.asarray(v) for k, v in flat.items()})


def _edge_time_scale(system, plan, flat):
    """The smallest time scale [s] of the valve's switching edges over every point (None: a valve without edges)."""
    base = system.valve.switching_time_scale()
    if base is None:
        return None
    if not any(where == "system" for where, _ in plan.targets):
        return float(np.min(np.asarray(base)))
    lanes = jax.vmap(lambda vals: lane_system(system, plan, vals).valve.switching_time_scale())
    return float(np.min(np.asarray(lanes({k: jnp.asarray(v) for k, v in flat.items()}))))


def channel_shapes(system, signal, y0, plan, values, t0):
    """{channel: shape} of one lane's outputs at `t0` (`values`: one point's swept values), traced, not solved: a
    joint's "pressure" is both muscles', (2,)."""

    def outputs(vals):
        sys_l, sig_l, y0_l = make_lane(system, signal, y0, plan, vals)
        command = sig_l(sys_l.valve.command_time(t0))
        return dict(sys_l.outputs(t0, y0_l, command), command=command)

    return {c: tuple(v.shape) for c, v in jax.eval_shape(outputs, values).items()}


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
