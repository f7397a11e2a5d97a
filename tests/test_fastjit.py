"""`pamjax._core.fastjit.filter_jit` against `equinox.filter_jit`: the same values and outputs, retraced exactly when
a static leaf, the tree structure or an array's shape or dtype changes, and the fallback for unhashable leaves;
`SameCode`, a user's function keyed by its code and closure values (an inline sweep factory reuses its program)."""

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


# --- `SameCode`: a user's function keyed by its code and closure values, so that an inline lambda reuses a program


def _scaled(scale):
    return lambda v: v * scale


def test_same_code_is_equal_exactly_when_the_functions_compute_the_same():
    from pamjax._core.fastjit import SameCode

    assert SameCode(_scaled(2.0)) == SameCode(_scaled(2.0))  # two closures, one code, equal values
    assert hash(SameCode(_scaled(2.0))) == hash(SameCode(_scaled(2.0)))
    assert SameCode(_scaled(2.0)) != SameCode(_scaled(3.0))
    assert SameCode(_scaled(2.0)) != SameCode(_scaled(2))  # 2.0 and 2 are other constants of a program
    assert SameCode(_scaled(0.0)) != SameCode(_scaled(-0.0))
    assert SameCode(_scaled((1.0, "a"))) == SameCode(_scaled((1.0, "a")))
    assert SameCode(_scaled(_scaled(1.0))) == SameCode(_scaled(_scaled(1.0)))  # a function in the closure, by its code
    assert SameCode(_scaled(_scaled(1.0))) != SameCode(_scaled(_scaled(5.0)))
    lambdas = [lambda v: v + 1 for _ in range(2)]
    assert SameCode(lambdas[0]) == SameCode(lambdas[1])
    assert SameCode(lambda v: v + 1) != SameCode(lambdas[0])  # another lambda's code (another line)
    array = jnp.ones(2)  # what cannot change in place (a JAX array, a system, a module): by its identity
    assert SameCode(_scaled(array)) == SameCode(_scaled(array)) and SameCode(_scaled(array)) != SameCode(_scaled(
        jnp.ones(2)))
    system = presets.mas10_system("averaged")
    assert SameCode(_scaled(system)) == SameCode(_scaled(system))
    mutable = [[1.0], {"k": 1.0}, np.ones(2)]  # what may have changed since: never shared, traced afresh
    for value in mutable:
        assert SameCode(_scaled(value)) != SameCode(_scaled(value))
    assert SameCode(_scaled(2.0))(3.0) == 6.0
    # a loop at a script's top level rebinds a global that its inline lambda reads: each value is another function
    script = {}
    exec("def make():\n    return lambda v: v * scale\n", script)
    script["scale"] = 1.0
    first = SameCode(script["make"]())
    script["scale"] = 1.0
    assert SameCode(script["make"]()) == first
    script["scale"] = 2.0
    assert SameCode(script["make"]()) != first
    script["params"] = {"scale": 1.0}  # a global dict changed between two calls: not shared
    exec("def make_from_dict():\n    return lambda v: v * params['scale']\n", script)
    assert SameCode(script["make_from_dict"]()) != SameCode(script["make_from_dict"]())


def test_an_inline_factory_reuses_the_sweeps_program_and_another_closure_value_does_not():
    """A sweep called in a loop with its signal factory written inline compiles once; a factory closing over another
    value is another program, whose results are its own (checked against the same sweep written without it)."""
    from helpers import counted_compilations

    system = presets.mas10_tank_system("averaged")
    ts = jnp.linspace(0.0, 0.2, 5)

    def run(scale, duty=(0.2, 0.6)):
        return pamjax.sweep(system, lambda v: pamjax.Constant(v["duty"] * scale), ts, {"duty": jnp.asarray(duty)},
                            progress=False).outputs["pressure"]

    first = run(1.0)
    with counted_compilations() as compiled:
        again = run(1.0, duty=(0.3, 0.5))
    assert compiled == [], compiled
    np.testing.assert_allclose(again, run(0.5, duty=(0.6, 1.0)), rtol=1e-12)  # its own program: 0.5 x (0.6, 1)
    assert not np.allclose(run(0.5), first)


class _DutyFactory:
    """A callable object whose attribute a script changes between two sweeps."""

    def __init__(self, scale):
        self.scale = scale

    def __call__(self, v):
        return pamjax.Constant(v["duty"] * self.scale)


def test_a_callable_object_is_keyed_by_its_attributes_so_a_changed_one_is_traced_afresh():
    """A factory object whose attribute changed between two sweeps gave the first sweep's results again (the program
    was keyed by the object's identity); it is keyed by its type and attributes' values, or, with an attribute that
    may change in place, shared with no other call."""
    from pamjax._core.fastjit import SameCode

    factory = _DutyFactory(1.0)
    first = SameCode(factory)
    assert SameCode(_DutyFactory(1.0)) == first and hash(SameCode(_DutyFactory(1.0))) == hash(first)
    factory.scale = 0.5
    assert SameCode(factory) != first
    held = SameCode(_DutyFactory([1.0]))  # a list attribute may change in place: this call's own program
    assert held == held and held != SameCode(held.fn)
    assert SameCode(factory.__call__) != SameCode(_DutyFactory(1.0).__call__)  # a bound method: its object's state

    system = presets.mas10_tank_system("averaged")
    ts = jnp.linspace(0.0, 0.2, 5)
    factory.scale = 1.0
    run = lambda: pamjax.sweep(system, factory, ts, {"duty": jnp.asarray([0.2, 0.6])},  # noqa: E731
                               progress=False).outputs["pressure"]
    full = run()
    factory.scale = 0.5
    half = run()
    expected = pamjax.sweep(system, lambda v: pamjax.Constant(v["duty"] * 0.5), ts, {"duty": jnp.asarray([0.2, 0.6])},
                            progress=False).outputs["pressure"]
    np.testing.assert_allclose(half, expected, rtol=1e-12)
    assert not np.allclose(half, full)
