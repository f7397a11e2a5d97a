"""Property-based tests (hypothesis): over random valid parameters and states, equal pressures (chamber = supply,
chamber = atmosphere) and zero velocity included, the vector field, its Jacobian and a short trajectory's gradient
are always finite. The systems' vector fields (`pamjax._systems`), the gradient through `pamjax._solve.simulate`."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from helpers import P_ATM
from hypothesis import given, settings, strategies as st

import pamjax
from pamjax import presets
from pamjax._solve.simulate import solve

SETTINGS = settings(max_examples=12, deadline=None, derandomize=True)


def _system(cv_in, b_in, cv_out, b_out, supply, mass, fc, cf, scale, n):
    valve = pamjax.OnOffValve(
        inflate=pamjax.EllipseRestriction(cv_in, b_in, 3.14e-6),
        exhaust=pamjax.EllipseRestriction(cv_out, b_out, 3.14e-6),
        supply_pressure=supply,
    )
    base = presets.mas10_muscle()
    law = base.force_law
    muscle = pamjax.Muscle(
        pamjax.PolynomialForce(law.max_force_coefficients * scale, law.k0 * scale, law.k1 * scale, law.k2),
        base.volume_law, base.min_position, base.max_position,
    )
    return pamjax.MuscleSystem(valve, muscle, payload_mass=mass, friction=pamjax.CoulombViscousFriction(fc, cf),
                               polytropic_index=n)


params = st.tuples(
    st.floats(0.1, 1.0), st.floats(0.05, 0.95), st.floats(0.1, 1.0), st.floats(0.05, 0.95),
    st.floats(2e5, 8e5), st.floats(0.5, 30.0), st.floats(0.0, 50.0), st.floats(0.0, 1000.0), st.floats(0.5, 2.0),
    st.sampled_from([1.0, 1.4]),
)
pressures = st.one_of(st.just("supply"), st.just(P_ATM), st.floats(1e3, 9e5))
positions = st.one_of(st.just(0.0), st.floats(-0.03, 0.09))
velocities = st.one_of(st.just(0.0), st.floats(-1.0, 1.0))


def _flat_field(system, t, y, u):
    state = pamjax.MuscleState(y[0], y[1], y[2])
    d = system.vector_field(t, state, u)
    return jnp.stack([d.pressure, d.position, d.velocity])


@eqx.filter_jit
def _field_and_jacobian(system, t, y, u):
    return _flat_field(system, t, y, u), jax.jacfwd(_flat_field, argnums=2)(system, t, y, u)


@SETTINGS
@given(params, pressures, positions, velocities, st.floats(0.0, 0.04), st.floats(0.0, 1.0))
def test_vector_field_and_jacobian_finite(p, pressure, x, v, t, u):
    system = _system(*p)
    pressure = p[4] if pressure == "supply" else pressure
    f, jac = _field_and_jacobian(system, jnp.asarray(t), jnp.asarray([pressure, x, v]), jnp.asarray(u))
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(jac))


@eqx.filter_jit
def _trajectory_gradient(system, y0, u):
    ts = jnp.linspace(0.0, 0.01, 3)

    def loss(params, u):
        s = eqx.combine(params, static)
        traj = solve(s, pamjax.Constant(u), ts, y0, ts[0], max_steps=20_000)
        return jnp.sum(traj.pressure / 1e5) + jnp.sum(traj.position / 1e-2)

    params, static = eqx.partition(system, eqx.is_inexact_array)
    return jax.grad(loss, argnums=(0, 1))(params, u)


@settings(max_examples=6, deadline=None, derandomize=True)
@given(params, pressures, st.floats(-0.01, 0.07), st.floats(0.0, 1.0))
def test_short_trajectory_gradient_finite(p, pressure, x, u):
    system = _system(*p)
    pressure = p[4] if pressure == "supply" else max(pressure, 5e4)
    y0 = pamjax.MuscleState(jnp.asarray(pressure), jnp.asarray(x), jnp.asarray(0.0))
    grads = _trajectory_gradient(system, y0, jnp.asarray(u))
    assert all(np.all(np.isfinite(g)) for g in jax.tree_util.tree_leaves(grads))


def _variant_system(variant):
    valve, kind = variant.split("-")
    if kind == "tank":
        return presets.mas10_tank_system(valve=valve)
    return presets.mas10_system(valve=valve, friction=kind)


@eqx.filter_jit
def _generic_field_and_jacobian(system, t, state, u):
    from jax.flatten_util import ravel_pytree

    flat, unravel = ravel_pytree(state)

    def field(z):
        return ravel_pytree(system.vector_field(t, unravel(z), u))[0]

    return field(flat), jax.jacfwd(field)(flat)


@SETTINGS
@given(st.sampled_from(["averaged-coulomb", "pwm-bristle", "averaged-bristle", "pwm-tank", "averaged-tank"]),
       pressures, positions, velocities, st.one_of(st.just(0.0), st.floats(-2.0, 2.0)), st.floats(0.0, 0.04),
       st.sampled_from([0.0, 1.0, 0.37]))
def test_other_systems_vector_field_and_jacobian_finite(variant, pressure, x, v, z, t, u):
    """The averaged valve (eq. 13), the bristle friction state and the constant-volume tank: finite at every state,
    friction states beyond ±1 (the solver may try them) and duty exactly 0 and 1 included."""
    system = _variant_system(variant)
    state = system.initial_state()
    pressure = presets.SUPPLY_PRESSURE if pressure == "supply" else pressure
    state = eqx.tree_at(lambda s: s.pressure, state, jnp.asarray(pressure))
    if hasattr(state, "position"):
        state = eqx.tree_at(lambda s: s.position, state, jnp.asarray(x))
        state = eqx.tree_at(lambda s: s.velocity, state, jnp.asarray(v))
    if getattr(state, "friction", None) is not None and jnp.ndim(state.friction) == 0:
        state = eqx.tree_at(lambda s: s.friction, state, jnp.asarray(z))
    f, jac = _generic_field_and_jacobian(system, jnp.asarray(t), state, jnp.asarray(u))
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(jac))
