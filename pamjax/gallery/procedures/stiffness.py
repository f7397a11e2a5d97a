"""Paper 001 Sect. 6.2 (Fig. 12): muscle stiffness, its rate and the valve flow along a simulated run.

A DMSP-40-400 carrying 893 N is fed by the physical VPPM model (`ISO6358Regulator`, Tables 1-2 flow limits) with the
Fig. 12 reference, a 0-3 V square wave at 1.5 Hz. Along the run, by autodiff of the model's own laws:

- eq. 9: K = −dF/dx of the closed isothermal chamber [N/m] (`RegulatedMuscleSystem.stiffness`);
- eq. 10: V'(x) ṗ + V''(x) ẋ p [N/s] (`RegulatedMuscleSystem.stiffness_rate`), checked against central differences
  of p V'(x) along the saved run, and, for comparison, the literal time derivative of eq. 9's K (a JVP);
- eq. 11: q = (V ṗ + V' ẋ p)/(R T) [kg/s] (`RegulatedMuscleSystem.eq11_flow`), checked against the ISO 6358 flow
  the regulator delivers (mass conservation), and correlated with eq. 10 (the paper's "equivalence").

Command line: `fits/stiffness.py`; in the gallery: `p001_03_stiffness`.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax.units import FLOW_UNIT

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
        return pj.muscle_stiffness(system.muscle, x, p, system.air, None, system.polytropic_index)

    dk_dt = jax.vmap(lambda *a: jax.jvp(stiffness, a[:2], a[2:])[1])(x, p, xdot, pdot)  # d/dt of eq. 9 along the run

    def closed_force(x0, p0, x1):  # the force at x1 of the closed chamber holding p0 at x0: p V(x)^n constant
        v0, v1 = system.muscle.volume(x0), system.muscle.volume(x1)
        return system.muscle.force(x1, p0 * (v0 / v1) ** system.polytropic_index, system.air)

    h = 1e-6  # m: central differences of the closed-chamber force, an independent route to eq. 9's K
    stiffness_fd = jax.vmap(lambda a, b: -(closed_force(a, b, a + h) - closed_force(a, b, a - h)) / (2 * h))(x, p)
    return dict(
        stiffness_fd=stiffness_fd,
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
        eq9_vs_finite_difference_max_relative=float(np.max(np.abs(r["stiffness"] - r["stiffness_fd"]))
                                                    / np.max(np.abs(r["stiffness"]))),
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
