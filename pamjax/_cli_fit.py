"""`pamjax fit CONFIG.toml`: fit parameters to recordings as a TOML config describes; write the result JSON and a
figure of data vs model with residuals. See `docs/fitting.md` for the config format and `examples/fit_example.toml`."""

import dataclasses
import inspect
import pathlib
import tomllib

import numpy as np

from ._errors import PamjaxInputError
from ._parameters import FREE_ENTRY_KEYS

_TOP_KEYS = {"model", "fit", "experiment"}
_MODEL_KEYS = {"preset", "options", "set"}
_FIT_KEYS = {"free", "max_steps", "rtol", "atol", "out", "validation_fraction"}
_EXPERIMENT_KEYS = {"name", "file", "signal", "channels", "scales", "tank_volume", "initial", "rate", "filter_hz",
                    "t_end", "max_steps", "rename"}
_SIGNALS = ("Constant", "Triangle", "Sine", "Step", "recorded")
_RECORDED_KEYS = {"kind", "period"}  # signal = { kind = "recorded", period = 0.02 }: the command channel, latched
_PRESETS = ("mas10_system", "mas10_tank_system")


def add_arguments(parser):
    parser.add_argument("config", help="TOML file: [model], [fit], [[experiment]] tables (docs/fitting.md)")
    parser.add_argument("--out", default=None, help="output folder (default: [fit] out, else results/<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing results file")
    parser.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")
    parser.add_argument("--profile", action="store_true", help="also profile every fitted parameter: write "
                        "profile.json and profile.png (pamjax.profile, docs/identifiability.md)")


def check_keys(table, valid, where):
    """`table` must be a TOML table whose keys are all in `valid`; else a `PamjaxInputError` naming `where`, the
    unknown keys and the valid ones."""
    if not isinstance(table, dict):
        raise PamjaxInputError(f"{where} must be a table (keys {sorted(valid)}), got {table!r}")
    unknown = set(table) - set(valid)
    if unknown:
        raise PamjaxInputError(f"{where}: unknown key(s) {sorted(unknown)}; valid keys are {sorted(valid)}")


def read_toml(path):
    """Parse a TOML config; a missing file or a syntax error is a `PamjaxInputError` naming the file."""
    path = pathlib.Path(path)
    if not path.exists():
        raise PamjaxInputError(f"config file {path} does not exist")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise PamjaxInputError(f"config file {path} is not valid TOML: {err}") from err


def _signal_keys(spec, where):
    """The valid keys of a signal table: `kind` plus the fields of the named pamjax signal class."""
    import pamjax as pj

    if spec == "recorded":
        return None
    if not isinstance(spec, dict) or spec.get("kind") not in _SIGNALS:
        raise PamjaxInputError(f"{where} signal must be 'recorded' or a table with kind in {list(_SIGNALS)}, "
                               f"got {spec!r}")
    if spec["kind"] == "recorded":
        return _RECORDED_KEYS
    return {"kind"} | {f.name for f in dataclasses.fields(getattr(pj, spec["kind"]))}


def _initial_keys(system):
    """Keyword arguments of `system.initial_state` (e.g. pressure, position, velocity)."""
    return set(inspect.signature(system.initial_state).parameters)


def validate_config(cfg, where="config"):
    """Check every table and key of a parsed fit config against the valid ones (no data loaded, nothing solved)."""
    check_keys(cfg, _TOP_KEYS, where)
    model_cfg, fit_cfg = cfg.get("model", {}), cfg.get("fit", {})
    check_keys(model_cfg, _MODEL_KEYS, "[model]")
    check_keys(fit_cfg, _FIT_KEYS, "[fit]")
    preset = model_cfg.get("preset", "mas10_system")
    if preset not in _PRESETS:
        raise PamjaxInputError(f"[model] preset must be one of {list(_PRESETS)}, got {preset!r}")
    import pamjax as pj

    check_keys(model_cfg.get("options", {}), inspect.signature(getattr(pj.presets, preset)).parameters,
               f"[model] options (keyword arguments of presets.{preset})")
    if not isinstance(model_cfg.get("set", {}), dict):
        raise PamjaxInputError(f"[model] set must be a table of parameter path = value, got {model_cfg['set']!r}")
    if "free" not in fit_cfg:
        raise PamjaxInputError("[fit] needs 'free': the list of parameter paths to fit")
    if isinstance(fit_cfg["free"], str) or not isinstance(fit_cfg["free"], list) or not fit_cfg["free"]:
        raise PamjaxInputError(f"[fit] free must be a non-empty list of parameter paths, got {fit_cfg['free']!r}")
    for entry in fit_cfg["free"]:
        if not isinstance(entry, str):
            check_keys(entry, FREE_ENTRY_KEYS, "[fit] free entry")
    experiments = cfg.get("experiment", [])
    if not isinstance(experiments, list):
        raise PamjaxInputError("experiments are an array of tables: write [[experiment]] (double brackets)")
    if not experiments:
        raise PamjaxInputError("the config needs at least one [[experiment]]")
    for k, e in enumerate(experiments):
        here = f"[[experiment]] #{k + 1}"
        check_keys(e, _EXPERIMENT_KEYS, here)
        if "file" not in e:
            raise PamjaxInputError(f"{here} needs 'file' (a CSV or NPZ recording, relative to the config)")
        valid = _signal_keys(e.get("signal", "recorded"), here)
        if valid is not None:
            check_keys(e["signal"], valid, f"{here} signal (kind = {e['signal']['kind']!r})")
        for key in ("scales", "initial", "rename"):
            if key in e and not isinstance(e[key], dict):
                raise PamjaxInputError(f"{here} {key} must be a table, got {e[key]!r}")


def load_config(path):
    """Parse and validate a fit config; returns (model, experiments, free, fit options, out). Every key is checked
    before any data is read; parameter paths, channels and initial-state keys before anything is solved."""
    import pamjax as pj

    path = pathlib.Path(path)
    cfg = read_toml(path)
    validate_config(cfg, str(path))
    model_cfg, fit_cfg = cfg.get("model", {}), cfg["fit"]
    preset = model_cfg.get("preset", "mas10_system")
    model = getattr(pj.presets, preset)(**model_cfg.get("options", {}))
    overrides = model_cfg.get("set", {})
    if overrides:
        space = pj.ParameterSpace(model, list(overrides))  # unknown path → error listing the model's parameters
        model = space.with_values(np.concatenate([np.ravel(v) for v in overrides.values()]))
    pj.ParameterSpace(model, fit_cfg["free"])  # the same check for the free list, before any solve
    experiments = [_experiment(e, k, path.parent, fit_cfg, model) for k, e in enumerate(cfg["experiment"])]
    options = {k: fit_cfg[k] for k in ("max_steps", "rtol", "atol") if k in fit_cfg}
    return model, experiments, fit_cfg["free"], options, fit_cfg.get("out")


def _signal(spec, rec, where):
    import pamjax as pj

    if spec == "recorded" or spec["kind"] == "recorded":
        period = spec.get("period") if isinstance(spec, dict) else None
        return pj.Sampled(rec.t, rec["command"], period=period)
    kwargs = {k: v for k, v in spec.items() if k != "kind"}
    try:
        return getattr(pj, spec["kind"])(**kwargs)
    except TypeError as err:
        raise PamjaxInputError(f"{where} signal: {err}") from err


def _experiment(e, k, root, fit_cfg, model):
    import pamjax as pj

    where = f"[[experiment]] #{k + 1}"
    build = pj.TankFromModel(e["tank_volume"]) if "tank_volume" in e else None
    system = build(model) if build is not None else model
    if "initial" in e:
        check_keys(e["initial"], _initial_keys(system), f"{where} initial (keyword arguments of "
                                                        f"{type(system).__name__}.initial_state)")
    rec = pj.Recording.load(root / e["file"], rename=e.get("rename"))
    if "t_end" in e:
        rec = rec.window(None, float(e["t_end"]))
    if "filter_hz" in e:
        rec = rec.filtered(float(e["filter_hz"]))
    if "rate" in e:
        rec = rec.resampled(float(e["rate"]))
    return pj.Experiment(
        rec, _signal(e.get("signal", "recorded"), rec, where), channels=e.get("channels"), scales=e.get("scales"),
        build=build, initial=e.get("initial"), name=e.get("name", rec.name), max_steps=e.get("max_steps", 200_000),
        validation_fraction=fit_cfg.get("validation_fraction", 0.0),
    )


_UNITS = {"pressure": "[Pa abs]", "position": "[m]", "velocity": "[m/s]", "force": "[N]", "mass_flow": "[kg/s]"}


def plot(path, model, experiments):
    """Data vs model per experiment and channel, residuals below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ._experiment import predict

    cols = [(e, c) for e in experiments for c in e.channels]
    fig, axes = plt.subplots(2, len(cols), figsize=(4 * len(cols), 6), squeeze=False, sharex="col")
    for j, (e, c) in enumerate(cols):
        pred = np.asarray(predict(model, e)[c])
        data = np.asarray(e.data[c])
        t = np.asarray(e.times)
        axes[0, j].plot(t, data, ".", ms=2, label="data")
        axes[0, j].plot(t, pred, "k-", lw=0.8, label="model")
        unit = _UNITS.get(c, "")
        axes[0, j].set(title=f"{e.name}: {c}", ylabel=f"{c} {unit}".strip())
        if hasattr(e, "split_time") and float(e.split_time) < t[-1]:
            for ax in axes[:, j]:
                ax.axvline(float(e.split_time), color="C3", lw=0.8, ls="--")
        axes[1, j].plot(t, pred - data, lw=0.8)
        axes[1, j].set(xlabel="t [s]", ylabel=f"model − data {unit.replace(' abs', '')}".strip())
    if any(hasattr(e, "split_time") and float(e.split_time) < np.asarray(e.times)[-1] for e, _ in cols):
        axes[0, 0].plot([], [], color="C3", lw=0.8, ls="--", label="identification | validation")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def run(args):
    import pamjax as pj

    model, experiments, free, options, out_cfg = load_config(args.config)
    out = pathlib.Path(args.out or out_cfg or f"results/{pathlib.Path(args.config).stem}")
    result_path = out / "fit.json"
    profile_files = (out / "profile.json", out / "profile.png") if args.profile else ()
    for existing in (result_path, out / "fit.png") + profile_files:
        if existing.exists() and not args.overwrite:
            raise SystemExit(f"{existing} exists; pass --overwrite to replace it")
    print(f"fitting {len(free)} parameter entries to {len(experiments)} experiments "
          f"({', '.join(e.name for e in experiments)})", flush=True)
    res = pj.fit(model, experiments, free, progress=not args.quiet, out=result_path, overwrite=args.overwrite,
                 **options)
    print(f"status {res.status}: {res.iterations} iterations, cost {res.initial_cost:.6g} → {res.cost:.6g} "
          f"({res.fit_s:.1f} s after {res.compile_s:.1f} s compilation)")
    print(res.table())
    for name, chans in res.channel_errors.items():
        for c, e in chans.items():
            val = f", validation {e['validation_rmse_percent']:.3f} %" if "validation_rmse_percent" in e else ""
            print(f"  {name} {c}: RMSE {e['rmse']:.4g} ({e['rmse_percent']:.3f} % of range){val}")
    for w in res.warnings:
        print("WARNING:", w)
    if not args.no_plot:
        try:
            plot(out / "fit.png", res.model, experiments)
            print(f"wrote {result_path} and {out / 'fit.png'}")
        except ModuleNotFoundError:
            print(f"wrote {result_path} (no figure: matplotlib is not installed)")
    if args.profile:  # issue 17: pamjax._profile
        pj.profile(res, progress=not args.quiet).write(out, overwrite=args.overwrite, report=True)
    return 0
