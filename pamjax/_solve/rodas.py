"""RODAS5: an L-stable, stiffly accurate Rosenbrock method of order 5(4): its step (`rodas5_step`), and as a diffrax
solver `Rodas5` (`pamjax/_solve/rodas_solver.py`, apart so that what steps without diffrax imports no diffrax).

Why pamjax needs it: the smooth Coulomb sign makes paper 000's plant stiff whenever the payload sticks
(λ ≈ F_c / (w M) ≈ 1,700 /s), and an explicit solver (Tsit5) then steps at its stability limit, not at the accuracy
asked for: half of the averaged-valve triangle run's 3,170 Tsit5 steps fall in the 4 s of stick. An L-stable method
takes steps bounded by accuracy alone. diffrax's implicit solvers (Kvaerno3/5) need Newton iterations that fail at
the stick-slip transitions (9,000-10,000 steps); a Rosenbrock method needs none: each step solves 8 linear systems
with one matrix, I/(hγ) - ∂f/∂y, built from one forward-mode Jacobian. Order 5 keeps the smooth phases as cheap as
Tsit5's (a fourth-order RODAS took twice Tsit5's steps there).

Scheme: G. Di Marzo, *RODAS5(4) - Méthodes de Rosenbrock d'ordre 5(4) adaptées aux problèmes
différentiels-algébriques*, Mémoire de diplôme, Université de Genève (1993), γ = 0.19, written in the
transformed variables of Hairer & Wanner (*Solving Ordinary Differential Equations II*, 2nd ed., Springer 1996,
Sec. IV.7). For y' = f(t, y), step h, J = ∂f/∂y(t0, y0), f_t = ∂f/∂t(t0, y0):

    (I/(hγ) - J) k_i = f(t0 + c_i h, y0 + Σ_j a_ij k_j) + Σ_j (C_ij / h) k_j + d_i h f_t,   i = 1..8,

the last three stages at t0 + h on y0 + Σ_j a_6j k_j + k_6 (+ k_7): y1 = y0 + Σ_j a_6j k_j + k_6 + k_7 + k_8, and
k_8 is the local error estimate (the difference to the embedded order-4 solution). Dense output: cubic Hermite
through y0, y1, f(t0, y0), f(t1, y1) (as the Rosenbrock solvers of later diffrax releases do).

The order and stability are checked numerically in tests/test_rodas.py (order 5 on a non-autonomous nonlinear
problem; a step 10⁵ times beyond the explicit stability limit stays accurate).

Works on any pytree state (ravelled to one vector per step); meant for small systems (the matrix is inverted
densely). Differentiable in forward and reverse mode (reverse mode differentiates through the Jacobian: second
derivatives of the vector field).
"""

import jax
import jax.numpy as jnp
import numpy as np

_GAMMA = 0.19
_STAGE_BOUND = 1e10  # a stage's state within 1e10 (|z0| + 1) of the step's start: see `rodas5_step`
_C = np.array([0.0, 0.38, 0.3878509998321533, 0.4839718937873840, 0.4570477008819580, 1.0, 1.0, 1.0])
_D = np.array([_GAMMA, -0.1823079225333714636, -0.319231832186874912, 0.3449828624725343, -0.377417564392089818,
               0.0, 0.0, 0.0])
_A = np.zeros((6, 5))  # a_ij for stages 2..6 (row i, stage i + 1); stages 7, 8 and y1 add k_6, k_7, k_8
_A[1, :1] = [2.0]
_A[2, :2] = [3.040894194418781, 1.041747909077569]
_A[3, :3] = [2.576417536461461, 1.622083060776640, -0.9089668560264532]
_A[4, :4] = [2.760842080225597, 1.446624659844071, -0.3036980084553738, 0.2877498600325443]
_A[5, :5] = [-14.09640773051259, 6.925207756232704, -41.47510893210728, 2.343771018586405, 24.13215229196062]
_CC = np.zeros((8, 7))  # C_ij (row i: stage i + 1)
_CC[1, :1] = [-10.31323885133993]
_CC[2, :2] = [-21.04823117650003, -7.234992135176716]
_CC[3, :3] = [32.22751541853323, -4.943732386540191, 19.44922031041879]
_CC[4, :4] = [-20.69865579590063, -8.816374604402768, 1.260436877740897, -0.7495647613787146]
_CC[5, :5] = [-46.22004352711257, -17.49534862857472, -289.6389582892057, 93.60855400400906, 318.3822534212147]
_CC[6, :6] = [34.20013733472935, -14.15535402717690, 57.82335640988400, 25.83362985412365, 1.408950972071624,
              -6.551835421242162]
_CC[7, :7] = [42.57076742291101, -13.80770672017997, 93.98938432427124, 18.77919633714503, -31.58359187223370,
              -6.685968952921985, -5.810979938412932]


# The tableau as square (8, 8) stage tables for the stage loop: row i gives stage i's argument (A) and right-hand
# side (C / h) from the earlier stages; stage 7 (the embedded solution) and 8 (y1) add k_6 and k_7 with weight 1.
_A_STAGE = np.zeros((8, 8))
_A_STAGE[1:6, :5] = _A[1:6, :5]
_A_STAGE[6, :5], _A_STAGE[6, 5] = _A[5, :5], 1.0
_A_STAGE[7, :5], _A_STAGE[7, 5], _A_STAGE[7, 6] = _A[5, :5], 1.0, 1.0
_CC_STAGE = np.zeros((8, 8))
_CC_STAGE[:, :7] = _CC


def small_inverse(a):
    """Inverse of a small dense matrix by Gauss-Jordan elimination with partial pivoting, unrolled over its size.

    For the handful of states pamjax integrates this fuses into a few kernels, where LAPACK's LU costs a library
    call per factorisation and two per solve (a third of a step's time at n = 3). Rows are swapped by a gather
    (fastest for one solve); `small_inverse_lanes` is the variant for `vmap`.
    """
    n = a.shape[0]
    if n > 8:
        return jnp.linalg.inv(a)
    aug = jnp.concatenate([a, jnp.eye(n, dtype=a.dtype)], axis=1)
    rows = jnp.arange(n)
    for k in range(n):
        pivot = k + jnp.argmax(jnp.abs(aug[k:, k]))
        aug = aug[jnp.where(rows == k, pivot, jnp.where(rows == pivot, k, rows))]
        aug = aug.at[k].divide(aug[k, k])
        factors = jnp.where(rows == k, 0.0, aug[:, k])
        aug = aug - factors[:, None] * aug[k][None, :]
    return aug[:, n:]


def small_inverse_lanes(a):
    """`small_inverse` with rows swapped by `jnp.where`: under `vmap` (sweeps) plain elementwise arithmetic across
    lanes, where the gather of `small_inverse` batches poorly (1,024-lane sweep: 15 % faster)."""
    n = a.shape[0]
    if n > 8:
        return jnp.linalg.inv(a)
    eye = jnp.eye(n, dtype=a.dtype)
    rows = [jnp.concatenate([a[i], eye[i]]) for i in range(n)]
    for k in range(n):
        for i in range(k + 1, n):  # partial pivoting: the largest |a[i, k]|, i >= k, to row k
            swap = jnp.abs(rows[i][k]) > jnp.abs(rows[k][k])
            rows[k], rows[i] = jnp.where(swap, rows[i], rows[k]), jnp.where(swap, rows[k], rows[i])
        rows[k] = rows[k] / rows[k][k]
        for i in range(n):
            if i != k:
                rows[i] = rows[i] - rows[i][k] * rows[k]
    return jnp.stack(rows)[:, n:]


def _jacobian(f, t0, z0):
    """f(t0, z0), ∂f/∂t and ∂f/∂z at (t0, z0), in one forward-mode pass over w = (t, z)."""

    def f_tz(w):
        out = f(w[0], w[1:])
        return out, out

    jac, f0 = jax.jacfwd(f_tz, has_aux=True)(jnp.concatenate([jnp.asarray(t0, z0.dtype)[None], z0]))
    return f0, jac[:, 0], jac[:, 1:]


def _jacobian_columns(f, t0, z0):
    """`_jacobian` as the time direction on its own (a forward-mode derivative with a constant unit tangent, which XLA
    leaves out for a field that does not depend on t; a batched tangent over (t, z) hid that from it) and the
    state's directions as one batched tangent (`jax.jacfwd`: the field's value computed once for the three, where one
    `jax.jvp` per direction let XLA fuse a copy of the whole field into each direction's kernel). A 1,024-lane
    RODAS5 step: 0.300 -> 0.268 ms (docs/performance.md)."""
    n, dtype = z0.shape[0], z0.dtype
    t0 = jnp.asarray(t0, dtype)
    f0, f_t = jax.jvp(f, (t0, z0), (jnp.ones((), dtype), jnp.zeros(n, dtype)))
    return f0, f_t, jax.jacfwd(lambda z: f(t0, z))(z0)


def rodas5_step(f, t0, z0, h, inverse=small_inverse):
    """One RODAS5 step of z' = f(t, z) (flat vector) from t0 to t0 + h: (z1, local error estimate, f(t0, z0)).
    `inverse`: the small-matrix inverse. Its seven later stages are one loop over the tableau, so the vector field
    is traced and compiled once for them: for single trajectories (`Rodas5`, diffrax), whose compilation is what a
    user waits for. Batched lanes (`sweep`) use `rodas5_step_unrolled` (same step, faster there).

    Each later stage's state is clipped to within `_STAGE_BOUND` (|z0| + 1) of z0, componentwise: far beyond any
    step the error control accepts (whose stages move by a fraction of the state), it keeps a wild trial step finite.
    A trial step far too long (after a command jump, the step size carried over from before it: 0.30 s where 0.4 ms
    is accepted) drove its stages from 1e6 to 1e220, then inf and NaN; the step is rejected, but reverse mode
    multiplies its zero cotangent by those values, and 0 × inf is NaN: `jax.grad` through the whole solve was NaN."""
    f0, f_t, jac_z = _jacobian(f, t0, z0)
    w_inverse = inverse(jnp.eye(z0.shape[0], dtype=z0.dtype) / (h * _GAMMA) - jac_z)

    # Stages 2-8 as a loop over the tableau (the field traced once for all seven, not seven times): stage i's
    # argument is z0 + Σ_j A_ij k_j at t0 + c_i h, and k_i = W⁻¹ (f(·) + Σ_j (C_ij / h) k_j + d_i h f_t).
    n = z0.shape[0]
    k0 = w_inverse @ (f0 + (_D[0] * h) * f_t)
    ks = jnp.zeros((8, n), z0.dtype).at[0].set(k0)

    bound = _STAGE_BOUND * (jnp.abs(z0) + 1.0)

    def stage(i, ks):
        z = jnp.clip(z0 + jnp.asarray(_A_STAGE, z0.dtype)[i] @ ks, z0 - bound, z0 + bound)
        rhs = f(t0 + jnp.asarray(_C, z0.dtype)[i] * h, z) + (jnp.asarray(_CC_STAGE, z0.dtype)[i] / h) @ ks
        rhs = rhs + (jnp.asarray(_D, z0.dtype)[i] * h) * f_t
        return ks.at[i].set(w_inverse @ rhs)

    ks = jax.lax.fori_loop(1, 8, stage, ks)
    z = z0 + jnp.asarray(_A_STAGE, z0.dtype)[7] @ ks  # the embedded order-4 solution, the last stage's argument
    return z + ks[7], ks[7], f0


def rodas5_step_unrolled(f, t0, z0, h, inverse=small_inverse_lanes):
    """`rodas5_step` with its eight stages unrolled (the tableau's numbers folded in, zero terms left out, 1/h
    computed once): the form for batched lanes (`vmap`, `sweep`'s "rodas5a"), where each stage's field evaluation
    fuses with its arithmetic into one vectorised kernel over the lanes. The stage loop of `rodas5_step` keeps the
    eight stages' values in one (8, n) buffer indexed by the loop counter, which under `vmap` XLA runs as separate
    kernels per stage (dynamic slices, small batched products, a copy of the buffer): a 1,024-lane sweep took
    1.6x as long (docs/performance.md). Costs the field traced seven more times (compilation: the 1,024-lane
    sweep's first call ~1 s longer)."""
    z1, error, f0, _, _ = _unrolled_stages(f, t0, z0, h, inverse)
    return z1, error, f0


def rodas5_step_defect(f, t0, z0, h, inverse=small_inverse_lanes):
    """`rodas5_step_unrolled` with a second error estimate: (z1, local error estimate, filtered defect).

    The defect is the residual of the step's continuous solution at its midpoint tₘ = t0 + h/2, d = u'(tₘ) −
    f(tₘ, u(tₘ)), u the cubic Hermite through (z0, f(t0, z0)) and (z1, f(t0 + h, ẑ1)) (ẑ1 the embedded solution,
    whose field value the last stage computes: one more field evaluation per step, at tₘ). It enters the local error
    as e' = J e + d does: the estimate is h (I − hγJ)⁻¹ d = W⁻¹ d / γ with the step's own W⁻¹, so a component stiff
    over the step (a sticking payload, λ ≈ 1,700 /s) weighs d / |λ|, not h d (as RADAU5 filters its estimate,
    Hairer & Wanner II, IV.8; unfiltered, the creeping payload's cubic midpoint held the MAS-10 map's steps back:
    its slowest lane 143 iterations against 128 at the same allowance, 126 without the check).
    Residual control is what SciML's OrdinaryDiffEq.jl (issue #2054) proposes for stiffly accurate Rosenbrock
    methods, whose embedded estimate cannot see it.

    Why RODAS5 needs it: its embedded estimate k₈ comes from the last of three stages, all at t0 + h. A component
    that turns stiff inside the step (the payload through the friction's 1 mm/s band at a velocity reversal,
    ~1,700 /s, where the Jacobian at the sliding start has none of it) is pulled by those stages onto the same
    wrong quasi-steady value, so they agree and k₈ is small: on the averaged MAS-10 under a sine, a 12.5 ms step
    with k₈ at 0.86 of the tolerance was 4,000x it off (the lane 64.5 µm off a tight `simulate`, status 0). The
    Hermite's midpoint falls between the wrong end and the right start, where the field is far from u'."""
    z1, error, f0, f_end, w_inverse = _unrolled_stages(f, t0, z0, h, inverse)
    u = 0.5 * (z0 + z1) + (0.125 * h) * (f0 - f_end)
    du = (1.5 / h) * (z1 - z0) - 0.25 * (f0 + f_end)
    return z1, error, w_inverse @ (du - f(t0 + 0.5 * h, u)) / _GAMMA


def _unrolled_stages(f, t0, z0, h, inverse):
    """The unrolled step: (z1, error estimate k₈, f(t0, z0), f(t0 + h, ẑ1) (ẑ1 = z1 − k₈), W⁻¹)."""
    f0, f_t, jac_z = _jacobian_columns(f, t0, z0)
    inv_h = 1.0 / h
    w_inverse = inverse(jnp.eye(z0.shape[0], dtype=z0.dtype) * (inv_h / _GAMMA) - jac_z)

    def stage(value, i, ks):  # k_i = W⁻¹ (value + Σ_j (C_ij / h) k_j + d_i h f_t)
        rhs = value + sum((_CC[i, j] * inv_h) * ks[j] for j in range(i))
        if _D[i] != 0.0:
            rhs = rhs + (_D[i] * h) * f_t
        return w_inverse @ rhs

    ks = [stage(f0, 0, [])]
    for i in range(1, 6):
        ks.append(stage(f(t0 + _C[i] * h, z0 + sum(_A[i, j] * ks[j] for j in range(i))), i, ks))
    z = z0 + sum(_A[5, j] * ks[j] for j in range(5)) + ks[5]
    ks.append(stage(f(t0 + h, z), 6, ks))
    z = z + ks[6]  # the embedded order-4 solution
    f_end = f(t0 + h, z)
    ks.append(stage(f_end, 7, ks))
    return z + ks[7], ks[7], f0, f_end, w_inverse
