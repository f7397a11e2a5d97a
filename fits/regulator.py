"""Paper 001 identification, on synthetic data generated from the paper's own numbers.

What it computes, how and from which of the paper's numbers: the docstring of `pamjax.gallery.procedures.regulator`,
whose procedures this script runs (the gallery runs the same ones).

    python fits/regulator.py [--out results/regulator] [--quick] [--overwrite]
"""

import argparse
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from pamjax.gallery import json_text, refuse_existing  # noqa: E402
from pamjax.gallery.procedures.regulator import (  # noqa: E402, F401  (the procedures; this file is their command line)
    B_BOUNDS,
    NOISE_TANK,
    P_ATM,
    TANK,
    fit_tables,
    fit_tank,
    fit_valve,
    start_values,
    tank_horizon,
    tank_rate_constant,
    tank_run,
)
from pamjax.units import BAR  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/regulator")
    ap.add_argument("--quick", action="store_true", help="60 instead of 150 samples per tank run, 4 s square wave")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    path = out / "regulator_fit.json"
    refuse_existing("regulator.py", [path, out / "g_vref_fit.png"], args.overwrite)  # the figure alone too
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    report = fit_tables(rng, args.quick)
    rows = report["charging"] + report["discharging"]
    print(
        f"all {len(rows)} rows: |C error| ≤ {max(abs(r['C_error_percent']) for r in rows):.3f} %, "
        f"|b error| ≤ {max(abs(r['b_error']) for r in rows):.4f}"
    )
    v = fit_valve(rng, args.quick)
    print(
        f"G_Vref: gain {v['gain_bar_per_V']:.4f} bar/V (eq. 6: 1.01), τ1 {v['tau1_s']:.4f} s (0.041), "
        f"τ2 {v['tau2_s']:.4f} s (0.023), bandwidth {v['bandwidth_Hz']:.3f} Hz (3.14); validation (last 40 %) "
        f"MSE {v['validation_mse_bar2']:.2e} bar², fit {v['validation_fit_percent']:.2f} %"
    )
    report["G_Vref"] = {k: v[k] for k in v if not isinstance(v[k], np.ndarray) and k != "n_id"}
    path.write_text(json_text(report, indent=2))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(8, 3.5))
        t = v["ts"]
        ax.plot(t, (v["measured"] - P_ATM) / BAR, ".", ms=1, color="0.7", label="synthetic measurement")
        ax.plot(t, (v["smoothed"] - P_ATM) / BAR, color="C0", label="Butterworth 20 Hz")
        ax.plot(t, (v["simulated"] - P_ATM) / BAR, "--", color="C3", label="identified eq. 6")
        ax.axvline(t[v["n_id"]], color="k", lw=0.8)
        ax.set(xlabel="t [s]", ylabel="P_out [bar gauge]", title="G_Vref: 60 % identification | 40 % validation")
        ax.legend(loc="upper right", fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "g_vref_fit.png", dpi=120)
    except ImportError:
        pass
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
