"""`sweep`: one compiled, vmapped call over a batch of inputs and parameter values, chunked and sharded.

A sweep point ("lane") is the base system and signal with some leaves replaced, named by path
(`"valve.supply_pressure"`, `"payload_mass"`, `"signal.value"`, `"y0.pressure"`). Lanes integrate in lockstep with a
fixed-step scheme (`_fixed_step`), so no lane waits for another; outputs are kept whole or reduced on the fly
(`Final`, `Mean`, `Harmonic`). A failed lane gets a status code and NaN outputs; the others are unaffected.
"""

import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.flatten_util import ravel_pytree
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from . import _fixed_step
from ._errors import PamjaxInputError, check_time_grid, require_float64
from ._inputs import AbstractSignal
from ._system import AbstractSystem
from ._valve import OnOffValve

# Status codes per sweep point.
SUCCESS = 0  # finished with a finite, physical state
NON_FINITE = 1  # the state became NaN/inf (e.g. a step too large for this point's stiffness)
NON_PHYSICAL = 2  # an absolute pressure became <= 0
SOLVER_FAILED = 3  # the adaptive solver failed (max_steps, ...), method="adaptive" only
STATUS_NAMES = {SUCCESS: "success", NON_FINITE: "non-finite state", NON_PHYSICAL: "non-physical state (pressure <= 0)",
                SOLVER_FAILED: "adaptive solver failed"}

# Default step of the ROS2 scheme [s]: on paper 000's MAS-10 plant (averaged valve, 1,024 duties x 5 s) its
# final-state error against a tight adaptive reference is <= 0.5 um and <= 0.06 Pa (benchmarks/RESULTS.md, ## sweep).
ROS2_DEFAULT_STEP = 5e-3  # s
# A smoothed PWM edge needs steps no longer than ~2 edge widths: with RK4 at 2e-4 s (MHE2 preset, edge width 1e-4 s)
# the state after 2 s is within 0.2 um and 1.2 Pa of a tight reference at duties 0.105-0.88, at 5e-4 s off by up to
# 50 um and 285 Pa (the edges fall between RK4's samples; measured, docs/sweeps.md).
EDGE_WIDTHS_PER_STEP = 2.0
# A periodic command needs >= 100 steps per period for 2nd-order accuracy at the 1e-4 level.
STEPS_PER_SIGNAL_PERIOD = 100


# ----------------------------------------------------------------------------------------------------------------
# Reductions: every reduction is a weighted sum over the output times, Σ_k w_k y(t_k), with per-lane weights.


class AbstractReduction(eqx.Module):
    """A reduction of each output channel over the output times, evaluated on the fly: Σ_k w_k y(t_k)."""

    def weights(self, ts, system, signal):
        """Weights over the output times `ts` [s] for one lane (real or complex, shape `ts.shape`)."""
        raise NotImplementedError


class Final(AbstractReduction):
    """The value at the last output time."""

    def weights(self, ts, system, signal):
        return jnp.zeros_like(ts).at[-1].set(1.0)


class Mean(AbstractReduction):
    """Mean over the output times in the last `window` [s] (e.g. the last N PWM periods: N / f_PWM)."""

    window: float = eqx.field(static=True)

    def weights(self, ts, system, signal):
        inside = ts >= ts[-1] - self.window * (1 + 1e-12)
        return inside / jnp.sum(inside)


class Harmonic(AbstractReduction):
    """Complex Fourier coefficient at the lane's frequency f over its last `periods` periods:
    Y = (2/n) Σ y(t_k) exp(−i 2π f t_k), so y ≈ mean + Re(Y exp(i 2π f t)); |Y| is the amplitude, arg Y the phase.

    **Arguments:** `periods` (integer number of periods in the window); `frequency`: a path read from the lane
    (default "signal.frequency") or a number [Hz]. Needs output times that sample the window evenly.
    """

    periods: int = eqx.field(static=True, default=3)
    frequency: object = eqx.field(static=True, default="signal.frequency")

    def weights(self, ts, system, signal):
        f = _lane_value(self.frequency, system, signal)
        inside = ts >= ts[-1] - self.periods / f * (1 + 1e-9)
        # the window [t_end - P/f, t_end] sampled with both ends would count one point twice: drop the first
        first = jnp.argmax(inside)
        inside = inside.at[first].set(False)
        return inside * (2.0 / jnp.sum(inside)) * jnp.exp(-2j * jnp.pi * f * ts)


def _lane_value(path_or_number, system, signal):
    if isinstance(path_or_number, str):
        head, *rest = path_or_number.split(".")
        root = signal if head == "signal" else system
        parts = rest if head == "signal" else [head, *rest]
        return _get(root, parts)
    return jnp.asarray(path_or_number, dtype=float)


# ----------------------------------------------------------------------------------------------------------------
# Paths


def _get(obj, parts):
    for p in parts:
        obj = getattr(obj, p)
    return obj


def _split(key):
    parts = key.split(".")
    if parts[0] in ("signal", "y0"):
        return parts[0], parts[1:]
    return "system", parts


class _Plan(eqx.Module):
    """Static description of a sweep: which key goes where, and each swept leaf's own shape."""

    keys: tuple = eqx.field(static=True)
    targets: tuple = eqx.field(static=True)  # ("system" | "signal" | "y0" | "factory", parts)
    leaf_shapes: tuple = eqx.field(static=True)


def _make_signal(signal, plan, values):
    """The lane's signal: the base signal with its swept leaves replaced, or the factory's signal."""
    if not isinstance(signal, AbstractSignal):
        return signal(dict(values))
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if where == "signal":
            signal = eqx.tree_at(lambda s, parts=parts: _get(s, parts), signal, values[key])
    return signal


def _make_lane(system, signal, y0, plan, values):
    """The lane's (system, signal, y0) for one set of swept `values` (a dict key -> array)."""
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if where == "system":
            system = eqx.tree_at(lambda s, parts=parts: _get(s, parts), system, values[key])
    signal = _make_signal(signal, plan, values)
    y0_keys = [(key, parts) for key, (where, parts) in zip(plan.keys, plan.targets) if where == "y0"]
    if y0 is None:  # "y0.pressure" etc. are arguments of `initial_state` (position then in equilibrium with them)
        return system, signal, system.initial_state(**{parts[0]: values[key] for key, parts in y0_keys})
    for key, parts in y0_keys:
        y0 = eqx.tree_at(lambda s, parts=parts: _get(s, parts), y0, values[key])
    return system, signal, y0


# ----------------------------------------------------------------------------------------------------------------
# One lane, fixed step


def _observe(system, signal, t, state, channels):
    command = signal(system.valve.command_time(t))
    outs = dict(system.outputs(t, state, command), command=command)
    return jnp.stack([jnp.asarray(outs[c], dtype=float) for c in channels])


def _lane_fixed(system, signal, y0, ts, counts, steps, scheme, channels, reduction):
    scale = system.state_scale()
    z0, unravel = ravel_pytree(jtu.tree_map(lambda a, s: a / s, y0, scale))

    def state_of(z):
        return jtu.tree_map(lambda a, s: a * s, unravel(z), scale)

    def field(t, z):
        y = state_of(z)
        dy = system.vector_field(t, y, signal(system.valve.command_time(t)))
        return ravel_pytree(jtu.tree_map(lambda a, s: a / s, dy, scale))[0]

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
    from ._simulate import solve  # workflow-to-workflow import, kept local

    traj = solve(system, signal, ts, y0, ts[0], throw=False, **solve_options)
    obs = jnp.stack([jnp.asarray(traj.channel(c) if c != "command" else traj.command, dtype=float) for c in channels],
                    axis=-1)
    finite = jnp.all(jnp.isfinite(obs))
    if reduction is not None:
        obs = reduction.weights(ts, system, signal) @ obs
    status = jnp.where(traj.result != 0, SOLVER_FAILED, jnp.where(finite, SUCCESS, NON_FINITE))
    return obs, status


_LANE_MULTIPLE = 8  # pad batches to a multiple of this many lanes (bitwise batch-independence, see sweep)


@eqx.filter_jit
def _run_chunk(system, signal, y0, values, ts, plan, config, mesh=None):
    """One compiled call over a chunk of lanes. With a `mesh` the lanes are split over its devices by `shard_map`:
    each device runs its own lanes' loop, so an error-controlled scheme's while loop ends per device when that
    device's slowest lane ends, with no cross-device agreement per iteration."""
    method, counts, channels, reduction, solve_options = config
    counts = np.asarray(counts)

    def lane(vals):
        sys_l, sig_l, y0_l = _make_lane(system, signal, y0, plan, vals)
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


# ----------------------------------------------------------------------------------------------------------------
# Result


class SweepResult(eqx.Module):
    """The result of `sweep`.

    - `over`: the swept values, each broadcast to the batch shape (plus the leaf's own shape).
    - `t`: output times [s]; `channels`: names of the output channels.
    - `outputs`: channel -> array of shape batch_shape + (len(t),) for trajectories, batch_shape for reductions
      (complex for `Harmonic`). Pressures absolute [Pa], positions [m], flows [kg/s], as `simulate`.
    - `status`: int per point (0 success; 1 non-finite state; 2 non-physical state; 3 adaptive solver failed);
      failed points hold NaN outputs. `dt`, `method`: the step [s] and scheme used.
    - `points`: None for a whole result; for one process's shard (`sweep(..., gather="local")`) the flat indices
      (C order over `batch_shape`) of the points it holds, which then lie along one flat axis in `over`, `outputs`
      and `status`. `merge_sweep_shards` joins the shards of every process into the whole result.
    """

    over: dict
    t: np.ndarray
    channels: tuple = eqx.field(static=True)
    outputs: dict
    status: np.ndarray
    dt: float = eqx.field(static=True)
    method: str = eqx.field(static=True)
    points: np.ndarray | None = None
    batch_shape: tuple | None = eqx.field(static=True, default=None)

    @property
    def succeeded(self):
        return self.status == SUCCESS

    def __getitem__(self, channel):
        if channel not in self.outputs:
            raise PamjaxInputError(f"unknown channel {channel!r}; this sweep has {list(self.outputs)}")
        return self.outputs[channel]


# ----------------------------------------------------------------------------------------------------------------
# Validation and step choice (concrete, before any solve)


def _check_module(module, name):
    """Re-run the `__check_init__` of every class of `module` (equinox skips them under `tree_at`)."""
    for cls in type(module).__mro__:
        check = cls.__dict__.get("__check_init__")
        if check is not None:
            try:
                check(module)
            except PamjaxInputError as err:
                raise PamjaxInputError(f"over[{name!r}]: {err}") from None


def _validate_values(system, signal, y0, plan, values, batch_size):
    """Checks of the swept values against each component's own constraints, batched where the checks allow it
    (they are elementwise `np.all`); per point otherwise."""
    flat = {k: v.reshape((batch_size,) + shape) for (k, v), shape in zip(values.items(), plan.leaf_shapes)}
    for key, v in flat.items():
        if not np.all(np.isfinite(v)):
            bad = int(np.argmin(np.all(np.isfinite(v.reshape(batch_size, -1)), axis=1)))
            raise PamjaxInputError(f"over[{key!r}] must be finite, point {bad} is {v[bad]}")

    def check_lanes(vals, n):
        for key, (where, parts) in zip(plan.keys, plan.targets):
            if where != "system":
                continue
            lane_system = eqx.tree_at(lambda s, parts=parts: _get(s, parts), system, jnp.asarray(vals[key]))
            for i in range(len(parts)):
                sub = _get(lane_system, parts[:i])
                if isinstance(sub, eqx.Module):
                    _check_module(sub, key)

    try:
        check_lanes(flat, batch_size)
        batched_ok = True
    except PamjaxInputError:
        raise
    except Exception:  # a check that cannot take an array (e.g. `bool(hi > lo)`): check point by point
        batched_ok = False
    if not batched_ok:
        for i in range(batch_size):
            check_lanes({k: v[i] for k, v in flat.items()}, 1)
    # The command must stay in the valve's range at every point: all points at once where the signal's `bounds()`
    # takes arrays (Constant), point by point otherwise.
    signal_keys = [k for k, (w, _) in zip(plan.keys, plan.targets) if w in ("signal", "factory")]
    if not signal_keys and isinstance(signal, AbstractSignal):
        _check_bounds(system, signal, None)
        return
    try:
        if not isinstance(signal, AbstractSignal):
            raise TypeError
        _check_bounds(system, _make_signal(signal, plan, {k: jnp.asarray(v) for k, v in flat.items()}), None)
    except PamjaxInputError:
        pass  # find and name the offending point below
    except Exception:
        pass
    else:
        return
    for i in range(batch_size):
        _check_bounds(system, _make_signal(signal, plan, {k: jnp.asarray(v[i]) for k, v in flat.items()}),
                      {k: np.asarray(v[i]).tolist() for k, v in flat.items()} | {"index": i})


def _check_bounds(system, sig, point):
    if not isinstance(sig, AbstractSignal):
        raise PamjaxInputError(f"the signal factory must return a pamjax signal, got {type(sig)}")
    clo, chi = system.valve.command_range
    lo, hi = sig.bounds()
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < clo - 1e-12 or hi > chi + 1e-12:
        where = "" if point is None else f" at sweep point {point}"
        raise PamjaxInputError(
            f"signal (the valve command) must stay within [{clo}, {chi}], its range is [{lo}, {hi}]{where}"
        )


def _signal_frequency(signal, values, plan):
    """The highest frequency [Hz] of the (possibly swept) signal, or None."""
    freqs = []
    if isinstance(signal, AbstractSignal) and hasattr(signal, "frequency"):
        freqs.append(float(np.max(np.asarray(signal.frequency))))
    for key, (where, parts) in zip(plan.keys, plan.targets):
        if parts and parts[-1] == "frequency" and where in ("signal", "factory"):
            freqs.append(float(np.max(values[key])))
    return max(freqs) if freqs else None


def _default_method_and_step(system, signal, values, plan, method, dt, stiffness):
    valve = system.valve
    if method == "auto":  # see sweep's docstring
        method = "rk4" if isinstance(valve, OnOffValve) else "rodas5a"
    if method == "adaptive":
        return method, float("nan")
    if dt is not None:
        return method, float(dt)
    caps = []
    if isinstance(valve, OnOffValve):
        widths = np.asarray(valve.edge_width)
        if "valve.edge_width" in plan.keys:
            widths = values["valve.edge_width"]
        caps.append(EDGE_WIDTHS_PER_STEP * float(np.min(widths)))
    frequency = _signal_frequency(signal, values, plan)
    if frequency is not None:
        caps.append(1.0 / (STEPS_PER_SIGNAL_PERIOD * frequency))
    if method == "rk4":
        caps.append(_fixed_step.RK4_STABILITY_LIMIT / stiffness())
    else:
        caps.append(ROS2_DEFAULT_STEP)
    return method, min(caps)


# ----------------------------------------------------------------------------------------------------------------
# Sharding


def _mesh(devices):
    if isinstance(devices, Mesh):
        return devices
    devices = jax.devices() if devices is None else list(devices)
    if len(devices) < 2:
        return None
    return Mesh(np.asarray(devices), ("batch",))


_CPU_CHUNK = 8192  # points per compiled call on CPU: wider batches run no faster there (measured, benchmarks/sweep.py)
# On a GPU/TPU every integration step is a few kernel launches whatever the width, so the whole batch in one call is
# fastest (100,000 points x 5 s on an H100: 0.24 s in one chunk, 1.15 s in chunks of 8,192; benchmarks/RESULTS.md);
# the default chunk is as many points as this many bytes of outputs (and at least _CPU_CHUNK).
_ACCELERATOR_CHUNK_BYTES = 1 << 30


def default_chunk_size(batch_size, values_per_point, platform, n_devices=1):
    """`sweep`'s points per compiled call when `chunk_size` is not given: 8,192 on CPU; on an accelerator as many
    as 1 GiB of outputs per device holds (`values_per_point` float64 outputs per point, counted as at least 64)."""
    if platform == "cpu":
        return min(batch_size, _CPU_CHUNK)
    fit = n_devices * _ACCELERATOR_CHUNK_BYTES // (8 * max(int(values_per_point), 64))
    return min(batch_size, max(_CPU_CHUNK, fit))


class _Layout:
    """Which points each compiled call computes, on which device.

    The batch is cut into groups of `per_device` consecutive points; each device computes one group per call, in
    `lanes` lanes (`per_device` rounded up to a multiple of 8, padded with copies of point 0). Group g runs in call
    g // n_dev on the mesh's device g % n_dev. XLA's code for a batch depends on its width, and a lane's result on
    its place in it (in the last bit, ~1e-16 relative), so a point's result is fixed by its group and place and by
    the program: one SPMD program per device for any mesh of 2 or more devices (however many processes hold them),
    another, optimised without the SPMD partitioner, for a single device. So: the same mesh size gives the same
    bits, one process or several; with `chunk_size` given, `per_device` does not depend on the device count, and
    any 2 or more devices give the same bits (2, 3 and 4 CPU devices measured), one device agreeing to round-off.
    Without it, the batch (up to `default_chunk_size` points per call) is split evenly over the devices."""

    def __init__(self, batch_size, per_device, n_dev, processes):
        self.batch_size, self.per_device, self.n_dev, self.processes = batch_size, per_device, n_dev, processes
        self.lanes = int(math.ceil(per_device / _LANE_MULTIPLE) * _LANE_MULTIPLE)
        groups = int(math.ceil(batch_size / per_device))
        self.calls = int(math.ceil(groups / n_dev))

    @classmethod
    def plan(cls, batch_size, chunk_size, mesh, devices, values_per_point):
        n_dev = 1 if mesh is None else mesh.devices.size
        processes = 1 if mesh is None else len({d.process_index for d in mesh.devices.flat})
        if chunk_size is not None:
            return cls(batch_size, min(chunk_size, batch_size), n_dev, processes)
        if mesh is not None:
            platform = mesh.devices.flat[0].platform
        else:
            platform = ((list(devices) if devices is not None else []) or jax.devices())[0].platform
        total = default_chunk_size(batch_size, values_per_point, platform, n_dev)
        return cls(batch_size, int(math.ceil(total / n_dev)), n_dev, processes)

    def lanes_of_call(self, c):
        """(point index per lane, whether the lane holds a real point) of call `c`, device-major."""
        group = c * self.n_dev + np.arange(self.n_dev)[:, None]
        place = np.arange(self.lanes)[None, :]
        point = group * self.per_device + place
        valid = (place < self.per_device) & (point < self.batch_size)
        return np.where(valid, point, 0).reshape(-1), valid.reshape(-1)

    def points_of_call(self, c):
        first = c * self.n_dev * self.per_device
        return first, min(first + self.n_dev * self.per_device, self.batch_size) - 1


def _local_part(out, status, index, valid):
    """(points, outputs, status) of the real lanes of one call that this process's devices computed."""
    if isinstance(out, jax.Array) and len(out.sharding.device_set) > 1:
        rows = [(shard.index[0], shard) for shard in out.addressable_shards]
        status_of = {s.device: s for s in status.addressable_shards}
        parts = []
        for lanes, shard in sorted(rows, key=lambda r: r[0].start or 0):
            keep = valid[lanes]
            parts.append((index[lanes][keep], np.asarray(shard.data)[keep],
                          np.asarray(status_of[shard.device].data)[keep]))
        return tuple(np.concatenate(p) for p in zip(*parts))
    return index[valid], np.asarray(out)[valid], np.asarray(status)[valid]


def _gather_processes(points, out, status):
    """Every process's (points, outputs, status), on every process (`process_allgather` of their bytes)."""
    import io

    from ._distributed import gather_bytes

    buffer = io.BytesIO()
    np.savez(buffer, points=points, out=out, status=status)
    parts = []
    for payload in gather_bytes(buffer.getvalue()):
        with np.load(io.BytesIO(payload)) as f:
            parts.append((f["points"], f["out"], f["status"]))
    return tuple(np.concatenate(p) for p in zip(*parts))


def _in_point_order(points, out, status, batch_size):
    """Outputs and status placed by point index (each point computed exactly once)."""
    order = np.argsort(points, kind="stable")
    if not np.array_equal(points[order], np.arange(batch_size)):
        raise RuntimeError(f"sweep: the devices returned points {np.unique(points).size} of {batch_size} "
                           "(or some twice); this is a bug in pamjax")
    return out[order], status[order]


def merge_sweep_shards(shards) -> SweepResult:
    """The whole `SweepResult` from the shards that `sweep(..., gather="local")` returned on every process (for
    instance saved by each process and loaded on one machine); every point must be in exactly one shard."""
    shards = list(shards)
    if not shards or any(not isinstance(s, SweepResult) or s.points is None for s in shards):
        raise PamjaxInputError("shards must be a non-empty list of SweepResults from sweep(..., gather='local')")
    first = shards[0]
    for s in shards[1:]:
        if (s.batch_shape, s.channels, s.method) != (first.batch_shape, first.channels, first.method) or not \
                np.array_equal(s.t, first.t):
            raise PamjaxInputError("shards must come from one sweep (same batch shape, channels, times, method)")
    batch_shape = tuple(first.batch_shape)
    size = int(np.prod(batch_shape))
    points = np.concatenate([s.points for s in shards])
    out = np.stack([np.concatenate([s.outputs[c] for s in shards]) for c in first.channels], axis=-1)
    try:
        out, status = _in_point_order(points, out, np.concatenate([s.status for s in shards]), size)
    except RuntimeError:
        raise PamjaxInputError(f"shards hold {points.size} points ({np.unique(points).size} distinct), the sweep "
                               f"has {size}: pass every process's shard once") from None
    order = np.argsort(points, kind="stable")
    over = {k: np.concatenate([s.over[k] for s in shards])[order] for k in first.over}
    over = {k: v.reshape(batch_shape + v.shape[1:]) for k, v in over.items()}
    outputs = {c: out[..., i].reshape(batch_shape + out.shape[1:-1]) for i, c in enumerate(first.channels)}
    return SweepResult(over=over, t=first.t, channels=first.channels, outputs=outputs,
                       status=status.reshape(batch_shape), dt=first.dt, method=first.method)


def _put(x, mesh):
    """A host array as a global array sharded over the mesh's batch axis (works single- and multi-host: every
    process holds the full host array and contributes its devices' slices)."""
    if mesh is None:
        return jnp.asarray(x)
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])




# ----------------------------------------------------------------------------------------------------------------


def sweep(
    system: AbstractSystem,
    signal,
    ts,
    over: dict,
    *,
    y0=None,
    reduce: AbstractReduction | None = None,
    channels=None,
    method: str = "auto",
    dt: float | None = None,
    chunk_size: int | None = None,
    devices=None,
    progress=True,
    solve_options: dict | None = None,
    gather: str = "all",
) -> SweepResult:
    """Simulate `system` at every point of a batch of inputs and parameter values, as one compiled vmapped call.

    Each point replaces some leaves of the base system, signal or initial state, named by path. All points step in
    lockstep with a fixed-step scheme, so the batch costs what one point costs times the batch size over the vector
    width; outputs are kept whole or reduced on the fly. A failed point gets a status code and NaN outputs, without
    raising and without affecting the others.

    **Arguments:**

    - `system`: the base system (`MuscleSystem`, `TankSystem`, ...).
    - `signal`: the base command signal (`Constant(0.5)`, `Sine(...)`), or a factory `values -> signal` called per
      point with the dict of that point's swept values (for keys that are not paths).
    - `ts`: concrete, strictly increasing output times [s]; the solve starts at `ts[0]` and steps land on every
      output time (so no step exceeds the spacing of `ts`).
    - `over`: `{path: values}`. Paths name a leaf of the system (`"payload_mass"`, `"valve.supply_pressure"`,
      `"friction.coulomb_force"`, `"muscle.force_law.k0"`), of the signal (`"signal.value"`,
      `"signal.frequency"`) or of the initial state (`"y0.pressure"` [Pa abs]: without `y0`, an argument of
      `system.initial_state`, so the payload starts in equilibrium at that pressure; with `y0`, its leaf); with a
      signal factory any other name is passed to the factory. Values broadcast together (NumPy rules) to the batch
      shape, so `{"signal.value": u[:, None], "valve.supply_pressure": p[None, :]}` is a grid; a non-scalar leaf
      takes its own shape as trailing axes.
    - `y0`: base initial state (default: each point's `system.initial_state()`, at rest in equilibrium).
    - `reduce`: None (whole trajectories at `ts`), `Final()`, `Mean(window)` or `Harmonic(periods, frequency)`.
    - `channels`: output channels to keep (default: all the system's outputs and "command").
    - `method`: "auto" (default: "rodas5a" for a continuous valve, "rk4" for a switching one), "rodas5a" (RODAS5,
      an L-stable Rosenbrock method of order 5, under per-lane error control at rtol = atol = 1e-5 on the scaled
      state, every output time landed on exactly: accurate along the whole trajectory and fastest for a stiff
      plant, as a sticking payload makes it; on the 1,024-duty MAS-10 map within 5e-5 Pa and 4e-10 m of a tight
      solve, `dt` its first step), "rk4" (fixed steps, accurate along the whole trajectory; its step is bounded by
      the plant's stiffest eigenvalue, which for paper 000's friction is also the time scale of the stick-slip
      transitions; the PWM valve's smoothed edges bound any scheme's step, and fixed steps keep the lanes in
      lockstep), "ros2" (L-stable Rosenbrock at a fixed step 3x larger: for steady-state maps, where only settled
      values matter; it smears the fast transients, by tens of um on the MAS-10), "ros2a" (ROS2 under per-lane
      error control, rtol = atol = 1e-3: a quick steady-state map, within about 1 Pa and 10 um of RK4 on the MAS-10
      map, tens of um with coarse output grids), or "adaptive" (vmapped diffrax Tsit5, a slow reference;
      `solve_options` go to it).
    - `dt`: the fixed step [s] (the first step for "rodas5a"/"ros2a"). Default: RK4 at 2.5 / (largest |eigenvalue|
      of the Jacobian at the initial states) (its stability limit with a 10 % margin), the others at 5 ms; all
      capped at 2 PWM edge widths for a switching valve and at 1/100 of the signal's shortest period. Check a
      fixed-step result by halving `dt`.
    - `chunk_size`: points per device per compiled call (memory bound). Default (`default_chunk_size`): all points
      split evenly over the devices, at most 8,192 per call on CPU, on a GPU/TPU as many as 1 GiB of outputs per
      device holds (one call is fastest there). The last call is padded. Results are bitwise the same for the same
      number of devices, in one process or several; with `chunk_size` given, for any 2 or more devices; between
      one device and several, to round-off (~1e-16 relative: XLA optimises a one-device program differently).
    - `devices`: None (all of `jax.devices()`: the batch axis is sharded over them with a `Mesh` and
      `NamedSharding`, each device running its own lanes under `shard_map`; after `pamjax.initialize_distributed()`
      (or `jax.distributed.initialize()`) the devices of every process, each process computing its devices'
      points), a list of devices, or a `Mesh` with a "batch" axis.
    - `progress`: True (print one line per chunk when there are several; process 0 only), False, or a callable
      taking a string.
    - `gather`: "all" (default: every process returns the whole result, gathered once at the end) or "local" (each
      process returns the points it computed, flat, with their indices in `points`: for batches larger than one
      host's memory; `merge_sweep_shards` joins them).

    **Returns:** a `SweepResult` (`over`, `t`, `outputs[channel]`, `status`, `dt`, `method`; `points` with
    `gather="local"`).

    **Raises:** `PamjaxInputError` naming the argument (unknown path, values that break a component's constraint,
    a command outside the valve's range, bad `ts`/`dt`/`chunk_size`), before any solve.
    """
    require_float64("pamjax.sweep")
    if not isinstance(system, AbstractSystem):
        raise PamjaxInputError(f"system must be a pamjax system (MuscleSystem, TankSystem, ...), got {type(system)}")
    factory = not isinstance(signal, AbstractSignal)
    if factory and not callable(signal):
        raise PamjaxInputError(f"signal must be a pamjax signal or a factory values -> signal, got {type(signal)}")
    check_time_grid(ts, "ts")
    ts_np = np.asarray(ts, dtype=float)
    if ts_np.size < 2:
        raise PamjaxInputError("ts needs at least two times (the sweep starts at ts[0])")
    if not isinstance(over, dict) or not over:
        raise PamjaxInputError(f"over must be a non-empty dict {{path: values}}, got {over!r}")
    if method not in ("auto", "adaptive", *_fixed_step.SCHEMES):
        raise PamjaxInputError(
            f"method must be 'auto', 'rodas5a', 'rk4', 'ros2', 'ros2a' or 'adaptive', got {method!r}")
    if dt is not None and not (np.isfinite(dt) and dt > 0):
        raise PamjaxInputError(f"dt must be a step > 0 [s], got {dt}")
    if chunk_size is not None and not (isinstance(chunk_size, int) and chunk_size > 0):
        raise PamjaxInputError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    if gather not in ("all", "local"):
        raise PamjaxInputError(f"gather must be 'all' or 'local', got {gather!r}")
    if reduce is not None and not isinstance(reduce, AbstractReduction):
        raise PamjaxInputError(f"reduce must be None, Final(), Mean(window) or Harmonic(...), got {reduce!r}")
    base_state, available = _structure(system, y0)  # shapes only: no solve yet

    # --- resolve paths
    keys, targets, leaf_shapes, arrays = [], [], [], []
    for key, value in over.items():
        if not isinstance(key, str) or not key:
            raise PamjaxInputError(f"over keys must be path strings like 'valve.supply_pressure', got {key!r}")
        where, parts = _split(key)
        root = {"system": system, "signal": signal, "y0": base_state}[where]
        try:
            leaf = _get(root, parts) if not (where == "signal" and factory) else None
        except AttributeError:
            leaf = None
            if not factory:
                raise PamjaxInputError(
                    f"over[{key!r}]: the {where} ({type(root).__name__}) has no leaf {'.'.join(parts)!r}"
                ) from None
            where, parts = "factory", [key]
        if where == "signal" and factory:
            where = "factory"
        if where != "factory" and not isinstance(leaf, (jax.Array, np.ndarray, float, int, jax.ShapeDtypeStruct)):
            raise PamjaxInputError(f"over[{key!r}] must name an array parameter, it names a {type(leaf).__name__}")
        shape = () if leaf is None else tuple(np.shape(leaf))
        try:
            v = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise PamjaxInputError(f"over[{key!r}] must be numbers, got {value!r}") from None
        if v.ndim < len(shape) or v.shape[v.ndim - len(shape):] != shape:
            raise PamjaxInputError(f"over[{key!r}] must end in the leaf's shape {shape}, got shape {v.shape}")
        keys.append(key)
        targets.append((where, tuple(parts)))
        leaf_shapes.append(shape)
        arrays.append(v)
    try:
        batch_shape = np.broadcast_shapes(*[a.shape[: a.ndim - len(s)] for a, s in zip(arrays, leaf_shapes)])
    except ValueError:
        raise PamjaxInputError(
            "over values must broadcast together, got shapes "
            + ", ".join(f"{k}: {a.shape}" for k, a in zip(keys, arrays))
        ) from None
    batch_size = int(np.prod(batch_shape))
    values = {k: np.broadcast_to(a, batch_shape + s) for k, a, s in zip(keys, arrays, leaf_shapes)}
    plan = _Plan(tuple(keys), tuple(targets), tuple(leaf_shapes))
    _validate_values(system, signal, y0, plan, values, batch_size)
    flat = {k: np.ascontiguousarray(v.reshape((batch_size,) + s)) for (k, v), s in zip(values.items(), leaf_shapes)}

    # --- channels
    channels = tuple(available) if channels is None else tuple(channels)
    for c in channels:
        if c not in available:
            raise PamjaxInputError(f"unknown channel {c!r}; this system has {available}")

    # --- scheme and step
    def stiffness():
        sample = np.unique(np.linspace(0, batch_size - 1, min(batch_size, 64)).astype(int))
        vals = {k: jnp.asarray(v[sample]) for k, v in flat.items()}
        jacobians = np.asarray(_jacobians(system, signal, y0, plan, vals, float(ts_np[0])))
        return float(np.nanmax(np.abs(np.linalg.eigvals(jacobians))))

    method, dt = _default_method_and_step(system, signal, values, plan, method, dt, stiffness)
    counts = np.zeros(0, dtype=np.int64)
    if method != "adaptive":
        counts, _ = _fixed_step.step_counts(ts_np, dt)
    config = (method, tuple(int(c) for c in counts), channels, reduce,
              tuple(sorted((solve_options or {}).items())))

    # --- chunks over devices (and processes)
    mesh = _mesh(devices)
    layout = _Layout.plan(batch_size, chunk_size, mesh, devices, len(channels) * (1 if reduce is not None else
                                                                                 ts_np.size) * 2)  # x2: complex
    say = (print if progress is True else progress) if progress else None
    if say is not None and jax.process_index() != 0:
        say = None  # one report per sweep, from process 0
    pieces = []
    ts_j = jnp.asarray(ts_np)
    for c in range(layout.calls):
        start = time.perf_counter()
        index, valid = layout.lanes_of_call(c)
        vals = {k: _put(v[index], mesh) for k, v in flat.items()}
        out, status = _run_chunk(system, signal, y0, vals, ts_j, plan, config, mesh)
        pieces.append(_local_part(out, status, index, valid))
        if say is not None and layout.calls > 1:
            first, last = layout.points_of_call(c)
            failed = int(np.sum(pieces[-1][2] != SUCCESS))
            mine = "" if layout.processes == 1 else f" (of its {len(pieces[-1][0])} points on process 0)"
            say(f"sweep: chunk {c + 1}/{layout.calls}, points {first}-{last}, "
                f"{time.perf_counter() - start:.2f} s, {failed} failed{mine}")
    points, out, status = (np.concatenate(part) for part in zip(*pieces))
    if gather == "local":
        local = {k: v[points] for k, v in flat.items()}
        outputs = {ch: out[..., i] for i, ch in enumerate(channels)}  # (n,) or (n, T) per channel
        return SweepResult(over=local, t=ts_np, channels=channels, outputs=outputs, status=status, dt=dt,
                           method=method, points=points, batch_shape=batch_shape)
    if layout.processes > 1:
        points, out, status = _gather_processes(points, out, status)
    out, status = _in_point_order(points, out, status, batch_size)
    status = status.reshape(batch_shape)
    if reduce is None:  # (B, T, C) -> channel: batch_shape + (T,)
        outputs = {ch: out[:, :, i].reshape(batch_shape + (ts_np.size,)) for i, ch in enumerate(channels)}
    else:
        outputs = {ch: out[:, i].reshape(batch_shape) for i, ch in enumerate(channels)}
    return SweepResult(over=values, t=ts_np, channels=channels, outputs=outputs, status=status, dt=dt, method=method)


_STRUCTURES = {}


def _structure(system, y0):
    """(initial-state shapes, output channel names) of a system, traced once per system structure."""
    key = (jtu.tree_structure(system), None if y0 is None else jtu.tree_structure(y0))
    if key not in _STRUCTURES:
        def probe():
            state = system.initial_state() if y0 is None else y0
            return state, system.outputs(jnp.zeros(()), state, jnp.asarray(0.5))

        state, outs = jax.eval_shape(probe)
        _STRUCTURES[key] = (state, [*outs, "command"])
    state, channels = _STRUCTURES[key]
    return (state if y0 is None else y0), channels


@eqx.filter_jit
def _jacobians(system, signal, y0, plan, values, t0):
    """Each lane's Jacobian of the scaled vector field at its initial state [1/s] (eigenvalues taken on the host,
    as not every backend has a non-symmetric eigensolver)."""

    def lane(vals):
        sys_l, sig_l, y0_l = _make_lane(system, signal, y0, plan, vals)
        scale = sys_l.state_scale()
        z0, unravel = ravel_pytree(jtu.tree_map(lambda a, s: a / s, y0_l, scale))

        def field(t, z):
            y = jtu.tree_map(lambda a, s: a * s, unravel(z), scale)
            dy = sys_l.vector_field(t, y, sig_l(sys_l.valve.command_time(t)))
            return ravel_pytree(jtu.tree_map(lambda a, s: a / s, dy, scale))[0]

        return jax.jacfwd(lambda z: field(t0, z))(z0)

    return jax.vmap(lane)(values)
