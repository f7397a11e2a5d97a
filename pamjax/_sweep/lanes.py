"""One sweep lane (a point's system, signal and initial state) integrated and observed, and the compiled call over a
chunk of lanes; the scheme and step a sweep chooses from the plant's stiffness and the valve's edges."""

import contextlib
import functools
import inspect
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import PartitionSpec

from .._core.env import env_flag
from .._core.errors import PamjaxInputError
from .._core.xla_cpu import batched_options, compiled_with
from .._physics.signals import AbstractSignal
from .._physics.smooth import batched_lanes
from .._solve import fixed_step as _fixed_step, synchronous as _sync
from .._solve.edges import StartsOff
from .._solve.scaled import scaled
from .._solve.simulate import solve
from .._solve.trajectory import RESULT_NONFINITE, RESULT_NONPHYSICAL
from . import kernel
from .plan import host_lanes, lane_system, make_lane
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
# The default RK4 step's check (`checked_rk4_step`): lanes probed, the largest difference between RK4 at the step
# and at its half (pressure per 1e5 Pa, position per 1e-2 m: 200 Pa, 20 um) at the output times, and the halvings
# tried. A guard against a step that is unstable or does not resolve a fast mode the command excites, not an error
# control: past the limit the gaps fall by 15-70x per halving. Measured: the MAS-10's default step 4e-5 under
# constant duties, 1.05e-3 under 0.5-8 Hz sines at 1.25 ms (the 1/100-period cap; 33-44 Pa, 6-10 um off a tight
# solve there); the VPPM-regulated DMSP-40 at 5 / 2.5 / 1.25 ms 0.18 / 0.011 / 1.9e-4 (1.25 ms passes, 10 Pa and
# 1.6 um off a tight solve); ISO 6358 at 16.7 / 8.3 / 4.2 ms 0.048 / 0.0071 / 1.3e-4 (4.2 ms: 22 Pa); the averaged
# valve filling the MAS-10 tank at 50 / 25 / 12.5 ms 0.067 / 0.0029 / 1.5e-4 (12.5 ms: 16 Pa, 50 ms: 7 kPa).
RK4_CHECK_LANES = 4
RK4_CHECK_TOLERANCE = 2e-3
RK4_CHECK_HALVINGS = 6
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
        field, z0, ts, counts, steps, scheme, (init, jnp.asarray(True)), update, jumps=lane_jumps(system, signal)
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


def lane_jumps(system, signal):
    """The lane's command jumps (`signal.jump_times()`: a `Step`'s time, swept or not, traced in the lane) as one
    sorted 1-D array, each a step boundary of the lane as of `simulate`'s adaptive solve (`command_jumps`); None for
    a signal without jumps (checked when traced: its lanes compile as before) or a switching valve, which latches the
    command once per PWM period (`simulate` hands it none either)."""
    jumps = () if system.valve.switches else type(signal).jump_times(signal)
    if not jumps:
        return None
    return jnp.sort(jnp.concatenate([jnp.ravel(jnp.asarray(x, dtype=float)) for x in jumps]))


def _lane_adaptive(system, signal, y0, ts, channels, reduction, solve_options):
    # a sweep's results are concrete (nothing differentiates them): diffrax's plain loop, as a concrete `simulate`;
    # the command's jumps step boundaries, as `simulate` sets them (a Step stepped over: 17 Pa off on the MAS-10)
    jumps = lane_jumps(system, signal)
    if jumps is not None:
        given = solve_options.get("jump_ts")
        solve_options["jump_ts"] = jumps if given is None else jnp.sort(jnp.concatenate([jumps, jnp.ravel(given)]))
    traj = solve(system, signal, ts, y0, ts[0], throw=False, **{"adjoint": "forward", **solve_options})
    obs = jnp.stack([jnp.asarray(traj.channel(c), dtype=float) for c in channels], axis=-1)
    finite = jnp.all(jnp.isfinite(obs)) & (traj.result != RESULT_NONFINITE)
    # every absolute pressure > 0 at the output times, as the fixed-step lanes check it (`_observe`)
    physical = jnp.all(jnp.asarray(traj.channel("pressure"), dtype=float) > 0) & (traj.result != RESULT_NONPHYSICAL)
    if reduction is not None:
        obs = reduction.weights(ts, system, signal) @ obs
    # the codes of `_lane_fixed` (1 non-finite, 2 non-physical); 3 for diffrax's own failures (max_steps, ...): a
    # state that became non-finite (`solve`'s RESULT_NONFINITE) is status 1 as on the other methods, not 3
    failed = (traj.result != 0) & (traj.result != RESULT_NONFINITE) & (traj.result != RESULT_NONPHYSICAL)
    status = jnp.where(failed, SOLVER_FAILED,
                       jnp.where(finite, jnp.where(physical, SUCCESS, NON_PHYSICAL), NON_FINITE))
    return obs, status


def lane_function(system, signal, y0, ts, plan, config, vector_log=False):
    """One lane as a function of its swept values (a dict key -> the point's value): (outputs, status)."""
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

    return lane


def _run_chunk(system, signal, y0, values, ts, plan, config, mesh=None, vector_log=False):
    """One compiled call over a chunk of lanes. With a `mesh` the lanes are split over its devices by `shard_map`:
    each device runs its own lanes' loop, so an error-controlled scheme's while loop ends per device when that
    device's slowest lane ends, with no cross-device agreement per iteration. `vector_log` (static; on a CPU): the
    fixed-scheme lanes' softplus takes its log from `smooth.log1p_exp` (`smooth.batched_lanes`), as XLA's CPU code
    for a float64 log is not vectorised (a GPU's is native: there, not measured, XLA's own is kept)."""
    lane = lane_function(system, signal, y0, ts, plan, config, vector_log)
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


def _signal_frequency(system, signal, plan, flat):
    """The highest frequency [Hz] of the (possibly swept) signal over every lane, or None: each lane's signal's own
    `cycle_frequency()` (a factory called on the host, `host_lanes`), whatever key a factory reads it from (a
    factory's "f" went uncapped: 5 ms steps, 7.7 kPa off with ros2 at 8 Hz), and any swept signal or factory key
    named "frequency" (a signal class that does not report its own)."""
    if not isinstance(signal, AbstractSignal) or any(where in ("signal", "factory") for where, _ in plan.targets):
        signals = [lane for _, lane in host_lanes(system, signal, plan, flat, len(next(iter(flat.values()))))]
    else:
        signals = [signal]
    freqs = [float(np.max(np.asarray(f, dtype=float))) for f in (type(s).cycle_frequency(s) for s in signals)
             if f is not None]
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if parts and parts[-1] == "frequency" and where in ("signal", "factory"):
            freqs.append(float(np.max(flat[key])))
    return max(freqs) if freqs else None


def method_and_step(system, signal, flat, plan, method, dt, stiffness):
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
    frequency = _signal_frequency(system, signal, plan, flat)
    if frequency is not None:
        caps.append(1.0 / (STEPS_PER_SIGNAL_PERIOD * frequency))
    if method == "rk4":
        caps.append(_fixed_step.RK4_STABILITY_LIMIT / stiffness())
    elif method == "rodas5a":
        caps.append(RODAS5A_FIRST_STEP)
    else:
        caps.append(ROS2_DEFAULT_STEP)
    return method, min(caps)


@eqx.filter_jit
def lane_paths(system, signal, y0, plan, values, ts, steps, counts):
    """Each lane's "pressure" [1e5 Pa] and "position" [1e-2 m] (where the system has one), at every output time,
    by RK4 (`counts` static): the probe of `checked_rk4_step`, a continuous valve's lanes as `_lane_fixed`
    integrates them (its jumps step boundaries)."""

    def lane(vals):
        sys_l, sig_l, y0_l = make_lane(system, signal, y0, plan, vals)
        z0, scaled_state = scaled(sys_l, y0_l)

        def field(t, z):
            return scaled_state.field(sys_l, t, z, sys_l.valve.read_command(sig_l, t))

        def observe(t, z):
            outs = sys_l.outputs(t, scaled_state.state(z), sys_l.valve.read_command(sig_l, t))
            return jnp.concatenate([jnp.ravel(outs["pressure"]) / 1e5,
                                    *([jnp.ravel(outs["position"]) / 1e-2] if "position" in outs else [])])

        init = jnp.zeros((ts.shape[0], observe(ts[0], z0).shape[0]))
        paths, _, _ = _fixed_step.integrate(field, z0, ts, np.asarray(counts, dtype=np.int64), steps, "rk4", init,
                                            lambda acc, k, t, z: acc.at[k].set(observe(t, z)),
                                            jumps=lane_jumps(sys_l, sig_l))
        return paths

    return jax.vmap(lane)(values)


def checked_rk4_step(system, signal, y0, plan, flat, ts, dt):
    """The default RK4 step `dt` [s] of a continuous valve's sweep, halved until RK4 at it and at half of it agree
    within `RK4_CHECK_TOLERANCE` on `RK4_CHECK_LANES` lanes spread over the batch (pressure per 1e5 Pa, position per
    1e-2 m, at every output time; at most `RK4_CHECK_HALVINGS` times, then a `UserWarning` naming method="rodas5a").
    The stability limit on the Jacobians at the initial states misses a plant that stiffens as it moves, and a fast
    mode the command excites: paper 001's VPPM-regulated DMSP-40 (73 /s at the start, 3,432 /s at 0.04 s) took 5 ms
    steps, 9.3 kPa and 1.9 mm off a tight `simulate`, status 0 (now 1.25 ms: 10 Pa, 1.6 um); the ISO 6358 regulator
    16.7 ms, 5.5 kPa off (now 4.2 ms: 22 Pa). On the host CPU (a GPU's loop of small kernels is slower), one
    program per step tried; the MAS-10's default step passes (it and its half agree to 4e-5)."""
    batch = len(next(iter(flat.values())))
    sample = np.unique(np.linspace(0, batch - 1, min(batch, RK4_CHECK_LANES)).astype(int))
    cpu = jax.local_devices(backend="cpu")[0]  # this process's: every process decides alike
    arrays, static = eqx.partition((system, signal, y0), eqx.is_array)
    system, signal, y0 = eqx.combine(jax.device_put(arrays, cpu), static)
    vals = jax.device_put({k: v[sample] for k, v in flat.items()}, cpu)
    ts_j = jax.device_put(ts, cpu)

    def paths(step):
        counts, steps = _fixed_step.step_counts(ts, step)
        return np.asarray(lane_paths(system, signal, y0, plan, vals, ts_j, jax.device_put(steps, cpu),
                                     tuple(int(c) for c in counts)))

    dt = float(np.max(_fixed_step.step_counts(ts, dt)[1]))  # the step taken (none longer than the output spacing)
    coarse = paths(dt)
    for _ in range(RK4_CHECK_HALVINGS):
        fine = paths(dt / 2)
        both = np.isfinite(coarse) & np.isfinite(fine)  # a lane non-finite at both steps fails whatever the step
        gap = float(np.max(np.abs(coarse - fine)[both], initial=0.0))
        if gap <= RK4_CHECK_TOLERANCE and not np.any(np.isfinite(fine) & ~np.isfinite(coarse)):
            return dt
        dt, coarse = dt / 2, fine
    warnings.warn(f"sweep: RK4's default step is still off its half by {gap:.2g} (pressure per 1e5 Pa, position per "
                  f"1e-2 m) after {RK4_CHECK_HALVINGS} halvings, at {dt:.3g} s: pass a smaller dt, or use "
                  "method='rodas5a' (error control)", stacklevel=3)
    return dt

def hybrid_method_and_step(system, signal, flat, plan, method, dt, ts):
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
    frequency = _signal_frequency(system, signal, plan, flat)
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

    leaves, treedef = jax.tree_util.tree_flatten((system, signal, y0, values))
    key = (treedef, repr(plan), tuple((type(x), np.shape(x), getattr(x, "dtype", None)) if eqx.is_array(x) else
                                      (type(x), id(x)) for x in leaves))
    try:
        return dict(_CHANNEL_SHAPES[key])
    except TypeError:  # an unhashable static field: traced every time
        key = None
    except KeyError:
        pass
    shapes = {c: tuple(v.shape) for c, v in jax.eval_shape(outputs, values).items()}
    if key is not None and len(_CHANNEL_SHAPES) < 256:
        _CHANNEL_SHAPES[key] = shapes
    return dict(shapes)


# (the lane's structure, the plan, its leaves' types and shapes) -> {channel: shape}: the outputs' shapes depend on
# those alone, and their trace was 60 % of a sweep's time outside its lanes (8-16 ms a call, 2-core CPU)
_CHANNEL_SHAPES = {}


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


def _run_kernel_chunk(system, signal, y0, values, ts, plan, config, interpret=False, block=None, warps=None):
    """`_run_chunk` (one device) as one GPU kernel (`kernel.py`): the lane-uniform arrays (the plant, the signal,
    the initial state, the output times) are the kernel's inputs, each point's values its lanes."""
    dynamic, static = eqx.partition((system, signal, y0, ts), eqx.is_array)

    def lane(uniform, vals):
        s, g, y, t = eqx.combine(uniform, static)
        return lane_function(s, g, y, t, plan, config)(vals)

    out, status = kernel.kernel_lanes(lane, dynamic, values, interpret=interpret, block=block, warps=warps)
    failed = (status != SUCCESS).reshape(status.shape + (1,) * (out.ndim - 1))
    return jnp.where(failed, jnp.nan, out), status


run_kernel_chunk = eqx.filter_jit(_run_kernel_chunk)
KERNEL_FLAG = "PAMJAX_SWEEP_KERNEL"  # on/off: a sweep's lanes on one GPU as one kernel (`run_lanes`)
_KERNEL_REFUSED = {}  # a lane program's structure -> why the GPU kernel does not apply to it (said once)


def run_lanes(platform, program, system, signal, y0, vals, ts, plan, config, mesh):
    """A chunk's call: `program` (`chunk_program(platform)`, `_run_chunk`'s XLA program); with
    `PAMJAX_SWEEP_KERNEL=1` on one GPU (no mesh), the lanes as one kernel (`kernel.py`), unless the kernel cannot
    express the lane's program or Triton cannot compile it (a `UserWarning` once per program says why, and
    `program` runs).

    Off by default: on an H200 the kernel ran the 100,000-point averaged map 1.75-1.9x faster (0.032-0.035 s against
    0.061 s) but took 12.7-13.9 s to compile against XLA's 4.1-4.7 s (benchmarks/RESULTS.md, g4), so a sweep run
    once waits longer; it pays for sweeps repeated in one process (a design loop) or read from JAX's compilation
    cache (2.4 s; docs/performance.md)."""
    if platform == "gpu" and mesh is None and env_flag(KERNEL_FLAG, False):
        key = str(jax.tree_util.tree_structure((system, signal, y0, vals, plan, config)))
        if key not in _KERNEL_REFUSED:
            try:
                return run_kernel_chunk(system, signal, y0, vals, ts, plan, config, block=kernel.BLOCK_LANES,
                                        warps=kernel.NUM_WARPS)
            except PamjaxInputError:
                raise
            except Exception as err:  # Unsupported, or a lowering/compilation error of the kernel
                _KERNEL_REFUSED[key] = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
                warnings.warn(f"sweep: the GPU kernel does not apply to this sweep ({_KERNEL_REFUSED[key]}); "
                              f"running XLA's program ({KERNEL_FLAG}=0 skips the attempt)", stacklevel=3)
    return program(system, signal, y0, vals, ts, plan, config, mesh)
