"""Profile likelihoods of the joint MAS-10 bench fit: which parameters paper 000's experiments determine.

    python fits/joint_profile.py [--data DIR] [--out DIR] [--rate HZ] [--names KEY ...] [--workers N] [--overwrite]

Fits the bench directory's tank tests and triangle runs (E1, E2, E3, E4) from the presets exactly as
`fits/joint.py` does (switching valve on the PWM-synchronous grid, exact stick-slip friction, the 15 parameters of
`fitted_keys`, k2 held), then profiles the named bench parameters (default all) with `pamjax.profile_likelihood`. Writes
`OUT/profile.json` (every profile, its likelihood-ratio interval and verdict, by pamjax label) and
`OUT/profile.png`, and prints the table with the bench's names; docs/identifiability.md quotes it.
"""

import argparse
import pathlib
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)
import pamjax as pj  # noqa: E402
from pamjax.gallery import bench_folder, refuse_existing  # noqa: E402

DEFAULT_DATA = bench_folder()  # the hybrid bench recordings shipped with pamjax (pamjax/data/)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DEFAULT_DATA), help="bench directory (meta.json + <experiment>.npz)")
    ap.add_argument("--out", default=None, help="output directory (default results/joint_profile_<data name>)")
    ap.add_argument("--rate", type=float, default=None, help="decimate the recordings to this rate [Hz]")
    ap.add_argument("--names", nargs="*", default=None, help="bench parameter names to profile (default all)")
    ap.add_argument("--workers", type=int, default=2, help="threads running the profile branches")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args(argv)
    data = pathlib.Path(args.data)
    out = pathlib.Path(args.out or f"results/joint_profile_{data.resolve().name}")
    refuse_existing("joint_profile.py", [out / "profile.json", out / "profile.png"], args.overwrite)

    model = pj.presets.mas10_system(valve="pwm", friction="karnopp")
    bench = pj.bench.load_bench(data, model, rate=args.rate)
    keys = list(args.names or bench.fitted_keys)
    bad, twice = [k for k in keys if k not in bench.fitted_keys], sorted({k for k in keys if keys.count(k) > 1})
    if bad or twice:  # before the joint fit (minutes), not after it
        ap.error(f"--names {bad or twice}: " + ("not among the bench's fitted parameters" if bad else "given twice")
                 + f"; the fitted ones (meta.json's fitted_keys) are: {' '.join(bench.fitted_keys)}")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pj.PamjaxIdentifiabilityWarning)
        res = pj.fit(model, bench.experiments, bench.free, progress=False)
    print(f"fit: {res.status}, {res.iterations} iterations, {time.perf_counter() - t0:.1f} s")
    label = {k: pj.bench.BENCH_PARAMETERS[k][1] for k in bench.fitted_keys}
    names = [label[k] for k in keys]
    prof = pj.profile_likelihood(res, names, workers=args.workers)
    print(f"profiles of {len(names)} parameters: {prof.profile_s:.1f} s (σ² = {prof.sigma2:.3g})")
    key = {v: k for k, v in label.items()}
    print(f"{'key':<6}{'fitted':>13}{'LR lower':>13}{'LR upper':>13}{'lin. lower':>13}{'lin. upper':>13}  verdict")
    for p in prof.profiles:
        print(f"{key[p.label]:<6}{p.value:>13.6g}{p.interval[0]:>13.6g}{p.interval[1]:>13.6g}"
              f"{p.linearised[0]:>13.6g}{p.linearised[1]:>13.6g}  {p.verdict}")
    prof.write(out, overwrite=args.overwrite)
    print(f"wrote {out / 'profile.json'} and {out / 'profile.png'}")


if __name__ == "__main__":
    main()
