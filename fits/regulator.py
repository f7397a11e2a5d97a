"""Paper 001 identification, on synthetic data generated from the paper's own numbers.

1. C and b from constant-volume tank runs (appendix eq. 12-14): for each row of Tables 1 (charging) and 2
   (discharging), the 0.04 m³ tank is charged from atmosphere at that row's supply pressure, or discharged from
   that row's tank pressure, through the VPPM model (`ISO6358Regulator`, main stage fully open) with the row's C, b;
   2 mbar pressure noise is added; C and b are fitted back (Levenberg-Marquardt from C 30 % and b 15 % low, b
   bounded to (0, 0.95)) and compared.
2. G_Vref (eq. 6) from a 1.5 Hz, 0-3 V square wave at the closed port (paper's Fig. 7 set-up): eq. 6's response plus
   0.05 bar noise, smoothed by a 2nd-order Butterworth at 20 Hz (paper 001, Sect. 5), identified on the first 60 %
   and validated on the last 40 %, MSE [bar²] reported.

    python fits/regulator.py [--out results/regulator] [--quick]
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402
from scipy.signal import butter, filtfilt  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax._regulator import BAR, ISO6358RegulatorState  # noqa: E402

TANK = 0.04  # m³, paper 001 appendix
NOISE_TANK = 200.0  # Pa (2 mbar), assumed transducer noise
NOISE_VALVE = 0.05 * BAR  # Pa, assumed
P_ATM = 101325.0
B_MAX = 0.95  # upper bound of b in the fit (Tables 1-2: 0.53-0.75)


def _logit_b(b):
    return np.log(b / (B_MAX - b))


def tank_system(c_si, b, supply):
    path = pj.ISO6358Restriction(sonic_conductance=c_si, critical_ratio=b)
    reg = pj.ISO6358Regulator(charging=path, discharging=path, supply_pressure=supply)
    return pj.RegulatorSystem(reg, volume=TANK)


def tank_run(theta, mode, p_row, ts):
    """Tank pressure [Pa] for θ = (log C [m³/(s Pa)], logit b), charging at supply p_row or discharging from p_row."""
    c, b = jnp.exp(theta[0]), B_MAX * jax.nn.sigmoid(theta[1])  # b kept in (0, 0.95): b → 1 is a stiff dead end
    if mode == "charge":
        system, target, p0, volts = tank_system(c, b, p_row), P_ATM + 10.1 * BAR, P_ATM, 10.0
    else:
        system, target, p0, volts = tank_system(c, b, 7e5), P_ATM, p_row, 0.0
    y0 = ISO6358RegulatorState(pilot=jnp.asarray(target), pilot_output=jnp.asarray(target), pressure=jnp.asarray(p0))
    traj = pj.simulate(system, pj.Constant(volts), ts, y0=y0, adjoint="forward", rtol=1e-8, atol=1e-8)
    return traj.pressure


def fit_tank(mode, p_row, c_true, b_true, rng, quick):
    rate = 286.9 * 298.0 * 1.185 * c_true / TANK  # 1/s: eq. 14 gives ṗ = ±rate · p_up while choked
    if mode == "charge":  # linear rise at rate · p_s, then the subsonic approach
        horizon = 1.5 * (p_row - P_ATM) / (rate * p_row)
    else:  # exponential decay at `rate` down to p_atm / b, then the subsonic tail to p_atm
        horizon = (np.log(p_row / P_ATM) + 2.0) / rate
    ts = jnp.linspace(0.0, horizon, 60 if quick else 150)
    truth = jnp.array([np.log(c_true), _logit_b(b_true)])
    data = tank_run(truth, mode, p_row, ts) + NOISE_TANK * rng.standard_normal(ts.shape)
    start = jnp.array([np.log(0.7 * c_true), _logit_b(0.85 * b_true)])  # 30 % off in C, 15 % in b
    sol = optx.least_squares(
        lambda th, _: (tank_run(th, mode, p_row, ts) - data) / NOISE_TANK,
        optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8),
        start,
        max_steps=100,
        throw=False,
    )
    return float(jnp.exp(sol.value[0])), float(B_MAX * jax.nn.sigmoid(sol.value[1]))


def valve_response(params, ts):
    """Closed-port outlet pressure [Pa abs] of eq. 6 with params = (gain [bar/V], τ1 [s], τ2 [s])."""
    gain, t1, t2 = params
    reg = pj.LinearRegulator(
        calibration=pj.VoltageCalibration(voltage=(0.0, 10.0), gauge_pressure=jnp.stack([0.0, 10.0 * gain * BAR])),
        time_constants=jnp.stack([t1, t2]),
    )
    return pj.simulate(
        pj.RegulatorSystem(reg, volume=0.0), pj.SquareWave(0.0, 3.0, 1.5), ts, rtol=1e-9, atol=1e-9, adjoint="forward"
    ).pressure


def fit_valve(rng, quick):
    rate = 500.0  # Hz sampling (assumed; the NI USB-6009 samples up to 48 kS/s)
    ts = jnp.arange(0.0, 4.0 if quick else 8.0, 1.0 / rate)
    truth = jnp.array([1.01, 0.041, 0.023])  # eq. 6
    measured = np.asarray(valve_response(truth, ts)) + NOISE_VALVE * rng.standard_normal(ts.shape)
    bb, aa = butter(2, 20.0 / (rate / 2))  # 2nd-order Butterworth, f_c = 20 Hz (paper 001, Sect. 5)
    smoothed = filtfilt(bb, aa, measured)
    n_id = int(0.6 * ts.size)  # 60 % identification, 40 % validation (paper 001, Sect. 5)
    data_id = jnp.asarray(smoothed[:n_id])
    ts_id = np.asarray(ts)[:n_id]  # NumPy, so it stays a constant under jit
    sol = optx.least_squares(
        lambda th, _: (valve_response(th, ts_id) - data_id) / BAR,
        optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10),
        jnp.array([0.8, 0.06, 0.01]),
        max_steps=100,
        throw=False,
    )
    gain, t1, t2 = (float(v) for v in sol.value)
    t1, t2 = max(t1, t2), min(t1, t2)  # the two poles are interchangeable
    sim = np.asarray(valve_response(jnp.array([gain, t1, t2]), ts))
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
        steps=int(sol.stats["num_steps"]),
        ts=np.asarray(ts),
        measured=measured,
        smoothed=smoothed,
        simulated=sim,
        n_id=n_id,
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/regulator")
    ap.add_argument("--quick", action="store_true", help="fewer samples, shorter square wave")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    report = dict(charging=[], discharging=[])
    for mode, key, table, pcol in (
        ("charge", "charging", pj.presets.PAPER001_CHARGING_TABLE, "upstream_pressure_bar"),
        ("discharge", "discharging", pj.presets.PAPER001_DISCHARGING_TABLE, "tank_pressure_bar"),
    ):
        for p_bar, b, c in zip(table[pcol], table["critical_ratio"], table["sonic_conductance_m3_per_s_bar"]):
            c_fit, b_fit = fit_tank(mode, p_bar * 1e5, c / 1e5, b, rng, args.quick)
            row = dict(pressure_bar=p_bar, C_table=c, C_fit=c_fit * 1e5, b_table=b, b_fit=b_fit)
            report[key].append(row)
            print(
                f"{key:11s} {p_bar:6.3f} bar: C {c:.4e} → {c_fit * 1e5:.4e} m³/(s bar) "
                f"({100 * (c_fit * 1e5 / c - 1):+.2f} %), b {b:.4f} → {b_fit:.4f} ({b_fit - b:+.4f})"
            )
    v = fit_valve(rng, args.quick)
    print(
        f"G_Vref: gain {v['gain_bar_per_V']:.4f} bar/V (eq. 6: 1.01), τ1 {v['tau1_s']:.4f} s (0.041), "
        f"τ2 {v['tau2_s']:.4f} s (0.023), bandwidth {v['bandwidth_Hz']:.3f} Hz (3.14); validation (last 40 %) "
        f"MSE {v['validation_mse_bar2']:.2e} bar², fit {v['validation_fit_percent']:.2f} %"
    )
    report["G_Vref"] = {k: v[k] for k in v if not isinstance(v[k], np.ndarray) and k != "n_id"}
    (out / "regulator_fit.json").write_text(json.dumps(report, indent=2))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(8, 3.5))
        t = v["ts"]
        ax.plot(t, (v["measured"] - P_ATM) / BAR, ".", ms=1, color="0.7", label="synthetic measurement")
        ax.plot(t, (v["smoothed"] - P_ATM) / BAR, color="C0", label="Butterworth 20 Hz")
        ax.plot(t, (v["simulated"] - P_ATM) / BAR, "--", color="C3", label="identified eq. 6")
        ax.axvline(t[v["n_id"]], color="k", lw=0.8)
        ax.set(xlabel="t [s]", ylabel="P_out [bar gauge]", title="G_Vref: 60 % identification | 40 % validation")
        ax.legend(loc="upper right", fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "g_vref_fit.png", dpi=120)
    except ImportError:
        pass
    print(f"wrote {out}/regulator_fit.json")


if __name__ == "__main__":
    main()
