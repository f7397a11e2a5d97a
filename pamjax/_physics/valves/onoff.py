"""Paper 000's 3/2 on/off solenoid valve (Festo MHE2) under PWM: a switching valve (`AbstractSwitchingValve`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._core.arrays import device_array
from ..._core.custom_types import RealScalar
from ..._core.errors import PamjaxInputError, check_nonnegative, check_positive, concrete_values
from ..._core.fitting import positive
from ..._core.units import MAX_EDGE_WIDTH, check_absolute_pressure
from ..._papers import paper000
from ..gas import AbstractRestriction, Air, check_restriction
from ..smooth import smooth_step
from .base import AbstractSwitchingValve


@jax.custom_jvp
def _no_gradient_through_exact_edges(x):
    return x


@_no_gradient_through_exact_edges.defjvp
def _exact_edge_jvp(primals, tangents):
    raise PamjaxInputError(
        "OnOffValve(mode='exact') cannot be differentiated with respect to anything that moves a switching edge "
        "(duty, pwm_frequency, switch delays): the solver is told the edge times, which do not carry derivatives, so "
        "the result would be silently wrong (~1e26 where finite differences give ~5e3). Use mode='smooth' for "
        "gradients; the exact mode is a reference for checking it."
    )


@eqx.filter_jit
def _commands_at(signal, times):
    """`signal` at each of `times`, as one compiled program (evaluated eagerly, each of its operations would compile
    on its own: ~0.3 s of the exact-edge schedule)."""
    return jax.vmap(signal)(times)


def first_violation(holds, *params):
    """Where the condition `holds(*values)` fails for the concrete, broadcast values of `params` (a sweep's lanes
    checked at once): (the first failing point's values as floats, its index as a phrase where there are several), or
    None when it holds everywhere, a value is traced, or the shapes do not combine (named elsewhere)."""
    values = [concrete_values(x) for x in params]
    if any(v is None for v in values):
        return None
    try:
        values = np.broadcast_arrays(*values)
    except ValueError:
        return None
    with np.errstate(divide="ignore"):
        bad = ~holds(*values)
    if not np.any(bad):
        return None
    i = np.unravel_index(int(np.argmax(bad)), bad.shape)
    where = f" (at index {tuple(int(k) for k in i)} of the values given)" if bad.size > 1 else ""
    return tuple(float(v[i]) for v in values), where


def _check_delays_within_period(frequency, on_delay, off_delay):
    """Refuse switching delays whose sum is not shorter than the PWM period T = 1/f. The valve's timing (`opening`,
    `edge_schedule`, `switching_gates` and the PWM-synchronous grid's `open_at_start`) takes each period to open or
    close the valve within itself: t_on + t_off < T, so that a period whose on-pulse is too short to open the valve
    closes it, and the edges of one period never pass those of the next. Beyond it the three steppings disagree
    silently (300 Hz with the 2 ms delays: a tank at 650, 124 or 105 kPa by stepping) and a delay longer than the
    period never opens the valve. Concrete values only, elementwise (a sweep's lanes checked at once); traced ones
    (jit, vmap, grad) have no value to check here."""
    found = first_violation(lambda f, on, off: on + off < 1.0 / f, frequency, on_delay, off_delay)
    if found is None:
        return
    (f, on, off), where = found
    raise PamjaxInputError(
        f"OnOffValve: switch_on_delay ({on * 1e3:.6g} ms) + switch_off_delay ({off * 1e3:.6g} ms) = "
        f"{(on + off) * 1e3:.6g} ms must be shorter than the PWM period 1/pwm_frequency = {1e3 / f:.6g} ms "
        f"(pwm_frequency = {f:.6g} Hz){where}: the valve model assumes each delay plays out within one period (each "
        "period opens or closes the valve before the next begins); lower pwm_frequency below "
        f"1/(switch_on_delay + switch_off_delay) = {1.0 / (on + off):.6g} Hz or shorten the delays"
    )


# The widest smoothed edge, as a fraction of the PWM period: at a 50 % duty a period's on and off edges are half a
# period apart, 10 edge widths at 1/20, and the logistic opening between them still reaches 99.3 % (S(5)); a wider
# edge never fully opens or closes the valve within a period, which the valve's timing assumes (each period opens and
# closes it before the next begins). The default 1e-4 s is 0.5 % of paper 000's 20 ms period (and 2.5 % of the 4 ms
# period of the fastest PWM the 2 ms delays allow); milliseconds typed as seconds (0.1 for 0.1 ms) are 500 % of it.
MAX_EDGE_FRACTION = 0.05


def _check_edge_within_period(frequency, edge_width):
    """Refuse a smoothed edge wider than `MAX_EDGE_FRACTION` of the PWM period 1/f (concrete values only,
    elementwise, as `_check_delays_within_period`; `SquareWave` checks its edges so too)."""
    found = first_violation(lambda f, w: w <= MAX_EDGE_FRACTION / f, frequency, edge_width)
    if found is None:
        return
    (f, w), where = found
    unit = (f"; {w:g} looks like ms (pamjax takes seconds: 0.1 ms is 1e-4)" if w > MAX_EDGE_WIDTH else
            "; give a narrower edge")  # wider than any PWM's edge (`MAX_EDGE_WIDTH`): milliseconds typed as seconds
    raise PamjaxInputError(
        f"OnOffValve.edge_width ({w:.6g} s = {w * 1e3:.6g} ms) must not exceed {MAX_EDGE_FRACTION:.0%} of the PWM "
        f"period 1/pwm_frequency = {1e3 / f:.6g} ms, i.e. {MAX_EDGE_FRACTION / f:.6g} s{where}: a smoothed edge "
        f"that wide never lets the valve open or close fully within a period (the default is 1e-4 s, 0.5 % of "
        f"50 Hz's 20 ms){unit}"
    )


class OnOffValve(AbstractSwitchingValve):
    """Paper 000's 3/2 high-speed on/off valve (Festo MHE2) driven by PWM.

    Path 1→2 (supply → chamber) is open while the valve is on, path 2→3 (chamber → exhaust) while it is off:
    ṁ = o(t) ṁ₁₂(p_s, p) − (1 − o(t)) ṁ₂₃(p, p_atm), with the valve opening o(t) ∈ [0, 1].

    PWM timing (paper 000, "Analytic valve model"): the command is on during [kT, kT + uT) of each period T = 1/f.
    The valve opens `switch_on_delay` after the command goes on and closes `switch_off_delay` after it goes off; a
    command pulse shorter than the delay never switches it, nor does a zero-length one (duty 0 or 1, even with a zero
    delay). With the 2 ms delays at 50 Hz, duties below 10 % leave the valve shut and duties above 90 % leave it open
    (the paper's 10-90 % usable range).

    The duty is latched at each period start (`read_command`), as the valve driver, the bench and the
    PWM-synchronous grid latch it. `mode="smooth"` (default): edges are logistic steps of time width `edge_width` [s]
    (sharpness 1/`edge_width`), and the dead-band gates are smooth too: differentiable in everything, the latched duty
    included. `mode="exact"`: sharp edges, and `simulate` hands the switching times to the solver (step-size clipping
    at jump times). A reference for checking the smooth mode: its derivatives with respect
    to the duty, frequency or delays are wrong, so differentiating through them raises an error.

    **Arguments:**

    - `inflate`, `exhaust`: restrictions of paths 1→2 and 2→3 (Table 1: C_v 0.36 / 0.39, b_v 0.28 / 0.49,
      A = 3.14e-6 m²). An exhaust silencer is a `SeriesRestriction(exhaust_port, silencer)`.
    - `supply_pressure`: p_s [Pa abs]; 0.65 MPa abs (paper 000; the "6.5 MPa" in its valve section is a typo).
    - `pwm_frequency`: f [Hz]; 50 (paper 000).
    - `switch_on_delay`, `switch_off_delay`: [s]; 2e-3 each (paper 000: switching time ≈ 2 ms). Their sum must be
      shorter than the PWM period 1/f (each delay plays out within one period; refused otherwise).
    - `edge_width`: time width of a smoothed edge [s]; 1e-4 (0.5 % of the 20 ms period, 5 % of the switching time).
      At most 5 % of the PWM period (`MAX_EDGE_FRACTION`; refused otherwise).
    - `mode`: "smooth" or "exact".
    """

    inflate: AbstractRestriction
    exhaust: AbstractRestriction
    supply_pressure: RealScalar = positive(paper000.SUPPLY_PRESSURE, unit="Pa abs")
    pwm_frequency: RealScalar = positive(paper000.PWM_FREQUENCY, unit="Hz")
    switch_on_delay: RealScalar = positive(paper000.SWITCH_DELAY, unit="s")
    switch_off_delay: RealScalar = positive(paper000.SWITCH_DELAY, unit="s")
    edge_width: RealScalar = positive(1e-4, unit="s")
    mode: str = eqx.field(static=True, default="smooth")

    def __check_init__(self):
        check_restriction(self.inflate, "OnOffValve.inflate", "EllipseRestriction(0.36, 0.28, 3.14e-6)")
        check_restriction(self.exhaust, "OnOffValve.exhaust", "EllipseRestriction(0.39, 0.49, 3.14e-6)")
        check_positive(self.supply_pressure, "OnOffValve.supply_pressure")
        check_absolute_pressure(self.supply_pressure, "OnOffValve.supply_pressure", above_atmosphere=True)
        check_positive(self.pwm_frequency, "OnOffValve.pwm_frequency")
        check_nonnegative(self.switch_on_delay, "OnOffValve.switch_on_delay")
        check_nonnegative(self.switch_off_delay, "OnOffValve.switch_off_delay")
        check_positive(self.edge_width, "OnOffValve.edge_width")
        if self.mode not in ("smooth", "exact"):
            raise PamjaxInputError(f"OnOffValve.mode must be 'smooth' or 'exact', got {self.mode!r}")
        _check_delays_within_period(self.pwm_frequency, self.switch_on_delay, self.switch_off_delay)
        _check_edge_within_period(self.pwm_frequency, self.edge_width)

    def supply(self):
        return self.supply_pressure

    def with_supply_pressure(self, pressure):
        return eqx.tree_at(lambda v: v.supply_pressure, self, jnp.asarray(pressure, dtype=float))

    @property
    def exact_edges(self):
        return self.mode == "exact"

    @property
    def smooth_edges(self):
        return self.mode == "smooth"

    def switching_time_scale(self):
        """The time scale [s] of a switching edge, which bounds a fixed step (`sweep`'s RK4 at 2 edge widths):
        `edge_width`. The exact mode's sharp edges have none of their own; a fixed step across one is as coarse as
        across a smoothed one, so the same width is used."""
        return self.edge_width

    def next_edge_step(self, signal, t):
        """The first boundary after `t` among the edges ± 3 `edge_width` of the periods before, containing and after
        `t` (on edge: period start + t_on; off edge: + u T + t_off), in constant time per step.

        An adaptive step of up to `max_step` (2 ms) that straddles a 0.1 ms logistic edge is judged by an error
        estimate that can miss most of the edge: which edges are missed depends on the step sequence, so last-bit
        differences (jit or not) moved a tank discharge at 50 % duty by 0.9 kPa RMS at rtol 1e-6. With a step boundary
        either side the edge is always resolved by steps of its own (17 Pa at rtol 1e-4, 1.5 Pa at 1e-6)."""
        period = self.period
        starts = self.command_time(t) + jnp.asarray([-1.0, 0.0, 1.0], dtype=jnp.result_type(t)) * period
        duties = jax.vmap(signal)(starts)
        edges = jnp.concatenate([starts + self.switch_on_delay, starts + duties * period + self.switch_off_delay])
        margin = 3.0 * self.edge_width
        boundaries = jnp.concatenate([edges - margin, edges + margin])
        after = boundaries > t + 64 * jnp.finfo(jnp.result_type(t)).eps * jnp.maximum(jnp.abs(t), 1.0)
        return jnp.min(jnp.where(after, boundaries, jnp.inf))

    def max_step(self):
        """A tenth of the PWM period (2 ms at 50 Hz), at most the shortest open or closed window the 2 ms switching
        delays allow: an adaptive solver with larger steps can step over a whole window and silently miss it
        (seen: 25 % duty into a tank, 40 kPa off)."""
        return self.period / 10.0

    def command_time(self, t):
        """The start of the PWM period containing `t`: a PWM modulator latches its duty once per period."""
        return jnp.floor(t * self.pwm_frequency + 1e-9) * self.period

    def read_command(self, signal, t):
        """(u_k, u_{k−1}): the duty latched at the start of the period containing `t` and at the period before (its
        valve state carries over: a period whose off-pulse is too short to close the valve leaves it open)."""
        start = self.command_time(t)
        return jnp.stack([signal(start), signal(start - self.period)])

    def opening(self, t, command):
        """Valve opening o(t) ∈ [0, 1] (1 = path 1→2 open, 0 = path 2→3 open) for the latched duty `command`: a
        pair (u_k, u_{k−1}) of this period and the one before (`read_command`), or one duty held over both.

        The opening is a sum of steps at the switching edges: o = d_p + (a_p − d_p) S(φ − e_p) + (d_k − a_p) S(φ −
        t_on) + (a_k − d_k) S(φ − e_k), with φ the phase in this period, e = uT + t_off the off edges (e_p = u_{k−1} T
        + t_off − T, in this period's frame), d the state between a period's edges (open if its on-pulse opens the
        valve, else the state it started in) and a the state after them (closed if its off-pulse closes it, else
        d). S is a logistic step of width `edge_width` (mode "smooth") or a sharp step ("exact"). Each period's
        edges carry its own duty, so the opening is continuous across period starts, and a valve left open by a
        period above ~90 % duty stays open into the next until it closes (the bench, the exact mode and the PWM grid
        agree)."""
        command = jnp.asarray(command)
        duty, previous = (command[0], command[1]) if command.shape == (2,) else (command, command)
        period = self.period
        on_delay, off_delay = self.switch_on_delay, self.switch_off_delay
        if self.mode == "exact":
            duty, previous, period, on_delay, off_delay = (
                _no_gradient_through_exact_edges(x) for x in (duty, previous, period, on_delay, off_delay))

            def step(x):
                return jnp.where(x >= 0, 1.0, 0.0)

            def step_open(x):  # open intervals are [start, end): the edge itself belongs to the next interval
                return jnp.where(x > 0, 1.0, 0.0)
        else:

            def step(x):
                return smooth_step(x, self.edge_width)

            step_open = step
        phase = t - jnp.floor(t / period + 1e-9) * period  # in [0, T)

        def gates(u):  # a zero-length pulse (duty 0 or 1) switches nothing, whatever the delay (`switching_gates`)
            return (jnp.where(u > 0, step(u * period - on_delay), 0.0),
                    jnp.where(u < 1, step_open((1.0 - u) * period - off_delay), 0.0))

        (opens_p, closes_p), (opens_k, closes_k) = gates(previous), gates(duty)
        during_p = opens_p  # (a period that does not open it closes it: T > t_on + t_off, as __check_init__ requires)
        after_p = (1.0 - closes_p) * during_p
        during_k = opens_k + (1.0 - opens_k) * after_p
        after_k = (1.0 - closes_k) * during_k
        opening = (during_p + (after_p - during_p) * step(phase - (previous * period + off_delay - period))
                   + (during_k - after_p) * step(phase - on_delay)
                   + (after_k - during_k) * step(phase - (duty * period + off_delay)))
        if self.mode == "exact":
            return opening
        # Smooth gates let a pulse just short of t_on half-open the valve while its off edge u T + t_off comes
        # before the on edge t_on (t_off < t_on): the sum of steps dipped to -0.055 there (2 ms on, 0 off delay, duty
        # ~0.1), flow reversed through the supply path. An opening is a fraction in [0, 1].
        return jnp.clip(opening, 0.0, 1.0)

    def switching_gates(self, command):
        """(opens, closes) for a period of duty `command`: whether its on-pulse (u T) outlasts the switch-on delay
        and its off-pulse ((1 − u) T) the switch-off delay (paper 000: only duties of 10-90 % switch at 50 Hz). A
        zero-length pulse switches nothing even with a zero delay: duty 0 never opens the valve, duty 1 never closes
        it (`u T − t_on ≥ 0` alone would open it at duty 0 when t_on = 0)."""
        period = self.period
        return (jnp.logical_and(command > 0, command * period - self.switch_on_delay >= 0),
                jnp.logical_and(command < 1, (1.0 - command) * period - self.switch_off_delay > 0))

    def edge_phases(self, command):
        """Phases [s] of the period's on edge (t_on after its start) and off edge (u T + t_off), clipped to [0, T] and
        ordered; when the on-pulse is too short to open the valve, the 'on edge' is put at the off edge."""
        period = self.period
        opens, _ = self.switching_gates(command)
        off_edge = jnp.clip(command * period + self.switch_off_delay, 0.0, period)
        on_edge = jnp.where(opens, jnp.clip(self.switch_on_delay, 0.0, period), off_edge)
        return on_edge, jnp.maximum(off_edge, on_edge)

    def edge_schedule(self, signal, t0, t1):
        """The switching edges over [t0, t1] and the opening after each (concrete NumPy), for the exact mode.

        Per period k (start kT, duty u_k = signal(kT)): the on edge kT + t_on opens the valve if the on-pulse u_k T
        outlasts t_on; the off edge kT + u_k T + t_off closes it if the off-pulse (1 − u_k) T outlasts t_off;
        otherwise the valve keeps its state (above ~90 % duty it stays open into the next period). The valve is
        closed before the first period. Returns `(edges, openings)`: the sorted times [s] where the opening changes
        and the opening (0/1) from each on."""
        period = 1.0 / float(self.pwm_frequency)
        on, off = float(self.switch_on_delay), float(self.switch_off_delay)
        k0 = int(np.floor(t0 / period + 1e-9))
        n = int(np.ceil((t1 - k0 * period) / period)) + 2
        starts = (k0 + np.arange(n)) * period
        commands = np.asarray(_commands_at(signal, device_array(starts)), dtype=float)
        times, states, state = [], [], 0.0
        for start, u in zip(starts, commands):
            if u > 0 and u * period - on >= 0:  # a zero-length pulse opens nothing (`switching_gates`)
                state = 1.0
                times.append(start + on)
                states.append(state)
            if u < 1 and (1.0 - u) * period - off > 0:
                state = 0.0
                times.append(start + u * period + off)
                states.append(state)
        order = np.argsort(times, kind="stable")
        times, states = np.asarray(times)[order], np.asarray(states)[order]
        # Only the edges where the opening changes: a jump time where the field is smooth restarts the solver for
        # nothing (and diffrax's clipping controller can stall on one that a dtmax-sized step lands on exactly).
        change = np.diff(np.concatenate([[0.0], states])) != 0
        return times[change], states[change]

    def edge_times(self, commands_at_period_starts, t0):
        """Switching times [s] per period for the exact mode: (opening, closing) after period start t0 + kT."""
        starts = t0 + jnp.arange(commands_at_period_starts.shape[0]) * self.period
        return jnp.stack(
            [starts + self.switch_on_delay, starts + commands_at_period_starts * self.period + self.switch_off_delay],
            axis=-1,
        ).reshape(-1)

    def mass_flow(self, t, command, pressure, air: Air):
        return self.mass_flow_at_opening(self.opening(t, command), pressure, air)

    def mass_flow_at_opening(self, opening, pressure, air: Air):
        """ṁ = o ṁ₁₂(p_s, p) − (1 − o) ṁ₂₃(p, p_atm) [kg/s] for a given opening o ∈ [0, 1]."""
        inflow = self.inflate.mass_flow(self.supply_pressure, pressure, air)
        outflow = self.exhaust.mass_flow(pressure, air.atmospheric_pressure, air)
        return opening * inflow - (1.0 - opening) * outflow


