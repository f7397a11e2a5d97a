"""Paper 001 identification, on synthetic data generated from the paper's own numbers.

1. C and b from constant-volume tank runs (appendix eq. 12-14): for each row of Tables 1 (charging) and 2
   (discharging), the 0.04 m³ tank is charged from atmosphere at that row's supply pressure, or discharged from
   that row's tank pressure, through the VPPM model (`ISO6358Regulator`, main stage fully open) with the row's C, b.
   Each run is recorded at a constant rate until the tank is 0.1 bar from its final pressure (so the subsonic phase,
   28-71 % of the record, is in it), 2 mbar pressure noise is added, and C and b are fitted back: start values read
   off the record as the paper's appendix does (C from the choked slope, eq. 14; b from a scan at that C), then
   Levenberg-Marquardt through `simulate` with b kept in (0.1, 0.9). Reported with 1σ from (JᵀJ)⁻¹.
2. G_Vref (eq. 6) from a 1.5 Hz, 0-3 V square wave at the closed port (paper's Fig. 7 set-up): eq. 6's response plus
   0.05 bar noise, smoothed by a 2nd-order Butterworth at 20 Hz (paper 001, Sect. 5), identified on the first 60 %
   and validated on the last 40 %, MSE [bar²] reported.

Command line: `fits/regulator.py`; in the gallery: `p001_02_valve_model` (2.) and `p001_05_tables` (1.).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import quad
from scipy.signal import butter, filtfilt

import pamjax as pj
from pamjax import presets
from pamjax.units import BAR, ISO8778_DENSITY, ISO8778_TEMPERATURE

VPPM_HYSTERESIS = presets.VPPM_HYSTERESIS  # Pa
TANK = presets.PAPER001_TANK_VOLUME  # m³, 0.04 (paper 001 appendix)
NOISE_TANK = 200.0  # Pa (2 mbar), assumed transducer noise
NOISE_VALVE = 0.05 * BAR  # Pa, assumed
P_ATM = 101325.0  # Pa abs (paper001_air's atmosphere)
B_BOUNDS = (0.1, 0.9)  # fit range of b [-] (Tables 1-2: 0.53-0.75). Above 0.9 a discharge would stay choked to
#                        within p_atm/0.9 - p_atm = 0.11 bar of atmosphere, about where its record ends (SETTLED)
SETTLED = 2.0 * VPPM_HYSTERESIS  # Pa: a run is recorded until the tank is 0.1 bar from its final pressure; the
#                                  main stage closes over the last 50 mbar (full_opening_error), where b has no say


def tank_rate_constant(c_si):
    """k [1/s] of eq. 14 per unit upstream pressure: ṗ = k p_up while choked, k = R T ρ₀ C sqrt(T₀/T) / V."""
    air = presets.paper001_air()  # R = 286.9 J/(kg K), T = 298 K (built here: float64 once the caller enabled it)
    r, t = float(air.gas_constant), float(air.temperature)
    return r * t * ISO8778_DENSITY * c_si * np.sqrt(ISO8778_TEMPERATURE / t) / TANK


def tank_horizon(mode, p_row, c_si, b):
    """Duration [s] of a tank run until the tank is within `SETTLED` of its final pressure, from eq. 13-14 (the
    choked phase plus the subsonic phase; a logger's stopping rule applied to the noise-free run)."""
    k = tank_rate_constant(c_si)
    if mode == "charge":  # r = p/p_s: dr/dt = k φ(r); choked (φ = 1) from p_atm/p_s to b, then the quarter-ellipse
        r_end = 1.0 - SETTLED / p_row
        u_end = (r_end - b) / (1.0 - b)
        return (b - P_ATM / p_row + (1.0 - b) * np.arcsin(u_end)) / k
    # discharge, r = p_atm/p: dr/dt = k r φ(r); choked down to p_atm/b, then with u = (r - b)/(1 - b) = sin θ
    r_end = P_ATM / (P_ATM + SETTLED)
    theta_end = np.arcsin((r_end - b) / (1.0 - b))
    subsonic = quad(lambda th: (1.0 - b) / (b + (1.0 - b) * np.sin(th)), 0.0, theta_end)[0]
    return (np.log(p_row * b / P_ATM) + subsonic) / k


def to_b(z):
    lo, hi = B_BOUNDS
    return lo + (hi - lo) * jax.nn.sigmoid(z)


def from_b(b):
    lo, hi = B_BOUNDS
    return np.log((b - lo) / (hi - b))


def tank_system(c_si, b, supply):
    path = pj.ISO6358Restriction(sonic_conductance=c_si, critical_ratio=b)
    reg = pj.ISO6358Regulator(charging=path, discharging=path, supply_pressure=supply)
    return pj.RegulatorSystem(reg, volume=TANK)


def mode_values(mode, p_row):
    """The constants of a tank run (supply [Pa], pilot target [Pa], start pressure [Pa], voltage [V]): charging at
    supply `p_row` from atmosphere with the pilot at 10.1 bar gauge, or discharging from `p_row` with the pilot at
    atmosphere. As values (arguments of the compiled programs), so both modes and every row share one program."""
    if mode == "charge":
        values = (p_row, P_ATM + 10.1 * BAR, P_ATM, 10.0)
    else:
        values = (7e5, P_ATM, p_row, 0.0)
    return np.asarray(values, dtype=float)


def tank_run(theta, mode, p_row, ts, solver=None):
    """Tank pressure [Pa] for θ = (log C [m³/(s Pa)], scaled logit of b), charging at supply p_row or discharging from
    p_row (main stage fully open: pilot at 10.1 bar gauge, or at atmosphere); `solver`: `simulate`'s default or any."""
    return _tank_pressure(jnp.asarray(theta, dtype=float), mode_values(mode, p_row), jnp.asarray(ts), solver)


@eqx.filter_jit
def _tank_pressure(theta, values, ts, solver=None):
    """`tank_run` with the mode's constants as values: one program per sample count (and solver)."""
    c, b = jnp.exp(theta[0]), to_b(theta[1])  # b kept inside B_BOUNDS
    supply, target, p0, volts = values
    y0 = pj.ISO6358RegulatorState(pilot=target, pilot_output=target, pressure=p0)
    traj = pj.simulate(tank_system(c, b, supply), pj.Constant(volts), ts, y0=y0, adjoint="forward", rtol=1e-8,
                       atol=1e-8, solver=solver)
    return traj.pressure


@eqx.filter_jit
def _tank_pressure_and_jacobian(theta, values, ts):
    """(tank pressure, d(tank pressure)/dθ) by forward mode, one solve: with `_tank_pressure` the fit's only two
    programs (residuals and the cost of `start_values`' scan are NumPy on their output), shared by both modes and
    every row of a sample count."""
    jac, pressure = jax.jacfwd(lambda th: (_tank_pressure(th, values, ts),) * 2, has_aux=True)(theta)
    return pressure, jac


def _residuals(theta, values, ts, data):
    """Residuals of a tank run in noise units (NumPy, from the compiled `_tank_pressure`)."""
    return (np.asarray(_tank_pressure(jnp.asarray(theta, dtype=float), values, ts)) - data) / NOISE_TANK


def start_values(mode, p_row, ts, data):
    """(C [m³/(s Pa)], b) to start the fit from. C as the paper's appendix reads it off the record: the choked rate
    k of eq. 14, the least-squares slope of p/p_s (charge) or −ln p (discharge) over the first tenth of the record
    (choked in every Table 1-2 run: the choked phase lasts 29-72 % of it); b the best of a 0.02-spaced scan of
    `B_BOUNDS` at that C. From a start off in both C and b, Levenberg-Marquardt can trade one for the other and
    push b onto a flat end of its range, where the residuals no longer depend on it."""
    t, p = np.asarray(ts), np.asarray(data)
    n = max(t.size // 10, 3)
    y = p[:n] / p_row if mode == "charge" else -np.log(p[:n])
    c0 = float(np.polyfit(t[:n], y, 1)[0] / tank_rate_constant(1.0))
    grid = np.arange(B_BOUNDS[0] + 0.02, B_BOUNDS[1] - 0.01, 0.02)
    values, data = mode_values(mode, p_row), np.asarray(data)
    cost = [float(np.sum(_residuals(np.array([np.log(c0), from_b(b)]), values, ts, data) ** 2)) for b in grid]
    return c0, float(grid[int(np.argmin(cost))])


def fit_tank(mode, p_row, c_true, b_true, rng, quick):
    """Simulate one noisy tank run with (C, b) = (`c_true` [m³/(s Pa)], `b_true`) and fit them back: start values
    from the record (`start_values`), then Levenberg-Marquardt through `simulate` (forward-mode derivatives)."""
    ts = jnp.asarray(np.linspace(0.0, tank_horizon(mode, p_row, c_true, b_true), 60 if quick else 150))
    truth = np.array([np.log(c_true), from_b(b_true)])
    data = np.asarray(tank_run(truth, mode, p_row, ts)) + NOISE_TANK * rng.standard_normal(ts.shape)
    c0, b0 = start_values(mode, p_row, ts, data)
    values = mode_values(mode, p_row)

    def residuals(theta):
        r = _residuals(theta, values, ts, data)
        return r if np.all(np.isfinite(r)) else None

    def jacobian(theta):
        pressure, jac = _tank_pressure_and_jacobian(jnp.asarray(theta, dtype=float), values, ts)
        return (np.asarray(pressure) - data) / NOISE_TANK, np.asarray(jac) / NOISE_TANK

    sol = pj.levenberg_marquardt(residuals, jacobian, np.array([np.log(c0), from_b(b0)]), max_steps=100,
                                 ftol=1e-12, xtol=1e-10)
    # 1σ from the Gauss-Newton covariance (JᵀJ)⁻¹ (residuals are already in noise units), mapped to C and b
    jac = sol.jacobian
    cov = np.linalg.inv(jac.T @ jac)
    b_fit = float(to_b(sol.theta[1]))
    db_dz = (b_fit - B_BOUNDS[0]) * (B_BOUNDS[1] - b_fit) / (B_BOUNDS[1] - B_BOUNDS[0])
    return dict(
        C_start=c0,
        b_start=b0,
        C_fit=float(np.exp(sol.theta[0])),
        b_fit=b_fit,
        C_sigma_percent=100 * float(np.sqrt(cov[0, 0])),
        b_sigma=float(db_dz * np.sqrt(cov[1, 1])),
        horizon_s=float(ts[-1]),
        samples=int(ts.size),
        steps=int(sol.step),
        converged=bool(sol.reason.startswith("converged")),
    )


def valve_response(params, ts, solver=None):
    """Closed-port outlet pressure [Pa abs] of eq. 6 with params = (gain [bar/V], τ1 [s], τ2 [s]); `solver`:
    `simulate`'s default or any."""
    gain, t1, t2 = params
    reg = pj.LinearRegulator(
        calibration=pj.VoltageCalibration(voltage=(0.0, 10.0), gauge_pressure=jnp.stack([0.0, 10.0 * gain * BAR])),
        time_constants=jnp.stack([t1, t2]),
    )
    return pj.simulate(
        pj.RegulatorSystem(reg, volume=0.0), pj.SquareWave(0.0, 3.0, 1.5), ts, rtol=1e-9, atol=1e-9, adjoint="forward",
        solver=solver,
    ).pressure


# eq. 6's closed-port response and its forward-mode Jacobian, compiled once per sample count (and solver): the
# parameters and times are arguments and the residuals NumPy on the output (a `jax.jit(lambda ...)` closing over the
# data compiles on every call, and the truth's and the fit's responses share one program).
_VALVE_RESPONSE = eqx.filter_jit(valve_response)
_VALVE_JACOBIAN = eqx.filter_jit(jax.jacfwd(valve_response))


def fit_valve(rng, quick, solver=None):
    rate = 500.0  # Hz sampling (assumed; the NI USB-6009 samples up to 48 kS/s)
    ts = np.arange(0.0, 4.0 if quick else 8.0, 1.0 / rate)
    truth = np.array([1.01, 0.041, 0.023])  # eq. 6
    measured = np.asarray(_VALVE_RESPONSE(truth, ts, solver)) + NOISE_VALVE * rng.standard_normal(ts.shape)
    bb, aa = butter(2, 20.0 / (rate / 2))  # 2nd-order Butterworth, f_c = 20 Hz (paper 001, Sect. 5)
    smoothed = filtfilt(bb, aa, measured)
    n_id = int(0.6 * ts.size)  # 60 % identification, 40 % validation (paper 001, Sect. 5)
    data_id, ts_id = smoothed[:n_id], ts[:n_id]

    def res(th):
        return (np.asarray(_VALVE_RESPONSE(th, ts_id, solver)) - data_id) / BAR

    sol = pj.levenberg_marquardt(res, lambda th: (res(th), np.asarray(_VALVE_JACOBIAN(th, ts_id, solver)) / BAR),
                                 np.array([0.8, 0.06, 0.01]), max_steps=100, ftol=1e-12, xtol=1e-12)
    gain, t1, t2 = (float(v) for v in sol.theta)
    t1, t2 = max(t1, t2), min(t1, t2)  # the two poles are interchangeable
    sim = np.asarray(_VALVE_RESPONSE(np.array([gain, t1, t2]), ts, solver))
    val = slice(n_id, None)
    mse = float(np.mean(((sim[val] - smoothed[val]) / BAR) ** 2))
    fit_pct = 100 * (
        1 - np.linalg.norm(sim[val] - smoothed[val]) / np.linalg.norm(smoothed[val] - smoothed[val].mean())
    )
    ss = pj.linearise(
        pj.RegulatorSystem(
            pj.LinearRegulator(
                calibration=pj.VoltageCalibration(gauge_pressure=(0.0, 10 * gain * BAR)), time_constants=(t1, t2)
            ),
            volume=0.0,
        ),
        pj.LinearRegulator().initial_state(P_ATM + 3 * gain * BAR),
        3.0,
    )
    return dict(
        gain_bar_per_V=gain,
        tau1_s=t1,
        tau2_s=t2,
        validation_mse_bar2=mse,
        validation_fit_percent=fit_pct,
        bandwidth_Hz=ss.bandwidth(),
        steps=int(sol.step),
        ts=ts,
        measured=measured,
        smoothed=smoothed,
        simulated=sim,
        n_id=n_id,
    )


def fit_tables(rng, quick, rows=None):
    """Fit C and b back from a synthetic tank run for each Table 1 (charging) and Table 2 (discharging) row; `rows`
    optionally restricts to {"charging": [row indices], "discharging": [...]}. Returns {"charging": [...], ...}."""
    report = {}
    for mode, key, table, pcol in (
        ("charge", "charging", pj.presets.PAPER001_CHARGING_TABLE, "upstream_pressure_bar"),
        ("discharge", "discharging", pj.presets.PAPER001_DISCHARGING_TABLE, "tank_pressure_bar"),
    ):
        report[key] = []
        for i, (p_bar, b, c) in enumerate(
            zip(table[pcol], table["critical_ratio"], table["sonic_conductance_m3_per_s_bar"])
        ):
            if rows is not None and i not in rows.get(key, ()):
                continue
            r = fit_tank(mode, p_bar * BAR, c / BAR, b, rng, quick)
            row = dict(pressure_bar=p_bar, C_table=c, b_table=b, **r)
            for name in ("C_start", "C_fit"):  # m³/(s Pa) → the tables' m³/(s bar)
                row[name] = r[name] * BAR
            row["C_error_percent"] = 100 * (row["C_fit"] / c - 1)
            row["b_error"] = row["b_fit"] - b
            report[key].append(row)
            print(
                f"{key:11s} {p_bar:6.3f} bar: C {c:.4e} → {row['C_fit']:.4e} m³/(s bar) "
                f"({row['C_error_percent']:+.3f} % ± {r['C_sigma_percent']:.3f}), b {b:.4f} → {r['b_fit']:.4f} "
                f"({row['b_error']:+.4f} ± {r['b_sigma']:.4f}), {r['steps']} steps"
            )
    return report
