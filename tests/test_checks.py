"""A system's parameters are checked before a solve however the system was made (`pamjax._solve.checks`; issue 33,
battery section 7): changed with `eqx.tree_at` (which skips the components' constructors), or traced inside
`jax.jit`/`jax.vmap`, a bad value is named — never a solver failure ("minimum step size reached", "INTERNAL: CpuCallback
error") or a silent result; good values under jit, vmap and grad give what the eager call gives."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import PamjaxInputError, presets

TS = np.linspace(0.0, 0.3, 7)


@pytest.fixture(scope="module")
def system():
    return presets.mas10_system(valve="averaged")


def _with_mass(system, mass):
    return eqx.tree_at(lambda s: s.payload_mass, system, mass)


@pytest.mark.parametrize("mass, match", [
    (-1.0, r"MuscleSystem\.payload_mass must be > 0 and finite, got -1"),  # was: PamjaxSolveError, minimum step
    (np.nan, r"MuscleSystem\.payload_mass must be > 0 and finite, got nan"),
    (9600.0, r"payload_mass = 9600 kg: more than 1000 kg; that looks like g"),  # grams, as configs refuse them
])
@pytest.mark.parametrize("as_value", [jnp.asarray, float], ids=["array", "python float"])
def test_a_bad_parameter_set_with_tree_at_is_named_before_the_solve(system, mass, match, as_value):
    # a Python float set with tree_at stays a Python number (no constructor ran): checked as an array is
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.simulate(_with_mass(system, as_value(mass)), pamjax.Constant(0.5), TS)


def test_python_floats_set_with_tree_at_are_arguments_of_one_program(system, caplog):
    # `jax.jit` takes a Python number as a constant of the program: each value compiled a solve of its own (~1 s).
    # simulate and sweep make them arrays first (pamjax._core.arrays.floats_as_arrays), as a constructor would.
    from pamjax._core.arrays import floats_as_arrays

    assert floats_as_arrays(system) is system  # nothing to convert: the same object
    changed = _with_mass(system, 9.0)
    converted = floats_as_arrays(changed)
    assert eqx.is_array(converted.payload_mass) and float(converted.payload_mass) == 9.0
    assert jax.tree_util.tree_structure(converted) == jax.tree_util.tree_structure(system)
    signal = pamjax.Constant(0.5)
    def swept(mass):
        return pamjax.sweep(_with_mass(system, mass), signal, TS, {"signal.value": [0.5, 0.6]}, progress=False)

    first, first_map = pamjax.simulate(_with_mass(system, 9.1), signal, TS), swept(9.1)  # compile, as any first call
    with caplog.at_level("WARNING"), jax.log_compiles():
        second, second_map = pamjax.simulate(_with_mass(system, 9.2), signal, TS), swept(9.2)
    compiled = [r.getMessage()[:80] for r in caplog.records if r.getMessage().startswith("Compiling")
                and ("solve" in r.getMessage() or "_run_chunk" in r.getMessage())]
    assert not compiled, compiled  # the second value reused the first one's programs
    assert np.all(first.position != second.position)  # and did use its own value
    np.testing.assert_array_equal(second.position,
                                  pamjax.simulate(_with_mass(system, jnp.asarray(9.2)), signal, TS).position)
    assert np.all(first_map.status == 0) and np.all(second_map.status == 0)
    np.testing.assert_allclose(second_map["position"][0], second.position, atol=1e-7)  # two solvers: to 0.1 um


def test_a_concrete_call_keeps_what_it_made_and_a_traced_call_makes_its_own(system):
    # A concrete `simulate` keeps what it makes of the same inputs (the system with its floats as arrays, its start
    # time and tolerances on the device: ~0.3 ms of a 1 ms call on a slow CPU). Inside a transformation nothing kept
    # is handed out, and nothing made there (a tracer) is kept.
    from pamjax._core.arrays import kept_on_device
    from pamjax._solve.checks import prepared

    changed = _with_mass(system, 9.3)
    ready, traced = prepared(changed)
    assert not traced and eqx.is_array(ready.payload_mass) and float(ready.payload_mass) == 9.3
    assert prepared(changed)[0] is ready and prepared(system)[0] is system
    kept = kept_on_device(("test", 0.25), lambda: jnp.asarray(0.25))
    assert kept_on_device(("test", 0.25), lambda: jnp.asarray(-1.0)) is kept and float(kept) == 0.25
    inside = {}

    def traced_call(x):
        inside["system"], inside["traced"] = prepared(_with_mass(system, x))
        inside["ready_again"] = prepared(changed)[0] is ready
        inside["number"] = kept_on_device(("test", 0.25), lambda: x * 0.0 + 0.25)
        return x

    jax.jit(traced_call)(9.3)
    assert inside["traced"] and not inside["ready_again"] and isinstance(inside["number"], jax.core.Tracer)
    assert kept_on_device(("test", 0.25), lambda: jnp.asarray(-1.0)) is kept  # the tracer was not kept
    # the time grid as NumPy, a list, a float64 or a float32 JAX array: the trajectory of its float64 values
    signal = pamjax.Constant(0.5)
    reference = np.asarray(pamjax.simulate(changed, signal, TS).position)
    for ts in (TS.tolist(), jnp.asarray(TS), jnp.asarray(TS, dtype=jnp.float32)):
        grid = np.asarray(ts, dtype=float)
        expected = reference if np.array_equal(grid, TS) else pamjax.simulate(changed, signal, grid).position
        np.testing.assert_array_equal(np.asarray(pamjax.simulate(changed, signal, ts).position), expected)
    in_jit = jax.jit(lambda m: pamjax.simulate(_with_mass(system, m), signal, jnp.asarray(TS)).position)(9.3)
    np.testing.assert_allclose(np.asarray(in_jit), reference, rtol=1e-12, atol=1e-15)


def test_a_parameter_with_an_axis_too_many_is_named(system):
    # was: TypeError "scan body function carry input and carry output must have equal types"
    with pytest.raises(PamjaxInputError, match=r"parameter 'payload_mass' has shape \(2,\) where the model takes one "
                                               "number"):
        pamjax.simulate(_with_mass(system, jnp.asarray([9.6, 5.0])), pamjax.Constant(0.5), TS)


def test_a_start_state_that_is_not_finite_is_named_by_its_leaf(system):
    # `check_finite_state`, which simulate, linearise and equilibrium share: the leaf named (was "y0 must be finite")
    y0 = eqx.tree_at(lambda s: s.position, system.initial_state(pressure=4e5), jnp.asarray(np.inf))
    with pytest.raises(PamjaxInputError, match=r"y0\.position must be finite \(no NaN or inf\), got inf"):
        pamjax.simulate(system, pamjax.Constant(0.5), TS, y0=y0)


def test_a_duty_in_percent_is_named_as_percent(system):
    with pytest.raises(PamjaxInputError, match=r"its range is \[50\.0, 50\.0\]; that looks like percent: a duty ratio "
                                               r"of 0\.5 is written 0\.5"):
        pamjax.simulate(system, pamjax.Constant(50.0), TS)


def test_a_bad_parameter_inside_jit_is_named_at_run_time(system):
    run = jax.jit(lambda m: pamjax.simulate(_with_mass(system, m), pamjax.Constant(0.5), TS).position[-1])
    with pytest.raises(Exception, match=r"MuscleSystem\.payload_mass must be > 0 and finite"):
        run(-1.0)
    assert float(run(9.6)) == pytest.approx(float(pamjax.simulate(system, pamjax.Constant(0.5), TS).position[-1]),
                                            rel=1e-9, abs=1e-12)


def test_a_bad_parameter_inside_vmap_is_named(system):
    run = jax.vmap(lambda m: pamjax.simulate(_with_mass(system, m), pamjax.Constant(0.5), TS).position[-1])
    with pytest.raises(PamjaxInputError, match=r"MuscleSystem\.payload_mass must be > 0 and finite"):
        run(jnp.asarray([9.6, -1.0]))
    good = np.asarray(run(jnp.asarray([9.6, 5.0])))
    eager = [float(pamjax.simulate(_with_mass(system, jnp.asarray(m)), pamjax.Constant(0.5), TS).position[-1])
             for m in (9.6, 5.0)]
    np.testing.assert_allclose(good, eager, rtol=1e-9, atol=1e-12)


def test_a_duty_out_of_range_inside_vmap_is_refused(system):
    # was: a position returned for duty 1.5, no error, no NaN
    run = jax.vmap(lambda d: pamjax.simulate(system, pamjax.Constant(d), TS).position[-1])
    with pytest.raises(PamjaxInputError, match=r"signal \(the valve command, e\.g\. duty ratio\) must stay within "
                                               r"\[0\.0, 1\.0\]"):
        run(jnp.asarray([0.3, 1.5]))
    good = np.asarray(run(jnp.asarray([0.3, 0.6])))
    eager = [float(pamjax.simulate(system, pamjax.Constant(d), TS).position[-1]) for d in (0.3, 0.6)]
    np.testing.assert_allclose(good, eager, rtol=1e-9, atol=1e-12)


def test_gradients_pass_through_the_checks(system):
    def final(m):
        return pamjax.simulate(_with_mass(system, m), pamjax.Constant(0.5), TS).position[-1]

    g = float(jax.grad(final)(9.6))
    fd = (float(final(9.6 * (1 + 1e-6))) - float(final(9.6 * (1 - 1e-6)))) / (2 * 9.6e-6)
    assert np.isfinite(g) and g == pytest.approx(fd, rel=1e-4)


@pytest.mark.parametrize("value", [9.6, 3, [1.0, 2.0], [1, 2], (0.5,), [[1.0], [2.0]], [1, 2.5], np.arange(3.0),
                                   np.float32(2.0), np.int64(4)])
def test_component_converters_make_jnp_asarrays_without_compiling(value, monkeypatch):
    """`as_scalar`/`as_array`/`as_table` (every component's field converter): for host numbers, lists and NumPy
    arrays the same array as `jnp.asarray` (values, dtype, weak type, shape), made on the host: `jnp.asarray`
    compiles a small program per shape and dtype (~50 ms the first time), in every command's set-up."""
    import pamjax
    from pamjax._core.arrays import as_array, as_scalar, as_table

    # integers become floats (a parameter is float64: an int payload made jax.grad fail), as if written 3.0
    expected = jnp.asarray(float(value) if type(value) is int
                           else np.asarray(value, dtype=float) if np.asarray(value).dtype.kind in "iu" else value)
    convert = as_scalar if np.ndim(value) == 0 else as_table if np.ndim(value) == 1 else as_array

    def compiling(*args, **kwargs):  # the program of an earlier call may be cached: the route itself is checked
        raise AssertionError("jnp.asarray of a host value (it compiles a program per shape and dtype)")

    monkeypatch.setattr(jnp, "asarray", compiling)
    with pamjax.runtime.CompileStats() as stats:
        got = convert(value)
    monkeypatch.undo()
    assert stats.count["compile"] == 0 and stats.count["trace"] == 0, stats.summary()
    assert isinstance(got, jax.Array)
    assert (got.dtype, got.weak_type, got.shape) == (expected.dtype, expected.weak_type, expected.shape)
    np.testing.assert_array_equal(np.asarray(got), np.asarray(expected))


def test_a_tolerance_first_seen_inside_jit_does_not_leak_its_tracer(system):
    """The regression: `simulate`'s tolerances are kept as device arrays per value; the first call with a value made
    inside `jax.jit` kept the trace's copy (a tracer), and the next call with that value failed with JAX's
    UnexpectedTracerError (`pamjax.gallery`'s VPPM fits, depending on which test ran first)."""
    rtol = 1.2345e-6  # a value no other test uses
    run = jax.jit(lambda m: pamjax.simulate(_with_mass(system, m), pamjax.Constant(0.5), TS, rtol=rtol).position[-1])
    inside = float(run(9.6))
    outside = float(pamjax.simulate(system, pamjax.Constant(0.5), TS, rtol=rtol).position[-1])
    assert inside == pytest.approx(outside, rel=1e-9, abs=1e-12)
    assert float(jax.jit(lambda m: pamjax.simulate(_with_mass(system, m), pamjax.Constant(0.5), TS,
                                                   rtol=rtol).position[-1])(9.6)) == inside


@pytest.mark.parametrize("where, value, match", [
    # each was silent or a failure inside the solve; set with eqx.tree_at (no constructor ran), named before it
    (lambda s: s.end_stops.width, 0.1, r"EndStops\.width = 0\.1 m: more than 0\.005 m.*looks like mm"),  # 21 kN
    (lambda s: s.muscle.volume_law.v0, 0.02356, r"LinearVolume\.v0 = 0\.02356 m³.*looks like cm³ or litres"),
    (lambda s: s.muscle.volume_law.v1, -1e-4, r"LinearVolume\.v1 must be > 0 and finite"),
    (lambda s: s.friction, None, r"MuscleSystem\.friction must be an AbstractFriction .*got NoneType"),
])
def test_a_part_or_a_magnitude_set_with_tree_at_is_named_before_the_solve(system, where, value, match):
    changed = eqx.tree_at(where, system, value, is_leaf=lambda x: x is None)
    with pytest.raises(PamjaxInputError, match=match):
        pamjax.simulate(changed, pamjax.Constant(0.5), TS)


def test_a_nominal_length_and_an_edge_width_set_with_tree_at_are_named_before_the_solve():
    # the DMSP-40's L0 = 400 (mm) simulated silently; a valve edge of 0.1 (ms) too
    plant = eqx.tree_at(lambda s: s.muscle, presets.mas10_system("averaged"), presets.dmsp40_muscle())
    changed = eqx.tree_at(lambda s: s.muscle.volume_law.nominal_length, plant, 400.0)
    with pytest.raises(PamjaxInputError, match=r"CubicVolume\.nominal_length = 400 m: more than 10 m.*looks like mm"):
        pamjax.simulate(changed, pamjax.Constant(0.5), TS)
    tank = eqx.tree_at(lambda s: s.valve.edge_width, presets.mas10_tank_system(), 0.1)
    with pytest.raises(PamjaxInputError, match=r"OnOffValve\.edge_width \(0\.1 s = 100 ms\) must not exceed 5%"):
        pamjax.simulate(tank, pamjax.Constant(0.25), TS)


def test_an_empty_array_or_text_for_a_scalar_parameter_is_refused():
    # payload_mass = [] passed the positivity checks vacuously and the solve failed deep inside JAX ("scan body
    # function carry input and carry output must have equal types")
    with pytest.raises(pamjax.PamjaxInputError, match=r"a scalar parameter got an empty array \(shape \(0,\)\)"):
        presets.mas10_system(valve="averaged", payload_mass=np.array([]))
    with pytest.raises(pamjax.PamjaxInputError, match="empty array"):
        pamjax.Step(0.2, 0.8, [])
    with pytest.raises(pamjax.PamjaxInputError, match=r"a scalar parameter got the text '0.1': give a number"):
        pamjax.Step("0.1", 0.8, 1.0)  # a raw JAX TypeError before
