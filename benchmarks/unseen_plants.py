"""Identification on plants nobody has seen: new bench directories drawn as the perturbed sets were, then fitted.

    python benchmarks/unseen_plants.py [--plants 4] [--seed 100] [--substeps 64] [--out results/unseen_plants]

The two perturbed sets of `shared/data/hybrid-reference-bench-perturbed/` are "the truth set's value of every fitted
parameter × a draw from U(0.8, 1.2), k2 fixed". Further plants of that kind are how pamjax's identification is
judged, so this script makes `--plants` more of them and runs `benchmarks/identify.py` (each set fitted by
`fits/joint.py` from the datasheet presets, in a fresh process) on them:

1. For plant i: the truth set's `params` (meta.json) with each of its `fitted_keys` × U(0.8, 1.2) (NumPy seed
   `--seed` + i); the experiments of the truth set's meta.json that are fitted (tank charge / discharge at 25/50/75 %
   duty, 2 s each; the triangle runs E3 and E4 from rest); the bench's noise (2 kPa, 0.1 mm) and 1 kHz.
2. Recordings simulated by pamjax with exact stick-slip (Karnopp, events located inside the step) on the
   PWM-synchronous grid with `--substeps` RK4 nodes per PWM period (64: four times the fits' 16, so that the model
   that fits is not the one that made the data to the last bit; the bench itself comes from an independent LSODA
   simulation, which this cannot replace), written as `<name>.npz` (t, u, p, x) and `meta.json` in the bench layout.
3. `benchmarks/identify.py --sets ...` on the new directories: accuracy, residuals over the noise, convergence and
   time per plant, and its RESULT line.

The plants' directories are written under `--out` (not part of the repository). Ends with identify.py's
    RESULT sets=... converged=... max_param_err_pct=... worst_rmse_over_noise=... fit_s=... compile_s=...
"""

import argparse
import importlib.metadata
import json
import os
import pathlib
import subprocess
import sys

os.environ.setdefault("JAX_ENABLE_COMPILATION_CACHE", "false")
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / ".." / "shared" / "data" / "hybrid-reference-bench"
SHORT = {"pressure": "p", "position": "x", "command": "u"}  # the bench's short names


def draw_params(meta, rng):
    """The truth set's parameters with every fitted one × U(0.8, 1.2) (k2 is not fitted, so it stays)."""
    params = dict(meta["params"])
    for key in meta["fitted_keys"]:
        params[key] = float(params[key]) * float(rng.uniform(0.8, 1.2))
    return params


def truth_model(model, bench, params):
    """The preset model with `params`' values of the bench's fitted parameters."""
    space = pj.ParameterSpace(model, bench.free)
    return space.with_values(np.asarray([params[pj.bench.bench_key(label)] for label in space.labels]))


def write_plant(directory, meta, params, truth, bench, substeps, seed):
    """Simulate every fitted experiment of the bench on `truth` and write the bench layout into `directory`."""
    directory.mkdir(parents=True, exist_ok=True)
    noise = {"pressure": meta["noise"]["p_std_Pa"], "position": meta["noise"]["x_std_m"]}
    rng = np.random.default_rng(seed)
    for e in bench.experiments:
        t = np.asarray(e.times, dtype=float)
        system = e.system_for(truth)
        y0 = e.start_for(system, truth)
        traj = pj.simulate(system, e.signal, t, y0=y0, stepping="pwm", substeps=substeps)
        if int(traj.result) != 0:
            raise SystemExit(f"{directory.name}/{e.name}: the truth's solve failed (result {int(traj.result)})")
        columns = {"t": t, "u": np.asarray(traj.command, dtype=float)}
        for channel, short in (("pressure", "p"), ("position", "x")):
            if channel in traj.channels() and channel in e.channels:
                clean = np.asarray(traj.channel(channel), dtype=float)
                columns[short] = clean + noise[channel] * rng.standard_normal(clean.shape)
            elif short == "x":
                columns["x"] = np.zeros_like(t)  # the bench's tank tests: x = 0 exactly (no motion, no noise)
        np.savez(directory / f"{e.name}.npz", **columns)
    out = dict(meta, params=params)
    out["experiments"] = {k: v for k, v in meta["experiments"].items() if k in {e.name for e in bench.experiments}}
    version = importlib.metadata.version("pamjax")
    out["generated_by"] = (f"benchmarks/unseen_plants.py: pamjax {version}, PWM-synchronous grid with "
                           f"{substeps} RK4 nodes per period, exact stick-slip; noise seed {seed}")
    (directory / "meta.json").write_text(json.dumps(out, indent=1) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", type=int, default=4)
    ap.add_argument("--seed", type=int, default=100, help="plant i draws with NumPy seed SEED + i")
    ap.add_argument("--substeps", type=int, default=64, help="RK4 nodes per PWM period of the simulation")
    ap.add_argument("--bench", default=str(BENCH), help="the truth set whose parameters are perturbed")
    ap.add_argument("--out", default="results/unseen_plants")
    args = ap.parse_args(argv)
    if args.plants < 1:
        raise SystemExit("--plants must be >= 1")
    out = pathlib.Path(args.out)
    meta = json.loads((pathlib.Path(args.bench) / "meta.json").read_text())
    model = pj.presets.mas10_system(valve="pwm", friction="karnopp")
    bench = pj.bench.load_bench(args.bench, model)
    sets = []
    for i in range(args.plants):
        seed = args.seed + i
        params = draw_params(meta, np.random.default_rng(seed))
        directory = out / f"plant{seed}"
        write_plant(directory, meta, params, truth_model(model, bench, params), bench, args.substeps, seed)
        ratios = ", ".join(f"{k} {params[k] / meta['params'][k]:.3f}" for k in meta["fitted_keys"])
        print(f"{directory}: × truth set: {ratios}", flush=True)
        sets.append(str(directory))
    cmd = [sys.executable, str(ROOT / "benchmarks" / "identify.py"), "--sets", *sets, "--out", str(out / "fits")]
    sys.exit(subprocess.run(cmd).returncode)


if __name__ == "__main__":
    main()
