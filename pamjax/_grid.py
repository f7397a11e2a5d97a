"""Fixed-grid RK4 integration with events located inside the step: the solver of hybrid systems.

The grid is given as intervals [left_i, right_i] (the PWM-synchronous grid of `pamjax._synchronous` for a switching
valve, a uniform grid otherwise), each with the valve opening held over it (or None). Each interval is one classical
RK4 step. A hybrid system (`system.hybrid`, e.g. a muscle with `KarnoppFriction`) also gives an event function g
that stays ≥ 0 while its current mode holds; when g < 0 at the end of a step, the crossing τ is located on the
step's cubic Hermite interpolant (bisection, then one Newton step that carries the derivatives: dτ/dθ = −g_θ/g_τ,
the implicit function theorem), the state at τ is passed through `system.event_update` (the new mode), and the rest
of the interval is integrated from τ in the new mode. Up to `MAX_EVENTS` events per interval are resolved (the
grid's steps are ~1 ms; a stick-slip plant switches at most once or twice in one).

Between events the vector field is smooth (a mode holds the friction's sign fixed), so every segment is integrated
at RK4's full order, and the trajectory is a continuous, piecewise-smooth function of every parameter: fits get
the exact gradients of the sharp model, where a smooth sign would bias them and make the plant stiff.

Outputs at requested times are the cubic Hermite interpolants of the segment that contains them (end slopes from
the vector field), O(h⁴) like the steps.
"""

import jax
import jax.numpy as jnp

MAX_EVENTS = 2  # events resolved per interval; further ones in the same interval are counted as missed
_BISECTIONS = 40  # halvings of the step to bracket an event (2^-40 of a ~1 ms step), before the Newton step


def _hermite(s, h, za, zb, fa, fb):
    """Cubic Hermite interpolant at s ∈ [0, 1] of a step of length h from (za, fa) to (zb, fb)."""
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * za + h10 * h * fa + h01 * zb + h11 * h * fb


def _first(tree):
    return jax.tree_util.tree_map(lambda a: a[0], tree)


def integrate(system, field, event, update, z0, left, right, held, ts):
    """Integrate the flat scaled state `z0` over the intervals; returns `(z_at_ts, num_steps, num_events, missed,
    finite)`.

    - `field(system, t, z, held_i)` → dz/dt (flat scaled), `event(system, t, z, held_i)` → g (or `event` None for a
      system without modes), `update(system, t, z, held_i)` → z after an event.
    - `left`, `right`: (n,) interval ends (zero-length intervals are skipped exactly); `held`: a pytree with leading
      axis n, passed per interval (the valve opening), or None.
    - `ts`: output times inside [left[0], right[-1]]; earlier ones take `z0`.
    """
    hybrid = event is not None
    frozen = jax.lax.stop_gradient(system)

    def rk4(ta, tb, z, h_i):
        h = tb - ta
        k1 = field(system, ta, z, h_i)
        k2 = field(system, ta + 0.5 * h, z + 0.5 * h * k1, h_i)
        k3 = field(system, ta + 0.5 * h, z + 0.5 * h * k2, h_i)
        k4 = field(system, tb, z + h * k3, h_i)
        zb = z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return zb, k1, field(system, tb, zb, h_i)

    def locate(seg, h_i):
        """Time and state of the first crossing g = 0 in a step whose end has g < 0."""
        ta, tb, za, zb, fa, fb = seg
        h = tb - ta
        const = jax.lax.stop_gradient((ta, h, za, zb, fa, fb))

        def g_frozen(s):
            ta_, h_, za_, zb_, fa_, fb_ = const
            return event(frozen, ta_ + s * h_, _hermite(s, h_, za_, zb_, fa_, fb_), h_i)

        def bisect(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            below = g_frozen(mid) < 0
            return jnp.where(below, lo, mid), jnp.where(below, mid, hi)

        lo, hi = jax.lax.fori_loop(0, _BISECTIONS, bisect, (jnp.zeros(()), jnp.ones(())))
        s = jax.lax.stop_gradient(0.5 * (lo + hi))

        def g(s):
            return event(system, ta + s * h, _hermite(s, h, za, zb, fa, fb), h_i)

        value, slope = jax.jvp(g, (s,), (jnp.ones_like(s),))
        slope_ok = jnp.abs(jax.lax.stop_gradient(slope)) > 0
        # One Newton step from the bracketed root: its value moves by ~2^-40, its derivative is −g_θ/g_s.
        s_new = s - jnp.where(slope_ok, value / jnp.where(slope_ok, slope, 1.0), 0.0)
        s_new = jnp.clip(s_new, 0.0, 1.0)
        return ta + s_new * h, _hermite(s_new, h, za, zb, fa, fb)

    def empty(tb, zb):
        zero = jnp.zeros_like(zb)
        return (tb, tb, jnp.ones_like(tb), zb, zb, zero, zero)

    def interval(carry, xs):
        z, n_events, n_missed = carry
        ta, tb, h_i = xs
        zb, fa, fb = rk4(ta, tb, z, h_i)
        if not hybrid:
            return (zb, n_events, n_missed), ((ta, tb, tb - ta, z, zb, fa, fb),)
        segments = []
        seg_start, seg = ta, (ta, tb, z, zb, fa, fb)
        for _ in range(MAX_EVENTS):
            crossed = (tb > seg_start) & (event(system, tb, seg[3], h_i) < 0)

            def split(args):
                seg, seg_start = args
                tau, z_tau = locate(seg, h_i)
                z_new = update(system, tau, z_tau, h_i)
                zb2, fa2, fb2 = rk4(tau, tb, z_new, h_i)
                done = (seg_start, tau, seg[1] - seg[0], seg[2], seg[3], seg[4], seg[5])
                return done, (tau, tb, z_new, zb2, fa2, fb2), tau

            def keep(args):
                seg, seg_start = args
                done = (seg_start, seg[1], seg[1] - seg[0], seg[2], seg[3], seg[4], seg[5])
                tb_, zb_ = seg[1], seg[3]
                return done, (tb_, tb_, zb_, zb_, jnp.zeros_like(zb_), jnp.zeros_like(zb_)), tb_

            done, seg, seg_start = jax.lax.cond(crossed, split, keep, (seg, seg_start))
            segments.append(done)
            n_events = n_events + crossed
        # The last segment: from its start to tb (an empty one when the interval ended earlier).
        last_len = seg[1] - seg[0]
        segments.append((seg_start, seg[1], jnp.where(last_len > 0, last_len, 1.0), seg[2], seg[3], seg[4], seg[5]))
        z_end = seg[3]
        n_missed = n_missed + ((tb > seg_start) & (event(system, tb, z_end, h_i) < 0))
        return (z_end, n_events, n_missed), tuple(segments)

    if hybrid:  # a start state outside its mode (e.g. stuck under a net force beyond F_c) switches at once
        z0 = jnp.where(event(system, left[0], z0, _first(held)) < 0, update(system, left[0], z0, _first(held)), z0)
    zero = jnp.zeros((), dtype=jnp.int32)
    (z_end, n_events, n_missed), segs = jax.lax.scan(interval, (z0, zero, zero), (left, right, held))
    # Flatten (n, S) segments in time order.
    starts, stops, lengths, za, zb, fa, fb = (
        jnp.stack([s[k] for s in segs], axis=1).reshape((-1,) + segs[0][k].shape[1:]) for k in range(7)
    )
    index = jnp.clip(jnp.searchsorted(starts, ts, side="right") - 1, 0, starts.shape[0] - 1)
    h = lengths[index]
    del stops  # a segment holds from its start to the next segment's start
    s = jnp.where(h > 0, (ts - starts[index]) / jnp.where(h > 0, h, 1.0), 0.0)
    s = s[:, None]  # in [0, 1] by construction (no clip: its derivative is halved where s sits on a bound)
    z_out = _hermite(s, h[:, None], za[index], zb[index], fa[index], fb[index])
    z_out = jnp.where((ts <= left[0])[:, None], z0[None], z_out)
    num_steps = jnp.sum(right > left)
    finite = jnp.all(jnp.isfinite(z_end))
    return z_out, num_steps, n_events, n_missed, finite
