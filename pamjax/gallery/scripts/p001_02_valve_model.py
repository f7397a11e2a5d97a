"""Paper 001, eq. 5-8 and Figs. 7-10: the VPPM's linear model, its bandwidths, identification and validation.

- eq. 5-7 (`LinearRegulator`, closed port, 3 V) linearised by autodiff (`pj.linearise`): static gains and −3 dB
  bandwidths of P_out/V_ref (Fig. 8: 3.12 Hz; eq. 6: 3.14 Hz) and P_out/Q_in (Fig. 10: 3.69 Hz);
- why 3.69 Hz cannot follow from eq. 7 as printed: the bandwidth of every reading of it, computed;
- the linearised channels against eq. 6 and eq. 7 as printed (frequency responses, NumPy);
- eq. 8 (`FeedbackRegulator`, the paper's unnamed K1, K2 at pamjax's defaults): poles and bandwidth, and the poles
  of its denominator 1 + G_V G_Q from eq. 6-7 as printed (NumPy; K1, K2 enter the numerators only);
- G_Vref identified from a 1.5 Hz 0-3 V square wave, 60/40 split, Butterworth 20 Hz (`fits/regulator.py`): the fit
  percentage beside the paper's 94.64 %, and what that percentage implies for Fig. 7's MSE (no measured record is
  published, so Fig. 7's MSEs themselves cannot be recomputed);
- Fig. 9: the step response of eq. 7 (pamjax's linear regulator vs SciPy on eq. 7 as printed);
- the physical regulator (`ISO6358Regulator`) feeding the DMSP-40 with 893 N, linearised at 3 V: the paper found the
  valve slower with the muscle attached.
"""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np
from scipy import signal as sps
from scipy.optimize import brentq

import pamjax as pj
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures import regulator
from pamjax.gallery.procedures.linearised import describe, flow_input
from pamjax.units import BAR, FLOW_UNIT

PAPER = "001"
TITLE = "Linear valve model: bandwidths, 3.69 Hz, eq. 8, G_Vref identification, Figs. 7-10"
COVERS = ("eq. 5", "eq. 6", "eq. 7", "eq. 8", "Fig. 4", "Fig. 7", "Fig. 8", "Fig. 9", "Fig. 10",
          "text: G_Vref identified with 94.64 % fit (60/40 split, Butterworth 20 Hz)",
          "text: eq. 7 reduces to second order", "text: eq. 8's denominator is second order with real poles",
          "text: with the muscle attached the valve is slower than eq. 6")

T1, T2, TQ = 0.041, 0.023, 0.927  # s, eq. 6-7
PAPER_NUMBERS = dict(bandwidth_eq6_Hz=3.14, bandwidth_fig8_Hz=3.12, bandwidth_fig10_Hz=3.69, flow_gain=-0.922,
                     voltage_gain=1.01, fit_percent=94.64, mse_fig7_bar2={"1.5": 0.304, "1.0": 0.3183, "0.7": 0.2270},
                     mse_fig9=0.078)


def bandwidth(num, den, drop_db=3.0):
    """−`drop_db` frequency [Hz] of num/den (coefficients, highest power first) relative to its static gain."""
    g0 = abs(np.polyval(num, 0.0) / np.polyval(den, 0.0))

    def excess(f):
        g = abs(np.polyval(num, 2j * np.pi * f) / np.polyval(den, 2j * np.pi * f))
        return 20 * np.log10(g / g0) + drop_db

    grid = np.logspace(-3, 4, 3000)
    values = np.array([excess(f) for f in grid])
    crossing = np.flatnonzero((values[:-1] > 0) & (values[1:] <= 0))
    return float(brentq(excess, grid[crossing[0]], grid[crossing[0] + 1])) if crossing.size else None


def readings_of_369():
    """Bandwidth of each reading of eq. 7 (and of eq. 6's poles) that could give Fig. 10's 3.69 Hz [Hz]."""
    poles = np.polymul([T1, 1], [T2, 1])
    printed = (np.polymul([-0.922], [TQ, 1]), np.polymul(poles, [TQ, 1]))
    out = {
        "eq. 7 as printed (pole-zero pair cancels)": bandwidth(*printed),
        "eq. 7 without its 0.927 s pole (zero kept)": bandwidth(np.polymul([-0.922], [TQ, 1]), poles),
        "eq. 7 without its 0.927 s zero (pole kept)": bandwidth([-0.922], np.polymul(poles, [TQ, 1])),
        "eq. 6's poles, −6 dB instead of −3 dB": bandwidth([1.0], poles, 6.0),
        "eq. 6's slower pole alone, 1/(2π·0.041 s)": 1 / (2 * np.pi * T1),
    }
    scale = brentq(lambda k: bandwidth([1.0], np.polymul([k * T1, 1], [k * T2, 1])) - 3.69, 0.5, 1.0)
    tau2 = brentq(lambda t: bandwidth([1.0], np.polymul([T1, 1], [t, 1])) - 3.69, 1e-4, T2)
    return out, dict(both_time_constants_scaled_by=scale, second_time_constant_s=tau2)


def printed_responses(ss, freqs):
    """Max relative difference between the linearised channels and eq. 6 / eq. 7 as printed (NumPy, in the paper's
    units: bar/V and bar per l/min ANR) over `freqs` [Hz]."""
    s = 2j * np.pi * freqs
    poles = (1 + T1 * s) * (1 + T2 * s)
    printed = {"command": 1.01 / poles, "outlet_flow": -0.922 * (1 + TQ * s) / (poles * (1 + TQ * s))}
    scale = {"command": 1 / BAR, "outlet_flow": FLOW_UNIT / BAR}
    return max(float(np.max(np.abs(ss.frequency_response(freqs, "pressure", k) * scale[k] - g) / np.abs(g)))
               for k, g in printed.items())


def eq8_denominator_poles():
    """Roots [1/s] of the numerator of 1 + G_V(s) G_Q(s) with eq. 6-7 as printed (their 0.927 s pair cancelled):
    (1 + 0.041 s)² (1 + 0.023 s)² + 1.01 · (−0.922) = 0, NumPy."""
    d = np.polymul([T1, 1.0], [T2, 1.0])
    return np.roots(np.polyadd(np.polymul(d, d), [1.01 * -0.922]))


def muscle_bandwidth(u):
    """−3 dB bandwidth [Hz] of P_out/V_ref of the physical regulator feeding the DMSP-40 with 893 N, linearised at
    `u` [V] (as `fits/linearise.py` does)."""
    muscle = pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), pj.presets.dmsp40_muscle())
    p_set = muscle.air.atmospheric_pressure + muscle.regulator.calibration(u)
    guess = eqx.filter_jit(lambda m, p: m.initial_state(pressure=p))(muscle, p_set)
    ss = pj.linearise(muscle, pj.equilibrium(muscle, u, guess), u, outputs=("pressure", "position"))
    return ss.bandwidth("pressure", "command")


def draw(out, ours, printed_poles, scipy_step, ss, step, t_step, v):
    """The figure (written into `out`); returns its file name."""
    pyplot = plt()
    fig, axes = pyplot.subplots(2, 2, figsize=(12, 7.5))
    freqs = np.logspace(-1, 2, 200)
    for name, label, style in (("command", "P_out/V_ref (Fig. 8)", "C0-"), ("outlet_flow", "P_out/Q_in (Fig. 10)",
                                                                            "C3--")):
        mag, _ = ss.bode(freqs, "pressure", name)
        axes[0, 0].semilogx(freqs, mag - mag[0], style, label=f"{label}: {ss.bandwidth('pressure', name):.2f} Hz")
    axes[0, 0].axhline(-3, color="k", lw=0.6)
    axes[0, 0].axvline(3.69, color="C3", lw=0.6, ls=":")
    axes[0, 0].set(xlabel="f [Hz]", ylabel="|G| / |G(0)| [dB]", ylim=(-40, 3), title="eq. 5-7 at 3 V (dotted: 3.69 Hz)")
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].plot(v["ts"], (v["smoothed"] - 101325) / BAR, color="0.6", label="synthetic record, filtered")
    axes[0, 1].plot(v["ts"], (v["simulated"] - 101325) / BAR, "C0--", label="identified G_Vref")
    axes[0, 1].axvline(v["ts"][v["n_id"]], color="k", lw=0.8)
    axes[0, 1].set(xlabel="t [s]", ylabel="P_out [bar g]", title="G_Vref: 60 % identification | 40 % validation")
    axes[0, 1].legend(fontsize=8)
    axes[1, 0].plot(printed_poles.real, printed_poles.imag, "ko", ms=8, mfc="none", label="1 + G_V G_Q (NumPy)")
    axes[1, 0].plot(ours.real, ours.imag, "C2x", ms=8, label="FeedbackRegulator, linearised")
    axes[1, 0].axvline(0, color="0.6", lw=0.6)
    axes[1, 0].set(xlabel="Re s [1/s]", ylabel="Im s [1/s]", title="eq. 8: poles of the closed form (paper: two, real)")
    axes[1, 0].legend(fontsize=8)
    axes[1, 1].plot(t_step, step, "C0-", lw=2, label="pamjax LinearRegulator")
    axes[1, 1].plot(t_step, scipy_step, "k:", label="SciPy, eq. 7 as printed")
    axes[1, 1].set(xlabel="t [s]", ylabel="ΔP_out [bar] per l/min", title="Fig. 9: step of Q_in (1 l/min ANR)")
    axes[1, 1].legend(fontsize=8)
    return save(fig, out, "valve_model.png")


def run(out, quick=False):
    u = 3.0
    system = pj.RegulatorSystem(pj.LinearRegulator(), volume=0.0)
    ss = pj.linearise(system, pj.equilibrium(system, u, system.initial_state()), u,
                      inputs={"outlet_flow": flow_input})
    eq57 = describe(ss)
    feedback = pj.RegulatorSystem(pj.FeedbackRegulator(), volume=0.0)
    eq8 = describe(pj.linearise(feedback, pj.equilibrium(feedback, u, feedback.initial_state()), u,
                                inputs={"outlet_flow": flow_input}))
    readings, needed = readings_of_369()
    printed_poles = eq8_denominator_poles()
    ours = np.array([complex(*q) for q in eq8["poles_per_s"]])
    pole_gap = max(float(np.min(np.abs(ours - q))) / abs(q) for q in printed_poles)

    v = regulator.fit_valve(np.random.default_rng(0), quick, solver=dfx.Tsit5())  # not stiff
    var = float(np.var(v["smoothed"][v["n_id"]:] / BAR))
    implied_mse = (1 - PAPER_NUMBERS["fit_percent"] / 100) ** 2 * var  # fit % = 100 (1 − ‖e‖/‖y − ȳ‖)

    # Fig. 9: a 1 l/min ANR step of Q_in at the 3 V operating point, pamjax vs SciPy on eq. 7 as printed
    t_step = jnp.linspace(0.0, 3.0, 301)
    y0 = pj.equilibrium(system, u, system.initial_state())
    stepped = eqx.tree_at(lambda s: s.outlet_flow, system, jnp.asarray(FLOW_UNIT))
    step = (np.asarray(pj.simulate(stepped, pj.Constant(u), t_step, y0=y0, rtol=1e-10, atol=1e-10,
                                   solver=dfx.Tsit5()).pressure)
            - float(y0.pressure)) / BAR
    _, scipy_step = sps.step(sps.lti(np.polymul([-0.922], [TQ, 1]),
                                     np.polymul(np.polymul([T1, 1], [T2, 1]), [TQ, 1])), T=np.asarray(t_step))
    t63 = float(np.interp(0.632, step / step[-1], np.asarray(t_step)))

    numbers = dict(eq5_7=eq57, eq8={k: eq8[k] for k in ("poles_per_s", "bandwidth_Hz", "voltage_gain_bar_per_V",
                                                        "flow_gain_bar_per_l_min")},
                   readings_of_3_69_Hz=readings, needed_for_3_69_Hz=needed,
                   g_vref_fit={k: v[k] for k in ("gain_bar_per_V", "tau1_s", "tau2_s", "validation_mse_bar2",
                                                "validation_fit_percent", "bandwidth_Hz")},
                   paper_fit_percent_implies_mse_bar2=implied_mse,
                   eq5_7_vs_printed_max_relative=printed_responses(ss, np.logspace(-2, 3, 101)),
                   eq7_minus_eq6_bandwidth_Hz=eq57["flow_bandwidth_Hz"] - eq57["bandwidth_Hz"],
                   eq8_denominator=dict(poles=len(printed_poles),
                                        complex_poles=int(np.sum(np.abs(printed_poles.imag) > 1e-9)),
                                        poles_per_s=[[float(q.real), float(q.imag)] for q in printed_poles],
                                        feedback_regulator_vs_printed_max_relative=pole_gap),
                   muscle_attached_bandwidth_Hz=muscle_bandwidth(u),
                   fig9=dict(final_bar=float(step[-1]), t63_s=t63,
                             max_difference_to_scipy_bar=float(np.max(np.abs(step - scipy_step)))))

    fig_name = draw(out, ours, printed_poles, scipy_step, ss, step, t_step, v)

    rows = [
        Row("eq. 5-6, Fig. 8", "P_out/V_ref at 3 V: static gain, −3 dB bandwidth",
            "1.01 bar/V; 3.14 Hz (eq. 6), 3.12 Hz (Fig. 8)",
            f"{eq57['voltage_gain_bar_per_V']:.4f} bar/V; {eq57['bandwidth_Hz']:.4f} Hz", figure=fig_name),
        Row("eq. 7, Fig. 10", "P_out/Q_in: static gain, −3 dB bandwidth", "−0.922; 3.69 Hz",
            f"{eq57['flow_gain_bar_per_l_min']:.4f} bar per l/min; {eq57['flow_bandwidth_Hz']:.4f} Hz; other readings: "
            f"{'; '.join(f'{k} {val:.3g} Hz' for k, val in readings.items())}; 3.69 Hz needs both time constants × "
            f"{needed['both_time_constants_scaled_by']:.3f}, or τ2 = {needed['second_time_constant_s'] * 1e3:.1f} ms "
            "with τ1 = 41 ms", figure=fig_name),
        Row("eq. 8", "feedback form with pamjax's default K1, K2 (unnamed in the paper)", "no numbers",
            f"poles {', '.join(f'{complex(*p):.3g}' for p in eq8['poles_per_s'])} 1/s; bandwidth "
            f"{eq8['bandwidth_Hz']:.3f} Hz; gains {eq8['voltage_gain_bar_per_V']:.3f} bar/V, "
            f"{eq8['flow_gain_bar_per_l_min']:.3f} bar per l/min", figure=fig_name),
        Row("text: 94.64 %", "G_Vref identified from a 1.5 Hz square wave (60/40, Butterworth 20 Hz, 0.05 bar noise)",
            "best adjustment 94.64 %",
            f"validation fit {v['validation_fit_percent']:.2f} %, gain {v['gain_bar_per_V']:.4f} bar/V, τ "
            f"{v['tau1_s'] * 1e3:.1f} / {v['tau2_s'] * 1e3:.1f} ms", figure=fig_name),
        Row("Fig. 7", "MSE that a 94.64 % fit implies on a 0-3 V, 1.5 Hz square-wave record [bar²]",
            "0.2270 / 0.3183 / 0.304 (0.7 / 1 / 1.5 Hz)", f"{implied_mse:.4f}"),
        Row("Fig. 9", "step response of P_out/Q_in (1 l/min ANR)", "static gain −0.922; MSE 0.078 vs data",
            f"final {step[-1]:.4f} bar, 63 % at {t63 * 1e3:.0f} ms; SciPy on eq. 7 as printed within "
            f"{numbers['fig9']['max_difference_to_scipy_bar']:.1e} bar", figure=fig_name),
    ]
    return Result(rows, numbers, paper=PAPER_NUMBERS)


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
