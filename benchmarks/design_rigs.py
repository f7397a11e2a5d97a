"""Pilot, then design, on realistic rigs nobody has seen: `examples/pilot_fit.toml` + `examples/pilot_design.toml`'s
workflow, with the rig's nuisances, against the bench's E1-E4 (issue 29, item 7).

    python benchmarks/design_rigs.py [--rigs 3] [--seed 3100] [--steps 40] [--out results/design_rigs]

For each rig (`benchmarks/unseen_rigs.py --seed S`: an unseen plant, every fitted parameter x U(0.8, 1.2), logged
with a real rig's nuisances: supply pressure per run, pressure sensor offset and gain, an acquisition delay, E4 from
the middle of its triangle; CSV files in barg and mm), as a user runs it from the command line:

1. The pilot: `pamjax fit` of the rig's six tank tests and E4 (`[bench] runs`, `nuisance = true`), 15 parameters
   from the datasheet presets.
2. The design: `pamjax design` at the pilot's `model.json`, the pilot's `fit.json` as the prior (its covariance, the
   nuisances marginalised), a 25 s run in E3's place, E3 as the run to beat (margin 1), `--steps` iterations.
3. The designed run recorded on the same rig (`unseen_rigs.py --design-run`: E5, the design's duty through the rig's
   plant and nuisances, its own supply pressure drawn).
4. Two fits from the presets with the nuisances free, the same bench time (45 s: six 2 s tank tests, 8 s E4 and
   25 s more): "pilot + design" (tank tests, E4, E5) and "E1-E4" (tank tests, E3, E4, the bench's protocol).

Scored as `benchmarks/identify.py` scores a realistic rig (the truth in meta.json, read here only to score): every
plant quantity of issue 13's list (C_v, b of both valve paths, v0, v1, k0/k2, k1/k2, F_c, C_f, F_max(x) over the
runs' stroke), in the position sensor's frame. Per rig and arm: the worst error, the muscle and friction quantities'
worst (v0, v1, k0, k1, F_c, C_f, F_max), the standard errors, the RMSE over the noise, the status. Ends with

    RESULT rigs=... designed=... pilot_weak_motion=... pilot_max_err_pct=... e1e4_max_err_pct=...
           pilot_muscle_max_err_pct=... e1e4_muscle_max_err_pct=... pilot_tighter_se=N/M
           pilot_worst_rmse_over_noise=... design_s=...

(`designed`: the rigs whose design kept its limits and was recorded; `pilot_weak_motion`: pilots whose payload
barely moved (E4 logged on a stroke limit: the weak-motion warning), where the design stands on nothing;
`pilot_tighter_se`: the muscle and friction parameters whose standard error is smaller with the design on every
designed rig.) Everything is written under `--out`.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from identify import data_positions, score  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
TANKS = ["E1_u0.25", "E1_u0.50", "E1_u0.75", "E2_u0.25", "E2_u0.50", "E2_u0.75"]
ARMS = {"pilot + design": [*TANKS, "E4", "E5"], "E1-E4": [*TANKS, "E3", "E4"]}
MUSCLE = ["v0", "v1", "k0", "k1", "Fc", "Cf"]  # the muscle and friction parameters (with F_max(x))
FREE = ["valve.inflate.discharge_coefficient", "valve.inflate.critical_ratio", "valve.exhaust.discharge_coefficient",
        "valve.exhaust.critical_ratio", "muscle.volume_law.v0", "muscle.volume_law.v1",
        "muscle.force_law.max_force_coefficients", "muscle.force_law.k0", "muscle.force_law.k1",
        "friction.coulomb_force", "friction.viscous_coefficient"]  # the bench's 15 (examples/pilot_design.toml)


def command(args, what, allowed=(0,)):
    """Run a command; a failure (an exit status not in `allowed`) ends the benchmark naming it. Returns (stdout,
    seconds, exit status)."""
    t0 = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True, env=dict(os.environ, PAMJAX_COMPILATION_CACHE="0"))
    wall = time.perf_counter() - t0
    if proc.returncode not in allowed:
        print(proc.stdout[-4000:], proc.stderr[-4000:])
        raise SystemExit(f"{what} failed (exit {proc.returncode})")
    return proc.stdout, wall, proc.returncode


def fit_config(path, rig, runs, out):
    path.write_text(f'[model]\npreset = "mas10_system"\noptions = {{ valve = "pwm", friction = "karnopp" }}\n'
                    f'[bench]\ndir = "{rig}"\nruns = {json.dumps(runs)}\nnuisance = true\n'
                    f'[fit]\nmax_steps = 100\nout = "{out}"\n')


def design_config(path, pilot, steps, out):
    base = '{ name = "E3", signal = { kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.08 }, duration = 25.0 }'
    path.write_text(f'[model]\nfile = "{pilot / "model.json"}"\n[design]\nfree = {json.dumps(FREE)}\n'
                    f'duration = 25.0\nnoise = {{ pressure = 2e3, position = 1e-4 }}\nrate = 1000.0\n'
                    f'prior = "{pilot / "fit.json"}"\nbaseline_runs = [{base}]\nbaseline_margin = 1.0\n'
                    f'steps = {steps}\nout = "{out}"\n')


def fit_arm(rig, runs, out, name):
    cfg = out.parent / f"{out.name}.toml"
    fit_config(cfg, rig, runs, out)
    _, wall, _ = command([sys.executable, "-m", "pamjax", "fit", str(cfg), "--quiet", "--no-plot", "--overwrite"],
                         name)
    summary = json.loads((out / "bench.json").read_text())
    meta = json.loads((rig / "meta.json").read_text())  # the truth: read only to score
    positions = data_positions(rig)
    shift = meta["nuisance"]["position_offset_m"] - summary["nuisance"].get("position_offset_m", 0.0)
    scored = score(summary["params"], meta["params"], positions, shift)
    rel = scored["relative_error"]
    muscle = [abs(rel[k]) for k in MUSCLE if k in rel] + [scored.get("fmax_max_relative_error", 0.0)]
    noise = summary["noise"]
    rmse = max(v / noise["pressure" if c == "p" else "position"] for chans in summary["rmse"].values()
               for c, v in chans.items())
    return dict(status=summary["status"], max_err_pct=100 * scored["max_relative_error"],
                muscle_max_err_pct=100 * max(muscle), rmse_over_noise=rmse, wall_s=wall,
                se={k: summary["std_err"][k] for k in MUSCLE},
                err_pct={k: 100 * rel[k] for k in rel}, fmax_err_pct=100 * scored.get("fmax_max_relative_error", 0))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--rigs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=3100, help="rig i: unseen_rigs.py --seed SEED + i")
    ap.add_argument("--steps", type=int, default=40, help="design iterations at most")
    ap.add_argument("--out", default="results/design_rigs")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for i in range(args.rigs):
        seed = args.seed + i
        here = out / f"rig{seed}"
        here.mkdir(exist_ok=True)
        unseen = [sys.executable, str(ROOT / "benchmarks" / "unseen_rigs.py"), "--rigs", "1", "--seed", str(seed),
                  "--no-fit"]
        command([*unseen, "--out", str(here / "plain")], f"rig {seed}")
        pilot = here / "pilot"
        fit_config(here / "pilot.toml", here / "plain" / f"rig{seed}", [*TANKS, "E4"], pilot)
        _, pilot_s, _ = command([sys.executable, "-m", "pamjax", "fit", str(here / "pilot.toml"), "--quiet",
                                 "--no-plot", "--overwrite"], f"rig {seed}: the pilot fit")
        pilot_fit = json.loads((pilot / "fit.json").read_text())
        weak = [w.split(" (")[0] for w in pilot_fit["warnings"] if "payload never slides" in w or "slides in only" in w]
        design_config(here / "design.toml", pilot, args.steps, here / "design")
        text, design_s, code = command([sys.executable, "-m", "pamjax", "design", str(here / "design.toml"),
                                        "--quiet", "--overwrite"], f"rig {seed}: the design", allowed=(0, 1))
        predicted = [line for line in text.splitlines() if line.startswith(("muscle.", "friction.", "baseline",
                                                                            "not determined", "  VIOLATED"))]
        row = dict(seed=seed, pilot_status=pilot_fit["status"], pilot_weak_motion=weak, pilot_s=pilot_s,
                   design_s=design_s, design_failed=code != 0, predicted=predicted, arms={})
        rows.append(row)
        print(f"rig{seed}: pilot {pilot_fit['status']} ({pilot_s:.0f} s){'; ' + weak[0] if weak else ''}, design "
              f"{design_s:.0f} s" + (": FAILED, " + "; ".join(p.strip() for p in predicted if "VIOLATED" in p
                                                                  or "not determined" in p)[:300] if code else ""),
              flush=True)
        (out / "design_rigs.json").write_text(json.dumps(rows, indent=1))
        if code:  # no design.csv: nothing to record on the rig
            continue
        command([*unseen, "--design-run", str(here / "design"), "--out", str(here / "designed")],
                f"rig {seed}: the designed run")
        rig = here / "designed" / f"rig{seed}"
        row["arms"] = arms = {name: fit_arm(rig, runs, here / name.replace(" ", "").replace("+", "_"),
                                            f"rig {seed}: {name}") for name, runs in ARMS.items()}
        for name, a in arms.items():
            print(f"  {name:15s} {a['status']:10s} max {a['max_err_pct']:.3f} %, muscle/friction "
                  f"{a['muscle_max_err_pct']:.3f} %, RMSE/noise {a['rmse_over_noise']:.3f}, fit {a['wall_s']:.0f} s; "
                  "SE " + " ".join(f"{k} {a['se'][k]:.3g}" for k in MUSCLE), flush=True)
        print("  standard error, E1-E4 / (pilot + design): " + " ".join(
            f"{k} {arms['E1-E4']['se'][k] / arms['pilot + design']['se'][k]:.3f}" for k in MUSCLE), flush=True)
        (out / "design_rigs.json").write_text(json.dumps(rows, indent=1))
    done = [r for r in rows if r["arms"]]
    tighter = sum(all(r["arms"]["pilot + design"]["se"][k] < r["arms"]["E1-E4"]["se"][k] for r in done)
                  for k in MUSCLE) if done else 0

    def worst(arm, key):
        return f"{max(r['arms'][arm][key] for r in done):.3f}" if done else "nan"

    weak = sum(bool(r["pilot_weak_motion"]) for r in rows)
    print(f"RESULT rigs={len(rows)} designed={len(done)} pilot_weak_motion={weak} "
          f"pilot_max_err_pct={worst('pilot + design', 'max_err_pct')} "
          f"e1e4_max_err_pct={worst('E1-E4', 'max_err_pct')} "
          f"pilot_muscle_max_err_pct={worst('pilot + design', 'muscle_max_err_pct')} "
          f"e1e4_muscle_max_err_pct={worst('E1-E4', 'muscle_max_err_pct')} pilot_tighter_se={tighter}/{len(MUSCLE)} "
          f"pilot_worst_rmse_over_noise={worst('pilot + design', 'rmse_over_noise')} "
          f"design_s={float(np.median([r['design_s'] for r in rows])):.0f}")


if __name__ == "__main__":
    main()
