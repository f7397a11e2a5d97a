"""`simulate`: one jitted, differentiable diffrax solve of a system driven by a command signal."""

import contextlib
from typing import TYPE_CHECKING, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.arrays import device_array, kept_on_device
from .._core.custom_types import ArrayLike, Real, RealScalarLike, TimesLike
from .._core.errors import PamjaxInputError, PamjaxSolveError, check_time_grid, require_float64
from .._core.fastjit import filter_jit
from .._core.private import diffrax_result_code, equinox_errors_as_nan, jax_at_top_level
from .._core.xla_cpu import compiled_with, single_trajectory_options
from .._physics.signals import AbstractSignal
from .._physics.tabulated import prepared_tables
from .._systems.base import AbstractSystem
from . import chunks as _chunks, synchronous as _sync
from .checks import (
    check_parameters,
    check_positive_number,
    check_start_state,
    naming_batched,
    prepared,
    resolve_stepping,
    runtime_checks,
    vacuum,
)
from .edges import ScheduledValve, StartsOff, command_jumps
from .hints import default_max_steps, failure_hint, fixed_step_hint, negative_inflow
from .scaled import scaled
from .trajectory import (
    RESULT_NONFINITE,
    RESULT_NONPHYSICAL,
    Trajectory,
    fixed_grid_trajectory,
    result_message,
    trajectory,
)

if TYPE_CHECKING:  # annotations only: importing diffrax costs ~0.4 s that fixed-grid work never needs
    import diffrax as dfx

Stepping = Literal["auto", "adaptive", "pwm", "grid"]

_DEFAULT_SUBSTEPS = 16  # RK4 nodes per PWM period: step ≤ 1.25 ms at 50 Hz (docs/performance.md)
# s, stepping="grid": RK4 step of a hybrid system fed by a continuous valve; 1 ms puts paper 000's muscle-payload
# mode (~7 Hz) at ωh ≈ 0.045, as the PWM grid's 1.25 ms does (docs/performance.md).
_DEFAULT_GRID_STEP = 1e-3


def _is_traced(tree):
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jtu.tree_leaves(tree))


def solve(
    system: AbstractSystem,
    signal: AbstractSignal,
    ts: TimesLike,
    y0: eqx.Module | None,
    t0: RealScalarLike,
    *,
    solver: "dfx.AbstractSolver | None" = None,
    rtol: RealScalarLike = 1e-6,
    atol: RealScalarLike = 1e-6,
    max_steps: int = 200_000,
    dt0: RealScalarLike | None = None,
    adjoint: "Literal['forward', 'reverse'] | dfx.AbstractAdjoint | None" = None,
    jump_ts: Real[ArrayLike, " jumps"] | None = None,
    throw: bool = False,
    stepping: Stepping = "adaptive",
    substeps: int = _DEFAULT_SUBSTEPS,
    num_periods: int | None = None,
    grid_step: RealScalarLike = _DEFAULT_GRID_STEP,
    starts_off: bool = True,
) -> Trajectory:
    """The unchecked, traceable core of `simulate` (vmap- and grad-safe; no Python-side validation).

    `atol` applies to the scaled state (pressure in units of 1e5 Pa, position in 1e-2 m, ...: `state_scale`).
    `stepping="pwm"` integrates on the PWM-synchronous grid (`pamjax._solve.synchronous`), `stepping="grid"` on a
    uniform grid of at most `grid_step` [s]; inside jit they need the static `num_periods` (PWM periods covering [t0,
    ts[-1]], or grid steps). Adaptive stepping puts step boundaries either side of every smoothed switching edge
    (`EdgeClipController`), as `simulate` does (no `num_periods` needed). Two differ (`simulate` reads concrete times):
    an `OnOffValve(mode="exact")` gets its switching schedule computed here only from concrete arguments (traced ones
    are refused: use mode="smooth" or stepping="pwm"); for a continuous valve whose command jumps (a `Step`, a
    `Sampled` hold) pass `jump_ts` = `signal.jump_times()` inside (t0, ts[-1]), sorted, as `simulate` does, else the
    solver may step over a jump (~350 Pa off). `starts_off`: a switching valve's previous PWM period is off at `t0` (a
    run from rest); False reads the signal's own value there (a closed loop continuing period by period).
    """
    ts = jnp.asarray(ts, dtype=float)
    system = prepared_tables(system)  # interpolants' tables once, ahead of the loop (pamjax._physics.tabulated)
    y0 = system.initial_state() if y0 is None else y0
    stepping = resolve_stepping(system, stepping)
    if stepping in ("pwm", "grid"):
        return _solve_fixed(system, signal, ts, y0, t0, stepping, substeps, num_periods, grid_step, throw)
    if system.valve.exact_edges:  # its switching times handed to the solver, as `simulate` does (concrete only)
        system, jump_ts = _scheduled(system, signal, t0, ts[-1])
    if system.valve.switches and starts_off:  # the valve is off before the run (as the PWM grid and the schedule)
        signal = StartsOff(signal, system.valve.command_time(t0))
    edge_clip = system.valve.smooth_edges  # simulate's default (it passes `_EDGE_CLIP`): unclipped, 1.5 kPa off
    controller = _controller(system, signal, ts, rtol, atol, jump_ts, edge_clip)
    import diffrax as dfx  # here, not at the top: importing diffrax costs ~0.4 s that fixed-grid work never needs

    if isinstance(adjoint, str):
        adjoint = {"forward": dfx.ForwardMode(), "reverse": dfx.RecursiveCheckpointAdjoint()}[adjoint]
    adjoint = dfx.RecursiveCheckpointAdjoint() if adjoint is None else adjoint
    return _solve_adaptive(system, signal, ts, y0, t0, dfx.Tsit5() if solver is None else solver, controller,
                           max_steps, dt0, adjoint, throw)


def _controller(system, signal, ts, rtol, atol, jump_ts, edge_clip):
    """The PID step-size controller of an adaptive solve.

    dtmax: a switching valve's windows must not be stepped over (its `max_step`). dtmin without forcing: a state that
    turns non-finite makes every trial step fail, and the solve stops within a few dozen rejections (result
    "dt_min_reached") instead of grinding to max_steps and holding up a batch. With jump times (the exact valve's
    edges) no dtmin: a step that ends a few ulps short of an edge is followed by a step of a few ulps up to it, which
    the dtmin test would take for a failure (E4 of the hybrid bench failed so at every rtol above 1e-9). Without them,
    dtmin, 50 eps·|t1| (50-100 ULP of t1), stays below the shortest step diffrax itself takes: a last step that lands
    short of t1 by more than 100 ULP (diffrax snaps closer ones to t1, `FirstStepToEnd` the first step too) is taken
    as a sliver, and the controller's next proposal grows from it. A fixed 1e-12 s failed runs resting at dtmax
    ("minimum step size reached" at t1: the exact valve at duty 0 over 2.5 s); 50 eps·max(|t1|, 1 s) was 800 ULP
    of t1 = 0.07 s (a sliver of 100-800 ULP would fail). At least the smallest normal float: > 0 where t1 = 0."""
    import diffrax as dfx

    from .edge_clip import EdgeClipController, FirstStepToEnd

    finfo = jnp.finfo(float)
    dtmin = None if jump_ts is not None else jnp.maximum(50 * finfo.eps * jnp.abs(ts[-1]), finfo.tiny)
    # dtmax out of the gradient, as diffrax holds its step sizes (a step at dtmax = T/10 would carry the PWM
    # frequency's tangent into the step times, and a gradient with respect to it blew up: -1e17 over 0.2 s)
    dtmax = jax.lax.stop_gradient(system.valve.max_step())
    controller = FirstStepToEnd(rtol=rtol, atol=atol, dtmax=dtmax, dtmin=dtmin, force_dtmin=False)
    if edge_clip:  # steps end either side of every smoothed switching edge (the valve's next_edge_step)
        controller = EdgeClipController(controller, system.valve, signal)
    if jump_ts is not None:
        controller = dfx.ClipStepSizeController(controller, jump_ts=jump_ts)
    return controller


def _solve_adaptive(system, signal, ts, y0, t0, solver, controller, max_steps, dt0, adjoint, throw):
    """One `diffrax.diffeqsolve` of the flat scaled state (`pamjax._solve.scaled`), saved at `ts`."""
    import diffrax as dfx

    valve = system.valve
    z0, scaled_state = scaled(system, y0)

    @jax.jit
    def vector_field(t, z):
        return scaled_state.field(system, t, z, valve.read_command(signal, t))

    def field(t, z, args):
        return vector_field(t, z)

    sol = dfx.diffeqsolve(
        dfx.ODETerm(field),
        solver,
        t0=t0,
        t1=ts[-1],
        dt0=dt0,
        y0=z0,
        saveat=dfx.SaveAt(ts=ts),
        stepsize_controller=controller,
        max_steps=max_steps,
        adjoint=adjoint,
        throw=throw,
    )
    states = jax.vmap(scaled_state.state)(sol.ys)
    commands = jax.vmap(lambda t: signal(valve.command_time(t)))(ts)
    outs = jax.vmap(lambda t, y: system.outputs(t, y, valve.read_command(signal, t)))(ts, states)
    result = jnp.asarray(diffrax_result_code(sol.result))
    finite = jnp.all(jnp.isfinite(sol.ys))
    result = jnp.where((result == 0) & ~finite, RESULT_NONFINITE, result)
    stats = sol.stats
    return trajectory(
        ts, states, commands, outs, stats["num_steps"], stats["num_accepted_steps"], stats["num_rejected_steps"], result
    )


def _solve_fixed(system, signal, ts, y0, t0, stepping, substeps, size, grid_step, throw):
    if size is None:
        if _is_traced((ts, t0)):
            raise PamjaxInputError(
                f"stepping='{stepping}' inside jit needs num_periods (a static int: PWM periods covering [t0, ts[-1]], "
                "or grid steps); pamjax.simulate computes it for you"
            )
        size = fixed_grid_size(system, stepping, t0, ts[-1], grid_step)
    z0, scaled_state = scaled(system, y0)
    (states, num_steps, finite), = _sync.solve_runs(
        [system], [signal], [ts], [z0], scaled_state, [t0], stepping=stepping, substeps=substeps, sizes=[size]
    )
    traj = fixed_trajectory(system, signal, ts, t0, states, num_steps, finite, stepping)
    if throw:
        traj = eqx.error_if(traj, ~finite, "fixed-grid stepping produced a non-finite state; refine the grid")
    return traj


def fixed_grid_size(system, stepping, t0, t1, grid_step=None):
    """The static size of a fixed grid over [t0, t1]: PWM periods ("pwm") or uniform steps ("grid")."""
    if stepping == "pwm":
        return _sync.num_periods(system.valve, t0, t1)
    return _sync.num_grid_steps(t0, t1, _DEFAULT_GRID_STEP if grid_step is None else grid_step)


def fixed_trajectory(system, signal, ts, t0, states, num_steps, finite, stepping):
    """The `Trajectory` of a fixed-grid solve from its states at `ts` (on the PWM-synchronous grid: the duties latched
    per period, the valve held at its exact-edge opening for the outputs)."""
    if stepping == "pwm":
        commands = _sync.latched_commands(system.valve, signal, ts)
        outs = _sync.outputs_at(system, signal, ts, states, commands, t0)
    else:
        commands = jax.vmap(signal)(ts)
        outs = jax.vmap(system.outputs)(ts, states, commands)
    return fixed_grid_trajectory(ts, states, commands, outs, num_steps, finite)


_solve_jit = eqx.filter_jit(solve)
_SOLVE_TOP = {}  # compiler options (as a sorted tuple, or None) → `solve` jitted with them, for top-level calls


def _solve_program():
    """The jitted `solve` for this call: outside any transformation with the single-trajectory compiler options
    (`pamjax._core.xla_cpu.single_trajectory_options`: a 25-35 % shorter compilation at the same run time) and the
    cheaper dispatch of `pamjax._core.fastjit` (~0.1 ms less per call); under jit, vmap or grad the plain
    `equinox.filter_jit`, whose compilation the enclosing transformation decides (JAX takes compiler options on a
    top-level jit only, and a vmapped solve runs faster with XLA's default emitters)."""
    if not jax_at_top_level():
        return _solve_jit
    return compiled_with(_SOLVE_TOP, filter_jit, solve, single_trajectory_options())


def validate(system, signal, ts, y0=None, t0=None):
    """Concrete checks of everything `simulate` is given, before any solve. Raises `PamjaxInputError`."""
    require_float64("pamjax.simulate")
    if not isinstance(system, AbstractSystem):
        raise PamjaxInputError(f"system must be a pamjax system (TankSystem, MuscleSystem, ...), got {type(system)}")
    if not isinstance(signal, AbstractSignal):
        raise PamjaxInputError(f"signal must be a pamjax signal (Constant, Triangle, ...), got {type(signal)}")
    if shape := type(signal).command_shape(signal):  # a sweep's batch (diffrax's raw broadcasting error otherwise)
        raise PamjaxInputError(f"{type(signal).__name__} holds commands of shape {shape}: simulate takes one number "
                               "at each time (Constant(0.5)); several values are a sweep (pamjax.sweep or jax.vmap)")
    check_time_grid(ts, "ts")
    if t0 is not None and not _is_traced(t0) and not np.isfinite(float(t0)):  # (-inf overflowed the step budget)
        raise PamjaxInputError(f"t0 must be finite (no NaN or inf), got {t0}")
    if _is_traced(ts):  # inside jit: shape checks only; values were (or can only be) checked outside
        ts_np = np.zeros(jnp.shape(ts))
    else:
        ts_np = np.asarray(ts, dtype=float)
        if t0 is not None and not _is_traced(t0) and not float(t0) <= ts_np[0]:
            raise PamjaxInputError(f"t0 ({t0}) must not exceed ts[0] ({ts_np[0]})")
    if t0 is None and ts_np.size < 2:
        raise PamjaxInputError("ts needs at least two times when t0 is not given (the solve starts at ts[0])")
    if not _is_traced(signal):  # a traced signal (e.g. grad w.r.t. the duty) has no concrete bounds to check
        lo, hi = type(signal).bounds(signal)  # not `signal.bounds`: equinox makes a bound method a module (~80 µs)
        clo, chi = system.command_range
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise PamjaxInputError(f"signal must be finite, its bounds are ({lo}, {hi})")
        if lo < clo - 1e-12 or hi > chi + 1e-12:
            percent = (clo == 0 and chi == 1 and lo >= 0 and 1 < hi <= 100)  # a duty of 50 meant as 50 %
            raise PamjaxInputError(
                f"signal (the valve command, e.g. duty ratio) must stay within [{clo}, {chi}], "
                f"its range is [{lo}, {hi}]" + (f"; that looks like percent: a duty ratio of {hi / 100:g} is "
                                                f"written {hi / 100:g}, not {hi:g}" if percent else "")
            )
    check_parameters(system)  # a system changed with eqx.tree_at skipped its components' checks
    check_start_state(system, y0)  # y0's pressures (not bar, not gauge) and positions (not mm, inside the stroke)


def default_solver(system: AbstractSystem) -> "dfx.AbstractSolver":
    """`simulate`'s solver for `system`: `Rodas5()` for a continuous valve (no switching edges), else `Tsit5()`.

    Measured on paper 000's 25 s triangle run at rtol = atol = 1e-6 (benchmarks/simulate.py, RESULTS.md): averaged
    valve Tsit5 3,170 steps in 2.4 ms, Rodas5 805 in 1.1 ms (stick phases no longer bound the step); smoothed PWM
    valve Tsit5 38,908 steps in 31 ms, Rodas5 43,781 in 65 ms (the 0.1 ms edges bound both).
    """
    if not _SOLVERS:  # stateless, immutable: built once, not per call (and diffrax imported then, not before)
        import diffrax as dfx

        from .rodas_solver import Rodas5

        _SOLVERS.update(tsit5=dfx.Tsit5(), rodas5=Rodas5())
    return _SOLVERS["tsit5"] if system.valve.switches else _SOLVERS["rodas5"]  # (max_step() would run 1/f eagerly)


_SOLVERS = {}


def simulate(
    system: AbstractSystem,
    signal: AbstractSignal,
    ts: TimesLike,
    *,
    y0: eqx.Module | None = None,
    t0: RealScalarLike | None = None,
    solver: "dfx.AbstractSolver | None" = None,
    rtol: RealScalarLike = 1e-6,
    atol: RealScalarLike = 1e-6,
    max_steps: int | None = None,
    dt0: RealScalarLike | None = None,
    adjoint: "Literal['forward', 'reverse'] | dfx.AbstractAdjoint | None" = None,
    throw: bool = True,
    stepping: Stepping = "auto",
    substeps: int = _DEFAULT_SUBSTEPS,
    grid_step: RealScalarLike = _DEFAULT_GRID_STEP,
) -> Trajectory:
    """Simulate `system` driven by `signal` and return its channels at the times `ts`.

    The whole solve is one jitted `diffrax.diffeqsolve` in float64, differentiable in forward mode
    (`adjoint="forward"`, for Jacobians as in least squares) and reverse mode (the default, for scalar losses).

    **Arguments:**

    - `system`: a `TankSystem`, `MuscleSystem`, ... (its components carry every physical parameter).
    - `signal`: the command, e.g. `Constant(0.5)` or `Triangle(0.05, 0.95, 0.08)` (PWM duty ratio in [0, 1]).
    - `ts`: strictly increasing output times [s]. The solve starts at `t0` (default `ts[0]`).
    - `y0`: initial state (default `system.initial_state()`: atmospheric pressure, payload at rest in equilibrium).
    - `solver`: a diffrax solver. Default (`default_solver`): `pamjax.Rodas5()` (L-stable Rosenbrock, order 5)
      for a continuous valve (averaged, regulator), whose plant is stiff while the payload sticks under the smooth
      Coulomb sign; `diffrax.Tsit5()` for a switching valve, whose smoothed edges bound the step whatever the
      solver. `rtol`, `atol`: tolerances of the PID step-size controller, `atol` in scaled state units (pressure
      per 1e5 Pa, position per 1e-2 m, velocity per 1e-2 m/s); finite and > 0. They, `dt0` and an adaptive
      solve's horizon are arguments of its compiled program: another value does not compile again (a fixed grid's
      number of steps is its program's shape).
    - `max_steps`: the solve fails beyond this many steps; default (`_solve_hints.default_max_steps`): 200,000, or
      more for long runs (64 per PWM period of a switching valve, 1,000 per second otherwise). `dt0`: initial step
      (default: automatic).
    - `adjoint`: "reverse" (default; a concrete call runs forward mode, as nothing differentiates it), "forward",
      or any diffrax adjoint.
    - `throw`: raise `PamjaxSolveError` on a failed solve (default). With `throw=False` a failed solve returns a
      trajectory whose `result` is non-zero and whose channels are NaN, never plausible-looking numbers.
    - `stepping`: "auto" (default): "adaptive" for smooth systems; for hybrid ones (stick-slip friction,
      `KarnoppFriction`) "pwm" with a switching valve and "grid" with a continuous one. "adaptive": diffrax with the
      PID controller above. "grid": fixed RK4 steps of `grid_step` [s] (default 1 ms) with the hybrid system's
      events located inside the step (`pamjax._solve.grid`), for continuous valves (a switching valve is refused:
      uniform steps do not latch its duty per PWM period). "pwm" (switching `OnOffValve` only):
      PWM-synchronous fixed RK4 steps whose grid contains every switching edge, `substeps` (default 16)
      uniform nodes per PWM period plus the two edges. It integrates the exact-edge model (duty latched per period,
      sharp edges, whatever the valve's `mode`) and is differentiable with respect to everything, the duty, the PWM
      frequency and the switching delays included (the edges move the step boundaries). `solver`, `rtol`, `atol`,
      `max_steps`, `dt0` and `adjoint` do not apply to it; the default K = 16 keeps positions within ~1e-3 mm and
      pressures within ~10 Pa of a tight adaptive exact-edge solve (docs/performance.md).

    **Returns:** a `Trajectory` (`t`, `pressure` [Pa abs], `position` [m], `velocity` [m/s], `force` [N],
    `mass_flow` [kg/s], `command`, solver statistics, `result`).

    **Raises:** `PamjaxInputError` (naming the argument) for bad input, before any solve; `PamjaxSolveError` when
    the solve fails and `throw=True`.

    An `OnOffValve(mode="exact")` has its switching times handed to the solver (step-size clipping at jump times).
    """
    # a value set with eqx.tree_at as an array: an argument, not a constant of the program
    system, traced_model = prepared(system)
    validate(system, signal, ts, y0, t0)
    traced_model = traced_model or _is_traced(signal)
    if traced_model:  # inside jit/vmap/grad: the same checks, as run-time errors naming the value
        system, signal = runtime_checks(system, signal, ts, system.command_range)
    # Tolerances and the first step as arrays: arguments of the compiled solve, not constants baked into it (another
    # rtol does not compile again).
    rtol, atol = _positive(rtol, "rtol"), _positive(atol, "atol")
    dt0 = None if dt0 is None else _positive(dt0, "dt0")
    # concrete ts[0] and ts[-1] are read on the host (indexing a device array compiles a one-operation program),
    # before jnp.asarray: under an enclosing jit or vmap (a band's draws) that makes even concrete times tracers
    host = None if _is_traced(ts) else np.asarray(ts, dtype=float)
    ts = _as_times(ts)
    t_end = ts[-1] if host is None else float(host[-1])
    if t0 is None:
        start = None if host is None else float(host[0])
        t0 = ts[0] if host is None else kept_on_device(("t0", start), lambda: jnp.asarray(start))
    else:
        start = None if _is_traced(t0) else float(np.asarray(t0))
        t0 = jnp.asarray(t0, dtype=float)
    start = t0 if start is None else start  # the start as the fixed grid's size and the edge schedule read it
    traced_times = _is_traced((ts, t0))  # (after jnp.asarray: tracers under an enclosing jit or vmap)
    jump_ts = periods = None
    traced = traced_model or traced_times or _is_traced(y0)
    adjoint = "forward" if adjoint is None and not traced else adjoint  # see the docstring: a lighter trace
    stepping = resolve_stepping(system, stepping)
    if stepping in ("pwm", "grid"):
        periods = _fixed_grid_periods(system, stepping, substeps, grid_step, start, t_end)
    elif system.valve.exact_edges:
        system, jump_ts = _scheduled(system, signal, start, t_end)
    elif system.valve.smooth_edges:  # step boundaries at the smoothed edges (from the frequency: 1/f run eagerly
        # would compile a program); a static flag, one value for every horizon: another does not compile again
        periods = _EDGE_CLIP
    else:  # a continuous valve: a step boundary where its command jumps (`command_jumps`)
        jump_ts = command_jumps(signal, start, t_end)
    if solver is None and stepping == "adaptive":
        solver = default_solver(system)
    if max_steps is None:  # a budget that grows with the horizon (a 1,000 s PWM run needs ~1.6 M steps)
        max_steps = 200_000 if traced_times else default_max_steps(system, t0, t_end)
    # A concrete call checks the result on the host (below), so its program is traced with equinox's run-time
    # checks (diffrax's, on the save times) as NaN rather than as host callbacks: JAX does not keep a program with a
    # host callback in its persistent cache, and a second run would compile the solve again.
    # a long fixed-grid run in pieces: bounded memory (_chunks)
    pieces = None if traced or stepping == "adaptive" else _chunks.plan(system, signal, host, float(t0), stepping,
                                                                         substeps, grid_step, periods)
    with contextlib.nullcontext() if traced else equinox_errors_as_nan(), naming_batched(system):
        program = _solve_program()

        def solve_on(ts_, y0_, t0_, periods_, grid_step_):
            return program(system, signal, ts_, y0_, t0_, solver=solver, rtol=rtol, atol=atol, max_steps=max_steps,
                           dt0=dt0, adjoint=adjoint, jump_ts=jump_ts, throw=throw and traced, stepping=stepping,
                           substeps=substeps, num_periods=periods_, grid_step=grid_step_)

        traj = _forward_mode_named(lambda: solve_on(ts, y0, t0, periods, grid_step) if pieces is None
                                   else _chunks.solve_pieces(solve_on, system, stepping, host, y0, t0, pieces))
    if not traced:
        traj = vacuum(traj, system, signal, t0, y0)
        if throw:
            _raise_on_failure(traj, system, signal, ts, t0, y0, stepping, substeps, grid_step, max_steps, solver)
    return traj


_EDGE_CLIP = 1  # `num_periods` of an adaptive solve with smoothed edges: edge clipping on (its value is not used)


def _forward_mode_named(solve):
    """`solve()`, JAX's error for forward-mode autodiff (jax.jacfwd, jax.jvp) of the default reverse-mode adjoint
    raised as a `PamjaxInputError` naming `adjoint="forward"`: caught, not looked for, so no check of the tracers
    costs the solves that pass."""
    try:
        return solve()
    except TypeError as err:
        if "forward-mode autodiff" not in str(err):
            raise
        raise PamjaxInputError(
            'simulate is being forward-differentiated (jax.jacfwd, jax.jvp) with its reverse-mode adjoint: pass '
            'adjoint="forward" to simulate for forward-mode derivatives (the default adjoint serves jax.grad)'
        ) from err


def _as_times(ts):
    """`jnp.asarray(ts, dtype=float)`, without the eager operation it runs (~0.1 ms) where it would return a concrete
    float64 array as it is (outside any JAX transformation: inside one it makes a tracer of it)."""
    keep = isinstance(ts, jax.Array) and ts.dtype == np.float64 and not ts.weak_type and jax_at_top_level()
    return ts if keep and not isinstance(ts, jax.core.Tracer) else jnp.asarray(ts, dtype=float)


def _positive(value, name):
    """A tolerance or step [s] checked finite and > 0 (when concrete), as a float64 array; a Python number's made
    once per value (`kept_on_device`: a copy to the device costs ~0.1 ms, a tenth of an averaged `simulate`)."""
    checked = lambda: device_array(check_positive_number(value, name))  # noqa: E731
    if type(value) in (float, int):
        return kept_on_device(("positive", type(value), value), checked)
    return value if _is_traced(value) else checked()


def _fixed_grid_periods(system, stepping, substeps, grid_step, t0, t_end):
    """The checked settings of a fixed-grid solve and its static size (PWM periods or grid steps)."""
    if not (isinstance(substeps, int) and substeps >= 2):
        raise PamjaxInputError(f"substeps must be an int >= 2 (RK4 nodes per PWM period), got {substeps!r}")
    if not (isinstance(grid_step, (int, float)) and np.isfinite(grid_step) and grid_step > 0):
        raise PamjaxInputError(f"grid_step must be a positive number of seconds, got {grid_step!r}")
    return fixed_grid_size(system, stepping, t0, t_end, grid_step)


def _scheduled(system, signal, t0, t_end):
    """An exact-edge valve's switching times computed before the solve: the system with a `ScheduledValve` and the
    jump times inside (t0, ts[-1]) handed to the step-size controller (None if there are none)."""
    message = ("OnOffValve(mode='exact') needs a concrete signal, pwm_frequency and switch delays (its edge times are "
               "computed before the solve); use mode='smooth' inside jit/grad/vmap of them (other parameters may be)")
    if _is_traced((signal, t0, t_end)):
        raise PamjaxInputError(message)
    try:  # the flow coefficients may be traced (a gradient or a fit of them): the schedule reads the timing only
        edges, states = system.valve.edge_schedule(signal, float(t0), float(t_end))
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError) as err:
        raise PamjaxInputError(message) from err
    system = eqx.tree_at(lambda s: s.valve, system,
                         ScheduledValve(system.valve, device_array(edges), device_array(states)))
    inside = edges[(edges > float(t0)) & (edges < float(t_end))]
    return system, (device_array(inside) if inside.size else None)


def _raise_on_failure(traj, system, signal, ts, t0, y0, stepping, substeps, grid_step, max_steps, solver):
    """`PamjaxSolveError` for a failed solve, saying why and what fixes it (`pamjax._solve.hints`)."""
    inflow = negative_inflow(system, signal, t0, y0) if int(traj.result) == RESULT_NONPHYSICAL else None
    if inflow is not None:  # whatever the stepping: the model empties the chamber, no solver setting helps
        raise PamjaxSolveError(f"the solve drew the chamber below half an atmosphere: {inflow}. (throw=False returns "
                               "the result with its status instead.)")
    if int(traj.result) in (RESULT_NONFINITE, RESULT_NONPHYSICAL) and stepping in ("pwm", "grid"):
        step = float(grid_step) if stepping == "grid" else 1.0 / (float(system.valve.pwm_frequency) * substeps)
        hint = fixed_step_hint(system, signal, t0, y0, stepping, step)
        setting = f"substeps={substeps}" if stepping == "pwm" else f"grid_step={grid_step}"
        what = "a non-finite state" if int(traj.result) == RESULT_NONFINITE else "an absolute pressure at or below 0"
        raise PamjaxSolveError(
            f"fixed-grid stepping ('{stepping}', {setting}) produced {what}: {hint}. Pass throw=False to get the "
            "result with status instead."
        )
    if int(traj.result) != 0:
        message = result_message(int(traj.result)).split(" Try increasing")[0]  # the hint says what to change
        hint = failure_hint(system, signal, ts, t0, y0, traj, max_steps, solver, message)
        raise PamjaxSolveError(
            f"the ODE solve failed: {message} (result code {int(traj.result)}, max_steps={max_steps}): {hint}. "
            "(throw=False returns the partial result with its status instead.)"
        )
