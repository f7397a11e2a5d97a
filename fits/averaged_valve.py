"""Eq. 13's averaged valve (m1…m9) by two routes, compared on the switching valve's cycle-averaged flow:

1. fitted directly to the switching valve's cycle-averaged flow over a (duty, pressure) grid
   (`pamjax.fit_averaged_valve`);
2. paper 000's own procedure: noisy constant-volume tank recordings of the switching valve (charge from atmosphere
   and discharge from supply at duties 0.15…0.85, 1 kHz, 2 kPa noise), pressure filtered (zero-phase Butterworth,
   20 Hz), differentiated, turned into mass flow with eq. 12 (ṁ = V ṗ / (κ R T)), and the surface fitted.

Both are scored on the same grid against the cycle-averaged flow: max error and RMSE as % of the flow range, beside
the paper's 4.13 % and 1.16 % (its fit to its own measurements). Writes `averaged_valve.json` and
`averaged_valve.png` (flow curves of both routes against the cycle average, the tank-procedure estimates, and both
routes' error maps) to `--out`; refuses to replace either unless `--overwrite`.

    python fits/averaged_valve.py [--out results/averaged_valve] [--overwrite] [--quick]

`--quick` (a smoke run for the tests): the direct fit on a 17 × 17 instead of a 33 × 41 grid, the tank procedure
with 4 instead of 8 duties and 1.0 s instead of 1.5 s runs; the scoring grid is the same.
"""

import argparse
import pathlib

import jax

jax.config.update("jax_enable_x64", True)

from pamjax.gallery import json_text  # noqa: E402
from pamjax.gallery.procedures.averaged_valve import compute, plot  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/averaged_valve")
    ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--quick", action="store_true", help="coarser fit grid, fewer and shorter tank runs")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    json_path, png_path = out / "averaged_valve.json", out / "averaged_valve.png"
    for path in (json_path, png_path):
        if path.exists() and not args.overwrite:
            raise SystemExit(f"{path} exists; pass --overwrite to replace it")
    report, plot_args = compute(args.quick)
    for k in ("paper", "cycle_average_fit", "tank_procedure"):
        print(
            f"{k:<18} max error {report[k]['max_error_percent']:6.2f} %   "
            f"RMSE {report[k]['rmse_percent']:5.2f} % of range"
        )
    out.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json_text(report, indent=1))
    plot(png_path, *plot_args)
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
