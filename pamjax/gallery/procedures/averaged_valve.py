"""Eq. 13's averaged valve (m1…m9) by two routes, compared on the switching valve's cycle-averaged flow:

1. fitted directly to the switching valve's cycle-averaged flow over a (duty, pressure) grid
   (`pamjax.fit_averaged_valve`);
2. paper 000's own procedure: noisy constant-volume tank recordings of the switching valve (charge from atmosphere
   and discharge from supply at duties 0.15…0.85, 1 kHz, 2 kPa noise), pressure filtered (zero-phase Butterworth,
   20 Hz), differentiated, turned into mass flow with eq. 12 (ṁ = V ṗ / (κ R T)), and the surface fitted.

Both are scored on the same grid against the cycle-averaged flow: max error and RMSE as % of the flow range, beside
the paper's 4.13 % and 1.16 % (its fit to its own measurements). `plot` draws flow curves of both routes against the
cycle average, the tank-procedure estimates, and both routes' error maps. Command line: `fits/averaged_valve.py`;
in the gallery: `p000_05_averaged_valve`.

`compute(quick=True)`: the direct fit on a 17 × 17 instead of a 33 × 41 grid, the tank procedure with 4 instead of 8
duties and 1.0 s instead of 1.5 s runs; the scoring grid is the same.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets

PAPER = dict(max_error_percent=4.13, rmse_percent=1.16)  # paper 000, eq. 13 fit to its measurements (Fig. 9 text)
VOLUME = presets.TANK_VOLUME  # m³, the hybrid bench's test tank (paper 000 gives none)
SAMPLE_INTERVAL = 1e-3  # s: 1 kHz recordings (a typical bench DAQ rate; resolves the 50 Hz PWM ripple)
PRESSURE_NOISE = 2e3  # Pa: the hybrid bench's pressure noise (meta.json "noise")
FILTER_HZ = 20.0  # Hz: 2nd-order zero-phase Butterworth, paper 001's preprocessing
EDGE = 50  # samples (50 ms = 1/FILTER_HZ) dropped at each end: filtfilt's edge transients
USABLE_DUTY = (0.1, 0.9)  # the valve's usable range: 2 ms switching delay at 50 Hz = 10 % of a period (paper 000)
SCORE_GRID = 17  # points per axis of the scoring grid (duty × pressure)


def reference_grid(valve, air):
    """Scoring grid (duty in the usable range × pressure p_atm…p_s) and the switching valve's cycle-averaged flow."""
    u = np.linspace(*USABLE_DUTY, SCORE_GRID)
    p = np.linspace(float(air.atmospheric_pressure), float(valve.supply_pressure), SCORE_GRID)
    return u, p, pj.flow_surface(valve, u, p, air, samples=4000)  # cycle_averaged_flow's default resolution


@eqx.filter_jit
def _surface(averaged, air, uu, pp):
    """eq. 13's flow at each (u, p) pair: one program per grid shape (eagerly, each operation compiles its own)."""
    return jax.vmap(lambda u, p: averaged.mass_flow(0.0, u, p, air))(uu, pp)


def surface(averaged, u, p, air):
    """An averaged valve's eq. 13 flow [kg/s] on the grid u × p."""
    uu, pp = np.meshgrid(u, p, indexing="ij")
    return np.asarray(_surface(averaged, air, uu.ravel(), pp.ravel())).reshape(uu.shape)


def score(model, ref):
    """Max error and RMSE of `model` vs `ref` (same grid), in kg/s and % of the reference's flow range."""
    err, span = model - ref, float(np.ptp(ref))
    return dict(
        max_error_kg_s=float(np.max(np.abs(err))),
        rmse_kg_s=float(np.sqrt(np.mean(err**2))),
        max_error_percent=float(100 * np.max(np.abs(err)) / span),
        rmse_percent=float(100 * np.sqrt(np.mean(err**2)) / span),
    )


def paper_route(valve, air, rng, duties, horizon):
    """Tank recordings → filter → dṗ/dt → eq. 12 mass flow → least-squares surface (eq. 13).
    Returns the averaged valve and the (duty, pressure, mass flow) samples it was fitted to."""
    tank = pj.TankSystem(valve=valve, volume=VOLUME, air=air)
    ts = np.arange(0.0, horizon + 1e-9, SAMPLE_INTERVAL)
    kappa_rt = float(air.heat_capacity_ratio * air.gas_constant * air.temperature)
    us, ps, flows = [], [], []
    for u in duties:
        for p0 in (float(air.atmospheric_pressure), float(valve.supply_pressure)):
            rec = pj.synthetic_recording(
                tank,
                pj.Constant(u),
                ts,
                y0=tank.initial_state(p0),
                noise=dict(pressure=PRESSURE_NOISE),
                seed=int(rng.integers(1 << 30)),
                channels=["pressure"],
            )
            p = rec.filtered(FILTER_HZ)["pressure"]
            mdot = VOLUME * np.gradient(p, ts) / kappa_rt  # eq. 12 with V̇ = 0, adiabatic
            keep = slice(EDGE, -EDGE)
            us.append(np.full(ts[keep].size, u))
            ps.append(p[keep])
            flows.append(mdot[keep])
    u, p, f = np.concatenate(us), np.concatenate(ps), np.concatenate(flows)
    pg = p - float(air.atmospheric_pressure)
    scale = np.max(np.abs(pg))  # conditioning: fit in p / scale, then convert to SI
    design = np.stack([u**i * (pg / scale) ** j for i in range(3) for j in range(3)], axis=1)
    coef, *_ = np.linalg.lstsq(design, f, rcond=None)
    return pj.AveragedValve(jnp.asarray(coef.reshape(3, 3) / scale ** np.arange(3)[None, :])), (u, p, f)


def plot(path, u, p, ref, direct, procedure, samples, report, valve, air):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p_atm, span = float(air.atmospheric_pressure), float(np.ptp(ref))
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    ax = axes[0, 0]
    for k, j in enumerate(range(0, len(p), 4)):
        c = f"C{k}"
        ax.plot(u, ref[:, j] * 1e3, "o", color=c, ms=3, label=f"{(p[j] - p_atm) / 1e5:.2f} bar gauge")
        ax.plot(u, direct[:, j] * 1e3, "-", color=c, lw=1)
        ax.plot(u, procedure[:, j] * 1e3, "--", color=c, lw=1)
    ax.set(xlabel="duty ratio u [-]", ylabel="mass flow [g/s]",
           title="dots: cycle average; solid: route 1; dashed: route 2")
    ax.legend(fontsize=7)
    ax = axes[0, 1]
    su, sp, sf = samples
    duties, grid = np.unique(su), np.linspace(p_atm, p[-1], 41)
    curves = jax.jit(jax.vmap(jax.vmap(lambda d, q: pj.cycle_averaged_flow(valve, d, q, air), (None, 0)),
                              (0, None)))(duties, grid)
    for k, d in enumerate(duties):
        m = su == d
        ax.plot((sp[m] - p_atm) / 1e5, sf[m] * 1e3, ".", ms=1, color=f"C{k}", label=f"u = {d:.2f}")
        ax.plot((grid - p_atm) / 1e5, np.asarray(curves[k]) * 1e3, "k-", lw=0.7)
    ax.set(xlabel="gauge pressure [bar]", ylabel="mass flow [g/s]",
           title="tank procedure's eq. 12 estimates (dots) vs cycle average (lines)")
    ax.legend(fontsize=7, markerscale=8)
    for ax, model, key, name in ((axes[1, 0], direct, "cycle_average_fit", "route 1, fit to cycle average"),
                                 (axes[1, 1], procedure, "tank_procedure", "route 2, tank procedure")):
        err = 100 * (model - ref) / span
        lim = float(np.max(np.abs(err)))
        im = ax.pcolormesh(u, (p - p_atm) / 1e5, err.T, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="nearest")
        fig.colorbar(im, ax=ax, label="error [% of flow range]")
        s = report[key]
        ax.set(xlabel="duty ratio u [-]", ylabel="gauge pressure [bar]",
               title=f"{name}:\nmax {s['max_error_percent']:.2f} %, RMSE {s['rmse_percent']:.2f} % of range "
                     f"(paper 4.13 %, 1.16 %)")
    fig.suptitle("Eq. 13 averaged valve vs the switching valve's cycle-averaged flow (MHE2, 50 Hz, 2 ms delays)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def compute(quick=False):
    """Both routes scored on the cycle-averaged flow: (report, arguments of `plot` after its path)."""
    air, valve = pj.Air(), presets.mas10_valve("smooth")
    n_u, n_p = (17, 17) if quick else (33, 41)
    direct, _ = pj.fit_averaged_valve(valve, air, commands=jnp.linspace(*USABLE_DUTY, n_u),
                                      pressures=jnp.linspace(air.atmospheric_pressure, valve.supply_pressure, n_p))
    duties = np.linspace(0.15, 0.85, 4 if quick else 8)
    procedure, samples = paper_route(valve, air, np.random.default_rng(0), duties, 1.0 if quick else 1.5)
    u, p, ref = reference_grid(valve, air)
    flow_direct, flow_procedure = surface(direct, u, p, air), surface(procedure, u, p, air)
    report = dict(
        paper=PAPER,
        cycle_average_fit=score(flow_direct, ref),
        tank_procedure=score(flow_procedure, ref),
        flow_range_kg_s=float(np.ptp(ref)),
        m_cycle_average_fit=np.asarray(direct.coefficients).ravel().tolist(),
        m_tank_procedure=np.asarray(procedure.coefficients).ravel().tolist(),
        quick=quick,
        note=f"scored on duty {USABLE_DUTY[0]}-{USABLE_DUTY[1]} (the valve's usable range) x pressure p_atm..p_s, "
             f"{SCORE_GRID} x {SCORE_GRID} grid; m1..m9 in SI (kg/s, Pa gauge), row-major over (u power, p power)",
    )
    return report, (u, p, ref, flow_direct, flow_procedure, samples, report, valve, air)
