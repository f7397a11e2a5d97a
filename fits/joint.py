"""Joint identification of paper 000's MAS-10 plant from a bench directory, starting from the datasheet presets.

    python fits/joint.py --data DIR [--out DIR] [--rate HZ] [--max-steps N] [--overwrite] [--no-cache]

DIR holds one `.npz` recording per experiment and a `meta.json` describing them (the layout of
`shared/data/hybrid-reference-bench/`; default: that directory). The model is `pamjax.presets.mas10_system` with
the switching valve on the PWM-synchronous grid and exact stick-slip friction (`KarnoppFriction`): every start value
is a datasheet or paper value (`pamjax/presets.py`), never the bench's `params`, which are read only to score the
result when present. The 15 parameters named in `fitted_keys` (C_v and b of both valve paths, v0, v1, a0…a4, k0,
k1, F_c, C_f; k2 held: only k0/k2 and k1/k2 are identifiable) are fitted jointly to the tank tests (E1, E2) and the
triangle runs (E3, E4), at the recordings' own rate unless `--rate` decimates them (recorded samples, no filter).

Writes `OUT/joint.json`: `params` and `std_err` by the bench's names (SI units), `status`, `message`, `rmse`
(every experiment's 1 kHz residual RMSE of `p` [Pa] and `x` [m]), the noise levels, the residual diagnostics and,
when the bench lists its true parameters, `score` (relative errors, F_max over the recorded stroke); and
`OUT/joint.png`, data against model with residuals. A second run refuses to replace them without `--overwrite`.
The compiled programs stay in the `pamjax` command's cache directory (`PAMJAX_CACHE_DIR`; off with `--no-cache` or
`PAMJAX_COMPILATION_CACHE=0`), so a second run, on these recordings or another plant's of the same layout, loads
them instead of compiling (same experiments and lengths: the same programs). Like the `pamjax` command's fit, it
compiles with XLA's classic CPU emitters (`pamjax.prefer_fast_compilation`; `PAMJAX_FAST_COMPILE=0` turns it off).
"""

import argparse
import json
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import bench_folder  # noqa: E402

DEFAULT_DATA = bench_folder()  # the hybrid bench recordings shipped with pamjax (pamjax/data/)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DEFAULT_DATA), help="bench directory (meta.json + <experiment>.npz)")
    ap.add_argument("--out", default=None, help="output directory (default results/joint_<data folder name>)")
    ap.add_argument("--rate", type=float, default=None, help="decimate the recordings to this rate [Hz]")
    ap.add_argument("--max-steps", type=int, default=100, help="Levenberg-Marquardt trial steps at most")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    ap.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    ap.add_argument("--joint-only", action="store_true",
                    help="fit all parameters jointly from the presets at once (no staged start: pamjax.staged_start)")
    ap.add_argument("--multistart", type=int, default=1,
                    help="fit from this many starts (the presets and draws around them) and keep the best")
    ap.add_argument("--no-cache", action="store_true",
                    help="compile everything anew, keep nothing (default: the persistent compilation cache, as the "
                         "pamjax command's: a second run loads the compiled programs; PAMJAX_COMPILATION_CACHE=0 too)")
    return ap.parse_args(argv)


def score(values, truth, bench):
    """Relative errors against the bench's true parameters, and F_max(x) of a0…a4 against the truth's over the stroke
    the triangle runs cover (the a_i one by one are ill-conditioned; the curve is what the data determine)."""
    rel = {k: (values[k] - truth[k]) / abs(truth[k]) for k in values if k in truth and truth[k] != 0}
    out = {"relative_error": rel}
    if all(f"a{i}" in values and f"a{i}" in truth for i in range(5)):
        xs = np.concatenate([e.data["position"] for e in bench.experiments if "position" in e.channels])
        x = np.linspace(float(np.min(xs)), float(np.max(xs)), 200)
        fit_f = np.polyval([values[f"a{i}"] for i in range(4, -1, -1)], x)
        true_f = np.polyval([truth[f"a{i}"] for i in range(4, -1, -1)], x)
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


def main(argv=None):
    args = parse_args(argv)
    data = pathlib.Path(args.data)
    out = pathlib.Path(args.out or f"results/joint_{data.resolve().name}")
    targets = [out / "joint.json", out / "joint.png"]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not args.overwrite:
        sys.exit(f"joint.py: {', '.join(existing)} exist; pass --overwrite to replace them (or another --out)")
    out.mkdir(parents=True, exist_ok=True)
    if not args.no_cache:  # a second run (another start, more steps, the next plant) compiles nothing again
        pj.enable_compilation_cache()
    pj.prefer_fast_compilation()  # fits of single trajectories: XLA's classic CPU emitters compile them faster

    model = pj.presets.mas10_system(valve="pwm", friction="karnopp")  # datasheet / paper values
    bench = pj.load_bench(data, model, rate=args.rate)
    print(f"bench {data}: {len(bench.experiments)} experiments ({', '.join(e.name for e in bench.experiments)}); "
          f"left out: {bench.skipped or 'none'}; noise {bench.noise}")
    t0 = time.perf_counter()
    staged = None  # the staged start (its stages' fit and compilation times count in the totals)
    if args.multistart > 1:
        runs = pj.multistart(model, bench.experiments, bench.free, starts=args.multistart, max_steps=args.max_steps,
                             progress=not args.quiet)
        print(runs.table())
        res = runs.best
    else:
        start = model
        if not args.joint_only:  # valve on the tank tests, then muscle and friction on the runs, then all jointly
            staged = pj.staged_start(model, bench.experiments, bench.free, max_steps=args.max_steps,
                                     progress=not args.quiet)
            start = staged.model
            print("\n".join(staged.summary()))
        res = pj.fit(start, bench.experiments, bench.free, max_steps=args.max_steps, progress=not args.quiet)
    wall = time.perf_counter() - t0
    stages = staged.stages if staged is not None else []
    values, errors = pj.bench_values(res, bench.fitted_keys)
    full = bench if args.rate is None else pj.load_bench(data, model, rate=None)
    channel_errors = res.channel_errors if args.rate is None else pj.evaluate(res.model, full.experiments)
    rmse = {name: {"p" if c == "pressure" else "x": float(st["rmse"]) for c, st in chans.items()}
            for name, chans in channel_errors.items()}
    over_noise = {name: {c: float(st["rmse"]) / full.noise[c] for c, st in chans.items()}
                  for name, chans in channel_errors.items()}
    summary = dict(
        data=str(data), rate=args.rate, params=values, std_err=errors, status=res.status, converged=res.converged,
        message=res.message, rmse=rmse, rmse_over_noise=over_noise, noise=full.noise, mismatch=res.mismatch,
        warnings=res.warnings, iterations=res.iterations, cost=res.cost, initial_cost=res.initial_cost,
        fit_s=res.fit_s + sum(r.fit_s for *_, r in stages),
        compile_s=res.compile_s + (staged.compile_s if staged is not None else 0.0), wall_s=wall,
        held={"k2": float(model.muscle.force_law.k2)},
        skipped=bench.skipped, start={k: v for k, v in zip(res.labels, res.initial_values)},
        presets=dict(zip(res.labels, np.asarray(pj.ParameterSpace(model, bench.free).initial_values()).tolist())),
        stages=[dict(stage=name, free=paths, experiments=exps, status=r.status, iterations=r.iterations, cost=r.cost,
                     fit_s=r.fit_s, compile_s=r.compile_s) for name, paths, exps, r in stages],
        joint_precompile=None if staged is None else dict(wall_s=staged.precompile_s, waited_s=staged.waited_s),
    )
    truth = bench.meta.get("params")
    if truth:
        summary["score"] = score(values, truth, full)
    (out / "joint.json").write_text(json.dumps(summary, indent=1))
    report(res, values, errors, truth, summary, over_noise)
    plot(out / "joint.png", res.model, full.experiments)
    print(f"wrote {out / 'joint.json'} and {out / 'joint.png'}")


def report(res, values, errors, truth, summary, over_noise):
    print(f"\nstatus {res.status} ({res.message}); {res.iterations} trial steps, cost {res.initial_cost:.4g} → "
          f"{res.cost:.4g}; fit {res.fit_s:.1f} s + compilation {res.compile_s:.1f} s")
    print(f"{'key':<6}{'fitted':>14}{'± std err':>12}" + (f"{'true':>14}{'error %':>10}" if truth else ""))
    for k, v in values.items():
        row = f"{k:<6}{v:>14.6g}{errors[k]:>12.3g}"
        if truth and k in truth:
            row += f"{truth[k]:>14.6g}{100 * (v - truth[k]) / abs(truth[k]):>10.3f}"
        print(row)
    for name, chans in over_noise.items():
        print(f"  {name:<10} " + "  ".join(f"{c} RMSE {r:.3f}× noise" for c, r in chans.items()))
    if "score" in summary:
        sc = summary["score"]
        print(f"F_max over the recorded stroke: max error {100 * sc.get('fmax_max_relative_error', np.nan):.2f} %; "
              f"worst compared quantity {100 * sc['max_relative_error']:.2f} %")
    if res.mismatch:
        print("WARNING:", [w for w in res.warnings if w.startswith("model mismatch")][0])


def plot(path, model, experiments):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [e for e in experiments if "position" in e.channels]
    tanks = [e for e in experiments if "position" not in e.channels]
    fig, axes = plt.subplots(3, 1 + len(runs), figsize=(5 + 5 * len(runs), 9), squeeze=False)
    preds = dict(zip([e.name for e in experiments], pj.predictions(model, experiments)))
    for e in tanks:
        tr = preds[e.name]
        line, = axes[0, 0].plot(e.times, np.asarray(e.data["pressure"]) / 1e5, ".", ms=1, alpha=0.4)
        axes[0, 0].plot(e.times, tr["pressure"] / 1e5, "-", color=line.get_color(), lw=0.8, label=e.name)
        axes[1, 0].plot(e.times, (tr["pressure"] - np.asarray(e.data["pressure"])) / 1e3, lw=0.5,
                        color=line.get_color())
    axes[0, 0].set(ylabel="tank pressure [bar abs]", title="tank tests: data (dots), model (lines)")
    axes[0, 0].legend(fontsize=6)
    axes[1, 0].set(xlabel="t [s]", ylabel="model − data [kPa]", title="tank residuals")
    axes[2, 0].axis("off")
    for k, e in enumerate(runs, start=1):
        tr = preds[e.name]
        axes[0, k].plot(e.times, 1e3 * np.asarray(e.data["position"]), ".", ms=1, alpha=0.4, label="data")
        axes[0, k].plot(e.times, 1e3 * tr["position"], "k-", lw=0.7, label="model")
        axes[0, k].set(ylabel="position [mm]", title=f"{e.name}")
        axes[0, k].legend(fontsize=7)
        axes[1, k].plot(e.times, np.asarray(e.data["pressure"]) / 1e5, ".", ms=1, alpha=0.4)
        axes[1, k].plot(e.times, tr["pressure"] / 1e5, "k-", lw=0.5)
        axes[1, k].set(ylabel="pressure [bar abs]")
        axes[2, k].plot(e.times, 1e3 * (tr["position"] - np.asarray(e.data["position"])), lw=0.4,
                        label="position [mm]")
        axes[2, k].plot(e.times, (tr["pressure"] - np.asarray(e.data["pressure"])) / 1e4, lw=0.4,
                        alpha=0.7, label="pressure [10 kPa]")
        axes[2, k].set(xlabel="t [s]", ylabel="model − data", title="residuals")
        axes[2, k].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
