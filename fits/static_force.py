"""Fit paper 000's eq. 7 (and eq. 6, Tondu-Lopez, as a second model) to the real Festo DMSP-20-300 force map.

Data: Martens & Boblan, Actuators 2017, 6(4), 33, Appendix A1 (CC BY 4.0; `pamjax/data/README.md`). Pressures in the
file are gauge and are converted to absolute here; slack points (0 N) count only where the model pulls ("force ≤ 0").
Writes `fit_eq7.json`, `fit_eq6.json` and `static_force.png` to `--out` (default `results/static_force`).

    python fits/static_force.py [--out DIR] [--overwrite]
"""

import argparse
import pathlib

import equinox as eqx
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import refuse_existing  # noqa: E402
from pamjax.gallery.procedures.force_map import (  # noqa: E402
    AUTHORS_MAX_ERROR_PERCENT,
    L0,
    eq7_start,
    load_map,
    start_muscle,
)


def report(name, res):
    e = res.channel_errors["force_map"]["force"]
    print(f"{name}: RMSE {e['rmse']:.2f} N ({e['rmse_percent']:.2f} % of range), max error {e['max_error']:.2f} N "
          f"({e['max_error_percent']:.2f} % of range; authors' model: < {AUTHORS_MAX_ERROR_PERCENT} %)")
    print(f"  fit status: {res.status}" + ("" if res.converged else f" (warning: {res.message})"))
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
    # all three up front: pj.fit refuses its own `out` only when it gets there, after the fits before it were
    # written (a rerun left a new fit_eq7.json beside an old fit_eq6.json and figure)
    refuse_existing("static_force.py", [out / "fit_eq7.json", out / "fit_eq6.json", out / "static_force.png"],
                    args.overwrite)

    x, p, f = load_map()
    experiment = pj.bench.ForceMapExperiment(x, p, f, scale=1.0)  # residuals in N

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
