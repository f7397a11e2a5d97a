"""The command signals of several runs as one signal with a leading run axis, so that what a fixed-grid loop
computes from each run's signal (its PWM-synchronous grid, the latched duty and the valve's exact opening at each
sample) is traced once for all runs instead of once per run.

A rig's runs are driven by their logged duty (`Sampled` tables of different lengths): each table is extended past its
end to the longest (`AbstractSignal.extended_to`: the last sample held at later times, which reads the same at every
time, as a zero-order hold holds the last sample after the end either way). Signals of other kinds stack as they are
when their arrays have equal shapes. Runs whose signals differ in kind or structure (a `Triangle` beside a `Sampled`)
are not stacked: the caller keeps one trace per run. docs/performance.md, "Compilation".
"""

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu


def stacked_signals(signals):
    """`signals` (one per run) as one signal whose array leaves have a leading run axis, or None where they cannot be
    stacked (different kinds, static fields or array shapes)."""
    signals = list(signals)
    lengths = [u.table_length() for u in signals]
    if None not in lengths:  # tables (a rig's logged duties): each extended past its end to the longest
        signals = [u.extended_to(max(lengths)) for u in signals]
    arrays = [eqx.filter(u, eqx.is_array) for u in signals]
    statics = [eqx.filter(u, eqx.is_array, inverse=True) for u in signals]
    structure = jtu.tree_structure(arrays[0])
    if any(jtu.tree_structure(a) != structure for a in arrays):
        return None
    # the static fields are in the treedef; other leaves that are not arrays (Python numbers) must be equal
    if any(jtu.tree_structure(s) != jtu.tree_structure(statics[0]) or jtu.tree_leaves(s) != jtu.tree_leaves(statics[0])
           for s in statics):
        return None
    shapes = [[jnp.shape(x) for x in jtu.tree_leaves(a)] for a in arrays]
    if any(s != shapes[0] for s in shapes):
        return None
    stacked = jtu.tree_map(lambda *xs: jnp.stack(xs), *arrays)
    return eqx.combine(stacked, statics[0])
