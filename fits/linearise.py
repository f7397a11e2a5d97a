"""Paper 001 Sect. 5 (eq. 5-8, Figs. 8 and 10): the VPPM regulator linearised about its 3 V operating point.

`pj.linearise` takes autodiff Jacobians of the system's own vector field at the equilibrium `pj.equilibrium` finds
for a 3 V reference (paper: 3 V, 7 bar abs supply), with the reference voltage and eq. 5's outlet flow Q_in as
inputs, and gives the state space, the transfer functions, the static gains and the −3 dB bandwidth:

- eq. 5-7, `LinearRegulator` at a closed port: paper 3.14 Hz (3.12 Hz read off Fig. 8), 1.01 bar/V, −0.922 bar per
  l/min ANR;
- eq. 8, `FeedbackRegulator` with its default K1, K2 (same static gains; its own poles);
- the physical `ISO6358Regulator` feeding the DMSP-40 with 893 N (any pamjax system linearises): the paper saw
  slower dynamics with the muscle attached. Above ~5.93 V its set pressure exceeds the 7 bar abs supply: the
  outlet sits at the supply, the voltage no longer moves it, and that model is reported as saturated (no bandwidth).

The eq. 5-7 result is cross-checked against python-control when it is installed. Writes `linearise.json` and the
Bode diagram `linearise.png` to `--out`; refuses to overwrite existing results unless `--overwrite`.

    python fits/linearise.py [--out results/linearise] [--voltage 3.0] [--overwrite]
"""

import argparse
import pathlib
import sys
import time

import equinox as eqx
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import json_text, refuse_existing  # noqa: E402
from pamjax.gallery.procedures.linearised import describe, flow_input  # noqa: E402
from pamjax.units import BAR  # noqa: E402

PAPER = dict(
    operating_point_V=3.0,  # paper 001 Sect. 5: 3 V reference, 7 bar abs supply
    bandwidth_Hz=3.14,  # eq. 6 (3.12 Hz read off the Fig. 8 Bode plot)
    bandwidth_fig8_Hz=3.12,
    voltage_gain_bar_per_V=1.01,  # eq. 6
    flow_gain_bar_per_l_min=-0.922,  # eq. 7 (l/min ANR assumed, docs/regulator.md)
    flow_bandwidth_fig10_Hz=3.69,  # Fig. 10, P_out/Q_in with the muscle attached
)
FREQUENCIES = np.logspace(-1, 2, 121)  # Hz, Bode grid (Figs. 8, 10 span about 0.1-100 Hz)


def polynomial(coefficients):
    """'a s^2 + b s + c' from coefficients highest power first."""
    n = len(coefficients) - 1
    power = {0: "", 1: " s"}
    terms = [f"{c:.6g}" + power.get(n - k, f" s^{n - k}") for k, c in enumerate(coefficients)]
    return " + ".join(terms).replace("+ -", "- ")



def control_cross_check(ss):
    """Static gain, bandwidth and frequency response of the command channel from python-control, or None."""
    here = pathlib.Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if pathlib.Path(p or ".").resolve() != here]  # fits/control.py shadows it
    try:
        import control
    except ImportError:
        return None
    full = ss.to_control()
    siso = control.ss(full.A, full.B[:, :1], full.C, full.D[:, :1])
    resp = control.frequency_response(siso, 2 * np.pi * FREQUENCIES)
    ours = ss.frequency_response(FREQUENCIES, "pressure", "command")
    theirs = np.ravel(resp.magnitude) * np.exp(1j * np.ravel(resp.phase))
    return dict(
        version=control.__version__,
        voltage_gain_bar_per_V=float(np.real(control.dcgain(siso))) / BAR,
        bandwidth_Hz=float(control.bandwidth(siso)) / (2 * np.pi),
        frequency_response_max_relative_difference=float(np.max(np.abs(theirs - ours) / np.abs(ours))),
    )


def muscle_guess(muscle, u):
    """The equilibrium guess of the regulator feeding the muscle at `u` [V]: its pilot pair at the set pressure,
    the outlet (and the muscle) at the set pressure or, above ~5.93 V (a set pressure over the 7 bar abs supply),
    at the supply, where the outlet saturates. A guess with the outlet at a set pressure above the supply (or the
    pilot pair clipped to the supply with it) made Newton's method fail (`PamjaxSolveError`)."""
    p_set = muscle.air.atmospheric_pressure + muscle.regulator.calibration(u)
    outlet = jax.numpy.minimum(p_set, muscle.regulator.supply_pressure)
    guess = muscle.initial_state(pressure=outlet)  # load equilibrium at that pressure
    return eqx.tree_at(lambda s: (s.regulator.pilot, s.regulator.pilot_output), guess, (p_set, p_set))


def describe_saturated(ss, set_pressure, supply):
    """`describe` of the muscle model where the set pressure is at or above the supply: the outlet sits at the
    supply, the voltage no longer moves it (static gain ~0), so the voltage channel has no bandwidth."""
    return dict(
        saturated=True,
        set_pressure_Pa=set_pressure,
        supply_pressure_Pa=supply,
        state_names=list(ss.state_names),
        A=ss.A.tolist(),
        B=ss.B.tolist(),
        poles_per_s=[[float(p.real), float(p.imag)] for p in ss.poles()],
        voltage_gain_bar_per_V=ss.dc_gain("pressure", "command") / BAR,
        bandwidth_Hz=None,
    )


def linearise_all(u):
    """eq. 5-7, eq. 8 and the ISO 6358 regulator + DMSP-40 linearised at `u` [V]; the last one's report."""
    inputs = {"outlet_flow": flow_input}
    linear = pj.RegulatorSystem(pj.LinearRegulator(), volume=0.0)  # closed port (eq. 6 identification set-up)
    ss = pj.linearise(linear, pj.equilibrium(linear, u, linear.initial_state()), u, inputs=inputs)
    feedback = pj.RegulatorSystem(pj.FeedbackRegulator(), volume=0.0)
    ss8 = pj.linearise(feedback, pj.equilibrium(feedback, u, feedback.initial_state()), u, inputs=inputs)
    muscle = pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), pj.presets.dmsp40_muscle())
    guess = jax.jit(lambda v: muscle_guess(muscle, v))(u)
    ss_m = pj.linearise(muscle, pj.equilibrium(muscle, u, guess), u, outputs=("pressure", "position"))
    set_pressure = float(muscle.air.atmospheric_pressure + muscle.regulator.calibration(u))
    supply = float(muscle.regulator.supply_pressure)
    report = (describe_saturated(ss_m, set_pressure, supply) if set_pressure >= supply
              else describe(ss_m, flow=False))
    return ss, ss8, ss_m, report


def plot(models, path, volts):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (mag, ph) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    s = 2j * np.pi * FREQUENCIES
    eq6 = 1.0 / ((1 + 0.041 * s) * (1 + 0.023 * s))  # eq. 6 normalised, printed by the paper
    mag.semilogx(FREQUENCIES, 20 * np.log10(np.abs(eq6)), color="0.75", lw=4, label="eq. 6 as printed")
    ph.semilogx(FREQUENCIES, np.degrees(np.angle(eq6)), color="0.75", lw=4)
    styles = {"eq5_7": ("C0", "-"), "eq8": ("C2", "--"), "iso6358_muscle": ("C3", "-.")}
    for name, (ss, label) in models.items():
        m, p = ss.bode(FREQUENCIES, "pressure", "command")
        g0 = 20 * np.log10(abs(ss.dc_gain("pressure", "command")))
        colour, style = styles[name]
        bandwidth = ss.bandwidth("pressure", "command")
        mag.semilogx(FREQUENCIES, m - g0, style, color=colour, label=f"{label}: {bandwidth:.2f} Hz")
        ph.semilogx(FREQUENCIES, p, style, color=colour)
    mag.axhline(-3.0, color="k", lw=0.6)
    title = f"Regulator linearised at {volts:g} V (paper 001: 3 V)"
    mag.set(ylabel="|P_out/V_ref| / static gain [dB]", ylim=(-50, 5), title=title)
    mag.legend(fontsize=8, loc="lower left")
    ph.set(xlabel="f [Hz]", ylabel="phase [deg]")
    fig.tight_layout()
    fig.savefig(path, dpi=120, metadata={"Title": title})  # the title also as the PNG's text, for a reader
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/linearise")
    ap.add_argument("--voltage", type=float, default=PAPER["operating_point_V"], help="operating point [V], 0-10")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    path = out / "linearise.json"
    u = args.voltage
    lo, hi = pj.presets.VPPM_VOLTAGE_RANGE
    if not lo <= u <= hi:  # also refuses nan
        ap.error(f"--voltage must be within the VPPM's {lo:g}-{hi:g} V, got {u}")
    refuse_existing("linearise.py", [path, out / "linearise.png"], args.overwrite)
    start = time.perf_counter()
    try:
        ss, ss8, ss_m, muscle_report = linearise_all(u)
    except pj.PamjaxSolveError as err:
        raise SystemExit(f"linearise.py: no operating point at --voltage {u:g}: {err}") from None
    saturated = muscle_report.get("saturated", False)
    bode_models = [("eq5_7", ss), ("eq8", ss8)] + ([] if saturated else [("iso6358_muscle", ss_m)])

    report = dict(
        paper=PAPER,
        operating_point_V=u,
        eq5_7=describe(ss),
        eq8=describe(ss8),
        iso6358_muscle=muscle_report,
        python_control=control_cross_check(ss),
        bode=dict(
            frequency_Hz=FREQUENCIES.tolist(),
            **{
                f"{name}_{k}": v.tolist()
                for name, model in bode_models
                for k, v in zip(("magnitude_dB", "phase_deg"), model.bode(FREQUENCIES, "pressure", "command"))
            },
        ),
    )
    e = report["eq5_7"]
    np.set_printoptions(precision=5, linewidth=110)
    print(f"eq. 5-7 (LinearRegulator, closed port) at {u} V: states {ss.state_names}, inputs {ss.input_names}")
    print(f"A [1/s] =\n{ss.A}\nB =\n{ss.B}\nC = {ss.C}, D = {ss.D}")
    for channel, unit in (("command", "Pa/V"), ("outlet_flow", "Pa/(kg/s)")):
        num, den = ss.transfer_function("pressure", channel)
        print(f"P_out/{channel} [{unit}] = ({polynomial(num)}) / ({polynomial(den)})")
    print(
        f"bandwidth {e['bandwidth_Hz']:.4f} Hz (paper 3.14, Fig. 8 3.12); static gains "
        f"{e['voltage_gain_bar_per_V']:.4f} bar/V (1.01), {e['flow_gain_bar_per_l_min']:.4f} bar per l/min (-0.922);"
        f" P_out/Q_in bandwidth {e['flow_bandwidth_Hz']:.4f} Hz (Fig. 10: 3.69)"
    )
    for name, label in (("eq8", "eq. 8 (FeedbackRegulator)"), ("iso6358_muscle", "ISO6358Regulator + DMSP-40")):
        r = report[name]
        poles = ", ".join(f"{complex(*p):.3g}" for p in r["poles_per_s"])
        if r.get("saturated"):
            print(f"{label}: saturated: the set pressure {r['set_pressure_Pa'] / BAR:.3f} bar abs is at or above the "
                  f"{r['supply_pressure_Pa'] / BAR:g} bar abs supply, the outlet sits at the supply and the voltage "
                  f"does not move it ({r['voltage_gain_bar_per_V']:.3g} bar/V, no bandwidth; not in the figure); "
                  f"poles {poles}")
            continue
        print(f"{label}: bandwidth {r['bandwidth_Hz']:.3f} Hz, {r['voltage_gain_bar_per_V']:.4f} bar/V, poles {poles}")
    c = report["python_control"]
    if c is None:
        print("python-control not installed: no cross-check (pip install 'pamjax[control]')")
    else:
        print(
            f"python-control {c['version']}: bandwidth {c['bandwidth_Hz']:.4f} Hz, {c['voltage_gain_bar_per_V']:.4f} "
            f"bar/V, frequency response within {c['frequency_response_max_relative_difference']:.1e}"
        )
    report["wall_time_s"] = time.perf_counter() - start
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json_text(report, indent=1))
    try:
        labels = {"eq5_7": "eq. 5-7, closed port", "eq8": "eq. 8, default K1, K2",
                  "iso6358_muscle": "ISO 6358 regulator + DMSP-40, 893 N"}
        plot({name: (model, labels[name]) for name, model in bode_models}, out / "linearise.png", u)
    except ImportError:
        print("matplotlib not installed: no figure")
    print(f"wrote {path} ({report['wall_time_s']:.1f} s)")


if __name__ == "__main__":
    main()
