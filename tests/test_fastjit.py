"""`pamjax._core.fastjit.filter_jit` against `equinox.filter_jit`: the same values and outputs, retraced exactly when
a static leaf, the tree structure or an array's shape or dtype changes, and the fallback for unhashable leaves."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._core.fastjit import filter_jit


class Gain(eqx.Module):
    k: jax.Array
    label: str = eqx.field(static=True)


def _counted(fn):
    traces = []

    def wrapped(*args, **kwargs):
        traces.append(1)
        return fn(*args, **kwargs)

    return wrapped, traces


def test_same_results_as_equinox_with_static_leaves_and_non_array_outputs():
    def f(model, x, power, *, name):
        return {"y": model.k * x**power, "name": name, "label": model.label, "power": power}

    fast, slow = filter_jit(f), eqx.filter_jit(f)
    model = Gain(jnp.asarray(2.0), "g")
    x = np.linspace(0.0, 1.0, 5)
    for power in (1, 2, 2.5):
        a, b = fast(model, x, power, name="n"), slow(model, x, power, name="n")
        assert a["name"] == b["name"] == "n" and a["label"] == "g" and a["power"] == power
        np.testing.assert_array_equal(np.asarray(a["y"]), np.asarray(b["y"]))


def test_retraces_exactly_when_a_static_part_or_a_shape_changes():
    f, traces = _counted(lambda model, x, power: model.k * x**power)
    fast = filter_jit(f)
    model = Gain(jnp.asarray(2.0), "g")
    fast(model, jnp.ones(3), 2)
    fast(Gain(jnp.asarray(5.0), "g"), jnp.zeros(3), 2)  # new array values only
    assert len(traces) == 1
    fast(model, jnp.ones(3), 3)  # static leaf
    fast(model, jnp.ones(3), 3.0)  # equal to 3, another type: kept apart (int power vs float power)
    fast(Gain(jnp.asarray(2.0), "h"), jnp.ones(3), 2)  # static field of a module: in the tree structure
    fast(model, jnp.ones(4), 2)  # shape
    assert len(traces) == 5
    assert float(fast(model, jnp.full(4, 2.0), 3.0)[0]) == pytest.approx(16.0)  # (power 3.0, 4 points): new
    assert len(traces) == 6


def test_unhashable_static_leaf_goes_to_equinox_and_its_error():
    class Unhashable:
        __hash__ = None

        def __len__(self):
            return 3

    f = lambda x, table: x * len(table)  # noqa: E731
    with pytest.raises(ValueError, match="Non-hashable static arguments") as fast_error:
        filter_jit(f)(jnp.ones(2), Unhashable())
    with pytest.raises(ValueError, match="Non-hashable static arguments") as slow_error:
        eqx.filter_jit(f)(jnp.ones(2), Unhashable())
    assert type(fast_error.value) is type(slow_error.value)


def test_simulate_through_it_equals_the_equinox_program():
    system = presets.mas10_system("averaged")
    signal = pamjax.Triangle(0.05, 0.95, 0.25)
    ts = jnp.linspace(0.0, 2.0, 101)
    kwargs = dict(solver=pamjax.unchecked.default_solver(system))
    args = (system, signal, ts, None, ts[0])
    a = filter_jit(pamjax.unchecked.solve)(*args, **kwargs)
    b = eqx.filter_jit(pamjax.unchecked.solve)(*args, **kwargs)
    assert type(a) is type(b)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=0)
    traj = pamjax.simulate(system, signal, ts)  # simulate's own top-level program
    np.testing.assert_allclose(np.asarray(traj.position), np.asarray(a.position), rtol=1e-9, atol=1e-13)
