"""Fixed-grid RK4 integration with events located inside the step: the solver of hybrid systems.

The grid is given as intervals [left_i, right_i] (the PWM-synchronous grid of `pamjax._solve.synchronous` for a
switching valve, a uniform grid otherwise), each with the valve opening held over it (or None). Each interval is one
classical RK4 step. A hybrid system (`system.hybrid`, e.g. a muscle with `KarnoppFriction`) also gives an event function
g that stays ≥ 0 while its current mode holds; when g < 0 at the end of a step, the crossing τ is located on the
step's cubic Hermite interpolant (bisection; its derivatives are the implicit function theorem's,
dτ/dθ = −g_θ/g_τ, to every order: a custom JVP, `_locate`), the state at τ is passed through
`system.event_update` (the new mode), and the rest of the interval is integrated from τ in the new mode. Up to
`MAX_EVENTS` events per interval are resolved (the grid's steps are ~1 ms; a stick-slip plant switches at most once
or twice in one).

Between events the vector field is smooth (a mode holds the friction's sign fixed), so every segment is integrated
at RK4's full order, and the trajectory is a continuous, piecewise-smooth function of every parameter: fits get
the exact gradients of the sharp model, where a smooth sign would bias them and make the plant stiff.

Outputs at requested times are the cubic Hermite interpolants of the segment that contains them (end slopes from
the vector field), O(h⁴) like the steps.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

MAX_EVENTS = 2  # events resolved per interval; further ones in the same interval are counted as missed
# The classical RK4 tableau, with a fifth row: the step's end (the b weights), where the end slope is evaluated.
# (NumPy: importing pamjax creates no JAX array, docs/performance.md.)
_RK4_A = np.array([[0, 0, 0, 0, 0], [0.5, 0, 0, 0, 0], [0, 0.5, 0, 0, 0], [0, 0, 1, 0, 0],
                   [1 / 6, 1 / 3, 1 / 3, 1 / 6, 0]], dtype=float)
_RK4_C = np.array([0.0, 0.5, 0.5, 1.0, 1.0])
_RK4_AUX = np.array([0, 1, 1, 2, 2])  # which of the interval's (start, middle, end) aux values
_BISECTIONS = 40  # halvings of the step: the crossing within 2^-41 of it (2.5 ms: 1e-15 s, float64's step in t ~ 8 s)


def _hermite(s, h, za, zb, fa, fb):
    """Cubic Hermite interpolant at s ∈ [0, 1] of a step of length h from (za, fa) to (zb, fb), in Horner form:
    za + s (h fa + s (3d − h(2fa + fb) + s (h(fa + fb) − 2d))), d = zb − za: the same polynomial as the basis-function
    form h00 za + h10 h fa + h01 zb + h11 h fb in two thirds of its operations, each of which a forward-mode Jacobian
    repeats per parameter. Exactly za at s = 0; zb at s = 1 up to rounding."""
    d, ha, hb = zb - za, h * fa, h * fb
    return za + s * (ha + s * ((3 * d - 2 * ha - hb) + s * (ha + hb - 2 * d)))


def _rk4(field, system, ta, tb, z, a):
    """Classical RK4 from ta to tb, and the slopes at both ends (for the Hermite dense output). The five field
    evaluations (four stages and the end slope) run as one loop over a Butcher tableau, so the compiled program
    holds the vector field once, not five times (a forward-mode Jacobian multiplies whatever is there)."""
    h = tb - ta
    tableau, nodes, which = jnp.asarray(_RK4_A), jnp.asarray(_RK4_C), jnp.asarray(_RK4_AUX)

    def stage(i, slopes):
        zi = z + h * (tableau[i] @ slopes)
        return slopes.at[i].set(field(system, ta + nodes[i] * h, zi, a[which[i]]))

    slopes = jax.lax.fori_loop(0, 5, stage, jnp.zeros((5,) + z.shape, dtype=z.dtype))
    zb = z + h * (tableau[4] @ slopes)
    return zb, slopes[0], slopes[4]

def _locate(event, system, seg):
    """Time and state of the first crossing g = 0 in a step whose end has g < 0.

    The crossing s* ∈ [0, 1] (of the step) is found by bisection on the step's Hermite interpolant
    (`_BISECTIONS`); its derivatives are those of the implicit function g(s*, θ) = 0, to every order: a
    custom JVP gives ds*/dθ = −g_θ/g_s at s*, and differentiating that rule again (s* inside it is this function,
    whose rule applies again) gives the second derivatives a design's gradient of a Jacobian needs (a Newton step
    from a gradient-stopped root carries the first derivatives only: its mixed second derivatives had the wrong sign
    on a payload landing on and lifting off its stop, tests/test_grid.py). A first-order Jacobian (a fit's) traces
    the rule once: g's tangent and its slope in s. No Newton step polishes the root: the rule gives the
    derivatives, and a polishing step in the primal added a second evaluation of g and g_s to every program (the
    fit's Jacobian 7 % larger: docs/performance.md). 40 halvings place the root within 2^-41 of the step, below
    float64's resolution of the time itself (more would cost every lane of a sweep, where `cond` runs both branches)."""
    ta, tb, za, zb, fa, fb = seg
    args = (system, ta, tb - ta, za, zb, fa, fb)

    def g_of(s, a):
        sys_, ta_, h_, za_, zb_, fa_, fb_ = a
        return event(sys_, ta_ + s * h_, _hermite(s, h_, za_, zb_, fa_, fb_))

    # what `event` closes over (arrays of the enclosing trace) as explicit, differentiable inputs: a custom JVP may
    # not close over a tracer
    g_closed, consts = jax.closure_convert(g_of, jnp.zeros(()), args)

    def g(s, a):
        return g_closed(s, a[0], *a[1])

    @jax.custom_jvp
    def crossing(a):
        def bisect(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            below = g(mid, a) < 0
            return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

        lo, hi = jax.lax.fori_loop(0, _BISECTIONS, bisect, (jnp.zeros(()), jnp.ones(())))
        return jnp.where(lo > 0, 0.5 * (lo + hi), 0.0)  # lo = 0: g < 0 from the start (the step's start, fixed)

    @crossing.defjvp
    def _crossing_jvp(primals, tangents):
        (a,), (da,) = primals, tangents
        s = crossing(a)
        slope = jax.jvp(lambda q: g(q, a), (s,), (jnp.ones_like(s),))[1]  # g_s at the root
        g_dot = jax.jvp(lambda b: g(s, b), (a,), (da,))[1]
        ok = (jnp.abs(slope) > 0) & (s > 0)  # a crossing at the step's start moves with the start only
        return s, jnp.where(ok, -g_dot / jnp.where(ok, slope, 1.0), 0.0)

    s = crossing((args, tuple(consts)))
    return ta + s * (tb - ta), _hermite(s, tb - ta, za, zb, fa, fb)


def integrate(systems, field, event, update, z0s, left, right, aux, member, offsets, ts):
    """Integrate one or several runs over their concatenated intervals; returns `(z_at_ts, num_steps, num_events,
    missed, finite)`.

    - `systems`: the runs' systems stacked along a leading axis (one per run; `eqx` modules of one structure);
      `z0s`: (runs, n) flat scaled initial states; `member`: (intervals,) the run of each interval. A run's first
      interval starts from its initial state; runs follow each other in time (the caller shifts their clocks so
      that the intervals and `ts` increase through all runs).
    - `field(system, t, z, aux_j)` → dz/dt (flat scaled) with `aux_j` the interval's aux at RK4 stage time j ∈ {0:
      start, 1: middle, 2: end} (the held valve opening, or the command at that time); `event(system, t, z)` → g
      (None for systems without modes); `update(system, t, z)` → z after an event.
    - `left`, `right`: (intervals,) interval ends (a zero-length interval is one RK4 step of length 0, which carries
      the derivative in its length); `aux`: (intervals, 3).
    - `offsets`: (runs,) the shift [s] of each run's clock; `field`, `event` and `update` see the run's own time.
    - `ts`: output times (shifted like the intervals); a time at or before its run's start takes its initial state
      (the caller's job, as it knows the runs' starts).
    """
    hybrid = event is not None
    arrays, static = eqx.partition(systems, eqx.is_array)

    def system_of(m):
        return eqx.combine(jax.tree_util.tree_map(lambda a: a[m], arrays), static)

    if hybrid:  # a start state outside its mode (e.g. stuck under a net force beyond F_c) switches at once

        def switched(run_arrays, z):  # one run's; mapped over the runs (one trace, not one per run)
            sys_k = eqx.combine(run_arrays, static)
            return jnp.where(event(sys_k, 0.0, z) < 0, update(sys_k, 0.0, z), z)

        z0s = jax.vmap(switched)(arrays, z0s)
    first = jnp.concatenate([jnp.ones((1,), bool), member[1:] != member[:-1]])

    def interval(carry, xs):
        z, n_events, n_missed = carry
        ta, tb, a, m, is_first = xs
        z = jnp.where(is_first, z0s[m], z)
        system = system_of(m)
        off = offsets[m]

        def rk4_(ta, tb, z):  # steps in the run's own clock, stored in the shifted one
            zb, fa, fb = _rk4(field, system, ta - off, tb - off, z, a)
            return zb, fa, fb

        if not hybrid:
            zb, fa, fb = rk4_(ta, tb, z)
            return (zb, n_events, n_missed), (ta[None], (tb - ta)[None], z[None], zb[None], fa[None], fb[None])

        # Up to MAX_EVENTS + 1 segments, each integrated from its start to tb in its mode and cut at an event; one
        # loop body (one RK4, one event location) whatever MAX_EVENTS, so the compiled program stays small.
        slots = MAX_EVENTS + 1
        # `+ 0 * z[0]` gives every carry a derivative from the start (event times and states carry one after an
        # event), so JAX's forward-mode and batching rules trace the loop once instead of twice (compile time).
        dep = 0.0 * z[0]
        blank = jnp.zeros((slots,) + z.shape) + dep
        init = (ta + dep, z, jnp.full((slots,), tb) + dep, jnp.zeros((slots,)) + dep, blank, blank, blank, blank,
                n_events, n_missed)

        def segment(j, c):
            def work(c):
                seg_start, z_s, starts, lengths, za, zb_, fa_, fb_, n_ev, n_miss = c
                zb, fa, fb = rk4_(seg_start, tb, z_s)
                crossed = event(system, tb - off, zb) < 0
                resolve = crossed & (j < MAX_EVENTS)

                def split(_):
                    tau, z_tau = _locate(event, system, (seg_start - off, tb - off, z_s, zb, fa, fb))
                    return tau + off, update(system, tau, z_tau)

                end, z_next = jax.lax.cond(resolve, split, lambda _: (tb, zb), None)
                return (end, z_next, starts.at[j].set(seg_start), lengths.at[j].set(tb - seg_start),
                        za.at[j].set(z_s), zb_.at[j].set(zb), fa_.at[j].set(fa), fb_.at[j].set(fb),
                        n_ev + resolve, n_miss + (crossed & ~resolve))

            # The first segment is stepped even at zero length (an edge on a uniform node): its RK4 step of length 0
            # leaves the state and carries its derivative in that length (the field times it), which a skip lost.
            return jax.lax.cond((c[0] < tb) | (j == 0), work, lambda c: c, c)

        _, z_end, starts, lengths, za, zb, fa, fb, n_events, n_missed = jax.lax.fori_loop(0, slots, segment, init)
        # Unused slots: empty segments at tb holding the end state.
        unused = (lengths == 0)[:, None]
        za = jnp.where(unused, z_end[None], za)
        zb = jnp.where(unused, z_end[None], zb)
        return (z_end, n_events, n_missed), (starts, lengths, za, zb, fa, fb)

    zero = jnp.zeros((), dtype=jnp.int32)
    (z_end, n_events, n_missed), segs = jax.lax.scan(interval, (z0s[0], zero, zero), (left, right, aux, member, first))
    # Flatten the (intervals, slots) segments in time order; a segment holds from its start to the next one's.
    starts, lengths, za, zb, fa, fb = (x.reshape((-1,) + x.shape[2:]) for x in segs)
    index = jnp.clip(jnp.searchsorted(starts, ts, side="left") - 1, 0, starts.shape[0] - 1)  # see `output_segment`
    h = lengths[index]
    # s in [0, 1] by construction (no clip: its derivative is halved where s sits on a bound)
    s = jnp.where(h > 0, (ts - starts[index]) / jnp.where(h > 0, h, 1.0), 0.0)[:, None]
    z_out = _hermite(s, h[:, None], za[index], zb[index], fa[index], fb[index])
    num_steps = jnp.sum(right > left)
    finite = jnp.all(jnp.isfinite(z_end))
    return z_out, num_steps, n_events, n_missed, finite


# `output_segment`: `integrate` reads each output time t on the segment that starts BEFORE t (a t at a segment's end
# reads it at s = 1). A PWM grid of more periods than cover the outputs ends in zero-length segments at the last time
# t1, their nodes clipped to it (a node on t1 gets half its derivative from the clip); read there (side="right",
# s = 0), d(output)/d(pwm_frequency) was 12x off (0.163 vs 0.0137 mm/Hz, MAS-10 duty 0.5 at 0.3 s); read at s = 1,
# the Hermite end term cancels the end node's motion.


def _once(needed, work, default):
    """`work()` where `needed`, else `default`: a `cond` written as a while loop of at most one iteration. Under
    `vmap` a `cond` with a batched predicate computes both branches for every lane; this loop runs its body only when
    some lane needs it (the others keep `default`), so a batch of lanes pays for an event location only in the
    steps where one of them has an event. Not reverse-mode differentiable (sweeps are not differentiated)."""

    def body(c):
        return (jnp.zeros_like(c[0]), *work())

    return jax.lax.while_loop(lambda c: c[0], body, (needed, *default))[1:]


def integrate_observed(system, field, event, update, z0, left, right, aux, ts, observe, init):
    """`integrate`'s scheme for ONE run, its outputs observed on the fly instead of stored: the lane of a sweep.

    The same RK4 steps over the intervals `left`, `right` (with `aux` as in `integrate`), the same event location
    inside the step and the same cubic Hermite outputs, so each output equals `integrate`'s to round-off; but every
    output time `ts[k]` (concrete order, the first at the run's start `left[0]`) is passed to
    `observe(carry, k, t, z)` as soon as its step is done, and nothing of the trajectory is kept: memory does not
    grow with the horizon, whatever the number of lanes. A time at or before the start takes the initial state `z0`
    itself (as `integrate`'s callers do). Control flow is batch-friendly: the segments of a step, the event location
    and the outputs of a step are while loops that, under `vmap`, run as long as some lane needs them (see `_once`).

    Returns `(carry, z_end, finite)`.
    """
    n_out = ts.shape[0]
    t_start = left[0]
    z = jnp.where(event(system, 0.0, z0) < 0, update(system, 0.0, z0), z0)  # as in `integrate`
    slots = MAX_EVENTS + 1

    def emit(carry, k, end, seg):
        """Observe every output time before `end` (all of them with `end` = inf), on the segment `seg`."""
        seg_start, h, za, zb, fa, fb = seg

        def more(c):
            return (c[1] < n_out) & (ts[jnp.minimum(c[1], n_out - 1)] < end)

        def body(c):
            acc, k = c
            t = ts[k]
            s = jnp.where(h > 0, (t - seg_start) / jnp.where(h > 0, h, 1.0), 0.0)
            z_t = jnp.where(t <= t_start, z0, _hermite(s, h, za, zb, fa, fb))
            return observe(acc, k, t, z_t), k + 1

        return jax.lax.while_loop(more, body, (carry, k))

    def interval(state, xs):
        z, k, carry = state
        ta, tb, a = xs

        def more(c):
            return (c[0] < tb) & (c[1] < slots)

        def segment(c):
            seg_start, j, z_s, k, carry = c
            zb, fa, fb = _rk4(field, system, seg_start, tb, z_s, a)
            resolve = (event(system, tb, zb) < 0) & (j < MAX_EVENTS)

            def split():
                tau, z_tau = _locate(event, system, (seg_start, tb, z_s, zb, fa, fb))
                return tau, update(system, tau, z_tau)

            end, z_next = _once(resolve, split, (tb, zb))
            carry, k = emit(carry, k, end, (seg_start, tb - seg_start, z_s, zb, fa, fb))
            return end, j + 1, z_next, k, carry

        _, _, z, k, carry = jax.lax.while_loop(more, segment, (ta, jnp.zeros((), jnp.int32), z, k, carry))
        return (z, k, carry), None

    k0 = jnp.zeros((), jnp.int32)
    (z_end, k, carry), _ = jax.lax.scan(interval, (z, k0, init), (left, right, aux))
    zeros = jnp.zeros_like(z_end)
    carry, _ = emit(carry, k, jnp.inf, (right[-1], jnp.zeros(()), z_end, z_end, zeros, zeros))  # at the end time
    return carry, z_end, jnp.all(jnp.isfinite(z_end))
