"""Identification benchmark: `fits/joint.py` on the three ideal bench sets and on realistic rigs, from the presets.

    python benchmarks/identify.py [--sets DIR ...] [--realistic DIR ...] [--out DIR]

Sets (default): `shared/data/hybrid-reference-bench`, `hybrid-reference-bench-perturbed/perturbed3` and
`.../perturbed4`: recordings of an exact switching simulation with true stick-slip whose parameters (for the
perturbed sets, each fitted one × U(0.8, 1.2)) are listed in meta.json and read here only to score. Each set is
fitted in a fresh process (`python fits/joint.py --data SET --out OUT/<set>`: compilation included, as a user meets
it; JAX's persistent compilation cache off), at the recordings' 1 kHz.

Scored quantities (issue 13): C_v and b of both valve paths, v0, v1, k0/k2, k1/k2, F_c, C_f, and F_max(x) of a0…a4
over the stroke the triangle runs cover (the a_i one by one are ill-conditioned); every channel of every experiment's
1 kHz residual RMSE over the noise. Ends with

    RESULT sets=3 converged=... max_param_err_pct=... worst_rmse_over_noise=... fit_s=... compile_s=...
           realistic_sets=... realistic_converged=... realistic_max_param_err_pct=...
           realistic_worst_nuisance_over_tol=... realistic_worst_rmse_over_noise=... realistic_fit_s=...
           realistic_compile_s=... realistic_max_param_err_sensor_frame_pct=...
           realistic_worst_fitted_nuisance_over_tol=... realistic_weak_motion_warned=...
           realistic_unwarned_max_param_err_pct=...

(max over sets and quantities; fit_s and compile_s are those of the slowest set).

Realistic rigs (default `shared/data/bench-realistic/realistic1`: CSV files in barg and mm, supply pressure per run,
sensor offsets and gain, acquisition delay, a run logged mid-way) are fitted as a user would: `fits/joint.py --data
DIR --nuisance` on the files as they are. Their plant is scored as above; their nuisances against meta.json's
`nuisance` with issue 29's tolerances (delay 0.3 ms, pressure offset 300 Pa, pressure gain 0.3 %, position offset
0.05 mm, every run's supply pressure 0.5 %): `realistic_worst_nuisance_over_tol` is the largest |error| / tolerance
(≤ 1: every nuisance within its tolerance). The truth (`params`, `nuisance`) is read here, after the fit, to score:
`fits/joint.py` never reads it. The position sensor's offset cannot be determined from runs that never rest on a
stop of known position (a shift of the origin is absorbed exactly by F_max, k0 and v0; docs/fitting.md): the fit then
holds it and identifies the plant in the sensor's frame, which `realistic_max_param_err_sensor_frame_pct` scores
(the truth re-expanded about the sensor's origin, `in_sensor_frame`), beside the strict figure in the truth's frame;
`realistic_worst_fitted_nuisance_over_tol` is the worst over the nuisances the fit freed (the held offset left out).
`realistic_weak_motion_warned` counts the rigs whose fit warned that the muscle runs' payload barely moved (its
force law and friction rest on a few sliding samples; docs/fitting.md, "Runs that hold the payload on a stop"), and
`realistic_unwarned_max_param_err_pct` is the worst plant quantity over the others: what a user told nothing
should be able to trust (nan where every rig was warned).
`--score-only` scores the fits an earlier run left in `--out` again, without fitting.
"""

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED = ROOT / ".." / "shared" / "data"
DEFAULT_SETS = [SHARED / "hybrid-reference-bench", SHARED / "hybrid-reference-bench-perturbed" / "perturbed3",
                SHARED / "hybrid-reference-bench-perturbed" / "perturbed4"]
DEFAULT_REALISTIC = [SHARED / "bench-realistic" / "realistic1"]
TARGET_PCT, TARGET_RMSE, TARGET_S, TARGET_REALISTIC_S = 2.0, 1.2, 120.0, 180.0
# issue 29: tolerance of each nuisance (absolute; the gain and the supply pressures relative)
# the start of pamjax's weak-motion warning in a fit's `warnings` (pamjax._fit.force_balance: _NEVER, _ONLY)
WEAK_MOTION_MARKS = (": the payload slides in only", ": the payload never slides")
NUISANCE_TOLERANCE = {"delay_s": 3e-4, "pressure_offset_Pa": 300.0, "pressure_gain": 3e-3, "position_offset_m": 5e-5,
                      "supply_pressure_Pa": 5e-3}


def in_sensor_frame(truth, shift):
    """The true plant as seen through a position sensor that reads `shift` [m] more than the fit assumed (x_sensor = x
    + shift): eq. 14's v0 + v1 x and eq. 7's k0 − k1 x re-expanded about the sensor's origin (F_max's quartic is
    shifted where it is evaluated, `score`). A shift of the origin is absorbed exactly by these polynomials, so a fit
    that holds the offset identifies this plant; scoring against it separates the fit's own error from the offset the
    recordings cannot determine (docs/fitting.md, "Not the position sensor's offset")."""
    shifted = dict(truth)
    if "v0" in truth and "v1" in truth:
        shifted["v0"] = truth["v0"] - truth["v1"] * shift
    if "k0" in truth and "k1" in truth:
        shifted["k0"] = truth["k0"] + truth["k1"] * shift
    return shifted


def score(values, truth, data_positions, shift=0.0):
    """Relative errors against the bench's true parameters, and F_max(x) of a0…a4 against the truth's over the stroke
    the muscle runs cover, `data_positions` (the a_i one by one are ill-conditioned; the curve is what the data
    determine). `shift` [m]: score against the truth in a position sensor's frame that reads `shift` more
    (`in_sensor_frame`; 0: the truth's own frame)."""
    truth = in_sensor_frame(truth, shift) if shift else truth
    rel = {k: (values[k] - truth[k]) / abs(truth[k]) for k in values if k in truth and truth[k] != 0}
    out = {"relative_error": rel}
    if all(f"a{i}" in values and f"a{i}" in truth for i in range(5)) and len(data_positions):
        x = np.linspace(float(np.min(data_positions)), float(np.max(data_positions)), 200)
        fit_f = np.polyval([values[f"a{i}"] for i in range(4, -1, -1)], x)
        true_f = np.polyval([truth[f"a{i}"] for i in range(4, -1, -1)], x - shift)
        out["fmax_max_relative_error"] = float(np.max(np.abs(fit_f - true_f) / np.abs(true_f)))
        out["fmax_stroke_m"] = [float(x[0]), float(x[-1])]
    if "k0" in values and "k2" in truth:  # k2 is held at the preset; compare the identifiable ratios
        out["relative_error"]["k0/k2"] = rel.get("k0")
        out["relative_error"]["k1/k2"] = rel.get("k1")
    compared = [abs(v) for k, v in rel.items() if not k.startswith("a")]
    if "fmax_max_relative_error" in out:
        compared.append(out["fmax_max_relative_error"])
    out["max_relative_error"] = float(max(compared)) if compared else float("nan")
    return out


def score_nuisance(fitted, truth):
    """|error| / tolerance of every nuisance (issue 29's tolerances), and the worst."""
    over = {}
    for key in ("delay_s", "pressure_offset_Pa", "position_offset_m"):
        if key in truth:
            over[key] = abs(fitted[key] - truth[key]) / NUISANCE_TOLERANCE[key]
    if "pressure_gain" in truth:
        over["pressure_gain"] = abs(fitted["pressure_gain"] / truth["pressure_gain"] - 1) / NUISANCE_TOLERANCE[
            "pressure_gain"]
    for run, p in truth.get("supply_pressure_Pa", {}).items():
        if run in fitted["supply_pressure_Pa"]:
            over[f"supply_pressure_Pa[{run}]"] = abs(fitted["supply_pressure_Pa"][run] / p - 1) / NUISANCE_TOLERANCE[
                "supply_pressure_Pa"]
        else:
            over[f"supply_pressure_Pa[{run}]"] = float("inf")  # not reported
    return over, max(over.values()) if over else float("nan")


def data_positions(data):
    """The recorded positions [m] of a bench's muscle runs (the stroke F_max is scored over), read as pamjax reads
    them (any file format and units)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import pamjax as pj

    bench = pj.bench.load_bench(data, pj.presets.mas10_system(valve="pwm", friction="karnopp"))
    xs = [np.asarray(e.data["position"]) for e in bench.experiments if "position" in e.channels]
    return np.concatenate(xs) if xs else np.zeros(0)


def run_set(data, out, nuisance=False, score_only=False):
    if score_only:  # the fit of an earlier run in OUT, scored again (its process time unknown)
        if not (out / "joint.json").is_file():
            raise SystemExit(f"--score-only: {out / 'joint.json'} does not exist (run without --score-only first)")
        wall = float("nan")
    else:
        env = dict(os.environ, JAX_ENABLE_COMPILATION_CACHE="false", PAMJAX_COMPILATION_CACHE="0")
        cmd = [sys.executable, str(ROOT / "fits" / "joint.py"), "--data", str(data), "--out", str(out), "--overwrite",
               "--quiet"] + (["--nuisance"] if nuisance else [])
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            print(proc.stdout[-3000:], proc.stderr[-3000:])
            raise SystemExit(f"fits/joint.py failed on {data}")
        print(proc.stdout)
    summary = json.loads((out / "joint.json").read_text())
    summary["process_wall_s"] = wall
    meta = json.loads((pathlib.Path(data) / "meta.json").read_text())  # the truth, read only to score
    if meta.get("params"):
        positions = data_positions(data)
        summary["score"] = score(summary["params"], meta["params"], positions)
        offset = meta.get("nuisance", {}).get("position_offset_m")
        if nuisance and offset is not None:  # the plant in the sensor's frame: the offset the fit held, set apart
            shift = offset - summary.get("nuisance", {}).get("position_offset_m", 0.0)
            summary["score_sensor_frame"] = score(summary["params"], meta["params"], positions, shift)
    if nuisance and meta.get("nuisance"):
        summary["nuisance_over_tol"], summary["worst_nuisance_over_tol"] = score_nuisance(summary["nuisance"],
                                                                                          meta["nuisance"])
    return summary


def evaluate_sets(sets, out, nuisance, score_only=False):
    rows = []
    for data in sets:
        data = pathlib.Path(data)
        name = data.resolve().name
        s = run_set(data, out / name, nuisance, score_only)
        sc, frame = s.get("score", {}), s.get("score_sensor_frame", {})
        worst_rmse = max(r for chans in s["rmse_over_noise"].values() for r in chans.values())
        rows.append(dict(set=name, status=s["status"], converged=s["converged"],
                         warned=any(m in w for w in s.get("warnings", []) for m in WEAK_MOTION_MARKS),
                         max_err_pct=100 * sc.get("max_relative_error", float("nan")),
                         fmax_err_pct=100 * sc.get("fmax_max_relative_error", float("nan")),
                         worst_rmse=worst_rmse, fit_s=s["fit_s"], compile_s=s["compile_s"],
                         wall_s=s["process_wall_s"], iterations=s["iterations"],
                         errors={k: 100 * v for k, v in sc.get("relative_error", {}).items() if v is not None},
                         sensor_frame_err_pct=100 * frame.get("max_relative_error", float("nan")),
                         sensor_frame_fmax_pct=100 * frame.get("fmax_max_relative_error", float("nan")),
                         nuisance=s.get("nuisance_over_tol", {}),
                         worst_nuisance=s.get("worst_nuisance_over_tol", float("nan")),
                         worst_fitted_nuisance=max((v for k, v in s.get("nuisance_over_tol", {}).items()
                                                    if k not in s.get("nuisance", {}).get("held", {})),
                                                   default=float("nan"))))
    print(f"\n{'set':<28}{'status':<11}{'max err %':>10}{'F_max %':>9}{'RMSE/noise':>11}{'iters':>6}"
          f"{'fit s':>8}{'compile s':>10}{'process s':>10}  warned")
    for r in rows:
        print(f"{r['set']:<28}{r['status']:<11}{r['max_err_pct']:>10.3f}{r['fmax_err_pct']:>9.3f}{r['worst_rmse']:>11.3f}"
              f"{r['iterations']:>6}{r['fit_s']:>8.1f}{r['compile_s']:>10.1f}{r['wall_s']:>10.1f}"
              f"  {'weak motion' if r['warned'] else ''}")
    for r in rows:
        print(f"  {r['set']}: " + ", ".join(f"{k} {v:+.2f}" for k, v in r["errors"].items()
                                           if not k.startswith("a")))
        if not np.isnan(r["sensor_frame_err_pct"]):
            print(f"  {r['set']} in the position sensor's frame (the offset the fit held set apart): worst "
                  f"{r['sensor_frame_err_pct']:.3f} % (F_max {r['sensor_frame_fmax_pct']:.3f} %)")
        if r["nuisance"]:
            print(f"  {r['set']} nuisances, |error| / tolerance: "
                  + ", ".join(f"{k} {v:.2f}" for k, v in r["nuisance"].items()))
    return rows


def summary_of(rows):
    slowest = max(rows, key=lambda r: r["fit_s"] + r["compile_s"])
    return dict(sets=len(rows), converged=sum(r["converged"] for r in rows),
                max_param_err_pct=max(r["max_err_pct"] for r in rows), worst_rmse=max(r["worst_rmse"] for r in rows),
                fit_s=slowest["fit_s"], compile_s=slowest["compile_s"],
                worst_nuisance=max(r["worst_nuisance"] for r in rows),
                sensor_frame_err_pct=max(r["sensor_frame_err_pct"] for r in rows),
                worst_fitted_nuisance=max(r["worst_fitted_nuisance"] for r in rows),
                warned=sum(r["warned"] for r in rows),
                unwarned_err_pct=max((r["max_err_pct"] for r in rows if not r["warned"]), default=float("nan")))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="*", default=[str(s) for s in DEFAULT_SETS])
    ap.add_argument("--realistic", nargs="*", default=[str(s) for s in DEFAULT_REALISTIC],
                    help="realistic rigs (fitted with --nuisance); none: --realistic with no value")
    ap.add_argument("--out", default="results/benchmark_identify")
    ap.add_argument("--score-only", action="store_true",
                    help="score the joint.json files an earlier run left in --out again, fitting nothing")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, {platform.processor() or platform.platform()}")
    line = []
    if args.sets:
        ideal = summary_of(evaluate_sets(args.sets, out, nuisance=False, score_only=args.score_only))
        print(f"\nideal bench targets: every quantity within {TARGET_PCT} % (worst "
              f"{ideal['max_param_err_pct']:.2f} %), RMSE ≤ {TARGET_RMSE}× noise (worst {ideal['worst_rmse']:.3f}), "
              f"fit + compile ≤ {TARGET_S} s per set "
              f"(slowest {ideal['fit_s'] + ideal['compile_s']:.1f} s), converged {ideal['converged']}/{ideal['sets']}")
        line.append(f"sets={ideal['sets']} converged={ideal['converged']} "
                    f"max_param_err_pct={ideal['max_param_err_pct']:.3f} "
                    f"worst_rmse_over_noise={ideal['worst_rmse']:.3f} fit_s={ideal['fit_s']:.1f} "
                    f"compile_s={ideal['compile_s']:.1f}")
    if args.realistic:
        real = summary_of(evaluate_sets(args.realistic, out, nuisance=True, score_only=args.score_only))
        print(f"\nrealistic rig targets: every plant quantity within {TARGET_PCT} % (worst "
              f"{real['max_param_err_pct']:.2f} %), every nuisance within its tolerance (worst "
              f"{real['worst_nuisance']:.2f}× tolerance), RMSE ≤ {TARGET_RMSE}× noise (worst "
              f"{real['worst_rmse']:.3f}), "
              f"fit + compile ≤ {TARGET_REALISTIC_S} s per rig (slowest {real['fit_s'] + real['compile_s']:.1f} s), "
              f"converged {real['converged']}/{real['sets']}; warned of weak motion {real['warned']}, the others "
              f"within {real['unwarned_err_pct']:.2f} %")
        line.append(f"realistic_sets={real['sets']} realistic_converged={real['converged']} "
                    f"realistic_max_param_err_pct={real['max_param_err_pct']:.3f} "
                    f"realistic_worst_nuisance_over_tol={real['worst_nuisance']:.3f} "
                    f"realistic_worst_rmse_over_noise={real['worst_rmse']:.3f} realistic_fit_s={real['fit_s']:.1f} "
                    f"realistic_compile_s={real['compile_s']:.1f} "
                    f"realistic_max_param_err_sensor_frame_pct={real['sensor_frame_err_pct']:.3f} "
                    f"realistic_worst_fitted_nuisance_over_tol={real['worst_fitted_nuisance']:.3f} "
                    f"realistic_weak_motion_warned={real['warned']} "
                    f"realistic_unwarned_max_param_err_pct={real['unwarned_err_pct']:.3f}")
    print("RESULT " + " ".join(line))


if __name__ == "__main__":
    main()
