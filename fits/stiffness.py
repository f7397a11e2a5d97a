"""Paper 001 Sect. 6.2 (Fig. 12): muscle stiffness, its rate and the valve flow along a simulated run.

What it computes, how and from which of the paper's numbers: the docstring of `pamjax.gallery.procedures.stiffness`,
whose procedures this script runs (the gallery runs the same ones).

Writes `stiffness.json` and `stiffness.png` to `--out`; refuses to overwrite existing results unless `--overwrite`.

    python fits/stiffness.py [--out results/stiffness] [--duration 2.0] [--overwrite]
"""

import argparse
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

from pamjax.gallery import json_text, refuse_existing  # noqa: E402
from pamjax.gallery.procedures.stiffness import PAPER, RATE, plot, run, summarise  # noqa: E402,F401


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="results/stiffness")
    ap.add_argument("--duration", type=float, default=2.0, help="simulated time [s] (3 periods at 1.5 Hz)")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    path = out / "stiffness.json"
    # ten saving intervals at least: eq. 10 is compared with central differences away from the regulator's switching
    # instants, and a run of a few samples (4 ms) has none of them (a raw ValueError after the solve before)
    shortest = 10.0 / RATE
    if not (np.isfinite(args.duration) and args.duration >= shortest):
        ap.error(f"--duration must be a finite number >= {shortest:g} s (ten sampling intervals at {RATE:g} Hz), "
                 f"got {args.duration:g}")
    refuse_existing("stiffness.py", [path, out / "stiffness.png"], args.overwrite)
    start = time.perf_counter()
    r = run(args.duration)
    report = summarise(r)
    report["wall_time_s"] = time.perf_counter() - start
    report["series"] = {k: r[k].tolist() for k in ("t", "command", "pressure", "position", "stiffness", "eq10", "eq11")}
    print(
        f"eq. 9 stiffness {report['stiffness_eq9_range_N_per_m'][0]:.4g}-{report['stiffness_eq9_range_N_per_m'][1]:.4g}"
        f" N/m; eq. 10 {report['eq10_range_N_per_s'][0]:.4g} to {report['eq10_range_N_per_s'][1]:.4g} N/s"
    )
    print(
        f"eq. 11 vs delivered ISO 6358 flow: max difference {report['eq11_vs_delivered_max_relative']:.1e} of the "
        f"peak {report['peak_valve_flow_kg_per_s']:.3e} kg/s ({report['peak_valve_flow_l_per_min_anr']:.1f} l/min ANR;"
        f" paper 2.79 l/min)"
    )
    print(
        f"eq. 10 vs d/dt(p V') by central differences: {report['eq10_vs_finite_difference_max_relative']:.1e} of its "
        f"peak; correlation eq. 10 / eq. 11 {report['correlation_eq10_eq11']:.3f}, "
        f"dK/dt (eq. 9) / eq. 11 {report['correlation_dK_dt_eq11']:.3f}"
    )
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json_text(report, indent=1))
    try:
        plot(r, out / "stiffness.png")
    except ImportError:
        print("matplotlib not installed: no figure")
    print(f"wrote {path} ({report['wall_time_s']:.1f} s)")


if __name__ == "__main__":
    main()
