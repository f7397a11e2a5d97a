"""Shared test helpers: tree comparison, finite differences, and independent NumPy transcriptions of the papers'
equations (the oracles). Nothing here imports pamjax physics: the oracles are written from the papers."""

import contextlib

import equinox as eqx
import jax
import jax.monitoring
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.flatten_util import ravel_pytree

P_ATM = 101325.0  # Pa abs, ISO 2533 (pamjax.Air default)
R_AIR = 287.0  # J/(kg K), paper 000 Table 1
T_AIR = 293.0  # K, paper 000 Table 1
KAPPA = 1.4  # paper 000
LAMINAR_RATIO = 0.999  # ISO 6358-1:2013 laminar limit used by pamjax
RHO0, T0 = 1.185, 293.15  # ISO 8778 reference density [kg/m³] and temperature [K]


@contextlib.contextmanager
def counted_compilations():
    """The names of the programs XLA compiles inside the block (JAX's own compilation events), as a list."""
    names = []

    def listen(event, duration, **kw):
        if event.endswith("backend_compile_duration"):
            names.append(str(kw.get("fun_name")))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield names
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


def tree_allclose(a, b, rtol=1e-8, atol=1e-10):
    la, lb = jtu.tree_leaves(a), jtu.tree_leaves(b)
    return len(la) == len(lb) and all(
        np.allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol) for x, y in zip(la, lb)
    )


def central_difference(f, x, rel_step=1e-5, abs_step=1e-8):
    """Central finite-difference gradient of scalar `f` at the flat NumPy vector `x` (step relative per entry)."""
    x = np.asarray(x, dtype=float)
    g = np.zeros_like(x)
    for i in range(x.size):
        h = rel_step * abs(x[i]) if x[i] != 0 else abs_step
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        g[i] = (float(f(xp)) - float(f(xm))) / (2 * h)
    return g


def flat_parameters(module):
    """(flat float vector of every inexact-array leaf, function rebuilding the module from such a vector)."""
    params, static = eqx.partition(module, eqx.is_inexact_array)
    flat, unravel = ravel_pytree(params)

    def rebuild(v):
        return eqx.combine(unravel(jnp.asarray(v)), static)

    return np.asarray(flat), rebuild


def parameter_names(module):
    params, _ = eqx.partition(module, eqx.is_inexact_array)
    names = []
    for path, leaf in jtu.tree_leaves_with_path(params):
        name = jtu.keystr(path)
        size = int(np.size(leaf))
        names += [name] if size == 1 else [f"{name}[{i}]" for i in range(size)]
    return names


# --------------------------------------------------------------------------------------------------------------------
# Oracles: paper 000 eq. 10, 11; paper 001 eq. 13-14 (ISO 6358 ratio form); with the ISO 6358-1 laminar blend above
# r = 0.999 (a straight line from the law's value at 0.999 to zero flow at r = 1).
# --------------------------------------------------------------------------------------------------------------------


def np_ellipse_fraction(r, b, r_lam=LAMINAR_RATIO):
    """Paper 000 eq. 11 normalised: 1 for r ≤ b, sqrt(1 − ((r − b)/(1 − b))²) above; laminar line above r_lam."""
    r = np.asarray(r, dtype=float)

    def ell(q):
        return np.sqrt(np.maximum(1.0 - ((q - b) / (1.0 - b)) ** 2, 0.0))

    out = np.where(r <= b, 1.0, ell(np.clip(r, b, 1.0)))
    return np.where(r > r_lam, ell(r_lam) * (1.0 - r) / (1.0 - r_lam), out)


def _oriented(p1, p2):
    p1, p2 = float(p1), float(p2)
    if p1 >= p2:
        return p1, p2 / p1, 1.0
    return p2, p1 / p2, -1.0


def np_ellipse_flow(p1, p2, cv, b, area, R=R_AIR, T=T_AIR):
    """Paper 000 eq. 11 [kg/s] from port 1 to port 2 (absolute pressures), reversed when p2 > p1."""
    p_up, r, sign = _oriented(p1, p2)
    return sign * cv * area * p_up / np.sqrt(R * T) * float(np_ellipse_fraction(r, b))


def np_iso6358_flow(p1, p2, conductance, b, T=T_AIR):
    """Paper 001 eq. 13-14 (ratio form): ṁ = ρ0 C p_up sqrt(T0/T) · sqrt(1 − ((r − b)/(1 − b))²) [kg/s]."""
    p_up, r, sign = _oriented(p1, p2)
    return sign * RHO0 * conductance * p_up * np.sqrt(T0 / T) * float(np_ellipse_fraction(r, b))


def np_nozzle_cm(r, kappa=KAPPA, R=R_AIR, r_lam=LAMINAR_RATIO):
    """Paper 000 eq. 10's C_m(r) (laminar line above r_lam)."""
    r_cr = (2.0 / (kappa + 1.0)) ** (kappa / (kappa - 1.0))

    def sub(q):
        return np.sqrt(2 * kappa / (R * (kappa - 1)) * (q ** (2 / kappa) - q ** ((kappa + 1) / kappa)))

    if r <= r_cr:
        return np.sqrt(kappa / R * (2.0 / (kappa + 1.0)) ** ((kappa + 1.0) / (kappa - 1.0)))
    if r > r_lam:
        return sub(r_lam) * (1.0 - r) / (1.0 - r_lam)
    return sub(r)


def np_nozzle_flow(p1, p2, cq, area, kappa=KAPPA, R=R_AIR, T=T_AIR):
    """Paper 000 eq. 10: ṁ = A p_up C_q C_m / sqrt(T_up) [kg/s]."""
    p_up, r, sign = _oriented(p1, p2)
    return sign * area * p_up * cq * np_nozzle_cm(r, kappa, R) / np.sqrt(T)


# --------------------------------------------------------------------------------------------------------------------
# Oracles: muscle (paper 000 eq. 5, 6, 7, 14; paper 001 eq. 4), friction (eq. 8-9), valve opening, vector field.
# --------------------------------------------------------------------------------------------------------------------


def np_eq7_force(x, p_gauge, a, k0, k1, k2, p_max=6e5):
    """Paper 000 eq. 7: F = a0 + a1 x + … + a4 x⁴ − (p_max − p)(k0 − k1 x)/k2 (gauge pressure)."""
    fmax = sum(ai * x**i for i, ai in enumerate(a))
    return fmax - (p_max - p_gauge) * (k0 - k1 * x) / k2


def np_chou_hannaford(x, p_gauge, b, n, L0):
    """Paper 000 eq. 1-2, 5: F = (π D0²/4) p (3 cos²θ − 1), cosθ = L/b, D0 = b/(nπ), L = L0 − x."""
    cos_t = (L0 - x) / b
    d0 = b / (n * np.pi)
    return np.pi * d0**2 / 4 * p_gauge * (3 * cos_t**2 - 1)


def np_tondu_lopez(x, p_gauge, r0, theta0, L0, k=1.0):
    """Paper 000 eq. 6: F = π r0² p [a(1 − kε)² − b], a = 3/tan²θ0, b = 1/sin²θ0, ε = x/L0."""
    eps = x / L0
    return np.pi * r0**2 * p_gauge * (3 / np.tan(theta0) ** 2 * (1 - k * eps) ** 2 - 1 / np.sin(theta0) ** 2)


def softplus(x, w):
    return w * np.logaddexp(x / w, 0.0)


def logistic(x, w):
    return 0.5 * (1.0 + np.tanh(0.5 * x / w))


def np_friction(v, fc, cf, w):
    """Paper 000 eq. 8-9 with sign → tanh(v/w): F = F_c tanh(v/w) + C_f v."""
    return fc * np.tanh(v / w) + cf * v


def np_end_stops(x, v, x_min, x_max, k=1e6, c=6e3, w=1e-4):
    over, under = x - x_max, x_min - x
    return -k * softplus(over, w) + k * softplus(under, w) - c * v * (logistic(over, w) + logistic(under, w))


def np_pwm_opening(t, u, f=50.0, t_on=2e-3, t_off=2e-3, width=None, u_prev=None):
    """Valve opening of a PWM on/off valve with switching delays (paper 000 valve section).

    Exact (width None): the valve is open during [t_on, uT + t_off) of each period (wrapping into the next period),
    never if uT ≤ t_on (the on-pulse is too short to open it), always if (1 − u)T ≤ t_off (too short to close it).
    Smooth: every step replaced by a logistic of time width `width`.
    """
    T = 1.0 / f
    phase = t - np.floor(t / T) * T
    if width is None:
        if u * T <= t_on:
            return 0.0
        if (1 - u) * T <= t_off:
            return 1.0
        start, end = t_on, u * T + t_off
        return float((start <= phase < end) or (phase < end - T))
    # Smooth: the exact opening as a sum of its jumps at the edges of this period and the one before (the state
    # between a period's edges: open if its on-pulse opens the valve, else as before; after them: closed if its
    # off-pulse closes it), each jump a logistic step; the dead-band gates logistic too.
    s = lambda z: logistic(z, width)  # noqa: E731
    u_prev = u if u_prev is None else u_prev
    opens, closes = s(u * T - t_on), s((1 - u) * T - t_off)
    during_prev = s(u_prev * T - t_on)
    after_prev = (1 - s((1 - u_prev) * T - t_off)) * during_prev
    during = opens + (1 - opens) * after_prev
    after = (1 - closes) * during
    return (during_prev + (after_prev - during_prev) * s(phase - (u_prev * T + t_off - T))
            + (during - after_prev) * s(phase - t_on) + (after - during) * s(phase - (u * T + t_off)))


def np_valve_state_machine(ts, duties, f=50.0, t_on=2e-3, t_off=2e-3, dt=1e-6):
    """Open (1) / closed (0) at times `ts` of an on/off valve driven by PWM with duty `duties[k]` in period k,
    simulated as a state machine on a fine clock (dt): the command is on during [kT, kT + u_k T); the valve opens
    once the command has been on for t_on without a break and closes once it has been off for t_off. Starts closed,
    command off before t = 0. Independent of pamjax's edge formula."""
    T = 1.0 / f
    clock = np.arange(0.0, max(ts) + dt, dt)
    k = np.minimum(np.floor(clock / T + 1e-9).astype(int), len(duties) - 1)
    command = (clock - k * T) < np.asarray(duties)[k] * T
    state, on_for, off_for, out = 0, 0.0, t_off, np.empty(clock.size)
    for i, c in enumerate(command):
        on_for, off_for = (on_for + dt, 0.0) if c else (0.0, off_for + dt)
        if c and on_for >= t_on - 1e-12:
            state = 1
        if not c and off_for >= t_off - 1e-12:
            state = 0
        out[i] = state
    return out[np.clip(np.round(np.asarray(ts) / dt).astype(int), 0, clock.size - 1)]


class NumpyPlant:
    """A NumPy transcription of paper 000's plant (eq. 7, 8-9, 11, 14, 15, 16) with pamjax's smoothing choices
    (softplus slack 1 N, tanh sign, logistic PWM edges, softplus end stops), for scipy.integrate.solve_ivp."""

    def __init__(
        self,
        *,
        a,
        k0,
        k1,
        k2,
        v0,
        v1,
        x_min,
        x_max,
        mass=9.6,
        fc=16.0,
        cf=250.0,
        vw=1e-3,
        n=1.4,
        ps=6.5e5,
        valve="pwm",
        m=None,
        edge=1e-4,
        slack=1.0,
        volume=None,
    ):
        self.__dict__.update(locals())
        del self.__dict__["self"]

    def mass_flow(self, t, u, p):
        """`u`: the command signal (a function of time); a PWM valve latches it per 20 ms period (this period's
        and the previous period's duty), the averaged valve reads it continuously."""
        if self.valve == "averaged":
            pg = p - P_ATM
            u = u(t)
            return sum(self.m[i][j] * u**i * pg**j for i in range(3) for j in range(3))
        start = np.floor(t / 0.02 + 1e-9) * 0.02
        o = np_pwm_opening(t, u(start), width=self.edge, u_prev=u(start - 0.02))
        inflow = np_ellipse_flow(self.ps, p, 0.36, 0.28, 3.14e-6)  # Table 1 path 1→2
        outflow = np_ellipse_flow(p, P_ATM, 0.39, 0.49, 3.14e-6)  # Table 1 path 2→3
        return o * inflow - (1 - o) * outflow

    def tank_rhs(self, t, y, u_of_t):
        return [self.n * R_AIR * T_AIR * self.mass_flow(t, u_of_t, y[0]) / self.volume]

    def rhs(self, t, y, u_of_t):
        p, x, v = y
        mdot = self.mass_flow(t, u_of_t, p)
        vol = self.v0 + self.v1 * x  # eq. 14
        dp = self.n * (R_AIR * T_AIR * mdot - p * self.v1 * v) / vol  # eq. 15
        f_static = np_eq7_force(x, p - P_ATM, self.a, self.k0, self.k1, self.k2)
        f_muscle = softplus(f_static, self.slack)
        dv = (
            f_muscle - np_friction(v, self.fc, self.cf, self.vw) + np_end_stops(x, v, self.x_min, self.x_max)
        ) / self.mass - 9.81
        return [dp, v, dv]  # eq. 16


def np_stick_slip_run(plant, duties, ts, *, f=50.0, t_on=2e-3, t_off=2e-3, rtol=1e-11):
    """An event-driven reference for exact stick-slip (Karnopp) under a PWM valve with exact edges, independent of
    pamjax's integrator: SciPy's DOP853 integrates piece by piece between the valve's switching edges (found by
    `np_valve_state_machine`'s rules: open after t_on of command, closed after t_off without) and the friction's
    events located by `solve_ivp`'s root finder: sliding ends where v = 0 (stuck if |F_net| ≤ F_c, else reversing),
    sticking ends where |F_net| = F_c. `plant`: a `NumpyPlant` (its friction `fc`, `cf`; the sign is sharp here).
    Starts at rest in equilibrium at atmospheric pressure, stuck, valve closed. Returns (p, x) at `ts`."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    T = 1.0 / f
    t_end = float(ts[-1])
    edges = []  # (time, opening after it), the exact state machine per period
    for k, u in enumerate(duties):
        start = k * T
        if u * T - t_on >= 0:
            edges.append((start + t_on, 1.0))
        if (1.0 - u) * T - t_off > 0:
            edges.append((start + u * T + t_off, 0.0))
    edges = sorted(e for e in edges if e[0] < t_end)
    weight = plant.mass * 9.81

    def net_force(x, p):
        return softplus(np_eq7_force(x, p - P_ATM, plant.a, plant.k0, plant.k1, plant.k2), plant.slack) - weight

    def flow(o, p):
        return o * np_ellipse_flow(plant.ps, p, 0.36, 0.28, 3.14e-6) - (1 - o) * np_ellipse_flow(
            p, P_ATM, 0.39, 0.49, 3.14e-6)

    def rhs(o, z):
        def f(t, y):
            p, x, v = y
            vol = plant.v0 + plant.v1 * x
            if z == 0:
                return [plant.n * R_AIR * T_AIR * flow(o, p) / vol, 0.0, 0.0]
            dp = plant.n * (R_AIR * T_AIR * flow(o, p) - p * plant.v1 * v) / vol
            dv = (net_force(x, p) - plant.fc * z - plant.cf * v) / plant.mass
            return [dp, v, dv]
        return f

    x0 = brentq(lambda x: net_force(x, P_ATM), plant.x_min, plant.x_max, xtol=1e-15)
    y, z, t = np.array([P_ATM, x0, 0.0]), 0, 0.0
    times, states = [t], [y.copy()]
    bounds = [e[0] for e in edges] + [t_end]
    openings = [0.0] + [e[1] for e in edges]
    for t_stop, o in zip(bounds, openings):
        while t < t_stop - 1e-15:
            t_from = t
            if z == 0:
                event = lambda tt, yy: abs(net_force(yy[1], yy[0])) - plant.fc  # noqa: E731
            else:
                event = lambda tt, yy, z=z: z * yy[2]  # noqa: E731
            event.terminal, event.direction = True, (1 if z == 0 else -1)
            sol = solve_ivp(rhs(o, z), (t, t_stop), y, method="DOP853", rtol=rtol, atol=[1e-6, 1e-13, 1e-13],
                            events=event, dense_output=True)
            inside = (ts > t) & (ts <= sol.t[-1])
            if np.any(inside):
                times.extend(ts[inside])
                states.extend(np.atleast_2d(sol.sol(ts[inside]).T))
            t, y = sol.t[-1], sol.y[:, -1].copy()
            if sol.status == 1:  # an event
                if z == 0:
                    z = 1 if net_force(y[1], y[0]) > 0 else -1
                else:
                    y[2] = 0.0
                    force = net_force(y[1], y[0])
                    slide = 0 if abs(force) <= plant.fc else (1 if force > 0 else -1)
                    if slide == z and t - t_from <= 1e-12:
                        # A slide that starts at v = 0 "ends" where it began when the velocity's sign changes within
                        # the solver's first step (the event function is exactly 0 at the start, and the root finder
                        # returns the start): it would do so forever. Step it 1 ns without the event, then go on.
                        step = min(1e-9, t_stop - t)
                        y = solve_ivp(rhs(o, z), (t, t + step), y, method="DOP853", rtol=rtol,
                                      atol=[1e-6, 1e-13, 1e-13]).y[:, -1].copy()
                        t += step
                    z = slide
    states = np.asarray(states)
    order = np.argsort(times)
    times, states = np.asarray(times)[order], states[order]
    p = np.interp(ts, times, states[:, 0])
    x = np.interp(ts, times, states[:, 1])
    return p, x


def checkout_env():
    """The environment for a script run in a subprocess (`python fits/x.py`): the checkout's pamjax first on the
    path, so the script runs against the code under test, not another installed copy."""
    import os
    import pathlib

    root = str(pathlib.Path(__file__).resolve().parents[1])
    return {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}


def host_signal(u):
    """The command `u` (a pamjax signal) as a float function of a float time for SciPy's right-hand side, jitted once:
    called eagerly, each of the reference's thousands of evaluations runs the signal's operations one by one."""
    jitted = jax.jit(lambda t: u(t))
    return lambda t: float(jitted(t))


@eqx.filter_jit
def initial_state(system, **conditions):
    """`system.initial_state(**conditions)` as one compiled program: called eagerly, its static equilibrium (a
    bisection) compiles each of its dozens of operations as a program of its own, and its loop anew at every call.
    Give the conditions as arrays (`np.asarray(4.3e5)`): a Python float would be a constant of the program."""
    return system.initial_state(**conditions)
