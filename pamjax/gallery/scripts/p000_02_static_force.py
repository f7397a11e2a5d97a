"""Paper 000, eq. 7-8 and Figs. 3-5: the static force map with its hysteresis loop.

Eq. 7 is fitted to the real measured force map of a Festo DMSP-20-300 (Martens & Boblan 2017, `pamjax/data/`, the
procedure of `fits/static_force.py`); its error is split at 0.2 MPa, where paper 000 sees the fit deteriorate. That map
was measured isometrically, without the direction of motion, so the loop of Figs. 3 and 5 is made from it: every
measured point becomes a contracting and a stretching point 2 F_c + 2 C_f |ẋ| apart (F_c = 16 N, the preset's
C_f = 250 N s/m at |ẋ| = 5 mm/s), with 2 N load-cell noise (assumed). `LoopForceMapExperiment` then fits eq. 8 (eq. 7
and F_c together) and `loop_average` gives Fig. 4's averaged curves and the loop width (paper: 32 N). Eq. 7 as fitted
is checked against a NumPy transcription of the printed equation.

Every RMSE and maximum error here is over the loaded points (F > 0): a slack point (0 N, 66 of the map's 126) is an
inequality, "the model must not push", not a measurement of 0 N (`pj.fit`'s `channel_errors` leaves them out), so
Fig. 5's RMSE of eq. 8 and its reference √(eq. 7 RMSE² + noise²) count the same kind of points as the noise.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import presets
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures.force_map import eq7_start, load_map

PAPER = "000"
TITLE = "Static force map with hysteresis (eq. 7-8, Figs. 3-5)"
COVERS = ("eq. 7", "eq. 8", "Fig. 3", "Fig. 4", "Fig. 5")

COULOMB = 16.0  # N, paper 000: half the 32 N loop width
LOOP_SPEED = 5e-3  # m/s, quasi-static cycling (assumed; the paper gives no speed)
LOAD_CELL_NOISE = 2.0  # N (assumed)
P_ATM = 101325.0


@eqx.filter_jit
def static_forces(muscle, x, p, air):
    """The muscle's static force [N] at each (x, p): one jitted program per number of points (the eager vmap compiled
    each operation of the force law as a program of its own)."""
    return jax.vmap(lambda a, b: muscle.static_force(a, b, air))(x, p)


def loop_data(x, p, f, rng):
    """Both branches of a loop through the isometric map points (x, p, F): contracting (ẋ > 0) F − F_c − C_f ẋ,
    stretching F + F_c + C_f |ẋ|, plus noise; slack points (0 N) stay 0 N in both directions."""
    drag = COULOMB + presets.VISCOUS_COEFFICIENT * LOOP_SPEED
    xs, ps, vs, fs = [], [], [], []
    for sign in (1.0, -1.0):
        loaded = f > 0
        xs.append(x)
        ps.append(p)
        vs.append(np.full(x.shape, sign * LOOP_SPEED))
        fs.append(np.where(loaded, np.maximum(f - sign * drag + LOAD_CELL_NOISE * rng.standard_normal(f.shape), 0), 0))
    return (np.concatenate(a) for a in (xs, ps, vs, fs))


def draw(out, e7, fa, fc, fl, loop, p, pa, pl, res7, res8, vl, x, xa, xl):
    """The figure (written into `out`); returns its file name."""
    pyplot = plt()
    fig, axes = pyplot.subplots(1, 3, figsize=(15, 4.3))
    air = pj.Air()
    for k, pi in enumerate(np.unique(p)[2::4]):
        c = f"C{k}"
        for sign, mark in ((1.0, "v"), (-1.0, "^")):
            sel = (pl == pi) & (vl * sign > 0)
            axes[0].plot(xl[sel] * 1e3, fl[sel], mark + "-", color=c, ms=3, lw=0.7,
                         label=f"{(pi - P_ATM) / 1e5:.2f} bar" if sign > 0 else None)
        sel = pa == pi
        axes[1].plot(xa[sel] * 1e3, fa[sel], "o", color=c, ms=4, label=f"{(pi - P_ATM) / 1e5:.2f} bar")
        xx = np.linspace(0, x.max(), 50)
        model_xx = static_forces(res7.model, jnp.asarray(xx), jnp.asarray(np.full(xx.shape, pi)), air)
        axes[1].plot(xx * 1e3, np.maximum(model_xx, 0.0), "-", color=c)  # slack: no push
        pred = np.asarray(loop.predict(res8.model)["force"])
        for sign in (1.0, -1.0):
            sel = (pl == pi) & (vl * sign > 0)
            axes[2].plot(xl[sel] * 1e3, fl[sel], "o", color=c, ms=3)
            axes[2].plot(xl[sel] * 1e3, np.maximum(pred[sel], 0), "-", color=c, lw=1)
    axes[0].set(title="Fig. 3: loops (▼ contracting, ▲ stretching)", xlabel="contraction x [mm]", ylabel="force [N]")
    axes[1].set(title=f"Fig. 4: loop averages and eq. 7 (RMSE {e7['rmse']:.1f} N, loaded points)",
                xlabel="contraction x [mm]")
    axes[2].set(title=f"Fig. 5: eq. 8 (F_c = {fc:.1f} N) vs loop", xlabel="contraction x [mm]")
    for ax in axes[:2]:
        ax.legend(fontsize=7)
    return save(fig, out, "static_force.png")


def run(out, quick=False):
    del quick  # static fits: fast in both modes
    x, p, f = load_map()
    muscle, free = eq7_start()

    # eq. 7 on the real isometric map
    res7 = pj.fit(muscle, [pj.bench.ForceMapExperiment(x, p, f, scale=1.0)], free, progress=False)
    model_f = np.asarray(static_forces(res7.model, jnp.asarray(x), jnp.asarray(p), pj.Air()))
    err = np.where(f > 0, model_f - f, np.maximum(model_f, 0))
    low = (p - P_ATM < 2e5) & (f > 0)
    e7 = res7.channel_errors["force_map"]["force"]  # over the loaded points (slack ones: an inequality)
    high = ~low & (f > 0)
    band = dict(rmse_below_0_2MPa_N=float(np.sqrt(np.mean(err[low] ** 2))),
                rmse_from_0_2MPa_N=float(np.sqrt(np.mean(err[high] ** 2))),
                relative_rmse_below_0_2MPa_percent=float(100 * np.sqrt(np.mean((err[low] / f[low]) ** 2))),
                relative_rmse_from_0_2MPa_percent=float(100 * np.sqrt(np.mean((err[high] / f[high]) ** 2))))

    # eq. 8 on the loop made from it
    xl, pl, vl, fl = loop_data(x, p, f, np.random.default_rng(0))
    system = pj.MuscleSystem(valve=presets.mas10_valve(), muscle=muscle,
                             friction=pj.CoulombViscousFriction(10.0, presets.VISCOUS_COEFFICIENT))
    loop = pj.bench.LoopForceMapExperiment(xl, pl, vl, fl, scale=LOAD_CELL_NOISE)
    res8 = pj.fit(system, [loop], [f"muscle.{k}" for k in free] + ["friction.coulomb_force"], progress=False)
    i = res8.labels.index("friction.coulomb_force")
    fc, fc_se = float(res8.values[i]), float(res8.standard_errors[i])
    xa, pa, fa, width = pj.bench.loop_average(xl, pl, vl, fl)
    loaded = fa > 0
    e8 = res8.channel_errors["loop_force_map"]["force"]  # loaded points, as e7's and the noise

    law = res7.model.force_law  # eq. 7 as printed, NumPy: F_max(x) − (p_max − p_g)(k0 − k1 x)/k2
    a = np.asarray(law.max_force_coefficients)
    f_printed = np.polyval(a[::-1], x) - (float(law.max_pressure) - (p - P_ATM)) * (
        float(law.k0) - float(law.k1) * x) / float(law.k2)
    drag = COULOMB + presets.VISCOUS_COEFFICIENT * LOOP_SPEED
    numbers = dict(eq7_vs_transcription_max_relative=float(np.max(np.abs(model_f - f_printed)) / np.ptp(f_printed)),
                   loop_width_built_N=2 * drag,
                   eq8_rmse_over_eq7_and_noise=e8["rmse"] / float(np.hypot(e7["rmse"], LOAD_CELL_NOISE)),
                   relative_rmse_low_over_high=band["relative_rmse_below_0_2MPa_percent"]
                   / band["relative_rmse_from_0_2MPa_percent"],
                   eq7_rmse_N=e7["rmse"], eq7_max_error_N=e7["max_error"],
                   eq7_max_error_percent=e7["max_error_percent"],
                   eq7_rmse_percent=e7["rmse_percent"], **band, eq7_fit=dict(zip(res7.labels, res7.values)),
                   loop_coulomb_N=fc, loop_coulomb_standard_error_N=fc_se,
                   loop_width_mean_N=float(np.mean(width[loaded])), loop_width_std_N=float(np.std(width[loaded])),
                   eq8_rmse_N=e8["rmse"], eq8_max_error_N=e8["max_error"], points=int(x.size))

    fig_name = draw(out, e7, fa, fc, fl, loop, p, pa, pl, res7, res8, vl, x, xa, xl)

    rows = [
        Row("eq. 7, Fig. 4", f"eq. 7 fitted to a real Festo force map (DMSP-20-300, {x.size} isometric points)",
            "predicts well; deteriorates below 0.2 MPa",
            f"RMSE {e7['rmse']:.1f} N over the {int(np.sum(f > 0))} loaded points ({e7['rmse_percent']:.2f} % of "
            f"range), max {e7['max_error_percent']:.2f} %; "
            f"relative RMSE {band['relative_rmse_below_0_2MPa_percent']:.1f} % of the force below 0.2 MPa, "
            f"{band['relative_rmse_from_0_2MPa_percent']:.1f} % above (absolute {band['rmse_below_0_2MPa_N']:.1f} vs "
            f"{band['rmse_from_0_2MPa_N']:.1f} N)",
            figure=fig_name),
        Row("eq. 8, Figs. 3, 5", "loop width and F_c fitted with eq. 8 (`LoopForceMapExperiment`)",
            "loop width 32 N, F_c = 16 N",
            f"F_c {fc:.2f} ± {fc_se:.2f} N; loop width {numbers['loop_width_mean_N']:.1f} ± "
            f"{numbers['loop_width_std_N']:.1f} N (`loop_average`); eq. 8 RMSE {e8['rmse']:.1f} N (loaded points)",
            figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(loop_width_N=32.0, coulomb_N=16.0, authors_max_error_percent=2.35))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
