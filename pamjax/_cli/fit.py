"""`pamjax fit CONFIG.toml`: fit parameters to recordings as a TOML config describes; write the result (`fit.json`),
the complete fitted model (`model.json`, `pamjax.load_model`) and a figure of data vs model with residuals; keep a
checkpoint after every iteration (`checkpoint.npz`) that `--resume` continues bitwise. See `docs/fitting.md` for the
config and `docs/cli.md` for the files; `examples/fit_example.toml`.

Every key, type, parameter path, shape and unit of the config is checked before any data are read or anything is
compiled; the output folder is created, test-written and locked before the fit starts.
"""

import json
import pathlib
import sys

import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import check_setting
from .._fit.parameters import FREE_ENTRY_KEYS
from .._fit.profile import PROFILED_STATUSES
from .config import (
    build_model,
    check_keys,
    make_signal,
    read_toml,
    require,
    signal_keys,
    validate_model_table,
)
from .out import PENDING, OutputFolder, interrupt_status, raise_pending

_TOP_KEYS = {"model", "fit", "experiment", "bench", "rig"}
_RIG_KEYS = {"sensors", "free"}
_SENSOR_FIELDS = ("pressure_offset", "pressure_gain", "position_offset", "delay")
_RIG_FREE = _SENSOR_FIELDS + ("supply_pressure", "start")
_FIT_KEYS = {"free", "max_steps", "ftol", "xtol", "gtol", "out", "validation_fraction"}
_BENCH_KEYS = {"dir", "rate", "kinds", "fitted_keys", "substeps", "staged", "nuisance", "position_offset",
               "atmosphere"}
_EXPERIMENT_KEYS = {"name", "file", "signal", "channels", "scales", "tank_volume", "initial", "rate", "filter_hz",
                    "sensors", "supply_pressure", "start",
                    "t_end", "max_steps", "rename", "units", "unit_checks", "stepping"}
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
    parser.add_argument("--profile", action="store_true", help="also profile every fitted parameter: write "
                        "profile.json and profile.png (pamjax.profile, docs/identifiability.md)")


def _check_free(free):
    if not free:
        raise PamjaxInputError("[fit] free must be a non-empty list of parameter paths, e.g. "
                               '["friction.coulomb_force"]')
    for entry in free:
        if isinstance(entry, str):
            continue
        check_keys(entry, FREE_ENTRY_KEYS, "[fit] free entry")
        if "path" not in entry:
            raise PamjaxInputError(f"[fit] free entry {entry!r} needs a path")
        if "bounds" in entry:
            b = entry["bounds"]
            if not (isinstance(b, list) and len(b) == 2 and all(isinstance(x, (int, float)) for x in b)):
                raise PamjaxInputError(f"[fit] free entry {entry['path']!r}: bounds must be [lo, hi] (two numbers), "
                                       f"got {b!r}")


def _check_free_shapes(model, free):
    """A free table's `scale` must be one number or one per element of its parameter (matched by name and shape)."""
    from .._fit.parameters import _parse, join_path, parameter_paths

    valid = parameter_paths(model)
    for entry in free:
        if isinstance(entry, str) or "scale" not in entry:
            continue
        attrs, index = _parse(entry["path"])
        shape = () if index is not None else valid.get(join_path(attrs))
        given = np.shape(entry["scale"])
        if shape is not None and given not in ((), shape):
            raise PamjaxInputError(f"[fit] free entry {entry['path']!r}: scale expects one number or shape {shape}, "
                                   f"got shape {given} ({entry['scale']!r})")


def validate_config(cfg, where="config"):
    """Check every table, key and value type of a parsed fit config (no data loaded, nothing solved)."""
    check_keys(cfg, _TOP_KEYS, where)
    model_cfg, fit_cfg = cfg.get("model", {}), cfg.get("fit", {})
    validate_model_table(model_cfg)
    for old, new in (("rtol", "ftol"), ("atol", "xtol")):
        if isinstance(fit_cfg, dict) and old in fit_cfg:
            raise PamjaxInputError(f"[fit] {old} is no longer a setting: the fit stops on the relative cost decrease "
                                   f"({new} and its siblings ftol, xtol, gtol; docs/fitting.md)")
    check_keys(fit_cfg, _FIT_KEYS, "[fit]")
    bench_cfg = cfg.get("bench")
    if bench_cfg is not None:
        check_keys(bench_cfg, _BENCH_KEYS, "[bench]")
        if "dir" not in bench_cfg:
            raise PamjaxInputError("[bench] needs 'dir': a bench directory (meta.json + <experiment>.npz), relative "
                                   "to the config")
        require(bench_cfg["dir"], "string", "[bench] dir", '"../data/my-bench"')
        for key, kind, example in (("rate", "positive number", "1000.0 (Hz)"), ("substeps", "positive integer", "16"),
                                   ("kinds", "list of strings", '["tank_charge", "muscle_triangle"]'),
                                   ("fitted_keys", "list of strings", '["Cv12", "b12", "Fc"]'),
                                   ("staged", "boolean", "false"), ("position_offset", "number", "0.0 (m)"),
                                   ("atmosphere", "positive number", "101325.0 (Pa abs)")):
            if key in bench_cfg:
                require(bench_cfg[key], kind, f"[bench] {key}", example)
        if "nuisance" in bench_cfg and not isinstance(bench_cfg["nuisance"], bool):
            require(bench_cfg["nuisance"], "list of strings", "[bench] nuisance",
                    'true, or ["delay", "pressure_offset", "supply_pressure"]')
    rig_cfg = cfg.get("rig")
    if rig_cfg is not None:
        _validate_rig(rig_cfg, bench_cfg)
    if "free" not in fit_cfg and bench_cfg is None:
        raise PamjaxInputError("[fit] needs 'free': the list of parameter paths to fit")
    if "free" not in fit_cfg:
        pass  # the bench's fitted_keys
    elif isinstance(fit_cfg["free"], str) or not isinstance(fit_cfg["free"], list):
        raise PamjaxInputError(f"[fit] free must be a non-empty list of parameter paths, got {fit_cfg['free']!r}"
                               + (" (a single string where a list is expected: put it in brackets)"
                                  if isinstance(fit_cfg["free"], str) else ""))
    if "free" in fit_cfg:
        _check_free(fit_cfg["free"])
    for key, kind, example in (("max_steps", "positive integer", "40"), ("ftol", "positive number", "1e-10"),
                               ("xtol", "positive number", "1e-10"), ("gtol", "positive number", "1e-10"),
                               ("out", "string", '"results/my_fit"'), ("validation_fraction", "number", "0.4")):
        if key in fit_cfg:
            require(fit_cfg[key], kind, f"[fit] {key}", example)
    if not 0 <= fit_cfg.get("validation_fraction", 0.0) < 1:
        raise PamjaxInputError(f"[fit] validation_fraction must be in [0, 1), got {fit_cfg['validation_fraction']}")
    experiments = cfg.get("experiment", [])
    if not isinstance(experiments, list):
        raise PamjaxInputError("experiments are an array of tables: write [[experiment]] (double brackets)")
    if not experiments and bench_cfg is None:
        raise PamjaxInputError("the config needs at least one [[experiment]] (or a [bench] directory)")
    for k, e in enumerate(experiments):
        _validate_experiment(e, f"[[experiment]] #{k + 1}")


def _validate_rig(rig_cfg, bench_cfg):
    if not isinstance(rig_cfg, dict):
        raise PamjaxInputError(f"[rig] must be a table, got {rig_cfg!r}")
    check_keys(rig_cfg, _RIG_KEYS, "[rig]")
    if bench_cfg is not None:
        raise PamjaxInputError("[rig] describes the nuisances of [[experiment]] tables; a [bench] directory takes "
                               "them as [bench] nuisance = true (or a list)")
    sensors = rig_cfg.get("sensors", {})
    if not isinstance(sensors, dict):
        raise PamjaxInputError(f"[rig] sensors must be a table of start values, got {sensors!r}")
    groups = sensors if all(isinstance(v, dict) for v in sensors.values()) and sensors else {"rig": sensors}
    for group, values in groups.items():
        check_keys(values, set(_SENSOR_FIELDS), f"[rig] sensors{'' if group == 'rig' else '.' + group}")
        for key, value in values.items():
            require(value, "number", f"[rig] sensors.{key}", "0.0")
    if "free" in rig_cfg:
        require(rig_cfg["free"], "list of strings", "[rig] free", '["pressure_offset", "delay", "supply_pressure"]')
        unknown = sorted(set(rig_cfg["free"]) - set(_RIG_FREE))
        if unknown:
            raise PamjaxInputError(f"[rig] free names {unknown}, not nuisances pamjax fits; valid: {list(_RIG_FREE)}")


def _validate_experiment(e, here):
    check_keys(e, _EXPERIMENT_KEYS, here)
    if "file" not in e:
        raise PamjaxInputError(f"{here} needs 'file' (a CSV or NPZ recording, relative to the config)")
    require(e["file"], "string", f"{here} file", '"triangle_025.csv"')
    valid = signal_keys(e.get("signal", "recorded"), here)
    if valid is not None:
        check_keys(e["signal"], valid, f"{here} signal (kind = {e['signal']['kind']!r})")
    for key in ("scales", "initial", "rename", "units"):
        if key in e and not isinstance(e[key], dict):
            raise PamjaxInputError(f"{here} {key} must be a table, got {e[key]!r}")
    if "channels" in e:
        require(e["channels"], "list of strings", f"{here} channels", '["pressure", "position"]')
    if "stepping" in e and e["stepping"] not in ("auto", "adaptive", "pwm", "grid"):
        raise PamjaxInputError(f"{here} stepping must be 'auto', 'adaptive', 'pwm' or 'grid', got {e['stepping']!r}")
    for key, kind, example in (("name", "string", '"triangle"'), ("tank_volume", "positive number", "5e-5 (m³)"),
                               ("rate", "positive number", "100.0 (Hz)"), ("filter_hz", "positive number", "20.0"),
                               ("t_end", "positive number", "8.0 (s)"), ("max_steps", "positive integer", "200000"),
                               ("unit_checks", "boolean", "false")):
        if key in e:
            require(e[key], kind, f"{here} {key}", example)
    for c, s in e.get("scales", {}).items():
        require(s, "positive number", f"{here} scales.{c}", "2e3 (the channel's noise level, in its SI unit)")
    if "sensors" in e:
        require(e["sensors"], "string", f"{here} sensors", '"rig" (a [rig] sensors group)')
    if "supply_pressure" in e:
        require(e["supply_pressure"], "positive number", f"{here} supply_pressure", "6.5e5 (Pa abs)")
        check_setting("supply_pressure", e["supply_pressure"], here)
    if "start" in e:
        if not isinstance(e["start"], dict):
            raise PamjaxInputError(f"{here} start must be a table {{pressure = ..., position = ..., velocity = ...}} "
                                   f"(a run logged mid-way), got {e['start']!r}")
        check_keys(e["start"], {"pressure", "position", "velocity"}, f"{here} start")
        for key, value in e["start"].items():
            require(value, "number", f"{here} start.{key}", "4e5")
    for key, value in e.get("initial", {}).items():
        require(value, "number", f"{here} initial.{key}", "101325.0")
        check_setting(key, value, f"{here} initial")
    if "tank_volume" in e:
        check_setting("tank_volume", e["tank_volume"], here)
    for table in ("rename", "units"):
        for k, v in e.get(table, {}).items():
            require(v, "string", f"{here} {table}.{k}", '"pressure"' if table == "rename" else '"bar abs"')


def load_config(path):
    """Parse and validate a fit config; returns (model, experiments, free, fit options, out). Every key is checked
    before any data is read; parameter paths, shapes, channels and initial-state keys before anything is solved."""
    return _load(path)[:5]


def _load(path):
    """`load_config` and the config's `Bench` (None without a [bench] table)."""
    import pamjax as pj

    path = pathlib.Path(path)
    cfg = read_toml(path)
    validate_config(cfg, str(path))
    fit_cfg = cfg.get("fit", {})
    model = build_model(cfg.get("model", {}), path.parent)
    experiments, free = [], fit_cfg.get("free")
    bench = None
    if "bench" in cfg:
        b = cfg["bench"]
        kinds = tuple(b.get("kinds", pj.FITTED_KINDS))
        bench = pj.load_bench(path.parent / b["dir"], model, rate=b.get("rate"), kinds=kinds,
                              fitted_keys=b.get("fitted_keys"), substeps=b.get("substeps", 16),
                              nuisance=b.get("nuisance", False), position_offset=b.get("position_offset", 0.0),
                              atmosphere=b.get("atmosphere"))
        experiments += bench.experiments
        model = bench.model  # the plant, or a pamjax.Rig holding it with the rig's nuisances
        free = bench.free if free is None else free
    _check_free_shapes(model, free)
    pj.ParameterSpace(model, free)  # unknown path, index or transform: named, before any solve
    experiments += [_experiment(e, k, path.parent, fit_cfg, model) for k, e in enumerate(cfg.get("experiment", []))]
    names = [e.name for e in experiments]
    if len(set(names)) != len(names):
        raise PamjaxInputError(f"experiment names must be unique, got {names}: give each [[experiment]] a name")
    if "rig" in cfg:
        model, free = _rig(cfg["rig"], cfg.get("experiment", []), model, experiments, free)
    options = {k: fit_cfg[k] for k in ("max_steps", "ftol", "xtol", "gtol") if k in fit_cfg}
    staged = bench is not None and cfg["bench"].get("staged", True)  # pamjax.staged_start first (the default)
    return model, experiments, free, options, fit_cfg.get("out"), bench, staged


def _rig(rig_cfg, tables, model, experiments, free):
    """The model as a `pamjax.Rig` with the [rig] table's sensors and each [[experiment]]'s run conditions, and
    `free` with the plant's paths under `plant.` and the nuisances [rig] free names."""
    import pamjax as pj

    sensors = rig_cfg.get("sensors", {})
    groups = sensors if sensors and all(isinstance(v, dict) for v in sensors.values()) else {"rig": sensors}
    used = {e.sensor_group for e in experiments}
    groups = {g: pj.Sensors(**{k: float(v) for k, v in groups.get(g, {}).items()}) for g in used | set(groups)}
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
            nuisance.append(f"runs[{e.name}].supply_pressure")
        if "start" in wanted and start is not None:
            nuisance += [f"runs[{e.name}].start.{k}" for k in table["start"]]
    for g in sorted(groups):
        channels = {c for e in experiments if e.sensor_group == g for c in e.channels}
        for field in _SENSOR_FIELDS:
            acts = field == "delay" or any(field in pj.Sensors.channel_parameters(c) for c in channels)
            if field in wanted and acts:
                nuisance.append(f"sensors[{g}].{field}")
    plant_free = [f"plant.{p}" if isinstance(p, str) else {**p, "path": f"plant.{p['path']}"} for p in free]
    return pj.Rig(model, sensors=groups, runs=runs), plant_free + nuisance


def _experiment(e, k, root, fit_cfg, model):
    import inspect

    import pamjax as pj

    where = f"[[experiment]] #{k + 1}"
    build = pj.TankFromModel(e["tank_volume"]) if "tank_volume" in e else None
    system = build(model) if build is not None else model
    if "initial" in e:
        check_keys(e["initial"], set(inspect.signature(system.initial_state).parameters),
                   f"{where} initial (keyword arguments of {type(system).__name__}.initial_state)")
    rec = pj.Recording.load(root / e["file"], rename=e.get("rename"), units=e.get("units"),
                            unit_checks=e.get("unit_checks", True))
    if "t_end" in e:
        rec = rec.window(None, float(e["t_end"]))
    if "filter_hz" in e:
        rec = rec.filtered(float(e["filter_hz"]))
    if "rate" in e:
        rec = rec.resampled(float(e["rate"]))
    return pj.Experiment(
        rec, make_signal(e.get("signal", "recorded"), where, rec), channels=e.get("channels"), scales=e.get("scales"),
        build=build, initial=e.get("initial"), name=e.get("name", rec.name), max_steps=e.get("max_steps", 200_000),
        validation_fraction=fit_cfg.get("validation_fraction", 0.0), stepping=e.get("stepping", "auto"),
        sensors=e.get("sensors", "rig"),
    )


_UNITS = {"pressure": "[Pa abs]", "position": "[m]", "velocity": "[m/s]", "force": "[N]", "mass_flow": "[kg/s]"}


def plot(path, result, experiments):
    """Data vs model per experiment and channel (the fit result's predictions), residuals below
    (`pamjax/_cli/fit_figure.py`; drawn in the process `run` started, if any)."""
    from . import figures, fit_figure

    columns = []
    for e in experiments:
        t = np.asarray(e.times)
        split = float(e.split_time) if hasattr(e, "split_time") and float(e.split_time) < t[-1] else None
        for c in e.channels:
            columns.append(dict(title=f"{e.name}: {c}", channel=c, unit=_UNITS.get(c, ""), t=t,
                                data=np.asarray(e.data[c]), model=np.asarray(result.predictions[e.name][c]),
                                split=split))
    figures.draw(fit_figure, path, columns)


def _checkpoint_summary(path):
    """'iteration k (cost c)' of a checkpoint, or None if there is none."""
    try:
        with np.load(path, allow_pickle=False) as f:
            history = f["history"]
        return f"iteration {int(history[-1][0])} (cost {history[-1][1]:.6g})"
    except (OSError, KeyError, ValueError, IndexError):
        return None


def _resume_command(args, out):
    return f"pamjax fit {args.config} --out {out} --resume" + (" --profile" if args.profile else "")


def run(args):
    if not args.no_plot:  # matplotlib imported and warmed up in a process of its own while the fit runs
        from . import figures, fit_figure

        figures.start(fit_figure)
    model, experiments, free, options, out_cfg, bench, staged = _load(args.config)
    out = pathlib.Path(args.out or out_cfg or f"results/{pathlib.Path(args.config).stem}")
    if args.resume and args.overwrite:
        raise PamjaxInputError("pamjax fit: --resume continues the fit in --out, --overwrite starts it again: "
                               "give one of them")
    earlier = _checkpoint_summary(out / CHECKPOINT) if (out / CHECKPOINT).is_file() else None
    if earlier and not (args.resume or args.overwrite):  # named before the generic "exists" of the outputs
        if (out / RESULT).exists():
            raise PamjaxInputError(f"pamjax fit: {out / RESULT} exists; pass --overwrite to replace it (or --resume "
                                   "to continue that fit, e.g. with a larger [fit] max_steps)")
        raise PamjaxInputError(f"pamjax fit: {out / CHECKPOINT} holds an earlier fit (checkpointed after {earlier}); "
                               "continue it with --resume, or start again with --overwrite")
    outputs = [RESULT, MODEL, CHECKPOINT] + ([] if args.no_plot else [FIGURE]) + ([BENCH] if bench else [])
    if args.profile:
        outputs += [PROFILE] + ([] if args.no_plot else [PROFILE_FIGURE])
    # --resume replaces what the resumed run wrote (its checkpoint proves it is the same problem)
    replaceable = outputs if args.resume else []
    with OutputFolder(out, "pamjax fit", outputs, overwrite=args.overwrite, replaceable=replaceable) as folder:
        checkpoint = folder / CHECKPOINT
        if args.resume and not checkpoint.exists():
            raise PamjaxInputError(f"pamjax fit --resume: {out} holds no checkpoint ({CHECKPOINT}); run without "
                                   "--resume to start the fit")
        stage = {}  # "profiling": True once the fit's results are written and the profiles are being taken
        try:
            return _fit_and_write(args, folder, model, experiments, free, options, bench, staged, stage)
        except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM: one line on what is kept and how to go on
            PENDING.clear()  # handled here
            what = "terminated" if interrupt_status(err) == 143 else "interrupted"
            where = _checkpoint_summary(checkpoint)
            if stage.get("profiling"):
                print(f"pamjax fit: {what} while profiling; the fit itself is complete and written ({out / RESULT}, "
                      f"{out / MODEL}); no profile was written. Take the profiles with: {_resume_command(args, out)}",
                      file=sys.stderr, flush=True)
            elif where is None:
                again = f"pamjax fit {args.config} --out {out}" + (" --overwrite" if args.overwrite else "")
                print(f"pamjax fit: {what} before the first iteration finished; nothing to resume: run {again} to "
                      "start again", file=sys.stderr, flush=True)
            else:
                print(f"pamjax fit: {what}; the checkpoint after {where} is kept in {checkpoint}. Resume with: "
                      f"{_resume_command(args, out)}", file=sys.stderr, flush=True)
            return interrupt_status(err)


def _fit_and_write(args, folder, model, experiments, free, options, bench=None, staged=False, stage=None):
    import pamjax as pj

    from .._fit.model_io import model_json

    checkpoint = folder / CHECKPOINT
    done = _checkpoint_summary(checkpoint) if args.resume else None
    print(f"fitting {len(free)} parameter entries to {len(experiments)} experiments "
          f"({', '.join(e.name for e in experiments)})" + (f", resuming from {done}" if done else "")
          + f"; checkpoint {checkpoint}", flush=True)

    def progress(step, cost, step_size, accepted):  # fit's own line, and the point where a signal is honoured
        if not args.quiet:
            print(f"  iter {step:4d}  cost {cost:.6e}  damping {step_size:.3e}  "
                  f"{'accepted' if accepted else 'rejected'}", flush=True)
        raise_pending()

    if staged:  # valve on the tank tests, muscle on the runs, then the joint fit
        # (deterministic: a --resume computes the same start again, which its checkpoint's fingerprint checks)
        staged = pj.staged_start(model, experiments, free, max_steps=options.get("max_steps", 100),
                                 progress=progress)
        model = staged.model
        for line in staged.summary():
            print(line, flush=True)
    res = pj.fit(model, experiments, free, progress=progress, checkpoint=checkpoint,
                 resume=checkpoint if args.resume else None, overwrite=args.overwrite, **options)
    raise_pending()
    print(f"status {res.status}: {res.iterations} iterations, cost {res.initial_cost:.6g} → {res.cost:.6g} "
          f"({res.fit_s:.1f} s after {res.compile_s:.1f} s compilation)")
    print(res.table())
    for name, chans in res.channel_errors.items():
        for c, e in chans.items():
            val = f", validation {e['validation_rmse_percent']:.3f} %" if "validation_rmse_percent" in e else ""
            print(f"  {name} {c}: RMSE {e['rmse']:.4g} ({e['rmse_percent']:.3f} % of range){val}")
    for w in res.warnings:
        print("WARNING:", w)
    if res.status == "max_steps":
        print(f"not converged within max_steps = {res.iterations}: raise [fit] max_steps and continue with "
              f"{_resume_command(args, folder.path)}")
    provenance = {"written_by": f"pamjax fit {args.config}", "status": res.status, "cost": res.cost,
                  "free": res.labels, "result": RESULT,
                  "covariance": pj.FitUncertainty.of(res).document()}  # what --band propagates (docs/cli.md)
    plant = res.model.plant if isinstance(res.model, pj.Rig) else res.model  # the rig's nuisances: in bench.json
    written = [folder.write_text(RESULT, json.dumps(res.to_dict(), indent=1) + "\n"),
               folder.write_text(MODEL, model_json(plant, provenance))]
    if bench is not None:  # the bench's names: params, std_err, status, rmse of p [Pa] and x [m] per experiment
        values, errors = pj.bench_values(res, bench.fitted_keys)
        summary = dict(data=str(bench.directory), params=values, std_err=errors, status=res.status,
                       message=res.message, rmse=pj.bench_rmse(res), noise=bench.noise, mismatch=res.mismatch,
                       diagnosis=res.diagnosis, notes=bench.notes)
        if bench.nuisance:
            summary["nuisance"] = pj.bench_nuisance(res, bench)
            print("nuisances (the rig's, reported apart from the plant):\n" + pj.nuisance_table(summary["nuisance"]))
        written.append(folder.write_text(BENCH, json.dumps(summary, indent=1) + "\n"))
    if isinstance(res.model, pj.Rig) and (bench is None or not bench.nuisance):  # a [rig] table's nuisances
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
    if args.profile and res.status not in PROFILED_STATUSES:  # not a minimum: profiles would mean nothing
        print(f"pamjax fit: error: no profile taken: the fit stopped with status {res.status!r}, not at a minimum of "
              "the cost, where every profile would fall below the fit and read as non-identifiable. The fit is "
              f"written ({folder / RESULT}, {folder / MODEL}); raise [fit] max_steps in {args.config} and continue "
              f"it with: {_resume_command(args, folder.path)}", file=sys.stderr, flush=True)
        return 1
    if args.profile:  # pamjax.profile along every fitted parameter, re-using the fit's compiled programs
        if stage is not None:
            stage["profiling"] = True
        written, void = _profile_and_write(args, folder, res)
        if void:  # a re-fit found a lower cost: the profiles are written, each verdict void
            return 1
    return 1 if folder.failed else 0


def _profile_and_write(args, folder, res):
    import pamjax as pj

    prof = pj.profile(res, progress=not args.quiet)
    print(f"profiles ({prof.profile_s:.1f} s):\n{prof.table()}")
    for w in prof.warnings:
        print(f"pamjax fit: error: {w}", file=sys.stderr, flush=True)
    written = [folder.write_text(PROFILE, json.dumps(prof.to_dict(), indent=1) + "\n")]
    if not args.no_plot:
        try:
            written.append(folder.write(PROFILE_FIGURE, prof.plot))
        except ModuleNotFoundError:
            print("no profile figure: matplotlib is not installed (pip install matplotlib)")
    print("wrote " + ", ".join(str(p) for p in written if p is not None))
    return written, bool(prof.warnings)
