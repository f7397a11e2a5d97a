"""The output channels of several fixed-grid runs of one system structure, traced once for all of them.

`pamjax._fit.predictions` integrates the runs of a fit that share a system structure in one loop
(`pamjax._solve.synchronous.solve_runs`); their output channels were then traced once per run (`fixed_trajectory`),
so a rig's eight runs put eight copies of the outputs (a muscle's forces, a valve's flows through a silencer) into
every residual and Jacobian program. Here what depends on a run's signal (its latched duties and the valve's exact
opening at each sample) is computed per run, which is cheap, and `system.outputs` is traced once: the runs' samples
go side by side in blocks of at most `BLOCK`, each block with its run's parameters (a run's last block padded with
its last sample, whose outputs are dropped). Blocks rather than one parameter set per sample: in a forward-mode
Jacobian every parameter gathered per sample would carry a tangent per sample. docs/performance.md, "Compilation".
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .run_signals import stacked_signals
from .synchronous import exact_opening, held_at, latched_commands, stack_systems
from .trajectory import fixed_grid_trajectory

BLOCK = 256  # samples per block: at most BLOCK − 1 padded samples per run (a 2 s run at 1 kHz: 47 of 2,001)


def _blocks(x, size, count):
    """`x` (samples first) padded with its last sample to `count` blocks of `size`: shape (count, size, ...)."""
    pad = count * size - x.shape[0]
    if pad:
        x = jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)])
    return x.reshape((count, size) + x.shape[1:])


def run_trajectories(systems, signals, times, runs, t0s, stepping):
    """The `Trajectory` of each run of `solve_runs` (`runs`: its (states, num_steps, finite) per run) at its sample
    `times`, with `system.outputs` traced once for all runs."""
    stacked = stacked_signals(signals) if stepping == "pwm" else None
    if stacked is not None:  # the latched duties and exact openings too are computed in the blocks, traced once
        commands = openings = [None] * len(times)
    elif stepping == "pwm":
        commands = [latched_commands(s.valve, u, ts) for s, u, ts in zip(systems, signals, times)]
        openings = [jax.vmap(lambda t, c, s=s, u=u, t0=t0: exact_opening(s.valve, u, t, c, t0))(ts, cmd)
                    for s, u, ts, cmd, t0 in zip(systems, signals, times, commands, t0s)]
    else:
        commands = [jax.vmap(u)(ts) for u, ts in zip(signals, times)]
        openings = [jnp.zeros_like(ts) for ts in times]
    sizes = [int(ts.shape[0]) for ts in times]
    size = min(BLOCK, max(sizes))
    counts = [-(-n // size) for n in sizes]

    def side_by_side(per_run):  # a pytree per run → one pytree of (blocks, size, ...) leaves
        blocked = [jtu.tree_map(lambda a, c=c: _blocks(a, size, c), x) for x, c in zip(per_run, counts)]
        return jtu.tree_map(lambda *xs: jnp.concatenate(xs), *blocked)

    arrays, static = eqx.partition(stack_systems(systems), eqx.is_array)
    run_of_block = np.repeat(np.arange(len(systems)), counts)
    per_block = jtu.tree_map(lambda a: a[run_of_block], arrays)

    if stacked is None:
        signal_arrays = signal_static = t0_block = None
    else:
        signal_arrays, signal_static = eqx.partition(stacked, eqx.is_array)
        signal_arrays = jtu.tree_map(lambda a: a[run_of_block], signal_arrays)
        t0_block = jnp.stack([jnp.asarray(t0, float) for t0 in t0s])[run_of_block]

    def block(system_arrays, ts, states, cmds, opens, signal_arrays, t0):
        system = eqx.combine(system_arrays, static)
        if signal_arrays is not None:  # this block's run's signal: its latched duties and exact openings
            signal = eqx.combine(signal_arrays, signal_static)
            cmds = latched_commands(system.valve, signal, ts)
            opens = jax.vmap(lambda t, c: exact_opening(system.valve, signal, t, c, t0))(ts, cmds)

        def one(t, y, c, o):
            return (held_at(system, o) if stepping == "pwm" else system).outputs(t, y, c)

        return jax.vmap(one)(ts, states, cmds, opens), cmds

    outs, blocked_commands = jax.vmap(block)(per_block, side_by_side(times), side_by_side([r[0] for r in runs]),
                                             side_by_side(commands), side_by_side(openings), signal_arrays, t0_block)
    outs, blocked_commands = jtu.tree_map(lambda a: a.reshape((-1,) + a.shape[2:]), (outs, blocked_commands))
    starts = size * np.concatenate([[0], np.cumsum(counts)[:-1]])
    trajectories = []
    for ts, (states, num_steps, finite), first, n in zip(times, runs, starts, sizes):
        run_outs, cmd = jtu.tree_map(lambda a, first=first, n=n: a[first:first + n], (outs, blocked_commands))
        trajectories.append(fixed_grid_trajectory(ts, states, cmd, run_outs, num_steps, finite))
    return trajectories
