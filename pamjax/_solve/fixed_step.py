"""Integrators for batched sweeps, on a flat state vector y' = f(t, y), with outputs observed (or reduced) on the fly.

diffrax's adaptive loop vmaps badly (a batched while loop steps every lane with one shared step sequence until the
slowest finishes). Two kinds of scheme instead:

Fixed steps, every lane of a `vmap` the same (one `lax.scan` over output times; the step chosen per workload from
the plant's stiffness in `pamjax._sweep.sweep`):

- `"rk4"`: classical Runge-Kutta, order 4, 4 evaluations per step. Explicit: stable for |λ h| ≲ 2.78 on the
  negative real axis, so the plant's stiffest eigenvalue bounds the step (paper 000's smooth friction sign:
  λ ≈ F_c / (w M) ≈ 1,700 /s → h ≤ 1.6 ms).
- `"ros2"`: the two-stage, L-stable Rosenbrock(-W) method ROS2 of Verwer et al. (SIAM J. Sci. Comput. 20, 1999,
  eq. 2.3 with γ = 1 + 1/√2): order 2 for any Jacobian approximation, one Jacobian (forward mode) and one small
  LU per step. Its step is bounded by accuracy only, not by the friction's stiffness.

Error control per lane (`_integrate_adaptive`: one while loop over the whole grid, each lane with its own step
and its own next output time, landing exactly on every output time):

- `"rodas5a"`: RODAS5 (order 5(4), L-stable; `pamjax._solve.rodas`) at rtol = atol = 1e-5: trajectory-accurate, and
  the stiff stick phases cost a handful of steps. Besides its embedded estimate, each step's midpoint defect is held
  within `RODAS5A_DEFECT_ALLOWANCE` (`rodas5_step_defect`): the embedded estimate passed steps through a velocity
  reversal 4,000x the tolerance off.
- `"ros2a"`: ROS2 with its embedded first-order solution at 1e-3: a quick steady-state map.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .rodas import rodas5_step_defect, small_inverse_lanes

SCHEMES = ("rk4", "ros2", "ros2a", "rodas5a")

# Tolerances on the scaled state (1e5 Pa, 1e-2 m, 1e-2 m/s), measured on the 1,024-duty x 5 s MAS-10 map (outputs
# every 0.1 s, 2-core CPU, 2026-11-22, benchmarks/sweep.py; errors against DOP853 at rtol 1e-12):
# "ros2a" at 1e-3: 0.6 Pa and 4 µm in 0.045-0.073 s (with coarser output grids tens of µm, tests/test_sweep.py):
# a quick map, not a reference. "rodas5a" at 1e-5: 3.3e-5 Pa and 2.2e-10 m in 0.044-0.048 s (2026-11-26, session
# 37; 4.8e-5 Pa and 3.5e-10 m in 0.05-0.08 s before its step-control changes), better than SciPy's
# LSODA at rtol 1e-8 (2.6e-4 Pa, 1.4e-9 m); 1e-4 gave 3.7e-4 Pa and 2.8e-9 m (just looser than SciPy), 1e-6 took
# ~15 % longer. With the defect check: 1.7e-5 Pa and 1.2e-10 m at the 8 duties, and at duties 0.46 and
# 0.98, which had accepted steps through a reversal (2.5e-4 Pa, 2.3e-9 m), 4.1e-5 Pa and 3.3e-10 m; 1.1-1.2x the
# CPU time (one more field evaluation a step, 5 % more iterations).
ROS2A_RTOL = 1e-3
ROS2A_ATOL = 1e-3
RODAS5A_RTOL = 1e-5
RODAS5A_ATOL = 1e-5
# The filtered midpoint defect of a "rodas5a" step (`rodas5_step_defect`), scaled as the error, may be this many
# times the tolerance: a check that the step's continuous solution solves the ODE, which the embedded estimate misses
# where a component turns stiff inside the step (a velocity reversal into the friction's band) and underrates at a
# smoothed kink (the muscle's 1 N slack: 3-80x). A cubic's defect is O(h⁴), no error estimate for a fifth-order
# step, hence the allowance. Measured (averaged MAS-10 under Sine(0.368, 0.265, 2.58 Hz), outputs every
# 12.5 ms): accurate steps' defects have median 0.09, 99th percentile 4, max 8; steps through a reversal 830-2,700
# (their true error 3,300-4,000x the tolerance, the embedded estimate 0.86-0.99); through the slack 0.5-45. Effect
# (400 sines, offset 0.3-0.7, amplitude 0.05-0.3, 0.5-3 Hz, 8 s; against simulate at rtol 1e-11): lanes > 1 µm off
# 22 -> 4, the worst 64.5 µm / 245 Pa -> 1.9 µm / 6.5 Pa (allowance 10: 10 lanes, 2.7 µm; 2: none, 0.87 µm); the
# 1,024-duty x 5 s map's slowest lane 126 -> 132 iterations (10: 128; 2: 139). Old code at rtol 1e-6 instead: 13
# lanes, 4.1 µm, 170 iterations.
RODAS5A_DEFECT_ALLOWANCE = 5.0
ADAPTIVE_MAX_STEPS_PER_INTERVAL = 20_000  # x output intervals: a lane that needs more is reported as failed

# RK4's stability interval on the negative real axis is (-2.785, 0); with a 10 % margin:
RK4_STABILITY_LIMIT = 2.5  # |λ h|
_ROS2_GAMMA = 1.0 + 1.0 / np.sqrt(2.0)  # Verwer et al. 1999, L-stable choice


def rk4_step(field, t, y, h):
    """One classical RK4 step of y' = field(t, y) from t to t + h."""
    k1 = field(t, y)
    k2 = field(t + 0.5 * h, y + 0.5 * h * k1)
    k3 = field(t + 0.5 * h, y + 0.5 * h * k2)
    k4 = field(t + h, y + h * k3)
    return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def ros2_step(field, t, y, h):
    """One ROS2 step (Verwer et al. 1999): W = I − γ h J,  W k1 = f(t, y),  W k2 = f(t + h, y + h k1) − 2 k1,
    y₊ = y + h (3 k1 + k2) / 2, with J = ∂f/∂y at (t, y) by forward mode (the time derivative is left out, which
    a W-method allows at order 2)."""
    return ros2_step_error(field, t, y, h)[0]  # the unused error estimate is dead code to XLA


def ros2_step_error(field, t, y, h):
    """`ros2_step` and its error estimate y₊ − (y + h k1) = h (k1 + k2) / 2 (the embedded linearly implicit Euler
    solution, order 1), as in Verwer et al. 1999."""
    f0, jac = jax.linearize(lambda z: field(t, z), y)
    n = y.shape[0]
    jacobian = jax.vmap(jac, out_axes=1)(jnp.eye(n, dtype=y.dtype))
    w_inverse = small_inverse_lanes(jnp.eye(n, dtype=y.dtype) - _ROS2_GAMMA * h * jacobian)  # one for both stages
    k1 = w_inverse @ f0
    k2 = w_inverse @ (field(t + h, y + h * k1) - 2.0 * k1)
    return y + h * (1.5 * k1 + 0.5 * k2), 0.5 * h * (k1 + k2)


def _ros2_step_estimates(field, t, y, h):
    """`ros2_step_error` in `_ADAPTIVE`'s form: (y₊, ((its estimate, allowance 1),))."""
    y1, error = ros2_step_error(field, t, y, h)
    return y1, ((error, 1.0),)


def rodas5_step_error(field, t, y, h):
    """One RODAS5 step (order 5, L-stable; `pamjax._solve.rodas`), its stages unrolled (the form that runs fastest
    over batched lanes), and its error estimates as (estimate, allowance) pairs, each held to rms(estimate / scale)
    <= allowance: the embedded estimate (order 4) at 1, and the filtered midpoint defect of the step's cubic
    Hermite (`rodas5_step_defect`) at `RODAS5A_DEFECT_ALLOWANCE`."""
    y1, error, defect = rodas5_step_defect(field, t, y, h, inverse=small_inverse_lanes)
    return y1, ((error, 1.0), (defect, RODAS5A_DEFECT_ALLOWANCE))


# Error-controlled schemes: (step with its error estimates, rtol, atol, order of the error estimate).
_ADAPTIVE = dict(
    ros2a=(_ros2_step_estimates, ROS2A_RTOL, ROS2A_ATOL, 2),
    rodas5a=(rodas5_step_error, RODAS5A_RTOL, RODAS5A_ATOL, 5),
)


_STEPS = dict(rk4=rk4_step, ros2=ros2_step)


def step_counts(grid, dt):
    """Steps per interval of the concrete time grid so that no step exceeds `dt`: (counts, step sizes)."""
    widths = np.diff(np.asarray(grid, dtype=float))
    counts = np.maximum(1, np.ceil(widths / dt * (1.0 - 1e-12))).astype(np.int64)
    return counts, widths / counts


def integrate(field, y0, grid, counts, steps, scheme, carry_init, update, jumps=None):
    """Integrate y' = field(t, y) over the concrete time `grid`, `counts[k]` steps of `steps[k]` in interval k.

    At every grid point (the first included) `update(carry, k, t, y)` folds the state into a running carry
    (observations, reductions); `carry_init` is its initial value. Returns `(carry, y_final, finite)`, `finite`
    False when the state became non-finite at any grid point. The whole loop is one `lax.scan` (vmap it over lanes).
    `jumps`: None, or the sorted times (a 1-D array, traced per lane) where the field jumps (a `Step` command), each
    then a step boundary (`_integrate_across_jumps`; the error-controlled schemes land on them): a step straddling a
    jump is not the scheme's order, and one ending on it read the command after it (the averaged MAS-10 under a
    Step was 0.8-2.2 kPa off a tight `simulate`). Without them the program is the one before.
    """
    grid = jnp.asarray(grid)
    if scheme in _ADAPTIVE:
        return _integrate_adaptive(field, y0, grid, steps, carry_init, update, scheme, jumps)
    if jumps is not None:
        return _integrate_across_jumps(field, y0, grid, counts, scheme, carry_init, update, jumps)
    step = _STEPS[scheme]
    uniform = bool(np.all(counts == counts[0]))

    def advance(y, t_start, h, n):
        if uniform:
            return jax.lax.fori_loop(0, int(counts[0]), lambda i, z: step(field, t_start + i * h, z, h), y)
        return jax.lax.fori_loop(0, n, lambda i, z: step(field, t_start + i * h, z, h), y)

    carry = update(carry_init, 0, grid[0], y0)
    finite = jnp.all(jnp.isfinite(y0))

    def body(state, xs):
        y, carry, finite = state
        k, t_start, t_end, h, n = xs
        y = advance(y, t_start, h, n)
        finite = finite & jnp.all(jnp.isfinite(y))
        carry = update(carry, k + 1, t_end, y)
        return (y, carry, finite), None

    xs = (jnp.arange(len(counts)), grid[:-1], grid[1:], jnp.asarray(steps), jnp.asarray(counts))
    (y, carry, finite), _ = jax.lax.scan(body, (y0, carry, finite), xs)
    return carry, y, finite


def _next_jump(jumps, t, before):
    """(the first of the sorted `jumps` after `t`, whether it lies before `before`)."""
    index = jnp.searchsorted(jumps, t, side="right")
    jump = jumps[jnp.minimum(index, jumps.shape[0] - 1)]
    return jump, (index < jumps.shape[0]) & (jump < before)


def _ending_at(field, start, end):
    """`field` read at times no later than just before `end` (a step from `start` to `end`): a step ending on a jump
    reads the command before it, as the adaptive solve's step ending there does (`Step` switches at t >= time). Clipped
    from above only: a Rosenbrock step's time derivative at its start stays that of the field."""
    last = jnp.nextafter(end, start)
    return lambda t, y: field(jnp.minimum(t, last), y)


def _integrate_across_jumps(field, y0, grid, counts, scheme, carry_init, update, jumps):
    """`integrate` of a fixed scheme with a step boundary at each lane's jump: each output interval [a, b] of n
    steps h takes n + 1 steps, split at the first jump inside it into ceil(x) steps up to the jump and n + 1 −
    ceil(x) after it (x = (jump − a) / h: ceil(x) + ceil(n − x) <= n + 1, so no step is longer than h), or n + 1
    equal steps where no jump lies inside; a second jump inside the same interval is stepped over. The extra step
    per interval is the cost (a `Step` sweep only: other signals compile the program without it)."""
    step = _STEPS[scheme]
    uniform = bool(np.all(counts == counts[0]))

    def advance(y, a, b, count):
        n = count.astype(a.dtype)
        jump, inside = _next_jump(jumps, a, b)
        split = jnp.where(inside, jump, b)
        first = jnp.where(inside, jnp.clip(jnp.ceil((jump - a) * n / (b - a)), 1.0, n), n + 1.0)
        h1, h2 = (split - a) / first, (b - split) / jnp.maximum(n + 1.0 - first, 1.0)

        def node(i):
            after = jnp.where(i >= n + 1.0, b, split + (i - first) * h2)
            return jnp.where(i < first, a + i * h1, jnp.where(i == first, split, after))

        def one(i, z):
            s0, s1 = node(i.astype(a.dtype)), node(i.astype(a.dtype) + 1.0)
            return step(_ending_at(field, s0, s1), s0, z, s1 - s0)

        return jax.lax.fori_loop(0, int(counts[0]) + 1 if uniform else count + 1, one, y)

    carry = update(carry_init, 0, grid[0], y0)
    finite = jnp.all(jnp.isfinite(y0))

    def body(state, xs):
        y, carry, finite = state
        k, a, b, n = xs
        y = advance(y, a, b, n)
        finite = finite & jnp.all(jnp.isfinite(y))
        return (y, update(carry, k + 1, b, y), finite), None

    xs = (jnp.arange(len(counts)), grid[:-1], grid[1:], jnp.asarray(counts))
    (y, carry, finite), _ = jax.lax.scan(body, (y0, carry, finite), xs)
    return carry, y, finite


def _integrate_adaptive(field, y0, grid, steps, carry_init, update, scheme, jumps=None):
    """`integrate` for the error-controlled schemes ("ros2a", "rodas5a"): one loop over the whole grid per lane, each
    lane with its own step size and its own next output time (steps are shortened to land on it, and a step
    shortened only for that does not shrink the next one). Under `vmap` the loop runs until the slowest lane ends,
    so the cost is the largest number of steps any lane needs, not a sum of per-interval maxima. With `jumps` the
    steps land on each jump too (not observed there), and each step reads the field before its end
    (`_ending_at`): a step landing on a jump at an output time read the command after it (815 Pa off on the MAS-10)."""
    step_error, rtol, atol, order = _ADAPTIVE[scheme]
    n_out = grid.shape[0]
    span = grid[-1] - grid[0]
    max_iterations = ADAPTIVE_MAX_STEPS_PER_INTERVAL * (n_out - 1)

    def cond(state):
        t, y, h, k, carry, it, rejected = state
        return (k < n_out) & (it < max_iterations) & (h > 1e-12 * span)

    def body(state):
        t, y, h, k, carry, it, rejected = state
        target = grid[jnp.minimum(k, n_out - 1)]
        if jumps is not None:  # the next jump before the next output time is the step's target
            jump, to_jump = _next_jump(jumps, t, target)
            target = jnp.where(to_jump, jump, target)
        # a step that would end within 1e-6 of its length short of the next output time ends on it: otherwise
        # t + h can round onto that time without landing, and the next step's length is 0 (a lane failed so)
        remaining = target - t
        land = h >= remaining * (1.0 - 1e-6)
        h_try = jnp.where(land, remaining, h)
        stepped = field if jumps is None else _ending_at(field, t, jnp.where(land, target, t + h_try))
        y_new, estimates = step_error(stepped, t, y, h_try)
        scale = atol + rtol * jnp.maximum(jnp.abs(y), jnp.abs(y_new))
        err = jnp.max(jnp.stack([jnp.sqrt(jnp.mean((e / scale) ** 2)) / allowed for e, allowed in estimates]))
        ok = (err <= 1.0) & jnp.all(jnp.isfinite(y_new))
        grow = 0.9 * jnp.maximum(err, 1e-10) ** (-1.0 / order)
        factor = jnp.where(jnp.isfinite(err), jnp.clip(grow, 0.2, 5.0), 0.2)
        # a rejected step shrinks the next by at least 2; the step after a rejection may not grow (Hairer & Wanner,
        # Solving ODEs II, IV.8): at a sharp transient (a lane's payload breaking away) an accepted short step
        # followed by a 5x longer one was rejected again, every other step (1,024-duty map: 136 -> 129 iterations)
        factor = jnp.where(ok, jnp.where(rejected, jnp.minimum(factor, 1.0), factor), jnp.minimum(factor, 0.5))
        landed = ok & land
        h_next = jnp.where(ok & (h_try < h), jnp.maximum(h, h_try * factor), h_try * factor)
        t = jnp.where(ok, jnp.where(landed, target, t + h_try), t)
        y = jnp.where(ok, y_new, y)
        if jumps is not None:
            landed = landed & ~to_jump  # an output time reached (not a jump before it)
        observed = update(carry, k, t, y)
        carry = jax.tree_util.tree_map(lambda new, old: jnp.where(landed, new, old), observed, carry)
        return t, y, h_next, k + landed.astype(k.dtype), carry, it + 1, ~ok

    carry = update(carry_init, 0, grid[0], y0)
    h0 = jnp.asarray(steps)[0]
    state = (grid[0], y0, h0, jnp.asarray(1), carry, jnp.asarray(0), jnp.asarray(False))
    _, y, _, k, carry, _, _ = jax.lax.while_loop(cond, body, state)
    return carry, y, (k == n_out) & jnp.all(jnp.isfinite(y))
