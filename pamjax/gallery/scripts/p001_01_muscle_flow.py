"""Paper 001, eq. 3-4 and Figs. 5, 6, 11: the flow the VPPM delivers to the DMSP-40 (893 N), split into its pressure
and volume terms, inlet against outlet, and the global linear model (eq. 5) against the voltage-only one (eq. 6).

The regulator is pamjax's physical VPPM (`ISO6358Regulator`: eq. 6 pilot, Tables 1-2 flow limits) feeding the
DMSP-40-400 preset (eq. 4 cubic volume) under a 1.5 Hz square wave, 0-3 V and 0-5 V (Sect. 4). Along the run:

- eq. 3: q = V ṗ/(RT) + V'(x) ẋ p/(RT) (isothermal), each term from the model's own rates; their sum equals the
  delivered ISO 6358 flow (mass conservation), and the volume term's share is Fig. 5's "about 10 %";
- Fig. 6: pamjax's regulator has no internal volume, so inlet and outlet MASS flows are equal; volumetric flows at the
  ports' own pressures differ by 1 − p_out/p_in (the continuity equation the paper cites);
- Fig. 11: this run stands in for the measurement (no measured record is published); eq. 6 alone (V_ref only,
  closed port) and eq. 5 (eq. 6 plus eq. 7 with its printed gain, driven by the run's Q_in in l/min ANR) are scored
  by MSE. No gain is re-fitted on the record: a fitted gain nests the voltage-only model and could only win;
- eq. 4: the DMSP-40's cubic against the volume it was fitted to (virtual work of its force map, no coefficients
  being printed), and the preset's force and stroke against the datasheet it was scaled to (6000 N, 25 %).
"""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import signal as sps

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures.force_map import virtual_work_volume
from pamjax.presets import EQ6_TIME_CONSTANTS, EQ7_GAIN
from pamjax.units import BAR, FLOW_UNIT

PAPER = "001"
TITLE = "Valve flow into the muscle: eq. 3 terms, inlet vs outlet, global vs voltage-only model (Figs. 5, 6, 11)"
COVERS = ("eq. 3", "eq. 4", "Fig. 5", "Fig. 11", "text: peak valve inflow 2.79 / 4.34 l/min at 3 / 5 V",
          "text: DMSP-40-400, 6000 N, 25 % contraction")

FREQUENCY = 1.5  # Hz, paper 001 Sect. 4
RATE = 400.0  # Hz, samples


def run_muscle(volts, duration):
    system = pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), pj.presets.dmsp40_muscle())
    ts = jnp.arange(0.0, duration + 0.5 / RATE, 1.0 / RATE)
    traj = pj.simulate(system, pj.SquareWave(0.0, volts, FREQUENCY), ts, rtol=1e-8, atol=1e-8,
                       solver=dfx.Tsit5())  # not stiff: as many steps as Rodas5, a fifth of its compile time
    return {k: np.asarray(v) for k, v in flow_terms(system, traj).items()}


@eqx.filter_jit
def flow_terms(system, traj):
    """eq. 3's pressure and volume terms along `traj`, and the channels the figures use. Jitted (one program for both
    voltages): run eagerly, each vmapped operation compiled a program of its own (~100 of them)."""
    rates = jax.vmap(system.vector_field)(traj.t, traj.state, traj.command)
    rt = system.air.gas_constant * system.air.temperature * system.polytropic_index
    volume = jax.vmap(system.muscle.volume)(traj.position)
    slope = jax.vmap(system.muscle.volume_slope)(traj.position)
    pressure_term = volume * rates.regulator.pressure / rt
    volume_term = slope * rates.position * traj.pressure / rt
    return dict(
        t=traj.t, command=traj.command, pressure=traj.pressure, delivered=traj.mass_flow, pressure_term=pressure_term,
        volume_term=volume_term, supply=jnp.full_like(traj.pressure, system.regulator.supply_pressure),
        position=traj.position, rt=rt)


def global_model(r, volts):
    """(P_sim1 eq. 6 alone, eq. 7's response to Q_in per unit gain) [bar gauge] at the run's samples."""
    t = r["t"]
    poles = np.polymul([EQ6_TIME_CONSTANTS[0], 1], [EQ6_TIME_CONSTANTS[1], 1])
    p_v = sps.lsim(sps.lti([1.01], poles), r["command"], t)[1]  # eq. 6 [bar] from V_ref [V]
    q = r["delivered"] / FLOW_UNIT  # Q_in [l/min ANR]
    unit = sps.lsim(sps.lti([1.0], poles), q, t)[1]  # eq. 7 with unit gain (its pole-zero pair cancels)
    return p_v, unit


def dmsp40_checks():
    """The DMSP-40 preset against what it was derived from: its eq. 4 cubic against the virtual-work volume it was
    fitted to (max |difference| / range), its 6-bar force at x = 0 [N] and the contraction where that force vanishes."""
    length = presets.DMSP40_NOMINAL_LENGTH
    a = np.asarray(presets.DMSP40_MAX_FORCE_COEFFICIENTS)
    eps, dv = virtual_work_volume(a * length ** np.arange(5), length)
    d, c, b, a3 = presets.DMSP40_VOLUME_CUBIC
    cubic = d + c * eps + b * eps**2 + a3 * eps**3  # eq. 4 in the contraction ratio
    roots = np.roots(a[::-1])
    zero = float(roots[(np.abs(roots.imag) < 1e-9) & (roots.real > 0)].real.min())
    return dict(eq4_cubic_vs_virtual_work_max_relative=float(np.max(np.abs(cubic - (d + dv))) / np.ptp(d + dv)),
                force_at_0_6bar_N=float(a[0]), zero_force_contraction=zero / length)


def run(out, quick=False):
    duration = 4.0 / 3.0 if quick else 2.0  # two or three periods at 1.5 Hz
    runs = {v: run_muscle(v, duration) for v in (3.0, 5.0)}
    numbers = {}
    for v, r in runs.items():
        total = r["pressure_term"] + r["volume_term"]
        share = dict(rms=float(np.sqrt(np.mean(r["volume_term"] ** 2)) / np.sqrt(np.mean(total**2))),
                     peak=float(np.max(np.abs(r["volume_term"])) / np.max(np.abs(total))))
        charging = r["delivered"] > 0.05 * r["delivered"].max()
        ratio = r["pressure"][charging] / r["supply"][charging]  # Q_out/Q_in at equal mass flow = p_in/p_out
        numbers[f"{v:.0f}V"] = dict(
            peak_inflow_l_per_min_anr=float(r["delivered"].max() / FLOW_UNIT),
            peak_inflow_kg_per_s=float(r["delivered"].max()),
            volume_term_share=share,
            eq3_vs_delivered_max_relative=float(np.max(np.abs(total - r["delivered"]))
                                                / np.max(np.abs(r["delivered"]))),
            inlet_outlet_volumetric_difference_percent=[float(100 * (1 - ratio.max())), float(100 * (1 - ratio.min()))],
            position_range_mm=[float(1e3 * r["position"].min()), float(1e3 * r["position"].max())],
            pressure_range_bar_gauge=[float((r["pressure"].min() - 101325) / BAR),
                                      float((r["pressure"].max() - 101325) / BAR)],
        )
    r = runs[3.0]
    measured = (r["pressure"] - 101325.0) / BAR
    p_v, unit = global_model(r, 3.0)
    mse = dict(voltage_only=float(np.mean((p_v - measured) ** 2)),
               global_printed_gain=float(np.mean((p_v + EQ7_GAIN * unit - measured) ** 2)))
    numbers["fig11"] = dict(mse_bar2=mse)
    numbers["peak_inflow_ratio_5V_to_3V"] = numbers["5V"]["peak_inflow_l_per_min_anr"] / numbers["3V"][
        "peak_inflow_l_per_min_anr"]
    numbers["dmsp40"] = dmsp40_checks()

    pyplot = plt()
    fig, axes = pyplot.subplots(3, 1, figsize=(9, 9), sharex=True)
    t = r["t"]
    axes[0].plot(t, r["delivered"] / FLOW_UNIT, "k-", lw=2, label="delivered (ISO 6358)")
    axes[0].plot(t, r["pressure_term"] / FLOW_UNIT, "C0-", label="pressure term V ṗ/RT")
    axes[0].plot(t, r["volume_term"] / FLOW_UNIT, "C1-", label="volume term V' ẋ p/RT")
    axes[0].set(ylabel="flow [l/min ANR]", title="Fig. 5: 0-3 V, 1.5 Hz, DMSP-40 with 893 N")
    axes[0].legend(fontsize=8)
    charging = r["delivered"] > 0
    for port, label, c in (("supply", "inlet, at 7 bar", "C2-"), ("pressure", "outlet, at the muscle pressure", "C3-")):
        q = r["delivered"] * r["rt"] / r[port] * 6e4  # ṁ R T / p [m³/s] → l/min at the port's pressure
        axes[1].plot(t, np.where(charging, q, np.nan), c, label=label)
    axes[1].set(ylabel="flow at port pressure [l/min]", title="Fig. 6: same mass flow, different volumetric flows")
    axes[1].legend(fontsize=8)
    axes[2].plot(t, measured, "k-", lw=2, label="'measured' (pamjax physical regulator + muscle)")
    axes[2].plot(t, p_v, "C0--", label=f"eq. 6 alone: MSE {mse['voltage_only']:.3f} bar²")
    axes[2].plot(t, p_v + EQ7_GAIN * unit, "C3-",
                 label=f"eq. 5, printed gain: MSE {mse['global_printed_gain']:.3g} bar²")
    axes[2].set(xlabel="t [s]", ylabel="P_out [bar g]", ylim=(-0.5, 3.5), title="Fig. 11: global vs voltage-only")
    axes[2].legend(fontsize=8)
    fig_name = save(fig, out, "muscle_flow.png")

    n3, n5 = numbers["3V"], numbers["5V"]
    rows = [
        Row("eq. 3-4, Fig. 5", "volume term's share of the valve outlet flow (RMS; peak), 0-3 V",
            "≈ 10 %", f"{100 * n3['volume_term_share']['rms']:.1f} % RMS, {100 * n3['volume_term_share']['peak']:.1f} "
            f"% of the peak; eq. 3's sum equals the delivered flow to {n3['eq3_vs_delivered_max_relative']:.0e}",
            figure=fig_name),
        Row("text: 2.79 / 4.34 l/min", "peak valve inflow at 3 V / 5 V",
            "2.79 / 4.34 l/min (ratio 1.56)", f"{n3['peak_inflow_l_per_min_anr']:.0f} / "
            f"{n5['peak_inflow_l_per_min_anr']:.0f} l/min ANR (ratio "
            f"{n5['peak_inflow_l_per_min_anr'] / n3['peak_inflow_l_per_min_anr']:.2f})", figure=fig_name),
        Row("Fig. 6", "inlet vs outlet flow, while charging", "≈ 20 % difference",
            "mass flows equal (no internal volume); volumetric flows at the port pressures differ by "
            f"{n3['inlet_outlet_volumetric_difference_percent'][0]:.0f}-"
            f"{n3['inlet_outlet_volumetric_difference_percent'][1]:.0f} %", figure=fig_name),
        Row("Fig. 11", "MSE vs the 'measured' outlet pressure: eq. 6 alone / eq. 5 with the printed gain",
            "0.1663 (voltage-only) / 0.0499 (global)",
            f"{mse['voltage_only']:.3f} / {mse['global_printed_gain']:.3g} bar²", figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(volume_share=0.10, peak_inflow_l_per_min={"3V": 2.79, "5V": 4.34},
                                            inlet_outlet_difference=0.20, mse={"voltage_only": 0.1663,
                                                                               "global": 0.0499}))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
