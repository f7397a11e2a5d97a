"""Seeded NaN/inf search over the vector field, its Jacobian, trajectories, a loss and its gradient.

`run(n_points, seed)` returns a dict of counts; used by `test_nan_safety.py` (CI size) and
`benchmarks/reliability.py` (10,000 inputs).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax
from pamjax import presets
from pamjax._simulate import solve
from pamjax._system import MuscleState, TankState


def _random_states(rng, n):
    """Muscle states inside and far outside the physical range, with exact special values mixed in."""
    p = rng.choice([-1e5, 0.0, 1.0, 101325.0, 6.5e5, 2e6], size=n) * rng.choice([1.0, 0.0], size=n, p=[0.5, 0.5])
    p = np.where(rng.random(n) < 0.5, rng.uniform(-2e5, 2e6, n), p)
    p = np.where(rng.random(n) < 0.1, 101325.0, p)  # equal to exhaust pressure exactly
    p = np.where(rng.random(n) < 0.1, 6.5e5, p)  # equal to supply pressure exactly
    x = np.where(rng.random(n) < 0.2, 0.0, rng.uniform(-0.2, 0.3, n))
    v = np.where(rng.random(n) < 0.3, 0.0, rng.normal(0, 0.5, n))
    u = np.where(rng.random(n) < 0.2, rng.choice([0.0, 1.0], n), rng.uniform(0, 1, n))
    t = rng.uniform(0, 1, n)
    return p, x, v, u, t


def vector_field_counts(n, seed=0):
    """Non-finite entries in the vector field and its state Jacobian for n random inputs per system variant."""
    rng = np.random.default_rng(seed)
    bad = 0
    total = 0
    variants = [presets.mas10_system(v) for v in ("pwm", "averaged")] + [presets.mas10_system("pwm", "bristle")]
    for system in variants:
        p, x, v, u, t = (jnp.asarray(a) for a in _random_states(rng, n))
        friction = None if system.friction.initial_state() is None else jnp.asarray(rng.normal(0, 1e-4, n))

        def field(p, x, v, z, u, t, system=system):
            state = MuscleState(p, x, v, z)
            out = system.vector_field(t, state, u)
            jac = jax.jacfwd(lambda s: system.vector_field(t, s, u))(state)
            return out, jac

        axes = (0, 0, 0, None if friction is None else 0, 0, 0)
        out, jac = jax.jit(jax.vmap(field, in_axes=axes))(p, x, v, friction, u, t)
        leaves = jax.tree_util.tree_leaves((out, jac))
        bad += sum(int(np.sum(~np.isfinite(np.asarray(leaf)))) for leaf in leaves)
        total += n
    tank = presets.mas10_tank_system("pwm")
    p, _, _, u, t = (jnp.asarray(a) for a in _random_states(rng, n))

    def tank_field(p, u, t):
        out = tank.vector_field(t, TankState(p), u)
        jac = jax.jacfwd(lambda q: tank.vector_field(t, TankState(q), u).pressure)(p)
        return out.pressure, jac

    leaves = jax.jit(jax.vmap(tank_field))(p, u, t)
    bad += sum(int(np.sum(~np.isfinite(np.asarray(leaf)))) for leaf in leaves)
    total += n
    return dict(inputs=total, nonfinite=bad)


def trajectory_counts(n, seed=0):
    """Non-finite values in short trajectories, a loss and its gradient over n random duties/initial states."""
    rng = np.random.default_rng(seed)
    system = presets.mas10_system("pwm")
    ts = jnp.linspace(0.0, 0.1, 6)
    u = jnp.asarray(np.where(rng.random(n) < 0.3, rng.choice([0.0, 1.0], n), rng.uniform(0, 1, n)))
    p0 = jnp.asarray(rng.choice([101325.0, 6.5e5, 3e5], n))
    v0 = jnp.asarray(np.where(rng.random(n) < 0.5, 0.0, rng.normal(0, 0.05, n)))

    def loss(system, u, p0, v0):
        y0 = system.initial_state(pressure=p0, velocity=v0)
        traj = solve(system, pamjax.Constant(u), ts, y0, 0.0, rtol=1e-6, atol=1e-6, max_steps=4096)  # 5 periods
        return jnp.mean(traj.position**2) + jnp.mean((traj.pressure / 1e5) ** 2), traj

    def one(u, p0, v0):
        (value, traj), grad = eqx.filter_value_and_grad(loss, has_aux=True)(system, u, p0, v0)
        return value, traj.position, traj.pressure, grad

    value, pos, pres, grad = eqx.filter_jit(jax.vmap(one))(u, p0, v0)
    leaves = [value, pos, pres] + jax.tree_util.tree_leaves(eqx.filter(grad, eqx.is_inexact_array))
    bad = sum(int(np.sum(~np.isfinite(np.asarray(leaf)))) for leaf in leaves)
    return dict(inputs=n, nonfinite=bad)
