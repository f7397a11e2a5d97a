"""`pamjax fit CONFIG.toml`: fit parameters to recordings as a TOML config describes; write the result (`fit.json`),
the complete fitted model (`model.json`, `pamjax.load_model`) and a figure of data vs model with residuals; keep a
checkpoint after every iteration (`checkpoint.npz`) that `--resume` continues bitwise. See `docs/fitting.md` for the
config and `docs/cli.md` for the files; `examples/fit_example.toml`.

`load` reads the config in one pass (docs/architecture.md, "How a config is read"): the whole config against the
schema (`schema.validate_fit`), then the model, then the fit's experiments (`build_fit`: a [bench] directory, the free
parameters checked against the model, every [[experiment]] checked against it before any recording is read, then
read; a [rig] around the plant); the output folder is created, test-written and locked before the fit starts.
"""

import pathlib
import sys
from typing import NamedTuple

import numpy as np

from .._bench.checks import run_path
from .._core import jsonio
from .._core.errors import PamjaxInputError
from .._fit.measurement import check_measured_free
from .._identifiability.profile import PROFILED_STATUSES
from . import fit_start, schema
from .config import build_model, check_initial, experiment_signal, load_recording, parameter_shape, read_toml, window_to
from .kinds import sensor_groups
from .out import PENDING, OutputFolder, interrupt_status, raise_pending

RESULT, MODEL, FIGURE, CHECKPOINT, BENCH = "fit.json", "model.json", "fit.png", "checkpoint.npz", "bench.json"
PROFILE, PROFILE_FIGURE = "profile.json", "profile.png"


def add_arguments(parser):
    parser.add_argument("config", help="TOML file: [model], [fit], [[experiment]] tables (docs/fitting.md)")
    parser.add_argument("--out", default=None, help="output folder (default: [fit] out, else results/<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace earlier results and checkpoint in --out")
    parser.add_argument("--resume", action="store_true",
                        help="continue the fit checkpointed in --out (after Ctrl-C, a crash or a max_steps stop)")
    parser.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")
    parser.add_argument("--profile", nargs="?", const="all", default=None, metavar="NAMES",
                        help="also profile every fitted parameter, or those NAMES lists (comma-separated: labels "
                        "as fit.json's, or a bench's keys such as Fc): write profile.json and profile.png "
                        "(pamjax.profile_likelihood, docs/identifiability.md)")


class FitSetup(NamedTuple):
    """What a fit config describes: the start model (a `pamjax.Rig` with a [rig] table or a bench's nuisances), the
    experiments, the free parameters, `pamjax.fit`'s options, the output folder it names, the `Bench` (None without
    a [bench] table) and whether to start stage by stage (`pamjax.staged_start`)."""

    model: object
    experiments: list
    free: list
    options: dict
    out: str | None
    bench: object = None
    staged: bool = False


def validate_config(cfg, where="config"):
    """Check every table, key and value type of a parsed fit config (no data loaded, nothing solved)."""
    schema.validate_fit(cfg, where)


def load(path):
    """The fit a config describes, read in one pass: read → validate all → build the model → build the experiments.
    Every key, type, parameter path, shape and unit is checked before any data are read; every recording is read
    before anything is compiled."""
    path = pathlib.Path(path)
    cfg = read_toml(path)
    schema.validate_fit(cfg, str(path))
    model = build_model(cfg.get("model", {}), path.parent)
    return build_fit(cfg, model, path.parent)


def load_config(path):
    """Parse and validate a fit config; returns (model, experiments, free, fit options, out) (`load`)."""
    return tuple(load(path))[:5]


def build_fit(cfg, model, root):
    """The `FitSetup` of a validated config and its model: the bench's experiments (a [bench] table), the free
    parameters checked against the model, the [[experiment]] tables, then the [rig] around the plant."""
    fit_cfg = cfg.get("fit", {})
    experiments, free, bench = [], fit_cfg.get("free"), None
    if "bench" in cfg:
        bench = _bench(cfg["bench"], model, root)
        experiments += bench.experiments
        model = bench.model  # the plant, or a pamjax.Rig holding it with the rig's nuisances
        free = bench.free if free is None else _with_nuisance(free, bench)
    check_free(model, free)
    experiments += build_experiments(cfg.get("experiment", []), model, root, fit_cfg.get("validation_fraction", 0.0))
    names = [e.name for e in experiments]
    if len(set(names)) != len(names):
        raise PamjaxInputError(f"experiment names must be unique, got {names}: give each [[experiment]] a name")
    if "rig" in cfg:
        model, free = _rig(cfg["rig"], cfg.get("experiment", []), model, experiments, free)
    experiments += build_measurements(cfg.get("measurement", []), model)
    check_measured_free(model, experiments, free)  # each measured parameter free: named before any data are fitted
    names = [e.name for e in experiments]
    if len(set(names)) != len(names):
        raise PamjaxInputError(f"experiment and measurement names must be unique, got {names}: give each a name")
    options = {k: fit_cfg[k] for k in ("max_steps", "ftol", "xtol", "gtol") if k in fit_cfg}
    staged = bench is not None and cfg["bench"].get("staged", True)  # pamjax.staged_start first (the default)
    return FitSetup(model, experiments, free, options, fit_cfg.get("out"), bench, staged)


def _with_nuisance(free, bench):
    """[fit] free (the plant's paths, `plant.` on the rig) with the nuisances [bench] frees appended (was: dropped,
    silently, with `nuisance = true`): `[bench] nuisance` chooses them (a list of names for some), and its gauges'
    and calibration's measurements need them free."""
    given = {entry if isinstance(entry, str) else entry.get("path") for entry in free}
    added = [path for path in bench.nuisance if path not in given]
    if added:
        bench.notes.append(f"[fit] free: the nuisances [bench] frees are fitted beside it ({', '.join(added)})")
    return [*free, *added]


def _bench(table, model, root):
    import pamjax as pj

    return pj.bench.load_bench(
        pathlib.Path(root) / table["dir"], model, rate=table.get("rate"),
        kinds=tuple(table.get("kinds", pj.bench.FITTED_KINDS)), fitted_keys=table.get("fitted_keys"),
        substeps=table.get("substeps", 16), nuisance=table.get("nuisance", False),
        position_offset=table.get("position_offset", 0.0), atmosphere=table.get("atmosphere"),
        pressure_gain=table.get("pressure_gain"), pressure_gain_sd=table.get("pressure_gain_sd"),
        runs=table.get("runs"))


def build_measurements(tables, model):
    """`pamjax.Measurement`s of validated [[measurement]] tables (a parameter's independent measurement with its
    uncertainty: a calibration, a reference gauge), each checked against the fitted model."""
    import pamjax as pj

    out = []
    for k, table in enumerate(tables):
        try:
            m = pj.Measurement(table["path"], table["value"], table["sd"], name=table.get("name"))
            m.check(model)
        except PamjaxInputError as err:
            raise PamjaxInputError(f"[[measurement]] #{k + 1}: {err}") from None
        out.append(m)
    return out


def check_free(model, free, where="[fit] free"):
    """The free entries against the model, before any solve: every path, index and transform (`ParameterSpace`),
    and a table's `scale` one number or one per element of its parameter (matched by name and shape)."""
    import pamjax as pj

    for entry in free:
        if isinstance(entry, str) or "scale" not in entry:
            continue
        try:
            *_, shape = parameter_shape(model, entry["path"], where)
        except PamjaxInputError:
            continue  # an unknown path: named by ParameterSpace below
        given = np.shape(entry["scale"])
        if given not in ((), shape):
            raise PamjaxInputError(f"{where} entry {entry['path']!r}: scale expects one number or shape {shape}, "
                                   f"got shape {given} ({entry['scale']!r})")
    pj.ParameterSpace(model, free)  # unknown path, index or transform: named, before any solve


def build_experiments(tables, model, root, validation_fraction=0.0):
    """`pamjax.Experiment`s of validated [[experiment]] tables: each checked against `model` first (its `initial`
    keys against the system it drives), then each recording read, windowed, filtered and resampled."""
    import pamjax as pj

    systems, plant = [], model.plant if isinstance(model, pj.Rig) else model  # a [bench]'s rig: its plant
    for k, e in enumerate(tables):
        build = (pj.TankFromModel(e["tank_volume"]) if "tank_volume" in e
                 else pj.PayloadFromModel(e["payload_kg"]) if "payload_kg" in e else None)
        if "initial" in e:
            check_initial(build(plant) if build is not None else plant, e["initial"], f"{_where(k)} initial")
        systems.append(build)
    experiments = []
    for k, (e, build) in enumerate(zip(tables, systems)):
        rec = load_recording(e, root)
        if "t_end" in e:
            rec = window_to(rec, float(e["t_end"]), f"{_where(k)} t_end")
        if "filter_hz" in e:
            rec = rec.filtered(float(e["filter_hz"]))
        if "rate" in e:
            rec = rec.resampled(float(e["rate"]))
        experiments.append(pj.Experiment(
            rec, experiment_signal(e, _where(k), rec, plant), channels=e.get("channels"),
            scales=e.get("scales"), build=build, initial=e.get("initial"), name=e.get("name", rec.name),
            max_steps=e.get("max_steps", 200_000), validation_fraction=validation_fraction,
            stepping=e.get("stepping", "auto"), sensors=e.get("sensors", "rig")))
    return experiments


def _where(k):
    return f"[[experiment]] #{k + 1}"


def _rig(rig_cfg, tables, model, experiments, free):
    """The model as a `pamjax.Rig` with the [rig] table's sensors and each [[experiment]]'s run conditions, and
    `free` with the plant's paths under `plant.` and the nuisances [rig] free names."""
    import pamjax as pj

    groups = sensor_groups(rig_cfg.get("sensors", {}))
    used = {e.sensor_group for e in experiments}
    unused = sorted(g for g in groups if g not in used and groups[g])  # a typo'd group: its values would do nothing
    if unused:
        raise PamjaxInputError(f"[rig] sensors: no [[experiment]] reads its sensors as {unused} (their groups: "
                               f"{sorted(used)}; an experiment's `sensors` key names its group, \"rig\" by default)")
    groups = {g: _sensors(pj, g, groups.get(g, {})) for g in used | set(groups)}
    wanted = set(rig_cfg.get("free", []))
    runs, nuisance = {}, []
    for table, e in zip(tables, experiments):
        supply = table.get("supply_pressure")
        if "supply_pressure" in wanted and supply is None:
            try:
                supply = float(e.system_for(model).valve.supply())
            except PamjaxInputError:
                supply = None  # a valve without a supply pressure (averaged): nothing to fit
        start = pj.StartState(**{k: float(v) for k, v in table["start"].items()}) if "start" in table else None
        if supply is not None or start is not None:
            runs[e.name] = pj.RunConditions(supply_pressure=supply, start=start)
        if "supply_pressure" in wanted and supply is not None:
            nuisance.append(run_path(e.name, "supply_pressure", "[[experiment]] name"))
        if "start" in wanted and start is not None:
            nuisance += [run_path(e.name, f"start.{k}", "[[experiment]] name") for k in table["start"]]
    for g in sorted(groups):
        channels = {c for e in experiments if e.sensor_group == g for c in e.channels}
        for field in schema.SENSOR_FIELDS:
            acts = field == "delay" or any(field in pj.Sensors.channel_parameters(c) for c in channels)
            if field in wanted and acts:
                nuisance.append(f"sensors[{g}].{field}")
    plant_free = [f"plant.{p}" if isinstance(p, str) else {**p, "path": f"plant.{p['path']}"} for p in free]
    return pj.Rig(model, sensors=groups, runs=runs), plant_free + nuisance


def _sensors(pj, group, values):
    """`pamjax.Sensors` of a [rig] sensors group's start values; an implausible one named by its key."""
    try:
        return pj.Sensors(**{k: float(v) for k, v in values.items()})
    except PamjaxInputError as e:
        raise PamjaxInputError(f"[rig] sensors{'' if group == 'rig' else '.' + group}: {e}") from None


_UNITS = {"pressure": "[Pa abs]", "position": "[m]", "velocity": "[m/s]", "force": "[N]", "mass_flow": "[kg/s]"}


def _columns(experiments, result=None):
    """The figure's columns (`pamjax/_cli/fit_figure.py`): per experiment and channel its data, and the fit
    `result`'s predictions as the model (none without a result: what the figure's process lays out in advance)."""
    columns = []
    for e in experiments:
        if e.split_time is None:  # no time axis (a parameter's Measurement: in the printed report)
            continue
        t = np.asarray(e.times)
        split = float(e.split_time) if e.split_time is not None and float(e.split_time) < t[-1] else None
        for c in e.channels:
            columns.append(dict(title=f"{e.name}: {c}", channel=c, unit=_UNITS.get(c, ""), t=t,
                                data=np.asarray(e.data[c]), split=split))
            if result is not None:
                columns[-1]["model"] = np.asarray(result.predictions[e.name][c])
    return columns


def plot(path, result, experiments):
    """Data vs model per experiment and channel (the fit result's predictions), residuals below
    (`pamjax/_cli/fit_figure.py`; drawn in the process `run` started, if any)."""
    from . import figures, fit_figure

    figures.draw(fit_figure, path, _columns(experiments, result))


def _resume_command(args, out):
    profile = "" if not args.profile else " --profile" if args.profile == "all" else f" --profile {args.profile}"
    return f"pamjax fit {args.config} --out {out} --resume{profile}"


def profiled_labels(value, labels):
    """The labels `--profile VALUE` names among a fit's `labels` (bench keys such as Fc, labels, or 'all'; None
    without --profile), checked before the fit (`pamjax.bench.fitted_labels`)."""
    import pamjax as pj

    return None if value is None else pj.bench.fitted_labels(value, labels, "--profile")


def run(args):
    try:  # starting the figure's process and reading the config (the model built): a second a Ctrl-C may fall in
        if not args.no_plot:  # matplotlib imported and warmed up in a process of its own while the fit runs
            from . import figures, fit_figure

            figures.start(fit_figure)
        model, experiments, free, options, out_cfg, bench, staged = load(args.config)
        if args.profile is not None:  # the names checked before any work
            import pamjax as pj

            profiled_labels(args.profile, pj.ParameterSpace(model, free).labels)
        if not args.no_plot:  # the figure laid out with the data while the fit runs
            figures.prepare(fit_figure, _columns(experiments))
    except KeyboardInterrupt as err:
        PENDING.clear()  # handled here
        what = "terminated" if interrupt_status(err) == 143 else "interrupted"
        print(f"pamjax fit: {what} while reading {args.config}, before the fit started; nothing to resume, nothing "
              "written", file=sys.stderr, flush=True)
        return interrupt_status(err)
    out = pathlib.Path(args.out if args.out is not None else out_cfg or f"results/{pathlib.Path(args.config).stem}")
    if args.resume and args.overwrite:
        raise PamjaxInputError("pamjax fit: --resume continues the fit in --out, --overwrite starts it again: "
                               "give one of them")
    # a damaged checkpoint named here (with --overwrite it is replaced)
    earlier = None if args.overwrite else fit_start.checkpoint_summary(out / CHECKPOINT, strict=True)
    if earlier and not (args.resume or args.overwrite):  # named before the generic "exists" of the outputs
        if (out / RESULT).exists():
            raise PamjaxInputError(f"pamjax fit: {out / RESULT} exists; pass --overwrite to replace it (or --resume "
                                   "to continue that fit, e.g. with a larger [fit] max_steps)")
        raise PamjaxInputError(f"pamjax fit: {out / CHECKPOINT} holds an earlier fit (checkpointed after {earlier}); "
                               "continue it with --resume, or start again with --overwrite")
    if args.resume and not (out / CHECKPOINT).is_file():  # refused before the output folder is made
        raise PamjaxInputError(f"pamjax fit --resume: {out} holds no checkpoint ({CHECKPOINT}); run without "
                               "--resume to start the fit")
    outputs = [RESULT, MODEL, CHECKPOINT] + ([] if args.no_plot else [FIGURE]) + ([BENCH] if bench else []) \
        + ([fit_start.STAGED_START] if staged else [])
    if args.profile:
        outputs += [PROFILE] + ([] if args.no_plot else [PROFILE_FIGURE])
    # --resume replaces what the resumed run wrote (its checkpoint proves it is the same problem); a staged start
    # without a checkpoint (a run stopped before the joint fit's first iteration) is replaced by the next start
    replaceable = outputs if args.resume else [fit_start.STAGED_START]
    stale = [FIGURE, BENCH, fit_start.STAGED_START, PROFILE, PROFILE_FIGURE]  # what an earlier fit here may have left
    with OutputFolder(out, "pamjax fit", outputs, overwrite=args.overwrite, replaceable=replaceable,
                      stale=stale) as folder:
        checkpoint = folder / CHECKPOINT
        stage = {}  # "profiling": True once the fit's results are written and the profiles are being taken
        found = fit_start.file_state(checkpoint)  # an --overwrite run's earlier checkpoint: not this run's to resume
        try:
            return _fit_and_write(args, folder, model, experiments, free, options, bench, staged, stage)
        except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM: one line on what is kept and how to go on
            PENDING.clear()  # handled here
            what = "terminated" if interrupt_status(err) == 143 else "interrupted"
            ours = args.resume or fit_start.file_state(checkpoint) != found  # --resume: the checkpoint is this fit's
            where = fit_start.checkpoint_summary(checkpoint) if ours else None
            if stage.get("profiling"):
                print(f"pamjax fit: {what} while profiling; the fit itself is complete and written ({out / RESULT}, "
                      f"{out / MODEL}); no profile was written. Take the profiles with: {_resume_command(args, out)}",
                      file=sys.stderr, flush=True)
            elif where is None:
                again = f"pamjax fit {args.config} --out {out}" + (" --overwrite" if args.overwrite else "")
                kept = "" if found is None or ours else f"; {checkpoint} is the earlier fit's, left as it was"
                print(f"pamjax fit: {what} before the first iteration finished; nothing to resume (this run "
                      f"checkpointed nothing{kept}): run {again} to start again", file=sys.stderr, flush=True)
            else:
                print(f"pamjax fit: {what}; the checkpoint after {where} is kept in {checkpoint}. Resume with: "
                      f"{_resume_command(args, out)}", file=sys.stderr, flush=True)
            return interrupt_status(err)


def _print_bench(bench):
    """The bench's runs left out (grouped by reason) and the loader's notes."""
    reasons = {}
    for name, reason in bench.skipped.items():
        reasons.setdefault(reason, []).append(name)
    left = "; ".join(f"{', '.join(names)} ({reason})" for reason, names in reasons.items()) or "none"
    print(f"bench {bench.directory}: left out: {left}", flush=True)
    for note in bench.notes:
        print(f"  {note}", flush=True)


def print_errors(channel_errors):
    """Each experiment's channels: RMSE (and validation RMSE) in % of range; a parameter's measurement: measured,
    fitted, and how many of its uncertainties apart."""
    for name, chans in channel_errors.items():
        for c, e in chans.items():
            if "z" in e:  # a parameter's Measurement
                print(f"  {name}: measured {e['measured']:.6g} ± {e['sd']:.3g}, fitted {e['fitted']:.6g} "
                      f"({e['z']:+.2f} uncertainties)")
                continue
            val = f", validation {e['validation_rmse_percent']:.3f} %" if "validation_rmse_percent" in e else ""
            print(f"  {name} {c}: RMSE {e['rmse']:.4g} ({e['rmse_percent']:.3f} % of range){val}")


def _fit_and_write(args, folder, model, experiments, free, options, bench=None, staged=False, stage=None):
    import pamjax as pj

    checkpoint = folder / CHECKPOINT
    done = fit_start.checkpoint_summary(checkpoint) if args.resume else None
    print(f"fitting {len(free)} parameter entries to {len(experiments)} experiments "
          f"({', '.join(e.name for e in experiments)})" + (f", resuming from {done}" if done else "")
          + f"; checkpoint {checkpoint}", flush=True)
    if bench is not None:  # what the loader left out and what it found, as fits/joint.py prints them
        _print_bench(bench)

    def progress(step, cost, step_size, accepted):  # fit's own line, and the point where a signal is honoured
        if not args.quiet:
            print(f"  iter {step:4d}  cost {cost:.6e}  damping {step_size:.3e}  "
                  f"{'accepted' if accepted else 'rejected'}", flush=True)
        raise_pending()

    kept = fit_start.load(folder / fit_start.STAGED_START, model, experiments, free) if staged and args.resume \
        else None
    if kept is not None:  # the start the resumed fit began at, as it was computed (fit_start's docstring)
        model, summary = kept
        print(f"the staged start of the fit resumed ({fit_start.STAGED_START}):", flush=True)
        for line in summary:
            print(f"  {line}", flush=True)
    elif staged:  # valve on the tank tests, muscle on the runs, then the joint fit
        staged_fit = pj.staged_start(model, experiments, free, max_steps=options.get("max_steps", 100),
                                     progress=progress)
        fit_start.save(folder, model, experiments, free, staged_fit)
        model = staged_fit.model
        for line in staged_fit.summary():
            print(line, flush=True)
    res = pj.fit(model, experiments, free, progress=progress, checkpoint=checkpoint,
                 resume=checkpoint if args.resume else None, overwrite=args.overwrite, **options)
    raise_pending()
    _report_and_write(args, folder, res, experiments, bench)
    if args.profile and res.status not in PROFILED_STATUSES:  # not a minimum: profiles would mean nothing
        print(f"pamjax fit: error: no profile taken: the fit stopped with status {res.status!r}, not at a minimum of "
              "the cost, where every profile would fall below the fit and read as non-identifiable. The fit is "
              f"written ({folder / RESULT}, {folder / MODEL}); raise [fit] max_steps in {args.config} and continue "
              f"it with: {_resume_command(args, folder.path)}", file=sys.stderr, flush=True)
        return 1
    if args.profile:  # pamjax.profile_to_minimum along the named parameters, re-using the fit's compiled programs
        if stage is not None:
            stage["profiling"] = True
        void = _profile_and_write(args, folder, res, experiments, bench, progress, options.get("max_steps", 100))
        if void:  # still a lower cost after the refits: the profiles are written, each verdict void
            return 1
    return 1 if folder.failed else 0


def _report_and_write(args, folder, res, experiments, bench):
    """Print a fit's report and write fit.json, model.json, bench.json (a [bench]) and the figure."""
    import pamjax as pj

    from .._files.model_file import model_json

    print(f"status {res.status}: {res.iterations} iterations, cost {res.initial_cost:.6g} → {res.cost:.6g} "
          f"({res.fit_s:.1f} s after {res.compile_s:.1f} s compilation)")
    print(res.table())
    print_errors(res.channel_errors)
    for w in res.warnings:
        print("WARNING:", w)
    if res.status == "max_steps":
        print(f"not converged within max_steps = {res.iterations}: raise [fit] max_steps and continue with "
              f"{_resume_command(args, folder.path)}")
    provenance = {"written_by": f"pamjax fit {args.config}", "status": res.status, "cost": res.cost,
                  "free": res.labels, "result": RESULT,
                  "covariance": pj.FitUncertainty.of(res).document()}  # what --band propagates (docs/cli.md)
    plant = res.model.plant if isinstance(res.model, pj.Rig) else res.model  # the rig's nuisances: in bench.json
    written = [folder.write_text(RESULT, jsonio.dumps(res.to_dict(), indent=1) + "\n"),
               folder.write_text(MODEL, model_json(plant, provenance))]
    if bench is not None:  # the bench's names: params, std_err, status, rmse of p [Pa] and x [m] per experiment
        values, errors = pj.bench.bench_values(res, bench.fitted_keys)
        summary = dict(data=str(bench.directory), params=values, std_err=errors, status=res.status,
                       message=res.message, rmse=pj.bench.bench_rmse(res), noise=bench.noise, mismatch=res.mismatch,
                       diagnosis=res.diagnosis, notes=bench.notes, skipped=bench.skipped)  # as joint.json's
        if bench.nuisance or bench.calibrated:
            summary["nuisance"] = pj.bench.bench_nuisance(res, bench)
            print("nuisances (the rig's, reported apart from the plant):\n"
                  + pj.bench.nuisance_table(summary["nuisance"]))
        written.append(folder.write_text(BENCH, jsonio.dumps(summary, indent=1) + "\n"))
    if isinstance(res.model, pj.Rig) and (bench is None or not (bench.nuisance or bench.calibrated)):  # [rig]
        report = pj.nuisance_report(res)
        lines = [f"  {kind}[{name}].{field}: {v:.6g} ± {se:.3g}" for kind in ("sensors", "runs")
                 for name, fields in report[kind].items() for field, (v, se) in fields.items()]
        print("nuisances (the rig's, reported apart from the plant; also in fit.json):\n" + "\n".join(lines))
    if not args.no_plot:
        try:
            written.append(folder.write(FIGURE, lambda p: plot(p, res, experiments)))
        except ModuleNotFoundError:
            print("no figure: matplotlib is not installed (pip install matplotlib)")
    print("wrote " + ", ".join(str(p) for p in written if p is not None))


def _profile_and_write(args, folder, res, experiments, bench, progress, max_steps):
    """Profile the named parameters (`pamjax.profile_to_minimum`); where a profile finds a lower cost, the fit from
    there replaces the fit's files (the checkpoint keeps the first fit: `--resume --profile` takes the same path
    again). Writes profile.json (with the refits) and profile.png; returns whether the verdicts are void."""
    import pamjax as pj

    done = pj.profile_to_minimum(res, profiled_labels(args.profile, res.labels), max_steps=max_steps,
                                 progress=not args.quiet, fit_progress=progress)
    raise_pending()
    prof = done.profile
    if done.refits:
        print(f"the profiles found a lower cost than the fit's: {len(done.refits)} refit(s) from the lowest point, "
              f"cost {res.cost:.6g} → {done.result.cost:.6g}; the refit's results replace the fit's (the checkpoint "
              "keeps the first fit: --resume --profile takes the same path again)", flush=True)
        _report_and_write(args, folder, done.result, experiments, bench)
    print(f"profiles ({done.profile_s:.1f} s):\n{prof.table()}")
    for w in prof.warnings:
        print(f"pamjax fit: error: {w}", file=sys.stderr, flush=True)
    written = [folder.write_text(PROFILE, jsonio.dumps(dict(prof.to_dict(), refits=done.refits), indent=1) + "\n")]
    if not args.no_plot:
        try:
            written.append(folder.write(PROFILE_FIGURE, prof.plot))
        except ModuleNotFoundError:
            print("no profile figure: matplotlib is not installed (pip install matplotlib)")
    print("wrote " + ", ".join(str(p) for p in written if p is not None))
    return bool(prof.warnings)
