"""A chunk of sweep lanes as one GPU kernel: each block of lanes integrates its whole run in one program.

On a GPU, `vmap` of a lane's error-controlled loop (`lanes._run_chunk`) runs each integration step as ~80 kernel
launches over all lanes (products, reductions, and the places where a value's components are read together), and
the 100,000-point averaged sweep was bound by those launches (1.6 M points/s on an H100, benchmarks/RESULTS.md).
Here the lane's program is evaluated element by element (`scalar.py`: every value one (block,) array across a
block of lanes, the plant's fixed parameters folded in as constants) inside one Pallas kernel (Triton): a block's
lanes step together until the block's slowest lane ends, with no launch per step and no trip through memory
between a step's stages.

Used by `sweep` on one GPU with `PAMJAX_SWEEP_KERNEL=1` (`lanes.run_lanes`: where the evaluator cannot express a
lane's program or Triton cannot compile it, XLA's program runs and a warning says why, once); off by default, as it
compiles ~9 s longer than XLA's program (docs/performance.md, "A GPU sweep as one kernel"). The kernel's arithmetic
is the lane program's, up to rounding (tests/test_sweep_kernel.py checks it against the XLA program in Pallas's
interpreter on the CPU; on an H200 the 100,000-point map agreed to 1.4e-9 Pa).
"""

import jax
import jax.numpy as jnp
import numpy as np

from .scalar import Unsupported, evaluate

# Lanes per kernel program (one lane per GPU thread with 4 warps of 32): a block steps until its slowest lane ends.
# On an H200, 32/1, 64/2, 128/2, 128/4 and 256/4 (lanes/warps) ran the 100,000-point map in 0.045-0.048 s alike
# (benchmarks/RESULTS.md, g4).
BLOCK_LANES = 128
NUM_WARPS = 4

__all__ = ["BLOCK_LANES", "Unsupported", "kernel_lanes"]


def _elements(block_refs, shapes):
    """The per-lane arguments' elements as object arrays, read from one (block,) ref per element."""
    out, at = [], 0
    for shape in shapes:
        n = int(np.prod(shape))
        arr = np.empty(n, dtype=object)
        for i in range(n):
            arr[i] = block_refs[at + i][...]
        out.append(arr.reshape(shape))
        at += n
    return out


def _pow2(n):
    return 1 << max(0, int(n) - 1).bit_length()


def _uniform_columns(uniform):
    """The lane-uniform arrays' elements grouped by kind into padded 1-D arrays: [(array, kind, count)]."""
    leaves = jax.tree_util.tree_leaves(uniform)
    groups = {}
    for leaf in leaves:
        if jnp.issubdtype(leaf.dtype, jnp.complexfloating):
            raise Unsupported("a complex lane-uniform array")
        kind = "f" if jnp.issubdtype(leaf.dtype, jnp.inexact) else "i"
        groups.setdefault(kind, []).append(jnp.ravel(leaf).astype(jnp.float64 if kind == "f" else jnp.int64))
    out = []
    for kind, parts in groups.items():
        flat = jnp.concatenate(parts) if parts else jnp.zeros(0)
        out.append((jnp.pad(flat, (0, _pow2(flat.shape[0]) - flat.shape[0])), kind, int(flat.shape[0])))
    return out


def _uniform_elements(refs, groups, uniform, block):
    """The lane-uniform arrays inside the kernel, each element one scalar read broadcast over the block."""
    taken = {kind: 0 for _, kind, _ in groups}
    by_kind = {kind: ref for ref, (_, kind, _) in zip(refs, groups)}
    leaves, tree = jax.tree_util.tree_flatten(uniform)
    out = []
    for leaf in leaves:
        kind = "f" if jnp.issubdtype(leaf.dtype, jnp.inexact) else "i"
        arr = np.empty(int(np.prod(leaf.shape)), dtype=object)
        for i in range(arr.size):
            value = by_kind[kind][taken[kind]]
            arr[i] = jnp.broadcast_to(value.astype(leaf.dtype), (block,))
            taken[kind] += 1
        out.append(arr.reshape(leaf.shape))
    return jax.tree_util.tree_unflatten(tree, out)


def kernel_lanes(lane, uniform, values, *, block=None, warps=None, interpret=False):
    """`jax.vmap(lane, in_axes=(None, 0))(uniform, values)` as one Pallas kernel: `lane(uniform, point)` maps the
    lane-uniform arrays (the plant, the output times) and a pytree of one point's values to a pytree of arrays;
    `values` holds the points along the leading axis of every leaf. Raises `Unsupported` (at trace time) where the
    lane's program uses an operation the element evaluator cannot express."""
    from jax.experimental import pallas as pl  # imported here: `import pamjax` does not need it

    block = BLOCK_LANES if block is None else int(block)
    leaves, tree = jax.tree_util.tree_flatten(values)
    n = int(leaves[0].shape[0])
    padded = -(-n // block) * block
    shapes = [tuple(leaf.shape[1:]) for leaf in leaves]
    columns = []
    for leaf in leaves:
        flat = jnp.reshape(leaf, (n, -1))
        if padded > n:  # the last point repeated: a full block, its results dropped
            flat = jnp.concatenate([flat, jnp.broadcast_to(flat[-1:], (padded - n, flat.shape[1]))])
        columns.extend(flat[:, i] for i in range(flat.shape[1]))
    groups = _uniform_columns(uniform)
    uniform_shapes = jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), uniform)
    example = jax.tree_util.tree_unflatten(tree, [jax.ShapeDtypeStruct(s, leaf.dtype) for s, leaf in
                                                  zip(shapes, leaves)])
    closed, run = evaluate(lane, block, uniform_shapes, example)
    out_avals = closed.out_avals
    out_tree = jax.tree_util.tree_structure(jax.eval_shape(lane, uniform_shapes, example))
    out_sizes = [int(np.prod(a.shape)) for a in out_avals]
    store_dtypes = [jnp.int32 if a.dtype == jnp.bool_ else a.dtype for a in out_avals]

    def kernel(*refs):
        u_refs, ins, outs = refs[:len(groups)], refs[len(groups):len(groups) + len(columns)], refs[len(groups) +
                                                                                               len(columns):]
        u = _uniform_elements(u_refs, groups, uniform_shapes, block)
        args = jax.tree_util.tree_unflatten(tree, _elements(ins, shapes))
        results = jax.tree_util.tree_leaves(run(u, args), is_leaf=lambda x: isinstance(x, np.ndarray))
        at = 0
        for result, dtype in zip(results, store_dtypes):
            for element in result.reshape(-1):
                value = jnp.broadcast_to(jnp.asarray(element), (block,))
                outs[at][...] = value.astype(dtype)
                at += 1

    spec = pl.BlockSpec((block,), lambda i: (i,))
    u_specs = [pl.BlockSpec((g.shape[0],), lambda i: (0,)) for g, _, _ in groups]
    out_shape = [jax.ShapeDtypeStruct((padded,), d) for d, size in zip(store_dtypes, out_sizes) for _ in range(size)]
    params = {} if interpret else {"compiler_params": _triton_params(NUM_WARPS if warps is None else int(warps))}
    flat_out = pl.pallas_call(kernel, out_shape=out_shape, grid=(padded // block,),
                              in_specs=u_specs + [spec] * len(columns), out_specs=[spec] * len(out_shape),
                              interpret=interpret, **params)(*[g for g, _, _ in groups], *columns)
    results, at = [], 0
    for aval, size in zip(out_avals, out_sizes):
        parts = jnp.stack(flat_out[at:at + size], axis=-1)[:n] if size else jnp.zeros((n, 0), aval.dtype)
        results.append(parts.reshape((n,) + tuple(aval.shape)).astype(aval.dtype))
        at += size
    return jax.tree_util.tree_unflatten(out_tree, results)


def _triton_params(warps):
    from jax.experimental.pallas import triton as pltriton

    return pltriton.CompilerParams(num_warps=warps, num_stages=1)
