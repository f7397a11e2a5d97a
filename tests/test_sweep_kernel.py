"""The GPU sweep kernel on the CPU: `pamjax/_sweep/scalar.py`'s element evaluator against `jax.vmap` of the same
function (products, polynomial scans, per-lane while loops, traced table lookups, conditionals), the whole kernel
(`kernel.py`) in Pallas's interpreter against the XLA program of a real sweep lane, and `run_lanes`' fallback (a
kernel that cannot compile runs XLA's program, said once) and its switch. The kernel's speed needs a GPU:
benchmarks/sweep_throughput.py --kernel on."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._sweep import lanes
from pamjax._sweep.kernel import kernel_lanes
from pamjax._sweep.scalar import Unsupported, evaluate

WIDTH = 6


def _elements(batch):
    """A (WIDTH, *shape) array as an object array of shape `shape` whose elements are (WIDTH,) arrays."""
    out = np.empty(batch.shape[1:], dtype=object)
    for idx in np.ndindex(*batch.shape[1:]):
        out[idx] = jnp.asarray(batch[(slice(None),) + idx])
    return out


def _batched(elements):
    """The inverse of `_elements` (constant elements broadcast over the lanes)."""
    flat = [np.broadcast_to(np.asarray(e), (WIDTH,)) for e in elements.reshape(-1)]
    return np.stack(flat, axis=-1).reshape((WIDTH,) + elements.shape)


def _check(fun, *example, rtol=1e-13):
    rng = np.random.default_rng(0)
    batch = [np.asarray(a, dtype=float)[None] * (1.0 + 0.2 * rng.uniform(size=(WIDTH,) + np.shape(a))) for a in example]
    want = jax.tree_util.tree_leaves(jax.vmap(fun)(*batch))
    _, run = evaluate(fun, WIDTH, *[jnp.asarray(a, dtype=float) for a in example])
    got = jax.tree_util.tree_leaves(run(*[_elements(b) for b in batch]), is_leaf=lambda x: isinstance(x, np.ndarray))
    assert len(got) == len(want)
    for g, w in zip(got, want):
        np.testing.assert_allclose(_batched(g), np.asarray(w), rtol=rtol, atol=1e-300)


def test_products_polynomials_and_reductions_match_vmap():
    def fun(x, m):
        v = m @ jnp.stack([jnp.ones_like(x), x, x * x])  # the averaged valve's form
        return v, jnp.polyval(jnp.array([1.0, -2.0, 3.0, 0.5, 5.0]), x), jnp.sum(m * x, axis=0), jnp.max(v)

    _check(fun, 0.7, np.eye(3) + 0.3)


def test_a_while_loop_runs_each_lane_to_its_own_end():
    """Lanes need different trip counts: each keeps its state once its own condition is false (as vmap)."""

    def fun(x):
        def body(c):
            return c[0] + 1.0, 0.5 * c[1] + jnp.tanh(x)

        return jax.lax.while_loop(lambda c: c[0] < 3.0 + 10.0 * x, body, (0.0, x))

    _check(fun, 0.5)


def test_traced_indices_conditionals_and_shapes_match_vmap():
    def fun(x):
        grid = jnp.linspace(0.0, 2.0, 11)
        k = jnp.floor(x * 7.0).astype(int)
        picked = grid[jnp.minimum(k, 10)]
        window = jax.lax.dynamic_slice(grid, (k,), (3,))
        branch = jax.lax.cond(x > 0.8, lambda y: jnp.exp(y), lambda y: jnp.log1p(y), x)
        parts = jnp.split(jnp.concatenate([grid[:4] * x, jnp.array([x])]), [2])
        written = jax.lax.dynamic_update_slice(grid, jnp.stack([x, 2.0 * x]), (k,)).at[1].set(-x)
        return picked, window, branch, parts[1][::-1], jnp.clip(x, 0.6, 0.9), written

    _check(fun, 0.75)


def test_what_it_cannot_express_is_refused():
    _, run = evaluate(lambda x: jnp.sort(jnp.stack([x, -x, 2 * x])), WIDTH, jnp.asarray(1.0))
    with pytest.raises(Unsupported, match="sort"):
        run(_elements(np.linspace(0.1, 1.0, WIDTH)[:, None].reshape(WIDTH)))


def _lane_program(n, reduce):
    """A real sweep lane (the MAS-10 averaged map, RODAS5 with error control) and its swept duties."""
    captured = {}

    def spy(platform, program, system, signal, y0, vals, ts, plan, config, mesh):
        captured.update(system=system, signal=signal, y0=y0, ts=ts, plan=plan, config=config)
        return lanes.run_lanes(platform, program, system, signal, y0, vals, ts, plan, config, mesh)

    duties = np.linspace(0.05, 0.95, n)
    ts = np.linspace(0.0, 1.0, 11)
    from pamjax._sweep import sweep as sweep_module

    original = sweep_module.run_lanes
    sweep_module.run_lanes = spy
    try:
        ref = pamjax.sweep(presets.mas10_system(valve="averaged"), pamjax.Constant(0.5), ts, {"signal.value": duties},
                           reduce=reduce, channels=("pressure", "position"), method="rodas5a", progress=False)
    finally:
        sweep_module.run_lanes = original
    return captured, {"signal.value": jnp.asarray(duties)}, ref


def test_the_kernel_in_the_interpreter_equals_the_xla_program():
    c, values, ref = _lane_program(12, pamjax.FinalValue())
    out, status = lanes.run_kernel_chunk(c["system"], c["signal"], c["y0"], values, c["ts"], c["plan"], c["config"],
                                         interpret=True, block=8)  # 12 lanes: two blocks, the last one padded
    assert np.all(np.asarray(status) == 0)
    np.testing.assert_allclose(np.asarray(out[:, 0]), ref["pressure"], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(out[:, 1]), ref["position"], rtol=1e-9, atol=1e-15)


def test_full_trajectories_are_refused_by_the_kernel():
    """reduce=None writes each output time at the lane's own index: a scatter the kernel cannot express."""
    c, values, _ = _lane_program(4, None)
    with pytest.raises(Unsupported, match="scatter"):
        lanes.run_kernel_chunk(c["system"], c["signal"], c["y0"], values, c["ts"], c["plan"], c["config"],
                               interpret=True, block=4)


def test_kernel_lanes_pads_the_last_block_and_keeps_point_order():
    def lane(uniform, point):
        return uniform["a"] * point["x"] + uniform["b"][1], point["x"] > 0.5

    x = jnp.linspace(0.0, 1.0, 5)
    value, flag = kernel_lanes(lane, {"a": jnp.asarray(2.0), "b": jnp.asarray([1.0, 3.0, 5.0])}, {"x": x}, block=4,
                               interpret=True)
    np.testing.assert_allclose(np.asarray(value), 2.0 * np.asarray(x) + 3.0)
    assert np.asarray(flag).dtype == bool and list(np.asarray(flag)) == [False, False, False, True, True]


def test_a_kernel_that_cannot_compile_falls_back_once_with_a_warning(monkeypatch):
    """On a CPU the Pallas kernel cannot be lowered (no GPU): with the switch on, `run_lanes` said so once and ran
    the XLA program (equal results); a second call does not try again; with it off there is no attempt."""
    c, values, ref = _lane_program(8, pamjax.FinalValue())
    args = (lanes.chunk_program("cpu"), c["system"], c["signal"], c["y0"], values, c["ts"], c["plan"], c["config"],
            None)
    monkeypatch.setattr(lanes, "_KERNEL_REFUSED", {})
    monkeypatch.setenv(lanes.KERNEL_FLAG, "1")
    with pytest.warns(UserWarning, match="the GPU kernel does not apply to this sweep"):
        out, status = lanes.run_lanes("gpu", *args)
    np.testing.assert_array_equal(np.asarray(out[:, 0]), ref["pressure"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lanes.run_lanes("gpu", *args)  # refused once, not tried again
    monkeypatch.setattr(lanes, "_KERNEL_REFUSED", {})
    monkeypatch.setenv(lanes.KERNEL_FLAG, "0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, _ = lanes.run_lanes("gpu", *args)
    np.testing.assert_array_equal(np.asarray(out[:, 0]), ref["pressure"])
