"""Fit paper 000's eq. 7 (and eq. 6, Tondu-Lopez, as a second model) to the real Festo DMSP-20-300 force map.

Data: Martens & Boblan, Actuators 2017, 6(4), 33, Appendix A1 (CC BY 4.0; `pamjax/data/README.md`). Pressures in the
file are gauge and are converted to absolute here; slack points (0 N) count only where the model pulls ("force ≤ 0").
Writes `fit_eq7.json`, `fit_eq6.json` and `static_force.png` to `--out` (default `results/static_force`).

    python fits/static_force.py [--out DIR] [--overwrite]
"""

import argparse
import importlib.resources
import pathlib

import equinox as eqx
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax import presets  # noqa: E402

DATA = pathlib.Path(str(importlib.resources.files("pamjax") / "data" / "DMSP-20-300_force_map_long.csv"))
L0 = 0.300  # m, nominal length (type code DMSP-20-300)
AUTHORS_MAX_ERROR_PERCENT = 2.35  # Martens & Boblan 2017: their model's maximum error on this muscle


def load_map():
    rows = np.loadtxt(DATA, delimiter=",", comments="#", skiprows=2)
    length, pressure_gauge, force = rows[:, 0], rows[:, 2], rows[:, 3]
    return L0 - length, pressure_gauge + 101325.0, force  # x [m] (contraction), p [Pa abs], F [N]


def start_muscle(force_law):
    """DMSP-20-300 start: the MAS-10 preset's shape (itself derived from this map) scaled to 1460 N at 6 bar."""
    return pj.Muscle(force_law=force_law, volume_law=pj.LinearVolume(1e-4, 1e-3), min_position=0.0, max_position=0.08)


def eq7_start():
    """Eq. 7 start model for the DMSP-20-300 (the MAS-10 preset's shape scaled to its 1460 N at 6 bar) and its free
    parameters (k2 fixed: only k0/k2 and k1/k2 are identifiable)."""
    scale = 1460.1 / presets.MAS10_MAX_FORCE_COEFFICIENTS[0]
    model = start_muscle(pj.PolynomialForce(np.asarray(presets.MAS10_MAX_FORCE_COEFFICIENTS) * scale,
                                            presets.MAS10_K0 * scale, presets.MAS10_K1 * scale, 1e5))
    return model, ["force_law.max_force_coefficients", "force_law.k0", "force_law.k1"]


def report(name, res):
    e = res.channel_errors["force_map"]["force"]
    print(f"{name}: RMSE {e['rmse']:.2f} N ({e['rmse_percent']:.2f} % of range), max error {e['max_error']:.2f} N "
          f"({e['max_error_percent']:.2f} % of range; authors' model: < {AUTHORS_MAX_ERROR_PERCENT} %)")
    print(res.table())


@eqx.filter_jit
def _forces(muscle, x, pressures, air):
    """The model's force [N] at contraction `x` for each pressure: one program per model and sample count (eagerly,
    each operation of the force law compiles on its own; `x` as a closed-over constant, once per length)."""
    return jax.vmap(lambda q: muscle.force(x, q, air))(pressures)


def plot(path, x, p, f, models):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    air = pj.Air()
    pp = np.linspace(p.min(), p.max(), 100)
    for k, xi in enumerate(np.unique(x)):
        sel = x == xi
        color = f"C{k}"
        ax[0].plot((p[sel] - 101325.0) / 1e5, f[sel], "o", color=color, ms=4, label=f"L = {L0 - xi:.3f} m")
        for (label, muscle), style in zip(models.items(), ("-", "--")):
            fm = np.asarray(_forces(muscle, xi, pp, air))
            ax[0].plot((pp - 101325.0) / 1e5, fm, style, color=color, lw=1, label=label if k == 0 else None)
            fs = np.asarray(_forces(muscle, xi, p[sel], air))
            if style == "-":
                ax[1].plot((p[sel] - 101325.0) / 1e5, fs - f[sel], "o-", color=color, ms=3)
    ax[0].set(xlabel="gauge pressure [bar]", ylabel="force [N]", title="DMSP-20-300: measured (dots) vs model")
    ax[1].set(xlabel="gauge pressure [bar]", ylabel="eq. 7 model − measured [N]", title="residuals (slack as 0 N)")
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/static_force")
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args()
    out = pathlib.Path(args.out)

    x, p, f = load_map()
    experiment = pj.ForceMapExperiment(x, p, f, scale=1.0)  # residuals in N

    eq7, free7 = eq7_start()
    res7 = pj.fit(eq7, [experiment], free7, out=out / "fit_eq7.json", overwrite=args.overwrite)
    report("eq. 7 (quartic F_max, linear pressure slope)", res7)

    # Eq. 6 (Tondu-Lopez): start from the DMSP-20's 20 mm inner diameter and a 25° braid angle.
    eq6 = start_muscle(pj.TonduLopezForce(radius=0.01, braid_angle=np.deg2rad(25.0), nominal_length=L0, correction=1.0))
    free6 = ["force_law.radius", {"path": "force_law.braid_angle", "bounds": (0.05, 1.5)}, "force_law.correction"]
    res6 = pj.fit(eq6, [experiment], free6, out=out / "fit_eq6.json", overwrite=args.overwrite)
    report("eq. 6 (Tondu-Lopez)", res6)

    plot(out / "static_force.png", x, p, f, {"eq. 7": res7.model, "eq. 6": res6.model})
    print(f"wrote {out}/fit_eq7.json, fit_eq6.json, static_force.png")


if __name__ == "__main__":
    main()
