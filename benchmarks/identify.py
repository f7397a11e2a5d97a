"""Identification benchmark: `fits/joint.py` on the three bench sets, each from the datasheet presets.

    python benchmarks/identify.py [--sets DIR ...] [--out DIR]

Sets (default): `shared/data/hybrid-reference-bench`, `hybrid-reference-bench-perturbed/perturbed3` and
`.../perturbed4`: recordings of an exact switching simulation with true stick-slip whose parameters (for the
perturbed sets, each fitted one × U(0.8, 1.2)) are listed in meta.json and read here only to score. Each set is
fitted in a fresh process (`python fits/joint.py --data SET --out OUT/<set>`: compilation included, as a user meets
it; JAX's persistent compilation cache off), at the recordings' 1 kHz.

Scored quantities (issue 13): C_v and b of both valve paths, v0, v1, k0/k2, k1/k2, F_c, C_f, and F_max(x) of a0…a4
over the stroke the triangle runs cover (the a_i one by one are ill-conditioned); every channel of every experiment's
1 kHz residual RMSE over the noise. Ends with

    RESULT sets=3 converged=... max_param_err_pct=... worst_rmse_over_noise=... fit_s=... compile_s=...

(max over sets and quantities; fit_s and compile_s are those of the slowest set).
"""

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED = ROOT / ".." / "shared" / "data"
DEFAULT_SETS = [SHARED / "hybrid-reference-bench", SHARED / "hybrid-reference-bench-perturbed" / "perturbed3",
                SHARED / "hybrid-reference-bench-perturbed" / "perturbed4"]
TARGET_PCT, TARGET_RMSE, TARGET_S = 2.0, 1.2, 120.0


def run_set(data, out):
    env = dict(os.environ, JAX_ENABLE_COMPILATION_CACHE="false", PAMJAX_COMPILATION_CACHE="0")
    cmd = [sys.executable, str(ROOT / "fits" / "joint.py"), "--data", str(data), "--out", str(out), "--overwrite",
           "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        print(proc.stdout[-3000:], proc.stderr[-3000:])
        raise SystemExit(f"fits/joint.py failed on {data}")
    print(proc.stdout)
    summary = json.loads((out / "joint.json").read_text())
    summary["process_wall_s"] = wall
    return summary


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="*", default=[str(s) for s in DEFAULT_SETS])
    ap.add_argument("--out", default="results/benchmark_identify")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, {platform.processor() or platform.platform()}")
    rows = []
    for data in args.sets:
        data = pathlib.Path(data)
        name = data.resolve().name
        s = run_set(data, out / name)
        score = s.get("score", {})
        worst_rmse = max(r for chans in s["rmse_over_noise"].values() for r in chans.values())
        rows.append(dict(set=name, status=s["status"], converged=s["converged"],
                         max_err_pct=100 * score.get("max_relative_error", float("nan")),
                         fmax_err_pct=100 * score.get("fmax_max_relative_error", float("nan")),
                         worst_rmse=worst_rmse, fit_s=s["fit_s"], compile_s=s["compile_s"],
                         wall_s=s["process_wall_s"], iterations=s["iterations"],
                         errors={k: 100 * v for k, v in score.get("relative_error", {}).items() if v is not None}))
    print(f"\n{'set':<28}{'status':<11}{'max err %':>10}{'F_max %':>9}{'RMSE/noise':>11}{'iters':>6}"
          f"{'fit s':>8}{'compile s':>10}{'process s':>10}")
    for r in rows:
        print(f"{r['set']:<28}{r['status']:<11}{r['max_err_pct']:>10.3f}{r['fmax_err_pct']:>9.3f}{r['worst_rmse']:>11.3f}"
              f"{r['iterations']:>6}{r['fit_s']:>8.1f}{r['compile_s']:>10.1f}{r['wall_s']:>10.1f}")
    for r in rows:
        print(f"  {r['set']}: " + ", ".join(f"{k} {v:+.2f}" for k, v in r["errors"].items()
                                           if not k.startswith("a")))
    slowest = max(rows, key=lambda r: r["fit_s"] + r["compile_s"])
    converged = sum(r["converged"] for r in rows)
    max_err = max(r["max_err_pct"] for r in rows)
    worst = max(r["worst_rmse"] for r in rows)
    print(f"\ntargets: every quantity within {TARGET_PCT} % (worst {max_err:.2f} %), RMSE ≤ {TARGET_RMSE}× noise "
          f"(worst {worst:.3f}), fit + compile ≤ {TARGET_S} s per set (slowest "
          f"{slowest['fit_s'] + slowest['compile_s']:.1f} s), converged {converged}/{len(rows)}")
    print(f"RESULT sets={len(rows)} converged={converged} max_param_err_pct={max_err:.3f} "
          f"worst_rmse_over_noise={worst:.3f} fit_s={slowest['fit_s']:.1f} compile_s={slowest['compile_s']:.1f}")


if __name__ == "__main__":
    main()
