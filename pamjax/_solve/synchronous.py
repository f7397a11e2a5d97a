"""PWM-synchronous stepping: fixed RK4 substeps that land exactly on every switching edge of an on/off valve.

A switching valve's vector field jumps at each PWM edge. An adaptive solver either smooths the edges (many small
steps per edge, and at loose tolerances it can step over whole windows) or is handed the edge times as jump times
(then the edges carry no derivative). Here the time grid of each PWM period is built from the edge times themselves:

    nodes_k = sort({kT + jT/K, j = 0…K} ∪ {kT + t_on, kT + t_off(u_k)}),
    t_on = switch_on_delay,  t_off = u_k T + switch_off_delay,  u_k = signal(kT)  (duty latched per period)

and each of the K + 2 intervals is one classical RK4 step with the valve opening held (1 between the edges, 0
outside; the 10 %/90 % dead bands of `OnOffValve` included). The opening is piecewise constant, so the vector field
is smooth inside every step, and because the node times are differentiable functions of the duty, frequency and
switching delays, d(trajectory)/d(duty) carries the edge-motion term (f_on − f_off) dt_edge/du exactly as the sharp
model implies. Outputs at the requested times are cubic Hermite interpolants between nodes (end slopes from the
vector field), O(h⁴) like the RK4 steps.

This integrates the EXACT-edge model (`OnOffValve(mode="exact")`'s physics) whatever the valve's `mode`; the smooth
model converges to it as `edge_width → 0`. Accuracy and the choice of K: `docs/performance.md`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import RealScalarLike
from .._core.errors import PamjaxInputError
from .._physics.valves.base import AbstractSwitchingValve, AbstractValve
from . import grid as _grid
from .run_signals import stacked_signals


class HeldOpeningValve(AbstractValve):
    """A switching valve whose opening is held at `opening` ∈ [0, 1] (one step of the PWM-synchronous scheme)."""

    valve: AbstractSwitchingValve
    opening: jax.Array

    def mass_flow(self, t, command, pressure, air):
        return self.valve.mass_flow_at_opening(self.opening, pressure, air)


def sharp_opening(valve: AbstractSwitchingValve, phase, command, open_before=False):
    """Exact-edge opening (0 or 1) at `phase` [s] ∈ [0, T) of a period with latched duty `command`, the valve open
    at the period start if `open_before` (no gradient)."""
    valve, phase, command = jax.lax.stop_gradient((valve, phase, command))
    on_edge, off_edge = valve.edge_phases(command)
    before, during, after = _region_openings(valve, command, open_before)
    return jnp.where(phase < on_edge, before, jnp.where(phase < off_edge, during, after))


def _region_openings(valve: AbstractSwitchingValve, command, open_before):
    """Opening (0/1) before the on edge, between the edges and after the off edge of one period."""
    opens, closes = jax.lax.stop_gradient(valve.switching_gates(command))
    before = jnp.where(open_before, 1.0, 0.0)
    during = jnp.where(opens, 1.0, before)
    after = jnp.where(closes, 0.0, during)
    return before, during, after


def open_at_start(valve: AbstractSwitchingValve, signal, start, first_start):
    """Whether the valve is open at the start `start` of a PWM period: it stays open from the period before when that
    period's off-pulse was too short to close it (duty above ~90 % at 50 Hz with 2 ms delays). The valve is closed
    before `first_start` (the start of the first period simulated: the runs start with the valve off). Exact, as
    T > switch_on_delay + switch_off_delay (`OnOffValve` refuses delays that outlast the period): each period then
    opens or closes the valve, so two periods back determine it."""
    period = valve.period
    state = jnp.zeros((), dtype=bool)
    for back in (2.0, 1.0):
        previous = start - back * period
        end_state = valve.open_at_period_end(signal(previous), state)
        state = jnp.where(previous >= first_start - 0.5 * period, end_state, False)
    return jax.lax.stop_gradient(state)


def num_periods(valve: AbstractSwitchingValve, t0: RealScalarLike, t1: RealScalarLike) -> int:
    """Number of PWM periods (static int) that cover [t0, t1]; needs concrete times and frequency."""
    try:
        frequency = float(valve.pwm_frequency)
        t0, t1 = float(t0), float(t1)
    except (TypeError, jax.errors.ConcretizationTypeError) as err:
        raise PamjaxInputError(
            "stepping='pwm' needs concrete t0, ts and pwm_frequency to size its grid; inside jit pass "
            "num_periods to pamjax's solve() explicitly; for gradients, differentiate with respect to the parameters "
            "only (pamjax.ParameterSpace(system, free).model(theta), or eqx.partition), not the whole system, so "
            "that pwm_frequency stays concrete"
        ) from err
    first = np.floor(t0 * frequency + 1e-9)
    return max(int(np.ceil(t1 * frequency - first - 1e-9)), 1)


def _period_grid(valve: AbstractSwitchingValve, signal, start, substeps, open_before):
    """Node times (K + 3,) of one period starting at `start` and the opening (K + 2,) of each interval."""
    period = valve.period
    command = signal(start)
    on_edge, off_edge = valve.edge_phases(command)
    uniform = jnp.arange(substeps + 1) * (period / substeps)
    phases = jnp.sort(jnp.concatenate([uniform, jnp.stack([on_edge, off_edge])]))
    # Ranks (not midpoints) decide which region an interval lies in, so that an edge that coincides with a uniform
    # node gets the derivative of the side it moves into: the stable order puts the uniform node first, the on edge
    # next, the off edge last.
    on_rank = jnp.sum(uniform <= on_edge)
    off_rank = jnp.sum(uniform <= off_edge) + 1
    index = jnp.arange(substeps + 2)
    before, during, after = _region_openings(valve, command, open_before)
    opening = jnp.where(index < on_rank, before, jnp.where(index < off_rank, during, after))
    return start + phases, opening


def pwm_intervals(valve: AbstractSwitchingValve, signal, t0, t1, substeps, periods):
    """The PWM-synchronous grid over [t0, t1]: interval ends (n,), (n,) each, and the opening held over each
    interval, repeated for the three RK4 stage times (n, 3). Intervals outside [t0, t1] have zero length."""
    period = valve.period
    first = jnp.floor(t0 * valve.pwm_frequency + 1e-9) * period
    starts = first + jnp.arange(periods) * period
    carried = jax.vmap(lambda s: open_at_start(valve, signal, s, first))(starts)
    nodes, openings = jax.vmap(lambda s, c: _period_grid(valve, signal, s, substeps, c))(starts, carried)
    left = jnp.clip(nodes[:, :-1], t0, t1).reshape(-1)
    right = jnp.clip(nodes[:, 1:], t0, t1).reshape(-1)
    openings = openings.reshape(-1)
    return left, right, jnp.stack([openings] * 3, axis=-1)


def period_intervals(valve: AbstractSwitchingValve, duty, start, substeps, open_before):
    """The PWM-synchronous grid of ONE period starting at `start` [s] with the latched `duty`, the valve open at its
    start if `open_before` (a period-by-period closed loop carries it): interval ends (K + 2,) each and the opening
    held over each interval, repeated for the three RK4 stage times (K + 2, 3)."""
    nodes, openings = _period_grid(valve, lambda s: duty, start, substeps, open_before)
    return nodes[:-1], nodes[1:], jnp.stack([openings] * 3, axis=-1)


def uniform_intervals(signal, t0, t1, steps):
    """A uniform grid of `steps` intervals over [t0, t1] and the command at each RK4 stage time (n, 3): the grid of a
    hybrid system fed by a continuous valve (averaged, proportional)."""
    nodes = t0 + (t1 - t0) * jnp.arange(steps + 1) / steps
    left, right = nodes[:-1], nodes[1:]
    # The last stage reads the command just before `right` (its left limit): a command held per period, or a step,
    # that changes on a node belongs to the next interval. Read at `right` itself, a duty held per PWM period
    # (what a closed loop or a recorded duty column gives) entered each interval's last stage a step early and made
    # RK4 first order (1,200 → 591 → 286 Pa as the step halved, against 4th order: 5.5e-4 → 3.6e-5 → 2.2e-6 Pa).
    # The offset: a millionth of the step, and enough beyond `right`'s rounding for a held signal's period test
    # (`Sampled`: 1e-9 of its period); a smooth command moves by its rate times it, far below RK4's error.
    before = right - (1e-6 * (right - left) + 2e-9 * jnp.abs(right))
    stage_times = jnp.stack([left, 0.5 * (left + right), before], axis=-1)
    return left, right, jax.vmap(jax.vmap(signal))(stage_times)


def num_grid_steps(t0, t1, max_step):
    """Number of uniform steps (static int) of at most `max_step` [s] over [t0, t1]; needs concrete times."""
    try:
        t0, t1 = float(t0), float(t1)
    except (TypeError, jax.errors.ConcretizationTypeError) as err:
        raise PamjaxInputError(
            "stepping='grid' needs concrete t0 and ts to size its grid; inside jit pass num_periods (the number of "
            "steps) to pamjax's solve() explicitly"
        ) from err
    return max(int(np.ceil((t1 - t0) / max_step - 1e-9)), 1)


def solve_runs(systems, signals, ts_list, z0s, scaled, t0s, *, stepping, substeps, sizes):
    """Integrate several runs of systems of one structure in ONE scan (a compiled loop shared by all of them).

    Each run: `systems[k]` driven by `signals[k]` from the flat scaled state `z0s[k]` (`scaled`: the map to the
    named state, `pamjax._solve.scaled`) at `t0s[k]`, output at
    `ts_list[k]`. `stepping` "pwm" (switching valves: the PWM-synchronous grid, `sizes[k]` periods of `substeps`)
    or "grid" (continuous valves: `sizes[k]` uniform steps). Runs are laid end to end on one clock (each shifted so
    that it starts 1 s after the previous one ends), so one loop integrates all of them and its compiled size does
    not grow with their number.

    Returns per run `(states at ts (named pytree), num_steps, finite)`.
    """
    lefts, rights, auxs, members, offsets, shifted_ts = [], [], [], [], [], []
    offset = 0.0
    stacked = stack_systems(systems)
    grids = _run_grids(systems, stacked.valve, signals, ts_list, t0s, stepping, substeps, sizes)
    for k, (ts, t0, (left, right, aux)) in enumerate(zip(ts_list, t0s, grids)):
        t1 = ts[-1]
        offset_k = offset - t0
        lefts.append(left + offset_k)
        rights.append(right + offset_k)
        auxs.append(aux)
        members.append(jnp.full(left.shape, k, dtype=jnp.int32))
        offsets.append(offset_k)
        shifted_ts.append(ts + offset_k)
        offset = offset + (t1 - t0) + 1.0
    field, event, update = _grid_functions(stepping, scaled, systems[0].hybrid)
    all_ts = jnp.concatenate(shifted_ts)
    z_out, num_steps, _, _, finite = _grid.integrate(
        stacked, field, event, update, jnp.stack(z0s), jnp.concatenate(lefts), jnp.concatenate(rights),
        jnp.concatenate(auxs), jnp.concatenate(members), jnp.stack([jnp.asarray(o, float) for o in offsets]), all_ts,
    )
    out, start = [], 0
    for k, ts in enumerate(ts_list):
        z_k = z_out[start : start + ts.shape[0]]
        start += ts.shape[0]
        z_k = jnp.where((ts <= t0s[k])[:, None], z0s[k][None], z_k)  # times at or before the start: the start state
        states = jax.vmap(scaled.state)(z_k)
        steps_k = jnp.sum(rights[k] > lefts[k])
        out.append((states, steps_k, finite))
    del num_steps  # the whole loop's; each run reports its own
    return out


def _run_grids(systems, valves, signals, ts_list, t0s, stepping, substeps, sizes):
    """Each run's grid `(left, right, aux)` (`pwm_intervals` or `uniform_intervals`; `valves`: the runs' valves
    stacked, `stack_systems`). Several runs on the PWM grid
    whose signals stack (`pamjax._solve.run_signals`) have their grids traced once: computed side by side over the
    longest run's periods, each run keeping its own (the periods past a run's end are dropped)."""
    stacked = stacked_signals(signals) if stepping == "pwm" and len(systems) > 1 else None
    if stacked is None:
        return [pwm_intervals(s.valve, u, t0, ts[-1], substeps, n) if stepping == "pwm" else
                uniform_intervals(u, t0, ts[-1], n) for s, u, ts, t0, n in zip(systems, signals, ts_list, t0s, sizes)]
    periods = max(sizes)
    left, right, aux = eqx.filter_vmap(lambda v, u, t0, t1: pwm_intervals(v, u, t0, t1, substeps, periods))(
        valves, stacked, jnp.stack([jnp.asarray(t0, float) for t0 in t0s]),
        jnp.stack([ts[-1] for ts in ts_list]))
    count = [n * (substeps + 2) for n in sizes]  # intervals per run: K + 2 per period
    return [(left[k, :c], right[k, :c], aux[k, :c]) for k, c in enumerate(count)]


def _grid_functions(stepping, scaled, hybrid):
    """The fixed grid's vector field `field(system, t, z, aux)` (aux: the opening held over a PWM-synchronous
    interval, or the command at the stage time), and a hybrid system's event function and update (None
    otherwise), all on the flat scaled state."""
    if stepping == "pwm":

        def field(system, t, z, opening):
            held = eqx.tree_at(lambda s: s.valve, system, HeldOpeningValve(system.valve, opening))
            return scaled.field(held, t, z, None)
    else:

        def field(system, t, z, command):
            return scaled.field(system, t, z, command)

    if not hybrid:
        return field, None, None

    def event(system, t, z):
        return system.event_function(t, scaled.state(z), None)

    def update(system, t, z):
        return scaled.vector(system.event_update(t, scaled.state(z), None))

    return field, event, update


def observe_run(system, signal, ts, z0, scaled, t0, *, stepping, substeps, size, observe, init):
    """One run of a hybrid `system` (or of one with an exact-edge valve) on the fixed grid of `solve_runs` (same
    intervals, steps and events), each output time passed on the fly to `observe(carry, k, t, state, command)`
    with the named state and the command in force (the latched duty with a switching valve), nothing of the
    trajectory kept: a sweep's lane (`pamjax._solve.grid.integrate_observed`). `ts` concrete, `ts[0]` ≥ `t0`.
    Returns `(carry, finite)`."""
    t1 = ts[-1]
    if stepping == "pwm":
        left, right, aux = pwm_intervals(system.valve, signal, t0, t1, substeps, size)
    else:
        left, right, aux = uniform_intervals(signal, t0, t1, size)
    field, event, update = _grid_functions(stepping, scaled, system.hybrid)
    if event is None:  # a smooth plant (a sweep of an exact-edge valve): no event ever fires

        def event(system, t, z):
            return jnp.ones((), dtype=z.dtype)

        def update(system, t, z):
            return z

    def seen(carry, k, t, z):
        command = latched_command(system.valve, signal, t) if stepping == "pwm" else signal(t)
        return observe(carry, k, t, scaled.state(z), command)

    carry, _, finite = _grid.integrate_observed(system, field, event, update, z0, left, right, aux, ts, seen, init)
    return carry, finite


def stack_systems(systems):
    """The systems' array leaves stacked along a new leading axis (their static structure must agree)."""
    arrays = [eqx.filter(s, eqx.is_array) for s in systems]
    structure = [jax.tree_util.tree_structure(a) for a in arrays]
    if any(st != structure[0] for st in structure):
        raise PamjaxInputError("runs solved together must have systems of one structure (same components)")
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *arrays)
    return eqx.combine(stacked, eqx.filter(systems[0], eqx.is_array, inverse=True))


def latched_command(valve: AbstractSwitchingValve, signal, t):
    """The duty in force at time `t`: the signal read at the start of the PWM period containing t."""
    return signal(jnp.floor(t * valve.pwm_frequency + 1e-9) * valve.period)


def latched_commands(valve: AbstractSwitchingValve, signal, ts):
    """`latched_command` at each of the times `ts`."""
    return jax.vmap(lambda t: latched_command(valve, signal, t))(ts)


def exact_opening(valve: AbstractSwitchingValve, signal, t, command, t0):
    """The valve's exact-edge opening (0 or 1) at time `t` with latched duty `command`, in a run from `t0`."""
    start = jnp.floor(t * valve.pwm_frequency + 1e-9) * valve.period
    first = jnp.floor(t0 * valve.pwm_frequency + 1e-9) * valve.period
    return sharp_opening(valve, t - start, command, open_at_start(valve, signal, start, first))


def held_at(system, opening):
    """`system` with its switching valve held at `opening` (`HeldOpeningValve`)."""
    return eqx.tree_at(lambda s: s.valve, system, HeldOpeningValve(system.valve, opening))


def output_at(system, signal, t, state, command, t0):
    """`system.outputs` at time `t` with the valve holding its exact-edge opening there (mass flow included), in a
    run from `t0`."""
    return held_at(system, exact_opening(system.valve, signal, t, command, t0)).outputs(t, state, command)


def outputs_at(system, signal, ts, states, commands, t0):
    """`output_at` at each of the times `ts`."""
    return jax.vmap(lambda t, state, command: output_at(system, signal, t, state, command, t0))(ts, states, commands)
