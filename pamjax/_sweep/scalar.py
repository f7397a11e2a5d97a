"""A lane's program as scalar arithmetic across lanes: the evaluator behind the GPU sweep kernel (`kernel.py`).

A sweep lane (`lanes.lane_function`) is a program on one point's small arrays: the (n,) state, the (3, 3) valve
coefficients, the (51,) output times, the (n, n) Jacobian. `vmap` keeps those shapes per lane, and XLA splits each
integration step into ~80 kernels over all lanes (products, reductions, and every place an output component reads
every component of an earlier value); on a GPU each is a launch, and the 100,000-point sweep was launch-bound
(benchmarks/RESULTS.md). A GPU kernel language (Triton, through Pallas) wants the opposite: each value one block of
lanes, elementwise. This module evaluates a lane's jaxpr with every array held as a NumPy object array of its
elements, each element either a concrete number (folded at trace time: the plant's fixed parameters, the output
times) or one (width,) array across lanes. Products, reductions, slices, concatenations and polynomial scans become
unrolled scalar arithmetic, a traced index into a constant table a chain of selects, a while loop one loop over
the block that runs while any lane's condition holds (each lane's state kept where its own is false, as `vmap`
does).

Only what a lane needs is supported; anything else raises `Unsupported`, and the sweep then runs its XLA program
(`kernel.py`). Same arithmetic as the lane's own program, up to rounding (tests/test_sweep_kernel.py).
"""

import functools
import math

import jax
import jax.extend.core as jcore
import jax.numpy as jnp
import numpy as np
from jax import lax

MAX_UNROLLED_SCAN = 256  # a scan longer than this is not unrolled (`Unsupported`)
MAX_CONCRETE_LOOP = 100_000  # a while loop on concrete values that runs longer is not folded (`Unsupported`)

_ELEMENTWISE = frozenset("""
    abs acos acosh add add_any and asin asinh atan atan2 atanh cbrt ceil clamp convert_element_type copy copy_p cos
    cosh div eq erf erf_inv erfc exp exp2 expm1 floor ge gt imag integer_pow is_finite le log log1p logistic lt max
    min mul ne neg nextafter not or pow real reduce_precision rem round rsqrt select_n sign sin sinh sqrt square
    stop_gradient sub tan tanh xor
""".split())
_REDUCTIONS = dict(reduce_sum=lax.add_p, reduce_max=lax.max_p, reduce_min=lax.min_p, reduce_prod=lax.mul_p,
                   reduce_and=lax.and_p, reduce_or=lax.or_p)
_NOT_ELEMENTWISE = ("cum", "sort", "argsort", "fft", "reduce", "select_and", "rng", "random", "triangular", "cholesky",
                    "lu", "qr", "eig", "svd", "schur", "hessenberg", "tridiagonal", "top_k", "all_", "psum", "pmax",
                    "pmin", "ppermute", "callback", "debug", "io_", "pure_", "custom", "approx_top", "dot", "conv")
_CALLS = ("jit", "pjit", "closed_call", "core_call", "custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr",
          "remat", "checkpoint", "custom_lin", "eval_jaxpr")


class Unsupported(NotImplementedError):
    """A lane's program uses an operation the scalar evaluator cannot express."""


def _traced(x):
    return isinstance(x, jax.Array | jax.core.Tracer) and not _concrete_array(x)


def _concrete_array(x):
    return isinstance(x, np.ndarray | np.generic)


class Evaluator:
    """Evaluates jaxprs on object arrays of elements, each a NumPy scalar or a (`width`,) array across lanes."""

    def __init__(self, width: int):
        self.width = width

    # --- elements -------------------------------------------------------------------------------------------------

    def lanes(self, x, dtype):
        """An element as a (width,) array of `dtype` (a constant broadcast)."""
        if _traced(x):
            return x if x.dtype == dtype else lax.convert_element_type(x, dtype)
        return jnp.full((self.width,), np.asarray(x, dtype=dtype), dtype=dtype)

    def apply(self, prim, params, dtypes, out_dtype, *elements):
        """One elementwise primitive on elements: folded when all are concrete."""
        if not any(_traced(e) for e in elements):
            with jax.ensure_compile_time_eval():
                args = [jnp.asarray(np.asarray(e, dtype=d)) for e, d in zip(elements, dtypes)]
                return np.asarray(prim.bind(*args, **params), dtype=out_dtype)[()]
        return prim.bind(*[self.lanes(e, d) for e, d in zip(elements, dtypes)], **params)

    def binary(self, prim, dtype, a, b):
        return self.apply(prim, {}, (dtype, dtype), dtype, a, b)

    def any_lane(self, pred):
        """Whether any lane's boolean element holds (a scalar): a maximum, which the GPU kernel language lowers."""
        if not _traced(pred):
            return jnp.asarray(bool(pred))
        return jnp.max(pred.astype(jnp.int32)) > 0

    def select(self, pred, on_true, on_false, dtype):
        """Elementwise `pred ? on_true : on_false` (pred a boolean element)."""
        if not _traced(pred):
            return on_true if bool(pred) else on_false
        return lax.select_n(pred, self.lanes(on_false, dtype), self.lanes(on_true, dtype))

    # --- jaxprs ---------------------------------------------------------------------------------------------------

    def closed(self, closed_jaxpr, *args):
        consts = [_const(c) for c in closed_jaxpr.consts]
        return self.jaxpr(closed_jaxpr.jaxpr, consts, args)

    def jaxpr(self, jaxpr, consts, args):
        env = {}

        def read(v):
            if isinstance(v, jcore.Literal):
                return _const(v.val)
            return env[v]

        for v, x in zip(jaxpr.constvars, consts):
            env[v] = x
        for v, x in zip(jaxpr.invars, args):
            env[v] = x
        for eqn in jaxpr.eqns:
            outs = self.eqn(eqn, [read(v) for v in eqn.invars])
            for v, x in zip(eqn.outvars, outs):
                env[v] = x
        return [read(v) for v in jaxpr.outvars]

    def eqn(self, eqn, args):
        name = eqn.primitive.name
        if name in _ELEMENTWISE:
            return [self._elementwise(eqn, args)]
        if name in _REDUCTIONS:
            return [self._reduce(_REDUCTIONS[name], eqn, args[0])]
        if name in _CALLS:
            return self._call(eqn, args)
        rule = getattr(self, "_" + name, None)
        if rule is None and _elementwise_like(eqn):  # a newer release's elementwise primitive (one_minus_square)
            return [self._elementwise(eqn, args)]
        if rule is None:
            raise Unsupported(f"the GPU sweep kernel cannot evaluate {name!r}")
        out = rule(eqn, *args)
        return out if eqn.primitive.multiple_results else [out]

    def _elementwise(self, eqn, args):
        shape = eqn.outvars[0].aval.shape
        dtypes = [v.aval.dtype for v in eqn.invars]
        out_dtype = eqn.outvars[0].aval.dtype
        ops = [np.broadcast_to(a, shape) for a in args]
        out = np.empty(shape, dtype=object)
        for idx in np.ndindex(*shape):
            out[idx] = self.apply(eqn.primitive, eqn.params, dtypes, out_dtype, *(o[idx] for o in ops))
        return out

    def _reduce(self, prim, eqn, x):
        axes = tuple(eqn.params["axes"])
        dtype = eqn.outvars[0].aval.dtype
        kept = [a for a in range(x.ndim) if a not in axes]
        moved = np.transpose(x, kept + list(axes)).reshape([x.shape[a] for a in kept] + [-1])
        out = np.empty(moved.shape[:-1], dtype=object)
        for idx in np.ndindex(*out.shape):
            out[idx] = functools.reduce(lambda a, b: self.binary(prim, dtype, a, b), list(moved[idx]))
        return out

    def _call(self, eqn, args):
        params = eqn.params
        for key in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
            inner = params.get(key)
            if isinstance(inner, jcore.ClosedJaxpr):
                return self.closed(inner, *args)
            if isinstance(inner, jcore.Jaxpr):
                return self.jaxpr(inner, [], args)
        raise Unsupported(f"the GPU sweep kernel cannot evaluate {eqn.primitive.name!r}")

    # --- shapes ---------------------------------------------------------------------------------------------------

    def _broadcast_in_dim(self, eqn, x, *dynamic):
        if dynamic:
            raise Unsupported("broadcast_in_dim with a dynamic shape")
        shape, dims = eqn.params["shape"], eqn.params["broadcast_dimensions"]
        expanded = [1] * len(shape)
        for axis, d in zip(range(x.ndim), dims):
            expanded[d] = x.shape[axis]
        return _objects(np.broadcast_to(x.reshape(expanded), shape))

    def _reshape(self, eqn, x, *dynamic):
        if dynamic or eqn.params.get("dimensions") is not None:
            raise Unsupported("reshape with dynamic shapes or dimensions")
        return _objects(np.reshape(x, eqn.params["new_sizes"]))

    def _squeeze(self, eqn, x):
        return _objects(np.reshape(x, eqn.outvars[0].aval.shape))

    def _expand_dims(self, eqn, x):
        return _objects(np.reshape(x, eqn.outvars[0].aval.shape))

    def _slice(self, eqn, x):
        strides = eqn.params["strides"] or (1,) * x.ndim
        index = tuple(slice(s, e, st) for s, e, st in zip(eqn.params["start_indices"], eqn.params["limit_indices"],
                                                            strides))
        return _objects(x[index])

    def _concatenate(self, eqn, *xs):
        return _objects(np.concatenate(xs, axis=eqn.params["dimension"]))

    def _stack(self, eqn, *xs):
        return _objects(np.stack(xs, axis=eqn.params["axis"]))

    def _split(self, eqn, x):
        cuts = np.cumsum(eqn.params["sizes"])[:-1]
        return [_objects(p) for p in np.split(x, cuts, axis=eqn.params["axis"])]

    def _rev(self, eqn, x):
        return _objects(np.flip(x, axis=tuple(eqn.params["dimensions"])))

    def _transpose(self, eqn, x):
        return _objects(np.transpose(x, eqn.params["permutation"]))

    def _iota(self, eqn, *dynamic):
        p = eqn.params
        values = np.arange(p["shape"][p["dimension"]], dtype=p["dtype"])
        expanded = [1] * len(p["shape"])
        expanded[p["dimension"]] = -1
        return _const(np.broadcast_to(values.reshape(expanded), p["shape"]))

    # --- products and indexing ------------------------------------------------------------------------------------

    def _dot_general(self, eqn, lhs, rhs):
        (lc, rc), (lb, rb) = eqn.params["dimension_numbers"]
        dtype = eqn.outvars[0].aval.dtype
        lf = [a for a in range(lhs.ndim) if a not in lc and a not in lb]
        rf = [a for a in range(rhs.ndim) if a not in rc and a not in rb]
        size = math.prod(lhs.shape[a] for a in lc)
        lm = np.transpose(lhs, list(lb) + lf + list(lc)).reshape(
            [lhs.shape[a] for a in lb] + [lhs.shape[a] for a in lf] + [size])
        rm = np.transpose(rhs, list(rb) + rf + list(rc)).reshape(
            [rhs.shape[a] for a in rb] + [rhs.shape[a] for a in rf] + [size])
        nb, nl = len(lb), len(lf)
        out = np.empty(eqn.outvars[0].aval.shape, dtype=object)
        for idx in np.ndindex(*out.shape):
            b, i, j = idx[:nb], idx[nb:nb + nl], idx[nb + nl:]
            terms = [self.binary(lax.mul_p, dtype, lm[b + i + (k,)], rm[b + j + (k,)]) for k in range(size)]
            out[idx] = functools.reduce(lambda a, c: self.binary(lax.add_p, dtype, a, c), terms)
        return out

    def _positions(self, operand_shape, operation):
        """`operation` (a function of an array) applied to the flat positions of an operand: which elements it
        reads, as an int array (-1 where it reads none: a fill)."""
        with jax.ensure_compile_time_eval():
            positions = jnp.arange(1, math.prod(operand_shape) + 1, dtype=jnp.int64).reshape(operand_shape)
            return np.asarray(operation(positions)) - 1

    def _indexed(self, operand, index_elements, read, clip):
        """An indexing operation whose index elements may be traced: the concrete case read directly, one traced
        index a chain of selects over its candidate values (`clip`: out-of-range indices clamp, as a gather in
        "clip" or "promise_in_bounds" mode; else they read the fill)."""
        traced = [i for i, e in enumerate(index_elements) if _traced(e)]
        if not traced:
            return read([int(e) for e in index_elements])
        if len({id(index_elements[i]) for i in traced}) > 1 or len(traced) > 1:
            raise Unsupported("an index with more than one traced element")
        k = traced[0]
        element = index_elements[k]
        candidates = range(max(operand.shape) if operand.ndim else 1)
        values = {v: read([v if i == k else int(e) for i, e in enumerate(index_elements)]) for v in candidates}
        out = values[0]
        for v in candidates[1:]:
            hit = self.apply(lax.ge_p if clip else lax.eq_p, {}, (element.dtype,) * 2, np.bool_, element, v)
            out = _objects(np.vectorize(lambda a, b, h=hit: self.select(h, a, b, _dtype_of(a, b)),
                                        otypes=[object])(values[v], out))
        return out

    def _take(self, operand, positions, fill):
        flat = operand.reshape(-1)
        out = np.empty(positions.shape, dtype=object)
        for idx in np.ndindex(*positions.shape):
            out[idx] = flat[positions[idx]] if positions[idx] >= 0 else fill
        return out

    def _gather(self, eqn, operand, indices):
        p = eqn.params
        mode = str(p["mode"]).lower()
        fill = p.get("fill_value")
        fill = np.asarray(np.nan if fill is None else fill, dtype=eqn.outvars[0].aval.dtype)[()]

        def read(values):
            idx = jnp.asarray(np.asarray(values).reshape(indices.shape), dtype=eqn.invars[1].aval.dtype)
            pos = self._positions(operand.shape, lambda x: eqn.primitive.bind(x, idx, **{**p, "fill_value": 0}))
            return self._take(operand, pos, fill)

        return self._indexed(operand, list(indices.reshape(-1)), read, clip="clip" in mode or "promise" in mode)

    def _dynamic_slice(self, eqn, operand, *starts):
        sizes = eqn.params["slice_sizes"]

        def read(values):
            pos = self._positions(operand.shape, lambda x: lax.dynamic_slice(x, values, sizes))
            return self._take(operand, pos, None)

        return self._indexed(operand, [s[()] for s in starts], read, clip=True)

    def _dynamic_update_slice(self, eqn, operand, update, *starts):
        def read(values):
            with jax.ensure_compile_time_eval():
                marks = np.asarray(lax.dynamic_update_slice(
                    jnp.zeros(operand.shape, jnp.int64), jnp.arange(1, update.size + 1).reshape(update.shape), values))
            return _written(operand, update, marks)

        return self._indexed(operand, [s[()] for s in starts], read, clip=True)

    def _scatter(self, eqn, operand, indices, updates):
        if any(_traced(e) for e in indices.reshape(-1)):
            raise Unsupported("a scatter at traced indices")
        p = eqn.params
        with jax.ensure_compile_time_eval():
            idx = jnp.asarray(np.asarray([int(e) for e in indices.reshape(-1)]).reshape(indices.shape),
                              dtype=eqn.invars[1].aval.dtype)
            marks = np.asarray(eqn.primitive.bind(jnp.zeros(operand.shape, jnp.int64), idx,
                                                  jnp.arange(1, updates.size + 1).reshape(updates.shape), **p))
        return _written(operand, updates, marks)

    # --- control flow ---------------------------------------------------------------------------------------------

    def _scan(self, eqn, *args):
        p = eqn.params
        if p["length"] > MAX_UNROLLED_SCAN:
            raise Unsupported(f"a scan of {p['length']} iterations")
        if "num_consts" in p:  # jax <= 0.10: counts; later releases: flat trees of (consts, carry, xs)
            nc, nk = p["num_consts"], p["num_carry"]
            consts, carry, xs = list(args[:nc]), list(args[nc:nc + nk]), args[nc + nk:]

            def split(out):
                return out[:nk], out[nk:]
        else:
            consts, carry, xs = (list(g) for g in p["ft_in"].update(list(args)).unpack())

            def split(out):
                return tuple(list(g) for g in p["ft_out"].update(out).unpack())
        nk = len(carry)
        ys = []
        order = range(p["length"] - 1, -1, -1) if p["reverse"] else range(p["length"])
        for i in order:
            carry, y = split(self.closed(p["jaxpr"], *consts, *carry, *[x[i:i + 1].reshape(x.shape[1:]) for x in xs]))
            ys.append((i, y))
        ys.sort(key=lambda iy: iy[0])
        stacked = [_objects(np.stack([y[j] for _, y in ys])) if ys else None for j in range(len(eqn.outvars) - nk)]
        if not ys:  # a scan of length 0
            stacked = [np.empty(v.aval.shape, dtype=object) for v in eqn.outvars[nk:]]
        return carry + stacked

    def _cond(self, eqn, index, *args):
        branches = eqn.params["branches"]
        index = index[()]
        if not _traced(index):
            return self.closed(branches[int(np.clip(int(index), 0, len(branches) - 1))], *args)
        outs = [self.closed(b, *args) for b in branches]
        result = outs[0]
        for k in range(1, len(branches)):
            hit = self.apply(lax.ge_p, {}, (index.dtype,) * 2, np.bool_, index, k)
            result = [_objects(np.vectorize(lambda a, b, h=hit, v=v: self.select(h, a, b, v.aval.dtype),
                                            otypes=[object])(new, old))
                      for new, old, v in zip(outs[k], result, eqn.outvars)]
        return result

    def _while(self, eqn, *args):
        p = eqn.params
        cc, bc = p["cond_nconsts"], p["body_nconsts"]
        cond_consts, body_consts, carry = list(args[:cc]), list(args[cc:cc + bc]), list(args[cc + bc:])

        def holds(state):
            return self.closed(p["cond_jaxpr"], *cond_consts, *state)[0][()]

        if not any(_traced(e) for x in args for e in x.reshape(-1)):  # all concrete: folded at trace time
            for _ in range(MAX_CONCRETE_LOOP):
                if not bool(holds(carry)):
                    return carry
                carry = self.closed(p["body_jaxpr"], *body_consts, *carry)
            raise Unsupported("a while loop on concrete values that does not end")
        shapes = [x.shape for x in carry]
        dtypes = [v.aval.dtype for v in eqn.outvars]
        counts = [x.size for x in carry]

        def unflatten(flat):
            out, at = [], 0
            for shape, n in zip(shapes, counts):
                out.append(_objects(_from_list(flat[at:at + n]).reshape(shape)))
                at += n
            return out

        def flatten(state):
            return tuple(self.lanes(e, d) for x, d in zip(state, dtypes) for e in x.reshape(-1))

        elem_dtypes = [d for x, d in zip(carry, dtypes) for _ in range(x.size)]

        def body(flat):
            state = unflatten(flat)
            active = holds(state)
            new = flatten(self.closed(p["body_jaxpr"], *body_consts, *state))
            return tuple(self.select(active, n, o, d) for n, o, d in zip(new, flat, elem_dtypes))

        final = lax.while_loop(lambda flat: self.any_lane(holds(unflatten(flat))), body, flatten(carry))
        return unflatten(final)


def _written(operand, updates, marks):
    """`operand` with the elements of `updates` written where `marks` (an int array of the operand's shape: 0 where
    nothing is written, else 1 + the flat index of the update element written there) says."""
    out = operand.copy()
    flat = updates.reshape(-1)
    for idx in np.ndindex(*operand.shape):
        if marks[idx]:
            out[idx] = flat[marks[idx] - 1]
    return out


def _elementwise_like(eqn):
    """Whether a primitive not named in `_ELEMENTWISE` acts elementwise: one output, every input shaped like it
    (or a scalar), and no name of a known same-shape operation that is not (a scan, a sort, a
    transform, a collective, a callback)."""
    name = eqn.primitive.name
    if eqn.primitive.multiple_results or name.startswith(_NOT_ELEMENTWISE):
        return False
    shape = eqn.outvars[0].aval.shape
    return all(np.shape(v.aval) in (shape, ()) for v in eqn.invars)


def _objects(x):
    """An object array (a copy) of the elements of `x`: an array of elements, or one element (a 0-d array)."""
    if isinstance(x, np.ndarray) and x.dtype == object:
        return x.copy()
    if isinstance(x, np.ndarray):
        return _const(x)
    out = np.empty((), dtype=object)
    out[()] = x
    return out


def _from_list(items):
    out = np.empty(len(items), dtype=object)
    for i, item in enumerate(items):
        out[i] = item
    return out


def _const(value):
    """A concrete value as an object array of NumPy scalars."""
    arr = np.asarray(value)
    out = np.empty(arr.shape, dtype=object)
    for idx in np.ndindex(*arr.shape):
        out[idx] = arr[idx]
    return out


def _dtype_of(*elements):
    for e in elements:
        if _traced(e):
            return e.dtype
    return np.result_type(*[np.asarray(e) for e in elements])


def evaluate(fun, width, *args):
    """`fun` traced on `args` (pytrees of per-lane arrays or `jax.ShapeDtypeStruct`s) as a function of elements:
    returns (the closed jaxpr, `run`), `run(*trees)` taking pytrees like `args` whose leaves are object arrays of
    elements (each a NumPy scalar or a (`width`,) array across lanes) and returning `fun`'s output pytree with such
    leaves."""
    closed, out_shape = jax.make_jaxpr(fun, return_shape=True)(*args)
    out_tree = jax.tree_util.tree_structure(out_shape)
    evaluator = Evaluator(width)

    def run(*trees):
        leaves = jax.tree_util.tree_leaves(trees, is_leaf=lambda x: isinstance(x, np.ndarray))
        return jax.tree_util.tree_unflatten(out_tree, evaluator.closed(closed, *leaves))

    return closed, run
