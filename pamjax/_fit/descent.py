"""The descent of pamjax's Levenberg-Marquardt (`pamjax._fit.solver`): the damped Gauss-Newton step with Moré's
scaling through an SVD of the scaled Jacobian and Transtrum & Sethna's geodesic acceleration (2012), and the helpers
that let one code run on the host (NumPy values: `pamjax.fit`) or traced (JAX arrays: `optimistix.least_squares`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._core.custom_types import ArrayLike

GEODESIC_ALPHA = 0.75  # acceleration trusted while 2‖a‖/‖v‖ ≤ α (Transtrum & Sethna 2012: α = 0.75)


def on_host(x):
    """Whether `x` (a pytree) holds host values (NumPy), not JAX arrays or tracers."""
    return not any(isinstance(leaf, jax.Array) for leaf in jax.tree_util.tree_leaves(x))


def array_module(host):
    return np if host else jnp


def flatten(out, host):
    if host:
        return np.asarray(out, dtype=float).ravel()
    return jnp.concatenate([jnp.ravel(x) for x in jax.tree_util.tree_leaves(out)])


# --- the descent: Moré-scaled damped Gauss-Newton with geodesic acceleration ---------------------------------------
# The states hold NumPy values where the solver runs from the host (`pamjax.fit`), JAX arrays where it is traced.
class Factors(eqx.Module):
    """The descent's state: Moré's scaling D (`scale`), the SVD J D⁻¹ = U S Vᵀ (`u`, `s`, `vt`) and c = Uᵀ r."""

    scale: ArrayLike
    u: ArrayLike
    s: ArrayLike
    vt: ArrayLike
    c: ArrayLike


class ScaledDampedDescent(optx.AbstractDescent):
    """The Levenberg-Marquardt step with Moré's scaling, through an SVD of the scaled Jacobian, and the geodesic
    acceleration's correction (`accelerate`). As an optimistix descent (`query`, `step`) it takes λ = 1/step_size,
    as `optimistix.DampedNewtonDescent` does; y is a 1-D array."""

    def init(self, y, f_info_struct):
        n = int(np.prod(jnp.shape(y)))
        m = sum(int(np.prod(x.shape)) for x in jax.tree_util.tree_leaves(f_info_struct.residual))
        k = min(m, n)
        return Factors(jnp.zeros(n), jnp.zeros((m, k)), jnp.zeros(k), jnp.zeros((k, n)), jnp.zeros(k))

    def query(self, y, f_info, state):
        residual = flatten(f_info.residual, False)
        return self.factor(residual, f_info.jac.as_matrix().reshape(residual.size, -1), state.scale)

    def step(self, step_size, state):
        velocity, *_ = self.damped(1.0 / step_size, state)
        return velocity, optx.RESULTS.successful

    @staticmethod
    def factor(residual, jacobian, scale):
        """The factors at a new point: D ← max(D, ‖Jᵢ‖) (1 for a column that has never moved the residuals)."""
        xp = array_module(on_host(jacobian))
        scale = xp.maximum(scale, xp.linalg.norm(jacobian, axis=0))
        scale = xp.where(scale > 0, scale, 1.0)
        u, s, vt = xp.linalg.svd(jacobian / scale, full_matrices=False)
        return Factors(scale, u, s, vt, u.T @ residual)

    @staticmethod
    def damped(damping, f):
        """(velocity, scaled coefficients, filter factors, predicted decrease, scaled size, potential) of the step
        with damping λ. `predicted` is the decrease the local linear model promises for the velocity (the yardstick
        of the acceptance ratio and the convergence tests: the acceleration's own can be negative on a curved
        valley); `potential` ½‖c‖² what an undamped Gauss-Newton step could still gain (~0 at a minimum)."""
        xp = array_module(on_host(f.s))
        filt = f.s / (f.s * f.s + damping)
        coef = -filt * f.c
        velocity = (f.vt.T @ coef) / f.scale
        fitted = f.c + f.s * coef
        predicted = 0.5 * (f.c @ f.c - fitted @ fitted)
        return velocity, coef, filt, predicted, xp.linalg.norm(coef), 0.5 * (f.c @ f.c)

    @staticmethod
    def accelerate(coef, filt, rvv, f):
        """(v + a/2, trusted): the step with the geodesic acceleration a = −(damped solve of r_vv), and whether
        2‖a‖ ≤ α‖v‖ (scaled)."""
        xp = array_module(on_host(f.s))
        acc = -filt * (f.u.T @ rvv)
        trusted = 2.0 * xp.linalg.norm(acc) <= GEODESIC_ALPHA * xp.linalg.norm(coef)
        return (f.vt.T @ (coef + 0.5 * acc)) / f.scale, trusted
