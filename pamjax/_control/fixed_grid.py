"""One control period of a plant on a fixed grid with events located inside the step: the closed loop's solver for
plants that an adaptive solve cannot take, such as the identified plant with exact PWM edges and exact stick-slip
(`presets.mas10_system(valve="pwm", friction="karnopp")`).

A PWM controller sets one duty per period, and the plant's grid for that period is built from it, as the open-loop
fixed grids are (`pamjax._solve.synchronous`, `pamjax._solve.grid`):

- `"pwm"` (a switching valve): the period's K uniform RK4 nodes plus its two switching edges, the opening held
  between them (exact edges, the 10-90 % dead bands and a valve left open by the period before, which the loop carries
  as `ClosedLoopState.valve_open`); the edge times are differentiable functions of the duty.
- `"grid"` (a continuous valve, e.g. the averaged eq. 13): K uniform RK4 steps with the duty held.

Stick-slip events (`KarnoppFriction`) and the inelastic stroke limits are located inside the steps (bisection on the
step's Hermite interpolant; the located time carries the implicit function theorem's derivatives), so the
loop is a continuous, piecewise-smooth function of gains and plant parameters: reverse-mode gradients for tuning.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu

from .._solve import grid as _grid, synchronous as _sync
from .._solve.scaled import scaled


def period_on_grid(plant, duty, open_before, state, start, period, times, *, stepping, substeps):
    """Integrate `plant` from its `state` at `start` [s] over one control period of `period` [s] with `duty` held.

    **Arguments:** `open_before` whether a switching valve is open at `start` (bool); `times` (n,) output times [s]
    inside [start, start + period]; `stepping` "pwm" (switching valve: its PWM period must be `period`) or "grid";
    `substeps` K uniform RK4 nodes per period (plus the two edges on the PWM grid).

    **Returns:** `(states at times (named pytree), finite)`.
    """
    z0, scaled_state = scaled(plant, state)
    if stepping == "pwm":
        left, right, aux = _sync.period_intervals(plant.valve, duty, start, substeps, open_before)

        def field(system, t, z, opening):
            held = eqx.tree_at(lambda s: s.valve, system, _sync.HeldOpeningValve(system.valve, opening))
            return scaled_state.field(held, t, z, None)
    else:
        nodes = start + period * jnp.arange(substeps + 1) / substeps
        left, right = nodes[:-1], nodes[1:]
        aux = jnp.broadcast_to(duty, (substeps, 3)).astype(float)

        def field(system, t, z, command):
            return scaled_state.field(system, t, z, command)

    event = update = None
    if plant.hybrid:

        def event(system, t, z):
            return system.event_function(t, scaled_state.state(z), None)

        def update(system, t, z):
            return scaled_state.vector(system.event_update(t, scaled_state.state(z), None))

    arrays, static = eqx.partition(plant, eqx.is_array)
    stacked = eqx.combine(jtu.tree_map(lambda a: jnp.asarray(a)[None], arrays), static)  # one run
    z_out, _, _, _, finite = _grid.integrate(
        stacked, field, event, update, z0[None], left, right, aux, jnp.zeros(left.shape, jnp.int32),
        jnp.zeros((1,)), times,
    )
    return jax.vmap(scaled_state.state)(z_out), finite
