"""Joint identification of paper 000's MAS-10 plant from a bench directory, starting from the datasheet presets.

    python fits/joint.py --data DIR [--out DIR] [--nuisance] [--rate HZ] [--max-steps N] [--overwrite] [--no-cache]
                         [--device auto|cpu|gpu] [--profile NAMES] [--runs NAMES]

DIR holds one recording per experiment (`<name>.npz`, `.csv` with units in its header such as `pressure [barg]`,
`position [mm]`, or `.mat`) and a `meta.json` describing them (the layout of `shared/data/hybrid-reference-bench/`
and `shared/data/bench-realistic/`; default: the former; docs/fitting.md, "Identifying your own rig"). Each run is
driven by the duty its recording logged (checked against meta.json's where both exist). The model is
`pamjax.presets.mas10_system` with the switching valve on the PWM-synchronous grid and exact stick-slip friction
(`KarnoppFriction`): every start value is a datasheet or paper value (`pamjax/presets.py`); a bench's `params` and
`nuisance` (a simulated bench's truth) are never read. The 15 parameters named in `fitted_keys` (C_v and b of both
valve paths, v0, v1, a0…a4, k0, k1, F_c, C_f; k2 held: only k0/k2 and k1/k2 are identifiable) are fitted jointly to
the tank tests (E1, E2) and the muscle runs (E3, E4), at the recordings' own rate unless `--rate` decimates them
(recorded samples, no filter). `--nuisance` fits a real rig's nuisances with them: the pressure sensor's offset and
gain and the acquisition delay (shared), each run's supply pressure, and the start state of runs whose meta.json
`init` is "unknown" (logged mid-way); the position sensor's offset is held at `--position-offset` (default 0), and
the pressure sensor's gain at `--pressure-gain` where given (a calibration: held; with `--pressure-gain-sd`, its
uncertainty, fitted with the calibration as one more datum: `pamjax.Measurement`). `--runs E1_u0.25,...,E4` fits
only the experiments named (a pilot before a design: docs/identifiability.md, "Pilot, then design").

Writes `OUT/joint.json`: `params` and `std_err` by the bench's names (SI units), `status`, `message`, `rmse` (every
experiment's residual RMSE of `p` [Pa] and `x` [m] at the recordings' rate), the noise levels, the residual
diagnostics (`diagnosis`: what a mismatch points to), with `--nuisance` the rig's `nuisance` (`delay_s`,
`pressure_offset_Pa`, `pressure_gain`, `position_offset_m`, `supply_pressure_Pa` per run, `start` per run, and
`std_err` of each; `calibration` and `gauges` where a calibration's uncertainty or supply readings were given: each
measured value, its sd and z); `OUT/model.json`, the fitted plant (`pamjax.load_model`; a `[model] file` of
`pamjax simulate` or `pamjax design`, e.g. to design the run a weak-motion warning names); and `OUT/joint.png`, data
against model with residuals. `--profile Fc,k0` (bench keys
or the fit's labels, or `all`) profiles those parameters after the fit (`pamjax.profile_likelihood`): their
likelihood-ratio intervals in `joint.json`'s `profile`, `OUT/profile.json` and `OUT/profile.png`; where a profile
finds a lower cost than the fit's, the fit is taken again from there and profiled again (`profile.refits`). A second
run refuses to replace them without `--overwrite`, which replaces them whole (an earlier `--profile`'s
profile.json and .png removed where this run profiles nothing, as `pamjax fit` does). A mistake in the data is one
line naming the file and key, exit status 2, and no output folder left behind. The compiled programs stay in the
`pamjax` command's cache directory (`PAMJAX_CACHE_DIR`; off with `--no-cache` or `PAMJAX_COMPILATION_CACHE=0`), so a
second run, on these recordings or another plant's of the same layout, loads them instead of compiling (same experiments
and lengths: the same programs).
Like the `pamjax` command's fit, it compiles with XLA's classic CPU emitters
(`pamjax.runtime.prefer_fast_compilation`; `PAMJAX_FAST_COMPILE=0` turns it off). `benchmarks/identify.py` scores the
results against a simulated bench's truth.
"""

import argparse
import pathlib
import shlex
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import bench_folder, json_text, refuse_existing  # noqa: E402

DEFAULT_DATA = bench_folder()  # the hybrid bench recordings shipped with pamjax (pamjax/data/)
# --profile: profile → (a lower cost found) fit again from it → profile again, at most this many profiles; a fit whose
# payload barely moves can have several minima about as low (docs/fitting.md, "Runs that hold the payload on a stop")
PROFILE_ROUNDS = 3  # pamjax.profile_to_minimum's default, named here for the help and the report


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DEFAULT_DATA), help="bench directory (meta.json + one recording per "
                    "experiment: <name>.npz, .csv or .mat)")
    ap.add_argument("--out", default=None, help="output directory (default results/joint_<data folder name>)")
    ap.add_argument("--rate", type=float, default=None, help="decimate the recordings to this rate [Hz]")
    ap.add_argument("--runs", default=None, metavar="NAMES",
                    help="fit only these experiments, comma-separated (e.g. the tank tests and E4 before a design: "
                         "pamjax.bench.load_bench's runs); default: every one the bench fits")
    ap.add_argument("--max-steps", type=int, default=100, help="Levenberg-Marquardt trial steps at most")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    ap.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    ap.add_argument("--joint-only", action="store_true",
                    help="fit all parameters jointly from the presets at once (no staged start: pamjax.staged_start)")
    ap.add_argument("--multistart", type=int, default=1,
                    help="fit from this many starts (the presets and draws around them) and keep the best")
    ap.add_argument("--nuisance", nargs="?", const="default", default=None, metavar="NAMES",
                    help="fit the rig's nuisances with the plant: the pressure sensor's offset and gain and the "
                         "acquisition delay (shared by all runs), each run's supply pressure, and the start state of "
                         "runs whose meta.json init is 'unknown'; or a comma-separated list of "
                         f"{', '.join(pj.bench.BENCH_NUISANCES)}")
    ap.add_argument("--position-offset", type=float, default=0.0, metavar="M",
                    help="the position sensor's calibrated offset [m] (what it reads at x = 0); held in the fit (a "
                         "shift of the position origin is absorbed by the force and volume laws: docs/fitting.md)")
    ap.add_argument("--pressure-gain", type=float, default=None, metavar="G",
                    help="the pressure sensor's calibrated gain (multiplies the gauge pressure); held in the fit "
                         "(with --nuisance, the other nuisances are freed; name pressure_gain to fit it from G). With "
                         "free supplies the runs fix the gain to ~0.3 %% only: docs/fitting.md")
    ap.add_argument("--pressure-gain-sd", type=float, default=None, metavar="SD",
                    help="the calibrated gain's standard uncertainty (absolute: 0.0005 for ±0.05 %%): the gain is "
                         "then fitted, the calibration weighed against the recordings by its uncertainty "
                         "(pamjax.Measurement)")
    ap.add_argument("--atmosphere", type=float, default=None, metavar="PA",
                    help="ambient pressure [Pa abs] that gauge readings (barg, kPa gauge) are referred to (default: "
                         "meta.json's atmosphere_Pa, else 101325)")
    ap.add_argument("--profile", default=None, metavar="NAMES",
                    help="after the fit, profile these parameters (comma-separated bench keys such as Fc,k0, or the "
                         "fit's labels; 'all': every fitted parameter): their likelihood-ratio intervals in joint.json "
                         "and OUT/profile.json, profile.png. Where a profile finds a lower cost than the fit's, fit "
                         f"again from there and profile again (at most {PROFILE_ROUNDS} rounds). Minutes per "
                         "parameter on a rig (pamjax.profile_likelihood, docs/identifiability.md)")
    ap.add_argument("--device", default="auto", choices=("auto", "cpu", "gpu", "tpu"),
                    help="where the fit runs (default auto: the CPU, where a single trajectory's solve loop is one "
                         "compiled function; on a GPU each step is a kernel launch: pamjax.runtime.for_command)")
    ap.add_argument("--no-cache", action="store_true",
                    help="compile everything anew, keep nothing (default: the persistent compilation cache, as the "
                         "pamjax command's: a second run loads the compiled programs; PAMJAX_COMPILATION_CACHE=0 too)")
    args = ap.parse_args(argv)
    # the command as given, for model.json's provenance (it said "--data DIR" alone: --nuisance, --rate left out)
    args.command = "fits/joint.py " + shlex.join(sys.argv[1:] if argv is None else [str(a) for a in argv])
    if args.multistart < 1:  # was: 0 or a negative count ran the single fit, silently
        ap.error(f"--multistart must be >= 1 (the starts fitted; 1: the presets alone), got {args.multistart}")
    return args


def _nuisance_arg(value):
    if value is None:
        return False
    if value == "default":
        return True
    return [v.strip() for v in value.split(",") if v.strip()]


def _runs_arg(value):
    return None if value is None else [v.strip() for v in value.split(",") if v.strip()]


def main(argv=None):
    """Run the identification; a mistake in the data or the arguments is one line on stderr and exit status 2
    (nothing written, no output folder left behind), Ctrl-C exit status 130."""
    args = parse_args(argv)
    data = pathlib.Path(args.data)
    out = pathlib.Path(args.out or f"results/joint_{data.resolve().name}")
    targets = [out / "joint.json", out / "model.json", out / "joint.png"]
    targets += [out / "profile.json", out / "profile.png"] if args.profile else []
    refuse_existing("joint.py", targets, args.overwrite)
    created = not out.exists()
    try:
        placed, where = pj.runtime.for_command("single", args.device)  # before JAX starts; said first
        print(f"joint.py: {where}", flush=True)
        with placed:
            run(args, data, out)
    except (pj.PamjaxInputError, FileExistsError, NotADirectoryError, PermissionError) as err:
        _clean(out, created)
        print(f"joint.py: error: {err}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        _clean(out, created)
        print("joint.py: interrupted; nothing written", file=sys.stderr)
        raise SystemExit(130) from None


def _clean(out, created):
    """Remove the output folder this run created if nothing was written into it."""
    if created and out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def run(args, data, out):
    model = pj.presets.mas10_system(valve="pwm", friction="karnopp")  # datasheet / paper values
    bench = pj.bench.load_bench(data, model, rate=args.rate, nuisance=_nuisance_arg(args.nuisance),
                                position_offset=args.position_offset, atmosphere=args.atmosphere,
                                pressure_gain=args.pressure_gain, pressure_gain_sd=args.pressure_gain_sd,
                                runs=_runs_arg(args.runs))
    profiled = _profiled(args.profile, pj.ParameterSpace(bench.model, bench.free).labels)  # named before any solve
    out.mkdir(parents=True, exist_ok=True)  # after the data are read: a mistake there leaves no folder behind
    probe = out / ".joint-write-test"
    probe.write_text("")  # the results can be written: checked before minutes of fitting
    probe.unlink()
    if not args.no_cache:  # a second run (another start, more steps, the next plant) compiles nothing again
        pj.runtime.enable_compilation_cache()
    else:  # none at all: JAX's own too, where JAX_COMPILATION_CACHE_DIR in the environment turned it on
        pj.runtime.disable_compilation_cache()
    pj.runtime.prefer_fast_compilation()  # fits of single trajectories: XLA's classic CPU emitters compile them faster
    start_model = bench.model
    print(f"bench {data}: {len(bench.experiments)} experiments ({', '.join(e.name for e in bench.experiments)}); "
          f"left out: {bench.skipped or 'none'}; noise {bench.noise}")
    for note in bench.notes:
        print(f"  {note}")
    if bench.nuisance:
        print(f"  nuisances fitted with the plant: {', '.join(bench.nuisance)}")
    t0 = time.perf_counter()
    staged = None  # the staged start (its stages' fit and compilation times count in the totals)
    if args.multistart > 1:
        runs = pj.multistart(start_model, bench.experiments, bench.free, starts=args.multistart,
                             max_steps=args.max_steps, progress=not args.quiet)
        print(runs.table())
        res = runs.best
    else:
        start = start_model
        if not args.joint_only:  # valve on the tank tests, then muscle and friction on the runs, then all jointly
            staged = pj.staged_start(start_model, bench.experiments, bench.free, max_steps=args.max_steps,
                                     progress=not args.quiet)
            start = staged.model
            print("\n".join(staged.summary()))
        res = pj.fit(start, bench.experiments, bench.free, max_steps=args.max_steps, progress=not args.quiet)
    prof, refits, profile_s = None, [], 0.0
    if profiled:  # likelihood-ratio intervals; a lower cost found on the way: fitted again from it
        print(f"profiling {', '.join(profiled)} (pamjax.profile_to_minimum: at most {PROFILE_ROUNDS} profiles)",
              flush=True)
        done = pj.profile_to_minimum(res, profiled, rounds=PROFILE_ROUNDS, max_steps=args.max_steps,
                                     progress=not args.quiet)
        res, prof, refits, profile_s = done.result, done.profile, done.refits, done.profile_s
    wall = time.perf_counter() - t0
    stages = staged.stages if staged is not None else []
    values, errors = pj.bench.bench_values(res, bench.fitted_keys)
    full = bench if args.rate is None else pj.bench.load_bench(data, model, rate=None,
                                                                nuisance=_nuisance_arg(args.nuisance),
                                                                position_offset=args.position_offset,
                                                                pressure_gain=args.pressure_gain,
                                                                pressure_gain_sd=args.pressure_gain_sd,
                                                                atmosphere=args.atmosphere, runs=_runs_arg(args.runs))
    recorded = {e.name for e in full.experiments if isinstance(e, pj.Experiment)}  # not a calibration's Measurement
    channel_errors = res.channel_errors if args.rate is None else pj.evaluate(res.model, full.experiments)
    channel_errors = {name: chans for name, chans in channel_errors.items() if name in recorded}
    rmse = {name: {"p" if c == "pressure" else "x": float(st["rmse"]) for c, st in chans.items()}
            for name, chans in channel_errors.items()}
    over_noise = {name: {c: float(st["rmse"]) / full.noise[c] for c, st in chans.items()}
                  for name, chans in channel_errors.items()}
    summary = dict(
        data=str(data), rate=args.rate, params=values, std_err=errors, status=res.status, converged=res.converged,
        message=res.message, rmse=rmse, rmse_over_noise=over_noise, noise=full.noise, mismatch=res.mismatch,
        diagnosis=res.diagnosis, warnings=res.warnings, iterations=res.iterations, cost=res.cost,
        initial_cost=res.initial_cost,
        fit_s=res.fit_s + (staged.fit_s if staged is not None else 0.0) + sum(r["fit_s"] for r in refits),
        compile_s=res.compile_s + (staged.compile_s if staged is not None else 0.0), wall_s=wall,
        held={"k2": float(model.muscle.force_law.k2)},
        skipped=bench.skipped, notes=bench.notes, start={k: v for k, v in zip(res.labels, res.initial_values)},
        presets=dict(zip(res.labels, np.asarray(pj.ParameterSpace(start_model, bench.free).initial_values()).tolist())),
        stages=[dict(stage=name, free=paths, experiments=exps, status=r.status, iterations=r.iterations, cost=r.cost,
                     fit_s=r.fit_s, compile_s=r.compile_s) for name, paths, exps, r in stages],
        joint_precompile=None if staged is None else dict(wall_s=staged.precompile_s, waited_s=staged.waited_s),
        stage2_start=None if staged is None else staged.balance,  # the force balance's start (pamjax.staged_start)
    )
    if bench.nuisance or args.position_offset or bench.calibrated:
        summary["nuisance"] = pj.bench.bench_nuisance(res, bench)
    if prof is not None:
        summary["profile"] = _profile_summary(prof, refits, profile_s)
    (out / "joint.json").write_text(json_text(summary, indent=1))
    plant = res.model.plant if isinstance(res.model, pj.Rig) else res.model  # the rig's nuisances: in joint.json
    pj.save_model(out / "model.json", plant, overwrite=True, provenance={  # what pamjax fit writes as its model.json
        "written_by": args.command, "status": res.status, "cost": res.cost, "free": res.labels,
        "covariance": pj.FitUncertainty.of(res).document()})
    report(res, values, errors, summary, over_noise)
    if prof is not None:
        print(f"profiles ({summary['profile']['profile_s']:.0f} s, {len(refits)} refit(s) from a lower point):\n"
              + prof.table())
        prof.write(out, overwrite=True)
        print(f"wrote {out / 'profile.json'} and {out / 'profile.png'}")
    elif pj.FitUncertainty.of(res).cautions:  # the fit's weak-motion warning: few samples fix the force law
        print("  the same command with --profile Fc looks along F_c for a lower minimum and fits again from it "
              "(minutes); no interval bounds the other minima: the run the warning names is what identifies them")
    plot(out / "joint.png", res.model, [e for e in full.experiments if e.name in recorded])
    if prof is None and args.overwrite:  # the earlier results replaced whole, as pamjax fit does: an earlier
        for name in ("profile.json", "profile.png"):  # --profile's files would read as this run's
            (out / name).unlink(missing_ok=True)
    print(f"wrote {out / 'joint.json'}, {out / 'model.json'} (the fitted plant: pamjax.load_model, a [model] file) "
          f"and {out / 'joint.png'}")


def _profiled(value, labels):
    """The fit's labels `--profile VALUE` names: bench keys (Fc, k0) or labels, comma-separated, or 'all'."""
    return None if value is None else pj.bench.fitted_labels(value, labels, "--profile")


def _profile_summary(prof, refits, profile_s):
    """joint.json's "profile": each profiled parameter by its bench key (else its label): likelihood-ratio and
    linearised intervals, verdict; the profiles' level, time and warnings, and the refits from a lower point."""
    params = {pj.bench.bench_key(p.label) or p.label: dict(
        value=p.value, interval=p.interval, linearised=p.linearised, verdict=p.verdict) for p in prof.profiles}
    return dict(level=prof.level, params=params, profile_s=profile_s, warnings=prof.warnings, refits=refits)


def report(res, values, errors, summary, over_noise):
    print(f"\nstatus {res.status} ({res.message}); {res.iterations} trial steps, cost {res.initial_cost:.4g} → "
          f"{res.cost:.4g}; fit {summary['fit_s']:.1f} s + compilation {summary['compile_s']:.1f} s")
    print(f"{'key':<6}{'fitted':>14}{'± std err':>12}")
    for k, v in values.items():
        print(f"{k:<6}{v:>14.6g}{errors[k]:>12.3g}")
    if "nuisance" in summary:
        print("nuisances (the rig's, reported apart from the plant):")
        print(pj.bench.nuisance_table(summary["nuisance"]))
    for name, chans in over_noise.items():
        print(f"  {name:<10} " + "  ".join(f"{c} RMSE {r:.3f}× noise" for c, r in chans.items()))
    for w in res.warnings:  # non-identifiable, a payload that barely moves, a measurement the data contradict
        if not (res.mismatch and w.startswith("model mismatch")):  # that one below, with what the residuals say
            print(f"WARNING: {w}")
    if res.mismatch:
        print("WARNING: model mismatch: standard errors understate the uncertainty")
        for hint in res.diagnosis:
            print(f"  the residuals point to {hint}")


def plot(path, model, experiments):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [e for e in experiments if "position" in e.channels]
    tanks = [e for e in experiments if "position" not in e.channels]
    fig, axes = plt.subplots(3, 1 + len(runs), figsize=(5 + 5 * len(runs), 9), squeeze=False)
    preds = dict(zip([e.name for e in experiments], pj.predictions(model, experiments)))  # as the sensors read it
    for e in tanks:
        tr = preds[e.name]
        line, = axes[0, 0].plot(e.times, np.asarray(e.data["pressure"]) / 1e5, ".", ms=1, alpha=0.4)
        axes[0, 0].plot(e.times, tr["pressure"] / 1e5, "-", color=line.get_color(), lw=0.8, label=e.name)
        axes[1, 0].plot(e.times, (tr["pressure"] - np.asarray(e.data["pressure"])) / 1e3, lw=0.5,
                        color=line.get_color())
    axes[0, 0].set(ylabel="tank pressure [bar abs]", title="tank tests: data (dots), model (lines)")
    if tanks:  # a bench of muscle runs only has no tank test to label
        axes[0, 0].legend(fontsize=6)
    else:
        axes[0, 0].text(0.5, 0.5, "no tank tests in this bench", ha="center", va="center",
                        transform=axes[0, 0].transAxes)
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
