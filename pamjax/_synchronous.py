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
from jax.flatten_util import ravel_pytree

from ._errors import PamjaxInputError
from ._valve import AbstractValve, OnOffValve


class HeldOpeningValve(AbstractValve):
    """An `OnOffValve` whose opening is held at `opening` ∈ [0, 1] (one step of the PWM-synchronous scheme)."""

    valve: OnOffValve
    opening: jax.Array

    def mass_flow(self, t, command, pressure, air):
        return self.valve.mass_flow_at_opening(self.opening, pressure, air)


def sharp_opening(valve: OnOffValve, phase, command):
    """Exact-edge opening (0 or 1) at `phase` [s] ∈ [0, T) of a period with latched duty `command` (no gradient)."""
    valve, phase, command = jax.lax.stop_gradient((valve, phase, command))
    period = valve.period
    opens = command * period - valve.switch_on_delay >= 0
    closes = (1.0 - command) * period - valve.switch_off_delay > 0
    window = (phase >= valve.switch_on_delay) & (phase < command * period + valve.switch_off_delay)
    return jnp.where(opens & (window | ~closes), 1.0, 0.0)


def num_periods(valve: OnOffValve, t0, t1):
    """Number of PWM periods (static int) that cover [t0, t1]; needs concrete times and frequency."""
    try:
        frequency = float(valve.pwm_frequency)
        t0, t1 = float(t0), float(t1)
    except (TypeError, jax.errors.ConcretizationTypeError) as err:
        raise PamjaxInputError(
            "stepping='pwm' needs concrete t0, ts and pwm_frequency to size its grid; inside jit pass "
            "num_periods to pamjax's solve() explicitly"
        ) from err
    first = np.floor(t0 * frequency + 1e-9)
    return max(int(np.ceil(t1 * frequency - first - 1e-9)), 1)


def _period_grid(valve: OnOffValve, signal, start, substeps):
    """Node times (K + 3,) of one period starting at `start` and the opening (K + 2,) of each interval."""
    period = valve.period
    command = signal(start)
    on_edge = jnp.clip(valve.switch_on_delay, 0.0, period)
    off_edge = jnp.clip(command * period + valve.switch_off_delay, on_edge, period)
    uniform = jnp.arange(substeps + 1) * (period / substeps)
    phases = jnp.sort(jnp.concatenate([uniform, jnp.stack([on_edge, off_edge])]))
    # Intervals between the on edge and the off edge are open. Ranks (not midpoints) decide, so that an edge that
    # coincides with a uniform node gets the derivative of the side it moves into: the stable order puts the
    # uniform node first, the on edge next, the off edge last.
    on_rank = jnp.sum(uniform <= on_edge)
    off_rank = jnp.sum(uniform <= off_edge) + 1
    index = jnp.arange(substeps + 2)
    window = (index >= on_rank) & (index < off_rank)
    gate_open = jax.lax.stop_gradient(command * period - valve.switch_on_delay >= 0)
    gate_close = jax.lax.stop_gradient((1.0 - command) * period - valve.switch_off_delay > 0)
    opening = jnp.where(gate_open & (window | ~gate_close), 1.0, 0.0)
    return start + phases, opening


def solve_pwm_synchronous(system, signal, ts, z0, flat_scale, unravel, t0, *, substeps, periods):
    """Integrate `system` from `t0` to `ts[-1]` on the PWM-synchronous grid; states at `ts` (named pytree).

    `z0` is the flat scaled initial state: the state is `unravel(z * flat_scale)`.

    Returns `(states, num_steps, finite)`. `substeps` K: uniform nodes per period (step ≤ T/K); `periods`: static
    number of PWM periods covering [t0, ts[-1]].
    """
    valve = system.valve
    if not isinstance(valve, OnOffValve):
        raise PamjaxInputError(
            f"stepping='pwm' needs a switching OnOffValve (its PWM edges define the grid), got {type(valve).__name__}; "
            "use the default adaptive stepping for other valves"
        )
    if not (isinstance(substeps, int) and substeps >= 2):
        raise PamjaxInputError(f"substeps must be an int >= 2 (RK4 steps per PWM period), got {substeps!r}")
    t1 = ts[-1]
    period = valve.period
    first = jnp.floor(t0 * valve.pwm_frequency + 1e-9) * period
    starts = first + jnp.arange(periods) * period
    nodes, openings = jax.vmap(lambda s: _period_grid(valve, signal, s, substeps))(starts)
    # Intervals outside [t0, t1] shrink to zero length (an RK step of length 0 is the identity).
    left = jnp.clip(nodes[:, :-1], t0, t1).reshape(-1)
    right = jnp.clip(nodes[:, 1:], t0, t1).reshape(-1)
    openings = openings.reshape(-1)

    def field(t, z, opening):
        held = eqx.tree_at(lambda s: s.valve, system, HeldOpeningValve(valve, opening))
        dy = held.vector_field(t, unravel(z * flat_scale), None)
        return ravel_pytree(dy)[0] / flat_scale

    def rk4(z, interval):
        ta, tb, opening = interval
        h = tb - ta
        k1 = field(ta, z, opening)
        k2 = field(ta + 0.5 * h, z + 0.5 * h * k1, opening)
        k3 = field(ta + 0.5 * h, z + 0.5 * h * k2, opening)
        k4 = field(tb, z + h * k3, opening)
        z_next = z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        slope_end = field(tb, z_next, opening)  # for the Hermite dense output
        return z_next, (z_next, k1, slope_end)

    _, (zs, slopes_start, slopes_end) = jax.lax.scan(rk4, z0, (left, right, openings))
    z_starts = jnp.concatenate([z0[None], zs[:-1]])

    # Cubic Hermite interpolation at the output times, inside the last interval that starts at or before t.
    index = jnp.clip(jnp.searchsorted(left, ts, side="right") - 1, 0, left.shape[0] - 1)
    ta, tb = left[index], right[index]
    h = tb - ta
    h_safe = jnp.where(h > 0, h, 1.0)
    s = jnp.where(h > 0, (ts - ta) / h_safe, 1.0)[:, None]
    h = h[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    z_out = h00 * z_starts[index] + h10 * h * slopes_start[index] + h01 * zs[index] + h11 * h * slopes_end[index]
    # Output times at or before t0 take the initial state.
    z_out = jnp.where((ts <= t0)[:, None], z0[None], z_out)
    states = jax.vmap(lambda z: unravel(z * flat_scale))(z_out)
    num_steps = jnp.sum(right > left)
    finite = jnp.all(jnp.isfinite(zs[-1]))
    return states, num_steps, finite


def latched_commands(valve: OnOffValve, signal, ts):
    """The duty in force at each time: the signal read at the start of the PWM period containing t."""
    return jax.vmap(lambda t: signal(jnp.floor(t * valve.pwm_frequency + 1e-9) * valve.period))(ts)


def outputs_at(system, ts, states, commands):
    """`system.outputs` at times `ts` with the valve holding its exact-edge opening there (mass flow included)."""
    valve = system.valve
    phases = ts - jnp.floor(ts * valve.pwm_frequency + 1e-9) * valve.period

    def one(t, state, command, phase):
        held = eqx.tree_at(lambda s: s.valve, system, HeldOpeningValve(valve, sharp_opening(valve, phase, command)))
        return held.outputs(t, state, command)

    return jax.vmap(one)(ts, states, commands, phases)
