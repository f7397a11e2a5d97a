"""Valves feeding a chamber: paper 000's 3/2 on/off solenoid valve under PWM, and its averaged model (eq. 13).

Convention: `mass_flow(t, command, pressure, air)` is the mass flow INTO the chamber [kg/s] for chamber pressure
`pressure` [Pa abs]; negative while the chamber exhausts.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._errors import PamjaxInputError, check_finite, check_nonnegative, check_positive
from ._gas import AbstractRestriction, Air, EllipseRestriction
from ._smooth import smooth_step
from ._units import check_absolute_pressure


class AbstractValve(eqx.Module):
    """A valve between supply, chamber and exhaust.

    - `mass_flow(t, command, pressure, air)`: flow into the chamber [kg/s] at time `t` [s] for the command
      (duty ratio in [0, 1] for paper 000's valves) and the chamber's absolute pressure [Pa].
    - `command_range`: the closed interval of valid commands.
    - `command_time(t)`: the time at which the command is read (the PWM period start for an exact-edge valve).
    """

    command_range = (0.0, 1.0)
    switches = False  # True for a valve that switches on PWM edges (its grid is the PWM-synchronous one)

    def mass_flow(self, t, command, pressure, air: Air):
        raise NotImplementedError

    def command_time(self, t):
        return t

    def read_command(self, signal, t):
        """The command the valve acts on at time `t` (what `mass_flow` takes): `signal(command_time(t))`."""
        return signal(self.command_time(t))

    def max_step(self):
        """Largest step [s] an adaptive solver may take without stepping over the valve's switching (None: any)."""
        return None


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


class OnOffValve(AbstractValve):
    """Paper 000's 3/2 high-speed on/off valve (Festo MHE2) driven by PWM.

    Path 1→2 (supply → chamber) is open while the valve is on, path 2→3 (chamber → exhaust) while it is off:
    ṁ = o(t) ṁ₁₂(p_s, p) − (1 − o(t)) ṁ₂₃(p, p_atm), with the valve opening o(t) ∈ [0, 1].

    PWM timing (paper 000, "Analytic valve model"): the command is on during [kT, kT + uT) of each period T = 1/f.
    The valve opens `switch_on_delay` after the command goes on and closes `switch_off_delay` after it goes off; a
    command pulse shorter than the delay never switches it. With the 2 ms delays at 50 Hz, duties below 10 % leave the
    valve shut and duties above 90 % leave it open (the paper's 10-90 % usable range).

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
    - `switch_on_delay`, `switch_off_delay`: [s]; 2e-3 each (paper 000: switching time ≈ 2 ms).
    - `edge_width`: time width of a smoothed edge [s]; 1e-4 (0.5 % of the 20 ms period, 5 % of the switching time).
    - `mode`: "smooth" or "exact".
    """

    inflate: AbstractRestriction
    exhaust: AbstractRestriction
    supply_pressure: jax.Array = eqx.field(converter=jnp.asarray, default=6.5e5)  # Pa abs
    pwm_frequency: jax.Array = eqx.field(converter=jnp.asarray, default=50.0)  # Hz
    switch_on_delay: jax.Array = eqx.field(converter=jnp.asarray, default=2e-3)  # s
    switch_off_delay: jax.Array = eqx.field(converter=jnp.asarray, default=2e-3)  # s
    edge_width: jax.Array = eqx.field(converter=jnp.asarray, default=1e-4)  # s
    mode: str = eqx.field(static=True, default="smooth")

    switches = True

    def __check_init__(self):
        check_positive(self.supply_pressure, "OnOffValve.supply_pressure")
        check_absolute_pressure(self.supply_pressure, "OnOffValve.supply_pressure", above_atmosphere=True)
        check_positive(self.pwm_frequency, "OnOffValve.pwm_frequency")
        check_nonnegative(self.switch_on_delay, "OnOffValve.switch_on_delay")
        check_nonnegative(self.switch_off_delay, "OnOffValve.switch_off_delay")
        check_positive(self.edge_width, "OnOffValve.edge_width")
        if self.mode not in ("smooth", "exact"):
            raise PamjaxInputError(f"OnOffValve.mode must be 'smooth' or 'exact', got {self.mode!r}")
        check_finite(self.switch_on_delay + self.switch_off_delay, "OnOffValve switch delays")

    @property
    def period(self):
        return 1.0 / self.pwm_frequency

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
        opens_p, closes_p = step(previous * period - on_delay), step_open((1.0 - previous) * period - off_delay)
        opens_k, closes_k = step(duty * period - on_delay), step_open((1.0 - duty) * period - off_delay)
        during_p = opens_p  # (a period that does not open the valve closes it: T > t_on + t_off)
        after_p = (1.0 - closes_p) * during_p
        during_k = opens_k + (1.0 - opens_k) * after_p
        after_k = (1.0 - closes_k) * during_k
        return (during_p + (after_p - during_p) * step(phase - (previous * period + off_delay - period))
                + (during_k - after_p) * step(phase - on_delay)
                + (after_k - during_k) * step(phase - (duty * period + off_delay)))

    def switching_gates(self, command):
        """(opens, closes) for a period of duty `command`: whether its on-pulse (u T) outlasts the switch-on delay
        and its off-pulse ((1 − u) T) the switch-off delay (paper 000: only duties of 10-90 % switch at 50 Hz)."""
        period = self.period
        return (command * period - self.switch_on_delay >= 0, (1.0 - command) * period - self.switch_off_delay > 0)

    def open_at_period_end(self, command, open_before):
        """Whether the valve is open at the end of a period of duty `command` that it started open (`open_before`)
        or closed: a period that closes it ends closed, one that opens and does not close it ends open."""
        opens, closes = self.switching_gates(command)
        return jnp.where(closes, False, jnp.where(opens, True, open_before))

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


class AveragedValve(AbstractValve):
    """Paper 000's averaged ("analytic") valve, eq. 13: the PWM cycle-averaged mass flow as a 2nd-order
    bi-polynomial in the duty ratio u and the chamber pressure.

    ṁ_eq(u, p) = Σᵢⱼ m[i, j] uⁱ pᵍʲ, i, j ∈ {0, 1, 2}, with p_g = p − p_atm the GAUGE chamber pressure [Pa]
    (paper 000's Fig. 8 plots relative pressure). The paper's m1…m9 are `coefficients` flattened row-wise:
    m1 = m[0,0], m2 = m[0,1], m3 = m[0,2], m4 = m[1,0], …, m9 = m[2,2]. SI units: m[i, j] in kg/(s Paʲ).

    **Arguments:** `coefficients` (3, 3) array (see `pamjax.presets` for the derived defaults).
    """

    coefficients: jax.Array = eqx.field(converter=jnp.asarray)  # kg/(s Pa^j)

    def __check_init__(self):
        if jnp.shape(self.coefficients) != (3, 3):
            raise PamjaxInputError(
                "AveragedValve.coefficients must have shape (3, 3) (m1…m9 row-wise), "
                f"got {jnp.shape(self.coefficients)}"
            )
        check_finite(self.coefficients, "AveragedValve.coefficients")

    @classmethod
    def from_m(cls, m):
        """Build from the paper's flat m1…m9 (SI units, gauge pressure in Pa)."""
        m = jnp.asarray(m)
        if m.shape != (9,):
            raise PamjaxInputError(f"AveragedValve.from_m needs 9 coefficients m1…m9, got shape {m.shape}")
        return cls(m.reshape(3, 3))

    def mass_flow(self, t, command, pressure, air: Air):
        del t
        p_gauge = pressure - air.atmospheric_pressure
        u_powers = jnp.stack([jnp.ones_like(command), command, command * command])
        p_powers = jnp.stack([jnp.ones_like(p_gauge), p_gauge, p_gauge * p_gauge])
        return u_powers @ self.coefficients @ p_powers


def default_onoff_valve(**kwargs):
    """Paper 000's MHE2 valve with the Table 1 paths (A = 3.14e-6 m²)."""
    return OnOffValve(
        inflate=EllipseRestriction(discharge_coefficient=0.36, critical_ratio=0.28, area=3.14e-6),
        exhaust=EllipseRestriction(discharge_coefficient=0.39, critical_ratio=0.49, area=3.14e-6),
        **kwargs,
    )


def cycle_averaged_flow(valve: OnOffValve, command, pressure, air: Air, samples: int = 4000):
    """PWM-period average of an on/off valve's flow into a chamber held at `pressure` [Pa abs], for duty `command`
    [kg/s] (paper 000's "equivalent mass flow"; midpoint rule over `samples` phases of one period)."""
    phases = (jnp.arange(samples) + 0.5) / samples * valve.period
    flows = jax.vmap(lambda t: valve.mass_flow(t, command, pressure, air))(phases)
    return jnp.mean(flows)


def fit_averaged_valve(valve: OnOffValve, air: Air, commands=None, pressures=None, pin_endpoints=True):
    """Least-squares fit of eq. 13's m1…m9 to the cycle-averaged flow of an on/off valve over a (duty, pressure)
    grid (duty 0…1, pressure p_atm…p_supply by default). Returns `(AveragedValve, report)`, the report holding the
    max error and RMSE in kg/s and in % of the flow range (paper 000: 4.13 % and 1.16 %).

    With `pin_endpoints` (default) the fit is constrained to zero flow where the physical valve has none: duty 0 at
    atmospheric pressure and duty 1 at supply pressure. Without it the unconstrained biquadratic charges a tank
    above the supply pressure at high duty (and below atmosphere at low duty)."""
    commands = jnp.linspace(0.0, 1.0, 41) if commands is None else jnp.asarray(commands)
    if pressures is None:
        pressures = jnp.linspace(air.atmospheric_pressure, valve.supply_pressure, 41)
    uu, pp = jnp.meshgrid(commands, pressures, indexing="ij")
    flows = jax.vmap(jax.vmap(lambda u, p: cycle_averaged_flow(valve, u, p, air)))(uu, pp)
    pg = (pp - air.atmospheric_pressure).ravel()
    u = uu.ravel()
    p_scale = jnp.max(jnp.abs(pg))  # conditioning: fit in p / p_scale, then convert to SI
    pn = pg / p_scale
    design = jnp.stack([u**i * pn**j for i in range(3) for j in range(3)], axis=1)
    if pin_endpoints:

        def row(u, p):
            pn = (p - air.atmospheric_pressure) / p_scale
            return jnp.stack([u**i * pn**j for i in range(3) for j in range(3)])

        constraints = jnp.stack([row(0.0, air.atmospheric_pressure), row(1.0, valve.supply_pressure)])
        _, _, vt = jnp.linalg.svd(constraints)
        null = vt[constraints.shape[0] :].T  # (9, 7): coefficients satisfying both constraints exactly
        z, *_ = jnp.linalg.lstsq(design @ null, flows.ravel())
        coef = null @ z
    else:
        coef, *_ = jnp.linalg.lstsq(design, flows.ravel())
    coef = coef.reshape(3, 3) / p_scale ** jnp.arange(3)[None, :]
    fitted = AveragedValve(coef)
    model = jax.vmap(lambda u, p: fitted.mass_flow(0.0, u, p, air))(u, pp.ravel())
    err = model - flows.ravel()
    span = jnp.max(flows) - jnp.min(flows)
    report = dict(
        max_error=float(jnp.max(jnp.abs(err))),
        rmse=float(jnp.sqrt(jnp.mean(err**2))),
        max_error_percent=float(100 * jnp.max(jnp.abs(err)) / span),
        rmse_percent=float(100 * jnp.sqrt(jnp.mean(err**2)) / span),
        flow_range=float(span),
    )
    return fitted, report
