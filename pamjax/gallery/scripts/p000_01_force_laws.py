"""Paper 000, eq. 1-7 and 14 (Figs. 2, 10): the geometric McKibben laws against the MAS-10-300 datasheet and the
preset's eq. 7 / eq. 14.

The braid of eq. 1-3 is fixed two ways from the datasheet (10 mm inner diameter at 300 mm, 630 N at 6 bar, 25 %
maximum contraction): (A) diameter and stroke (eq. 5's force vanishes at 25 %), (B) diameter and force. Eq. 4 (virtual
work) is checked by autodiff of `BraidVolume` against `ChouHannafordForce`; eq. 6 (Tondu-Lopez) takes braid (B) with
its correction k set so that the force vanishes at 25 %. Volumes: eq. 3 for both braids, eq. 14 (the preset's
v0 + v1 x) and the volume virtual work assigns to the preset's eq. 7 (`fits/derive_presets.py`). Eq. 1-3 and eq. 6
are checked against NumPy transcriptions of the printed equations, and the preset's eq. 7 gives the stroke at which
its 6-bar force vanishes (the datasheet's 25 %, paper 000's "typically 20 % to 25 %").
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures.force_map import virtual_work_volume

PAPER = "000"
TITLE = "McKibben geometry and force laws (eq. 1-7), muscle volume (eq. 14, Fig. 10)"
COVERS = ("eq. 1", "eq. 2", "eq. 3", "eq. 4", "eq. 5", "eq. 6", "eq. 14", "Fig. 2", "Fig. 10",
          "text: maximum contraction without load 20-25 %")

L0, D, F_RATED, STROKE = 0.3, 0.01, 630.0, 0.25  # m, m, N at 6 bar gauge, - (Festo MAS-10-300 datasheet)
P_MAX = 6e5  # Pa gauge (paper 000)
AIR = pj.Air()


def braid_for_force(nominal_length, diameter, force, gauge_pressure):
    """(b_s, n_s) of the braid with inner `diameter` at `nominal_length` whose eq. 5 force at x = 0 is `force`:
    F = π D0²/4 p (3 cos²θ0 − 1) with D0 = D/sin θ0 gives (3 cos²θ0 − 1)/sin²θ0 = 4F/(π D² p) =: q, so
    sin²θ0 = 2/(q + 3)."""
    q = 4 * force / (np.pi * diameter**2 * gauge_pressure)
    sin_theta = np.sqrt(2.0 / (q + 3.0))
    b = nominal_length / np.sqrt(1 - sin_theta**2)
    return b, b * sin_theta / (np.pi * diameter)


# The curves over x, jitted: one program per law (the braids, shared by (A) and (B)), where the eager vmaps compiled
# every operation of every law as a program of its own.
@eqx.filter_jit
def volume_slopes(volume_law, x):
    """dV/dx [m²] of `volume_law` at each x (eq. 4's virtual work per unit gauge pressure)."""
    return jax.vmap(jax.grad(volume_law.volume))(x)


@eqx.filter_jit
def gauge_forces(force_law, x):
    """Force [N] of a geometric law (eq. 5, eq. 6) at gauge pressure P_MAX at each x."""
    return jax.vmap(lambda q: force_law.static_force(q, P_MAX))(x)


@eqx.filter_jit
def muscle_forces(muscle, x, p, air):
    """The muscle's static force [N] at absolute pressure p at each x (eq. 7)."""
    return jax.vmap(lambda q: muscle.static_force(q, p, air))(x)


@eqx.filter_jit
def volumes(volume_law, x):
    """Volume [m³] of `volume_law` (a braid or a muscle) at each x."""
    return jax.vmap(volume_law.volume)(x)


def transcriptions(x, braids, vol, eq6):
    """Max relative differences between pamjax's laws and NumPy transcriptions of the printed eq. 1-3 (volume over
    the stroke, both braids; D0 from eq. 2 at x = 0 for braid A) and eq. 6 (braid B with its correction k)."""
    out = {}
    worst = 0.0
    for key, braid in zip(("A", "B"), braids):
        b, n = float(braid.strand_length), float(braid.turns)
        theta = np.arccos((L0 - x) / b)  # eq. 1: L = b_s cos θ
        v3 = b**3 / (4 * np.pi * n**2) * np.cos(theta) * np.sin(theta) ** 2  # eq. 3
        worst = max(worst, float(np.max(np.abs(vol[key] - v3)) / np.max(np.abs(v3))))
        if key == "A":
            out["eq2_diameter_at_0_mm"] = 1e3 * b * np.sin(theta[0]) / (n * np.pi)  # eq. 2
    out["eq3_vs_transcription_max_relative"] = worst
    theta0, k, forces6 = eq6
    a, b_ = 3 / np.tan(theta0) ** 2, 1 / np.sin(theta0) ** 2
    f6 = np.pi * (D / 2) ** 2 * P_MAX * (a * (1 - k * x / L0) ** 2 - b_)  # eq. 6 with Tondu's k
    out["eq6_vs_transcription_max_relative"] = float(np.max(np.abs(forces6 - f6)) / np.max(np.abs(f6)))
    return out


def zero_force_contraction(coefficients):
    """The smallest positive x [m] where F_max(x) = a0 + … + a4 x⁴ (eq. 7 at p_max) vanishes."""
    roots = np.roots(np.asarray(coefficients, dtype=float)[::-1])
    real = roots[(np.abs(roots.imag) < 1e-9) & (roots.real > 0)].real
    return float(real.min())


def draw(out, dv, eps, forces5, forces6, forces7, k, stroke_b, virtual, vol, vol14, x):
    """The figure (written into `out`); returns its file name."""
    pyplot = plt()
    fig, (ax0, ax1) = pyplot.subplots(1, 2, figsize=(11, 4.2))
    ax0.plot(x * 1e3, forces7, "k-", lw=2, label="eq. 7, preset (DMSP-20 map shape, 630 N)")
    ax0.plot(x * 1e3, forces5["A"], "C0-", label=f"eq. 5, braid A (10 mm, 25 % stroke): {forces5['A'][0]:.0f} N")
    ax0.plot(x * 1e3, forces5["B"], "C1-", label=f"eq. 5, braid B (10 mm, 630 N): stroke {100 * stroke_b:.0f} %")
    ax0.plot(x * 1e3, virtual["B"], "C1:", lw=3, label="eq. 4: p dV/dx of eq. 3 (braid B)")
    ax0.plot(x * 1e3, forces6, "C2--", label=f"eq. 6, braid B, k = {k:.2f}")
    ax0.axhline(0, color="0.6", lw=0.6)
    ax0.set(xlabel="contraction x [mm]", ylabel="force at 6 bar gauge [N]", title="MAS-10-300: eq. 4-7")
    ax0.legend(fontsize=7)
    ax1.plot(x * 1e3, vol14 * 1e6, "k-", lw=2, label="eq. 14, preset v0 + v1 x")
    ax1.plot(eps * L0 * 1e3, (presets.MAS10_V0 + dv) * 1e6, "k:", label="virtual work of eq. 7 (preset's v1)")
    ax1.plot(x * 1e3, vol["A"] * 1e6, "C0-", label="eq. 3, braid A")
    ax1.plot(x * 1e3, vol["B"] * 1e6, "C1-", label="eq. 3, braid B")
    ax1.set(xlabel="contraction x [mm]", ylabel="volume [cm³]", title="Fig. 10: volume against displacement")
    ax1.legend(fontsize=7)
    return save(fig, out, "force_laws.png")


def run(out, quick=False):
    del quick  # no simulation: the same in both modes
    x = np.linspace(0.0, STROKE * L0, 61)
    p = AIR.atmospheric_pressure + P_MAX
    braid_a = pj.BraidVolume.from_datasheet(L0, D, STROKE)
    b_b, n_b = braid_for_force(L0, D, F_RATED, P_MAX)
    braid_b = pj.BraidVolume(b_b, n_b, L0)
    eq5 = {k: pj.ChouHannafordForce(v.strand_length, v.turns, L0) for k, v in (("A", braid_a), ("B", braid_b))}

    # eq. 4: F = p_g dV/dx (x = L0 − L), by autodiff of eq. 3, against eq. 5
    virtual = {k: np.asarray(volume_slopes(v, jnp.asarray(x))) * P_MAX for k, v in (("A", braid_a), ("B", braid_b))}
    forces5 = {k: np.asarray(gauge_forces(f, jnp.asarray(x))) for k, f in eq5.items()}
    eq4_error = max(np.max(np.abs(virtual[k] - forces5[k])) / np.max(np.abs(forces5[k])) for k in eq5)
    stroke_b = 1 - float(braid_b.strand_length) / np.sqrt(3) / L0  # where cos²θ = 1/3

    # eq. 6 on braid (B): a(1 − kε)² = b at ε = 0.25 sets k
    theta0 = float(np.arccos(L0 / float(braid_b.strand_length)))
    a, b = 3 / np.tan(theta0) ** 2, 1 / np.sin(theta0) ** 2
    k = (1 - np.sqrt(b / a)) / STROKE
    eq6 = pj.TonduLopezForce(D / 2, theta0, L0, k)
    forces6 = np.asarray(gauge_forces(eq6, jnp.asarray(x)))
    muscle = presets.mas10_muscle()
    forces7 = np.asarray(muscle_forces(muscle, jnp.asarray(x), p, AIR))

    # volumes: eq. 3 (A, B), eq. 14 preset, virtual work of the preset's eq. 7
    vol = {k: np.asarray(volumes(v, jnp.asarray(x))) for k, v in (("A", braid_a), ("B", braid_b))}
    vol14 = np.asarray(volumes(muscle, jnp.asarray(x)))
    eps, dv = virtual_work_volume(np.asarray(presets.MAS10_MAX_FORCE_COEFFICIENTS) * L0 ** np.arange(5), L0)
    linearity = {}
    for key, xs, v in (("A", x, vol["A"]), ("B", x, vol["B"]), ("virtual_work", eps * L0, dv)):
        fit = np.polyval(np.polyfit(xs, v, 1), xs)
        linearity[key] = dict(max_deviation_from_line_percent=float(100 * np.max(np.abs(v - fit)) / np.ptp(v)),
                              mean_slope_m2=float((v[-1] - v[0]) / (xs[-1] - xs[0])))

    transcribed = transcriptions(x, (braid_a, braid_b), vol, (theta0, k, forces6))

    numbers = dict(
        **transcribed,
        eq5=dict(force_error_braid_A=float(1 - forces5["A"][0] / F_RATED),
                 stroke_error_braid_B=float(stroke_b / STROKE - 1)),
        eq7_zero_force_contraction=zero_force_contraction(presets.MAS10_MAX_FORCE_COEFFICIENTS) / L0,
        braid_A=dict(strand_length_m=float(braid_a.strand_length), turns=float(braid_a.turns),
                     braid_angle_deg=float(np.degrees(np.arccos(L0 / float(braid_a.strand_length)))),
                     force_at_0_N=float(forces5["A"][0]), volume_at_0_m3=float(vol["A"][0])),
        braid_B=dict(strand_length_m=float(b_b), turns=float(n_b), braid_angle_deg=float(np.degrees(theta0)),
                     force_at_0_N=float(forces5["B"][0]), zero_force_contraction=float(stroke_b)),
        eq4_max_relative_difference=float(eq4_error),
        eq6_correction_k=float(k), eq6_force_at_0_N=float(forces6[0]),
        eq6_vs_eq7_max_difference_N=float(np.max(np.abs(forces6 - forces7))),
        eq7_force_at_0_N=float(forces7[0]), cylinder_volume_m3=float(np.pi / 4 * D**2 * L0),
        eq14=dict(v0_m3=presets.MAS10_V0, v1_m2=presets.MAS10_V1), eq3_linearity=linearity,
        virtual_work_volume_gain_m3=float(dv[-1]),
    )

    fig_name = draw(out, dv, eps, forces5, forces6, forces7, k, stroke_b, virtual, vol, vol14, x)

    rows = [
        Row("eq. 1-3, Fig. 2", "braid of the MAS-10-300 from its datasheet (10 mm, 300 mm, 25 % stroke)",
            "geometry only, no numbers",
            f"b_s {numbers['braid_A']['strand_length_m']:.3f} m, n_s {numbers['braid_A']['turns']:.2f}, "
            f"θ0 {numbers['braid_A']['braid_angle_deg']:.1f}°, V(0) = π D² L0/4 exactly",
            figure=fig_name),
        Row("eq. 4", "virtual work: F = −p dV/dL of eq. 3 equals eq. 5", "eq. 5 derived from eq. 3-4",
            f"max relative difference {eq4_error:.1e} (autodiff of BraidVolume vs ChouHannafordForce)",
            figure=fig_name),
        Row("eq. 5", "Chou-Hannaford force at x = 0, 6 bar", "Festo muscles: ideal models too inaccurate (text)",
            f"braid A {forces5['A'][0]:.0f} N vs datasheet 630 N; braid B (630 N) would contract "
            f"{100 * stroke_b:.0f} % (datasheet 25 %)",
            figure=fig_name),
        Row("eq. 6", "Tondu-Lopez with its correction k (braid B, zero force at 25 %)", "no numbers",
            f"k = {k:.2f}; differs from the preset's eq. 7 by up to {numbers['eq6_vs_eq7_max_difference_N']:.0f} N "
            "over the stroke at 6 bar",
            figure=fig_name),
        Row("eq. 14, Fig. 10", "muscle volume against displacement", "\"nearly linear\"",
            f"eq. 3 braid B deviates {linearity['B']['max_deviation_from_line_percent']:.1f} % of its range from "
            f"a line (braid A {linearity['A']['max_deviation_from_line_percent']:.1f} %); preset v1 "
            f"{presets.MAS10_V1:.3g} m² vs braid B mean slope {linearity['B']['mean_slope_m2']:.3g} m²",
            figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(rated_force_N=F_RATED, stroke=STROKE, diameter_m=D, length_m=L0))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
