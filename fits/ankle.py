"""Demo: an antagonistic pair of DMSP-40 muscles, each fed by its own VPPM regulator (ISO 6358 flow limits), drives
an ankle joint along a gait-like trajectory (paper 001's future work) at stride frequencies in the human gait band
(0.125-1.5 Hz). Feed-forward only: at each instant the static map gives the pressure pair that holds the reference
angle at a fixed pressure sum (co-contraction, which sets the stiffness); the calibration (1.01 bar/V) turns them
into reference voltages. Prints the tracking RMSE per frequency and writes a figure.

    python fits/ankle.py [--out results/ankle] [--frequencies 0.125 0.5 1.5] [--sum-bar 5] [--overwrite]
"""

import argparse
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import json_text, refuse_existing  # noqa: E402
from pamjax.gallery.procedures.ankle import check_run, gait_angle, run  # noqa: E402,F401


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/ankle")
    ap.add_argument("--frequencies", type=float, nargs="+", default=[0.125, 0.5, 1.5])
    ap.add_argument("--sum-bar", type=float, default=5.0, help="gauge pressure sum (co-contraction) [bar]")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args(argv)
    m = pj.presets.dmsp40_muscle()
    joint = pj.AntagonisticJoint(pj.ISO6358Regulator(), pj.ISO6358Regulator(), m, m)
    # checked before any work (the runs' compiled static map cannot check them): 0 Hz divided by zero, a sum in bar
    # ran silently into a 19° RMSE, a sum beyond the regulators was clipped
    bad = [f for f in args.frequencies if not (np.isfinite(f) and f > 0)]
    if bad:
        ap.error(f"--frequencies must be finite stride frequencies > 0 [Hz], got {bad}")
    try:
        check_run(joint, args.frequencies[0], args.sum_bar * 1e5)
    except pj.PamjaxInputError as err:
        ap.error(f"--sum-bar {args.sum_bar:g} (gauge pressure sum [bar]): {err}")
    out = pathlib.Path(args.out)
    refuse_existing("ankle.py", [out / "ankle.json", out / "ankle.png"], args.overwrite)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for f in args.frequencies:
        r = run(joint, f, args.sum_bar * 1e5)
        results[f] = r
        print(
            f"{f:6.3f} Hz: angle RMSE {np.degrees(r['rmse']):.2f}° "
            f"(reference ±{np.degrees(np.abs(r['reference']).max()):.1f}°), "
            f"stiffness {r['stiffness'].min():.0f}-{r['stiffness'].max():.0f} N m/rad"
        )
    (out / "ankle.json").write_text(
        json_text({str(f): dict(rmse_rad=r["rmse"]) for f, r in results.items()}, indent=2)
    )
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(3, len(results), figsize=(4 * len(results), 7), squeeze=False, sharey="row")
        for k, (f, r) in enumerate(results.items()):
            axes[0, k].plot(r["t"], np.degrees(r["reference"]), "k--", label="reference")
            axes[0, k].plot(r["t"], np.degrees(r["angle"]), label="simulated")
            axes[0, k].set_title(f"{f} Hz, RMSE {np.degrees(r['rmse']):.2f}°")
            axes[1, k].plot(r["t"], (r["pressure"] - float(joint.air.atmospheric_pressure)) / 1e5)
            axes[2, k].plot(r["t"], r["stiffness"])
            axes[2, k].set_xlabel("t [s]")
        axes[0, 0].set_ylabel("angle [°]")
        axes[0, 0].legend(fontsize=8)
        axes[1, 0].set_ylabel("p flexor / extensor [bar g]")
        axes[2, 0].set_ylabel("K_θ [N m/rad]")
        fig.tight_layout()
        fig.savefig(out / "ankle.png", dpi=110)
    except ImportError:
        pass
    print(f"wrote {out}/ankle.json")


if __name__ == "__main__":
    main()
