"""`sweep`: one compiled, vmapped call over a batch of inputs and parameter values, chunked and sharded.

A sweep point ("lane") is the base system and signal with some leaves replaced, named by path
(`"valve.supply_pressure"`, `"payload_mass"`, `"signal.value"`, `"y0.pressure"`). Lanes integrate in lockstep with a
fixed-step scheme (`pamjax._solve.fixed_step`), so no lane waits for another; outputs are kept whole or reduced on the
fly (`FinalValue`, `WindowMean`, `FourierCoefficient`). A failed lane gets a status code and NaN outputs; the others
are unaffected.

By concern: the plan of swept paths and the checks of their values (`plan`), one lane and the compiled call over a
chunk of lanes with the scheme and step (`lanes`), the reductions (`reductions`), the spread over devices, calls and
processes (`sharding`), the result (`result`); this module is the front end.
"""

import inspect
import time
from collections.abc import Callable, Sequence
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import floats_as_arrays
from .._core.custom_types import RealArrayLike, RealScalarLike, TimesLike
from .._core.errors import PamjaxInputError, check_count, check_progress, check_time_grid, require_float64
from .._core.fastjit import keyed_by_code
from .._physics.signals import AbstractSignal
from .._solve import fixed_step as _fixed_step
from .._solve.simulate import solve
from .._systems.base import AbstractSystem
from .lanes import (
    channel_shapes,
    checked_rk4_step,
    chunk_program,
    hybrid_method_and_step,
    jacobians,
    method_and_step,
    run_lanes,
)
from .plan import host_lanes, make_plan, make_signal, structure, validate_values
from .reductions import AbstractReduction
from .result import SUCCESS, SweepResult, in_point_order, sweep_identity
from .sharding import Layout, check_devices, device_of, gather_processes, local_part, mesh_of, put


def sweep(
    system: AbstractSystem,
    signal: AbstractSignal | Callable[[dict[str, Any]], AbstractSignal],
    ts: TimesLike,
    over: dict[str, RealArrayLike],
    *,
    y0: eqx.Module | None = None,
    reduce: AbstractReduction | None = None,
    channels: Sequence[str] | None = None,
    method: Literal["auto", "rodas5a", "rk4", "ros2", "ros2a", "adaptive"] = "auto",
    dt: RealScalarLike | None = None,
    chunk_size: int | None = None,
    devices: Sequence[jax.Device] | jax.sharding.Mesh | None = None,
    progress: bool | Callable[[str], object] = True,
    solve_options: dict[str, Any] | None = None,
    gather: Literal["all", "local"] = "all",
) -> SweepResult:
    """Simulate `system` at every point of a batch of inputs and parameter values, as one compiled vmapped call.

    Each point replaces some leaves of the base system, signal or initial state, named by path. All points step in
    lockstep with a fixed-step scheme, so the batch costs what one point costs times the batch size over the vector
    width; outputs are kept whole or reduced on the fly. A failed point gets a status code and NaN outputs, without
    raising and without affecting the others.

    **Arguments:**

    - `system`: the base system (`MuscleSystem`, `TankSystem`, ...).
    - `signal`: the base command signal (`Constant(0.5)`, `Sine(...)`), or a factory `values -> signal` called per
      point with the dict of that point's swept values (for keys that are not paths). A factory written inline (a
      `lambda` in a loop) reuses the compiled program of an earlier one with the same code reading the same values.
    - `ts`: concrete, strictly increasing output times [s]; the solve starts at `ts[0]` and steps land on every
      output time (so no step exceeds the spacing of `ts`).
    - `over`: `{path: values}`. Paths name a leaf of the system (`"payload_mass"`, `"valve.supply_pressure"`,
      `"friction.coulomb_force"`, `"muscle.force_law.k0"`), of the signal (`"signal.value"`,
      `"signal.frequency"`) or of the initial state (`"y0.pressure"` [Pa abs]: without `y0`, an argument of
      `system.initial_state`, so the payload starts in equilibrium at that pressure; with `y0`, its leaf); with a
      signal factory any other name is passed to the factory, which must read it (a key it never reads, such as a
      misspelt parameter path, is refused with the nearest leaf's path). Values broadcast together (NumPy rules) to
      the batch shape, so `{"signal.value": u[:, None], "valve.supply_pressure": p[None, :]}` is a grid; a
      non-scalar leaf takes its own shape as trailing axes.
    - `y0`: base initial state (default: each point's `system.initial_state()`, at rest in equilibrium).
    - `reduce`: None (whole trajectories at `ts`), `FinalValue()`, `WindowMean(window)` or
      `FourierCoefficient(periods, frequency)`.
    - `channels`: output channels to keep (default: all the system's outputs and "command").
    - `method`: "auto" (default: "rodas5a" for a continuous valve, "rk4" for a switching one), "rodas5a" (RODAS5, an
      L-stable Rosenbrock method of order 5, under per-lane error control at rtol = atol = 1e-5 on the scaled state,
      every output time landed on exactly: accurate along the whole trajectory and fastest for a stiff plant, as a
      sticking payload makes it; on the 1,024-duty MAS-10 map within 5e-5 Pa and 4e-10 m of a tight solve, `dt` its
      first step), "rk4" (fixed steps, accurate along the whole trajectory; its step is bounded by the plant's stiffest
      eigenvalue, which for paper 000's friction is also the time scale of the stick-slip transitions; the PWM valve's
      smoothed edges bound any scheme's step, and fixed steps keep the lanes in lockstep), "ros2" (L-stable Rosenbrock
      at a fixed step 3x larger: for steady-state maps, where only settled values matter; it smears the fast transients,
      82-456 um and 0.1-2.7 kPa at t = 0.1 s on the MAS-10), "ros2a" (ROS2 under per-lane error control, rtol = atol
      = 1e-3: a quick steady-state map, within about 1 Pa and 10 um of RK4 on the MAS-10 map, tens of um with coarse
      output grids), or "adaptive"
      (vmapped diffrax Tsit5, a slow reference; `solve_options` go to it, and to no other method). A hybrid system
      (stick-slip friction, `KarnoppFriction`) is integrated as `simulate` integrates it, each lane on the fixed RK4
      grid with the stick/slip events located inside the step (method "grid" for a continuous valve, "pwm" on the
      PWM-synchronous grid for a switching one): "auto" or "rk4" (`dt` the grid step) only; the schemes that do not see
      the events are refused. So is a valve with exact edges (`OnOffValve(mode="exact")`): on the PWM-synchronous grid,
      its edges nodes of the grid, as `simulate(..., stepping="pwm")` (a fixed RK4 step straddling its jumps was 90-180
      Pa off after 2 s).
    - `dt`: the fixed step [s] (the first step for "rodas5a"/"ros2a"; not with "adaptive": its first step is
      `solve_options={"dt0": ...}`). Default: RK4 at 2.5 / (largest |eigenvalue| of the Jacobian at the initial
      states) (its stability limit with a 10 % margin), "rodas5a"'s first step 1 ms,
      the others 5 ms; all capped at 2 PWM edge widths for a switching valve and at 1/100 of the shortest period of
      the points' signals (`cycle_frequency()`); and at the spacing of `ts` (the result's `dt` is the longest step
      taken). With a continuous valve RK4's default is then halved until it and its half agree on 4 lanes within
      200 Pa and 20 um (a plant that stiffens as it moves). A command's jumps (`Step`) are step boundaries of every
      method, as in `simulate`. Check a fixed-step result by halving the result's `dt`.
    - `chunk_size`: points per device per compiled call (memory bound). Default (`default_chunk_size`): all points
      split evenly over the devices, at most 8,192 per call on CPU, on a GPU/TPU as many as 1 GiB of outputs per
      device holds (one call is fastest there). The last call is padded. Results are bitwise the same for the same
      number of devices, in one process or several; with `chunk_size` given, for any 2 or more devices; between
      one device and several, to round-off (~1e-16 relative: XLA optimises a one-device program differently).
    - `devices`: None (all of `jax.devices()`: the batch axis is sharded over them with a `Mesh` and
      `NamedSharding`, each device running its own lanes under `shard_map`; after
      `pamjax.runtime.initialize_distributed()` (or `jax.distributed.initialize()`) the devices of every process, each
      process computing its devices' points), a list of distinct devices (one device: the sweep runs there), or a
      1-D `Mesh` whose axis is named "batch".
    - `solve_options`: with `method="adaptive"` only, keyword arguments of its solve (`rtol`, `atol`, `max_steps`,
      `dt0`, `solver`, ...: `simulate`'s).
    - `progress`: True (print one line per chunk when there are several; process 0 only), False, or a callable
      taking a string.
    - `gather`: "all" (default: every process returns the whole result, gathered once at the end) or "local" (each
      process returns the points it computed, flat, with their indices in `points`: for batches larger than one
      host's memory; `merge_sweep_shards` joins them).

    **Returns:** a `SweepResult` (`over`, `t`, `outputs[channel]`, `status`, `dt`, `method`, `reduction`,
    `identity`: a digest of the whole sweep that every process's shard shares; `points` with `gather="local"`).

    **Raises:** `PamjaxInputError` naming the argument (unknown path, values that break a component's constraint,
    a start pressure that is not ABSOLUTE [Pa] > 0, a command outside the valve's range, bad `ts`/`dt`/`chunk_size`/
    `channels`/`devices`, `solve_options` with a method that takes none or an option `simulate` does not have, a
    reduction's window longer than the run or a frequency that is not > 0), before any solve.
    """
    require_float64("pamjax.sweep")
    system = floats_as_arrays(system)  # a value set with eqx.tree_at: an argument, not a constant of the program
    _check_arguments(system, signal, ts, over, method, dt, chunk_size, gather, reduce)
    check_progress(progress)
    devices, chunk_size = _check_run_options(method, dt, solve_options, devices, chunk_size)
    channels = channel_names(channels)
    if not isinstance(signal, AbstractSignal):  # a factory written inline: the program of an equal one is reused
        signal = keyed_by_code(signal)
    ts_np = np.asarray(ts, dtype=float)
    base_state, available = structure(system, y0)  # shapes only: no solve yet
    plan, values, batch_shape = make_plan(system, signal, base_state, over, y0_given=y0 is not None)
    batch_size = int(np.prod(batch_shape))
    validate_values(system, signal, y0, plan, values, batch_size)
    flat = {k: np.ascontiguousarray(v.reshape((batch_size,) + s))
            for (k, v), s in zip(values.items(), plan.leaf_shapes)}
    if reduce is not None:  # its window against the run, every lane's frequency (on the host, before any solve)
        reduce.check(ts_np, lambda: host_lanes(system, signal, plan, flat, batch_size))
    shapes = channel_shapes(system, signal, y0, plan, {k: jnp.asarray(v[0]) for k, v in flat.items()},
                            float(ts_np[0]))
    scalars = [c for c in available if shapes.get(c, ()) == ()]  # a sweep maps scalar channels (not a joint's pair)
    channels = tuple(scalars) if channels is None else tuple(channels)
    for c in channels:
        if c not in available:
            raise PamjaxInputError(f"unknown channel {c!r}; this system has {available}")
        if c not in scalars:
            raise PamjaxInputError(f"channel {c!r} of this system has shape {shapes[c]} per point; a sweep maps "
                                   f"scalar channels: choose among {scalars}")
    method, dt, grid = _scheme(system, signal, y0, plan, flat, ts_np, method, dt)
    counts = np.zeros(0, dtype=np.int64)
    if method != "adaptive" and not grid:  # no step longer than the output spacing: the step used is reported (a dt
        # of 5 s on a 1 ms grid was reported as 5 s; halving 2 ms -> 1 ms there changed nothing, unseen)
        counts, steps = _fixed_step.step_counts(ts_np, dt)
        dt = float(np.max(steps))
    config = (method, tuple(int(c) for c in counts), channels, reduce, tuple(sorted((solve_options or {}).items())),
              grid)
    record = dict(reduction=repr(reduce), identity=_identity(system, signal, y0, plan, flat, batch_shape, ts_np, config,
                                                             dt))
    mesh, device = mesh_of(devices), device_of(devices)
    layout = Layout.plan(batch_size, chunk_size, mesh, devices,
                         len(channels) * (1 if reduce is not None else ts_np.size) * 2)  # x2: complex
    points, out, status = _run_calls(system, signal, y0, flat, ts_np, plan, config, (mesh, device), layout, progress)
    if gather == "local":
        return SweepResult(over={k: v[points] for k, v in flat.items()}, t=ts_np, channels=channels,
                           outputs={ch: out[..., i] for i, ch in enumerate(channels)},  # (n,) or (n, T) per channel
                           status=status, dt=dt, method=method, points=points, batch_shape=batch_shape, **record)
    if layout.processes > 1:
        points, out, status = gather_processes(points, out, status)
    out, status = in_point_order(points, out, status, batch_size)
    if reduce is None:  # (B, T, C) -> channel: batch_shape + (T,)
        outputs = {ch: out[:, :, i].reshape(batch_shape + (ts_np.size,)) for i, ch in enumerate(channels)}
    else:
        outputs = {ch: out[:, i].reshape(batch_shape) for i, ch in enumerate(channels)}
    return SweepResult(over=values, t=ts_np, channels=channels, outputs=outputs, status=status.reshape(batch_shape),
                       dt=dt, method=method, **record)


def _identity(system, signal, y0, plan, flat, batch_shape, ts_np, config, dt):
    """`SweepResult.identity` of the whole sweep (`sweep_identity`), before its points are spread over processes: a
    factory by the signals it builds at the first and last points (a function's own text holds no values)."""
    if not isinstance(signal, AbstractSignal):
        signal = [make_signal(signal, plan, {k: v[i] for k, v in flat.items()}) for i in (0, -1)]
    method, counts, channels, reduce, solve_options, grid = config
    return sweep_identity(system=system, signal=signal, y0=y0, over=(dict(flat), batch_shape), reduce=reduce,
                          settings=(method, float(dt), counts, channels, solve_options, grid, ts_np))


def _scheme(system, signal, y0, plan, flat, ts_np, method, dt):
    """(method, dt, grid) of a sweep: a hybrid system's or an exact-edge valve's fixed grid as `simulate`'s
    (`hybrid_method_and_step`), else the scheme and step of `method_and_step`, RK4's default step on a continuous
    valve checked against its half (`checked_rk4_step`; a switching valve's is set by its edges); grid None."""
    if system.hybrid or system.valve.exact_edges:  # stick-slip friction or exact edges: simulate's fixed grid
        return hybrid_method_and_step(system, signal, flat, plan, method, dt, ts_np)
    batch_size = len(next(iter(flat.values())))

    def stiffness():
        sample = np.unique(np.linspace(0, batch_size - 1, min(batch_size, 64)).astype(int))
        vals = {k: jnp.asarray(v[sample]) for k, v in flat.items()}
        return float(np.nanmax(np.abs(np.linalg.eigvals(np.asarray(jacobians(system, signal, y0, plan, vals,
                                                                                float(ts_np[0])))))))

    chosen, step = method_and_step(system, signal, flat, plan, method, dt, stiffness)
    if chosen == "rk4" and dt is None and not system.valve.switches:
        step = checked_rk4_step(system, signal, y0, plan, flat, ts_np, step)
    return chosen, step, None


def _check_arguments(system, signal, ts, over, method, dt, chunk_size, gather, reduce):
    """`PamjaxInputError` for a bad argument of `sweep`, naming it (the swept values are checked by the plan)."""
    if not isinstance(system, AbstractSystem):
        raise PamjaxInputError(f"system must be a pamjax system (MuscleSystem, TankSystem, ...), got {type(system)}")
    if not isinstance(signal, AbstractSignal) and not callable(signal):
        raise PamjaxInputError(f"signal must be a pamjax signal or a factory values -> signal, got {type(signal)}")
    check_time_grid(ts, "ts")
    if np.asarray(ts, dtype=float).size < 2:
        raise PamjaxInputError("ts needs at least two times (the sweep starts at ts[0])")
    if not isinstance(over, dict) or not over:
        raise PamjaxInputError(f"over must be a non-empty dict {{path: values}}, got {over!r}")
    if method not in ("auto", "adaptive", *_fixed_step.SCHEMES):
        raise PamjaxInputError(
            f"method must be 'auto', 'rodas5a', 'rk4', 'ros2', 'ros2a' or 'adaptive', got {method!r}")
    if dt is not None and not (np.isfinite(dt) and dt > 0):
        raise PamjaxInputError(f"dt must be a step > 0 [s], got {dt}")
    if chunk_size is not None:
        check_count(chunk_size, "chunk_size", "a positive integer (points per device per call; not a bool)")
    if gather not in ("all", "local"):
        raise PamjaxInputError(f"gather must be 'all' or 'local', got {gather!r}")
    if reduce is not None and not isinstance(reduce, AbstractReduction):
        raise PamjaxInputError(f"reduce must be None, FinalValue(), WindowMean(window) or FourierCoefficient(...), "
                               f"got {reduce!r}")


# What `solve_options` may hold: `solve`'s keywords, less those each adaptive lane sets itself
_ADAPTIVE_OPTIONS = tuple(sorted(set(inspect.signature(solve).parameters) - {"system", "signal", "ts", "y0", "t0",
                                                                              "throw"}))


def _check_run_options(method, dt, solve_options, devices, chunk_size):
    """(`devices` checked by `check_devices`, `chunk_size` as an int or None), or `PamjaxInputError` for solver
    settings the chosen method would ignore or reject after the planning: options with a fixed-step method (every
    method but "adaptive": a tolerance there changed nothing, unseen), an unknown option's name (a raw TypeError from
    inside the solve), a `dt` with "adaptive" (its step is chosen by diffrax; the result's dt was NaN)."""
    if solve_options is not None and not isinstance(solve_options, dict):
        raise PamjaxInputError(f"solve_options must be None or a dict of simulate's options, got {solve_options!r}")
    if solve_options and method != "adaptive":
        raise PamjaxInputError(f"solve_options {sorted(solve_options)} go to method='adaptive' only; method={method!r} "
                               "takes none (its step is dt, its tolerances fixed: see sweep's method)")
    unknown = sorted(set(solve_options or {}) - set(_ADAPTIVE_OPTIONS))
    if unknown:
        raise PamjaxInputError(f"unknown solve_options {unknown}; valid: {list(_ADAPTIVE_OPTIONS)}")
    if method == "adaptive" and dt is not None:
        raise PamjaxInputError("dt is the step of the fixed-step methods; method='adaptive' chooses its own steps: "
                               "drop dt (its first step is solve_options={'dt0': ...})")
    return check_devices(devices), None if chunk_size is None else int(chunk_size)  # a NumPy integer too


def channel_names(channels):
    """`channels` as a tuple of names (None: the default), or `PamjaxInputError` naming it: a bare string would be
    read letter by letter ("unknown channel 'p'"), an empty one would stack no outputs."""
    if channels is None:
        return None
    names = tuple(channels) if not isinstance(channels, str) and np.iterable(channels) else None
    if not names or not all(isinstance(c, str) for c in names):
        example = f"({channels!r},)" if isinstance(channels, str) else '("pressure", "position")'
        raise PamjaxInputError(f"channels must be None or a non-empty sequence of channel names such as {example}, "
                               f"got {channels!r}")
    return names


def _run_calls(system, signal, y0, flat, ts_np, plan, config, placement, layout, progress):
    """Every compiled call of the layout; (points, outputs, status) of this process's devices, in call order. One
    progress line per call when there are several (process 0 only). `placement`: (the mesh, or None; without one,
    the one device given, or None for the default)."""
    mesh, device = placement
    say = (print if progress is True else progress) if progress else None
    if say is not None and jax.process_index() != 0:
        say = None  # one report per sweep, from process 0
    pieces = []
    ts_j = jnp.asarray(ts_np)
    for c in range(layout.calls):
        start = time.perf_counter()
        index, valid = layout.lanes_of_call(c)
        vals = {k: put(v[index], mesh, device) for k, v in flat.items()}
        platform = next(iter(next(iter(vals.values())).devices())).platform  # where the lanes were put
        out, status = run_lanes(platform, chunk_program(platform), system, signal, y0, vals, ts_j, plan, config, mesh)
        pieces.append(local_part(out, status, index, valid))
        if say is not None and layout.calls > 1:
            first, last = layout.points_of_call(c)
            failed = int(np.sum(pieces[-1][2] != SUCCESS))
            mine = "" if layout.processes == 1 else f" (of its {len(pieces[-1][0])} points on process 0)"
            say(f"sweep: chunk {c + 1}/{layout.calls}, points {first}-{last}, "
                f"{time.perf_counter() - start:.2f} s, {failed} failed{mine}")
    return tuple(np.concatenate(part) for part in zip(*pieces))
