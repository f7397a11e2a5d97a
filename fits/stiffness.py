"""Paper 001 Sect. 6.2 (Fig. 12): muscle stiffness, its rate and the valve flow along a simulated run.

A DMSP-40-400 carrying 893 N is fed by the physical VPPM model (`ISO6358Regulator`, Tables 1-2 flow limits) with the
Fig. 12 reference, a 0-3 V square wave at 1.5 Hz. Along the run, by autodiff of the model's own laws:

- eq. 9: K = −dF/dx of the closed isothermal chamber [N/m] (`RegulatedMuscleSystem.stiffness`);
- eq. 10: V'(x) ṗ + V''(x) ẋ p [N/s] (`RegulatedMuscleSystem.stiffness_rate`), checked against central differences
  of p V'(x) along the saved run, and, for comparison, the literal time derivative of eq. 9's K (a JVP);
- eq. 11: q = (V ṗ + V' ẋ p)/(R T) [kg/s] (`RegulatedMuscleSystem.eq11_flow`), checked against the ISO 6358 flow
  the regulator delivers (mass conservation), and correlated with eq. 10 (the paper's "equivalence").

Writes `stiffness.json` and `stiffness.png` to `--out`; refuses to overwrite existing results unless `--overwrite`.

    python fits/stiffness.py [--out results/stiffness] [--duration 2.0] [--overwrite]
"""

import argparse
import json
import pathlib
import time

import diffrax
import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax._regulated import muscle_stiffness  # noqa: E402
from pamjax._regulator import FLOW_UNIT  # noqa: E402

PAPER = dict(
    load_force_N=893.0,  # paper 001 Sect. 4 (91.3 kg subject)
    reference_high_V=3.0,  # Fig. 12 caption: 3 V
    reference_frequency_Hz=1.5,  # Fig. 12 caption: 1.5 Hz
    peak_valve_flow_l_per_min=2.79,  # Sect. 6.1, 3 V reference (unit conditions not stated)
)
RATE = 400.0  # Hz, saving rate: 0.15 % of the 1.5 Hz period (assumed, ≥ 2× the 20 Hz filter band of Sect. 5)


def run(duration, solver=None):
    """The Fig. 12 run and its eq. 9-11 series. `solver`: default Tsit5 — this frictionless regulated muscle is not
    stiff at rtol 1e-8 (Tsit5 compiles in ~5 s where the default Rodas5 takes ~30 s, same results to the
    tolerance); the series are computed in one compiled function (eagerly, ~150 small programs)."""
    system = pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), pj.presets.dmsp40_muscle())  # 893 N load by default
    signal = pj.SquareWave(0.0, PAPER["reference_high_V"], PAPER["reference_frequency_Hz"])
    ts = jnp.arange(0.0, duration + 0.5 / RATE, 1.0 / RATE)
    traj = pj.simulate(system, signal, ts, rtol=1e-8, atol=1e-8, solver=diffrax.Tsit5() if solver is None else solver)
    series = _series(system, traj.t, traj.state, traj.command, traj.position, traj.pressure)
    return dict(
        system=system,
        t=np.asarray(traj.t),
        command=np.asarray(traj.command),
        pressure=np.asarray(traj.pressure),
        position=np.asarray(traj.position),
        delivered=np.asarray(traj.mass_flow),
        succeeded=bool(np.all(np.asarray(traj.succeeded))),
        **{k: np.asarray(v) for k, v in series.items()},
    )


@jax.jit
def _series(system, t, state, command, x, p):
    rates = jax.vmap(system.vector_field)(t, state, command)
    xdot, pdot = rates.position, rates.regulator.pressure

    def stiffness(x, p):
        return muscle_stiffness(system.muscle, x, p, system.air, None, system.polytropic_index)

    dk_dt = jax.vmap(lambda *a: jax.jvp(stiffness, a[:2], a[2:])[1])(x, p, xdot, pdot)  # d/dt of eq. 9 along the run
    return dict(
        stiffness=jax.vmap(system.stiffness)(state),
        eq10=jax.vmap(system.stiffness_rate)(t, state, command),
        dk_dt=dk_dt,
        eq11=jax.vmap(system.eq11_flow)(t, state, command),
        p_dV=p * jax.vmap(system.muscle.volume_slope)(x),
    )


def summarise(r):
    t, eq10, eq11, q = r["t"], r["eq10"], r["eq11"], r["delivered"]
    fd = (r["p_dV"][2:] - r["p_dV"][:-2]) / (t[2:] - t[:-2])  # d/dt (p V'(x)), central differences
    mid = eq10[1:-1]
    # away from the regulator's switching instants, where ṗ jumps within a sample
    smooth = np.abs(np.diff(eq10)[1:] - np.diff(eq10)[:-1]) < 0.05 * np.abs(eq10).max()
    peak = float(np.max(np.abs(q)))
    p_atm = float(r["system"].air.atmospheric_pressure)
    return dict(
        paper=PAPER,
        duration_s=float(t[-1]),
        samples=int(t.size),
        solver_succeeded=r["succeeded"],
        pressure_range_bar_gauge=[float((f(r["pressure"]) - p_atm) / 1e5) for f in (np.min, np.max)],
        position_range_m=[float(r["position"].min()), float(r["position"].max())],
        stiffness_eq9_range_N_per_m=[float(r["stiffness"].min()), float(r["stiffness"].max())],
        eq10_range_N_per_s=[float(eq10.min()), float(eq10.max())],
        peak_valve_flow_kg_per_s=peak,
        peak_valve_flow_l_per_min_anr=peak / FLOW_UNIT,
        eq11_vs_delivered_max_relative=float(np.max(np.abs(eq11 - q)) / peak),
        eq10_vs_finite_difference_max_relative=float(np.max(np.abs(fd[smooth] - mid[smooth])) / np.abs(eq10).max()),
        eq10_finite_difference_fraction_compared=float(smooth.mean()),
        correlation_eq10_eq11=float(np.corrcoef(eq10, eq11)[0, 1]),
        correlation_dK_dt_eq11=float(np.corrcoef(r["dk_dt"], eq11)[0, 1]),
    )


def plot(r, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = r["t"]
    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    ax[0].plot(t, r["stiffness"] / 1e3, color="C0")
    ax[0].set(ylabel="K, eq. 9 [kN/m]", title="DMSP-40-400, 893 N, 0-3 V square wave at 1.5 Hz (paper 001 Fig. 12)")
    ax[1].plot(t, r["eq10"] / 1e3, color="C1", label="eq. 10: V'ṗ + V''ẋp")
    ax[1].set(ylabel="eq. 10 [kN/s]")
    ax[1].legend(loc="upper right", fontsize=8)
    ax[2].plot(t, r["delivered"] / FLOW_UNIT, color="0.6", lw=3, label="ISO 6358 flow delivered")
    ax[2].plot(t, r["eq11"] / FLOW_UNIT, "--", color="C3", label="eq. 11")
    ax[2].set(xlabel="t [s]", ylabel="valve flow [l/min ANR]")
    ax[2].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/stiffness")
    ap.add_argument("--duration", type=float, default=2.0, help="simulated time [s] (3 periods at 1.5 Hz)")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    path = out / "stiffness.json"
    if path.exists() and not args.overwrite:
        raise SystemExit(f"{path} exists; pass --overwrite")
    if not args.duration > 0:
        raise SystemExit(f"--duration must be > 0 s, got {args.duration}")
    start = time.perf_counter()
    r = run(args.duration)
    report = summarise(r)
    report["wall_time_s"] = time.perf_counter() - start
    report["series"] = {k: r[k].tolist() for k in ("t", "command", "pressure", "position", "stiffness", "eq10", "eq11")}
    print(
        f"eq. 9 stiffness {report['stiffness_eq9_range_N_per_m'][0]:.4g}-{report['stiffness_eq9_range_N_per_m'][1]:.4g}"
        f" N/m; eq. 10 {report['eq10_range_N_per_s'][0]:.4g} to {report['eq10_range_N_per_s'][1]:.4g} N/s"
    )
    print(
        f"eq. 11 vs delivered ISO 6358 flow: max difference {report['eq11_vs_delivered_max_relative']:.1e} of the "
        f"peak {report['peak_valve_flow_kg_per_s']:.3e} kg/s ({report['peak_valve_flow_l_per_min_anr']:.1f} l/min ANR;"
        f" paper 2.79 l/min)"
    )
    print(
        f"eq. 10 vs d/dt(p V') by central differences: {report['eq10_vs_finite_difference_max_relative']:.1e} of its "
        f"peak; correlation eq. 10 / eq. 11 {report['correlation_eq10_eq11']:.3f}, "
        f"dK/dt (eq. 9) / eq. 11 {report['correlation_dK_dt_eq11']:.3f}"
    )
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=1))
    try:
        plot(r, out / "stiffness.png")
    except ImportError:
        print("matplotlib not installed: no figure")
    print(f"wrote {path} ({report['wall_time_s']:.1f} s)")


if __name__ == "__main__":
    main()
