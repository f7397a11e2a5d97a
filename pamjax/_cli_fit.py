"""`pamjax fit CONFIG.toml`: fit parameters to recordings as a TOML config describes; write the result JSON and a
figure of data vs model with residuals. See `docs/fitting.md` for the config format and `examples/fit_example.toml`."""

import pathlib
import tomllib

import numpy as np

from ._errors import PamjaxInputError

_TOP_KEYS = {"model", "fit", "experiment"}
_MODEL_KEYS = {"preset", "options", "set"}
_FIT_KEYS = {"free", "max_steps", "rtol", "atol", "out", "validation_fraction"}
_EXPERIMENT_KEYS = {"name", "file", "signal", "channels", "scales", "tank_volume", "initial", "rate", "filter_hz",
                    "t_end", "max_steps", "rename"}
_SIGNALS = {"Constant", "Triangle", "Sine", "Step", "recorded"}


def add_arguments(parser):
    parser.add_argument("config", help="TOML file: [model], [fit], [[experiment]] tables (docs/fitting.md)")
    parser.add_argument("--out", default=None, help="output folder (default: [fit] out, else results/<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing results file")
    parser.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")


def _check_keys(table, valid, where):
    unknown = set(table) - set(valid)
    if unknown:
        raise PamjaxInputError(f"{where}: unknown key(s) {sorted(unknown)}; valid keys are {sorted(valid)}")


def load_config(path):
    """Parse and validate a fit config; returns (model, experiments, free, fit options)."""
    import pamjax as pj

    path = pathlib.Path(path)
    if not path.exists():
        raise PamjaxInputError(f"config file {path} does not exist")
    cfg = tomllib.loads(path.read_text())
    _check_keys(cfg, _TOP_KEYS, str(path))
    model_cfg, fit_cfg = cfg.get("model", {}), cfg.get("fit", {})
    _check_keys(model_cfg, _MODEL_KEYS, "[model]")
    _check_keys(fit_cfg, _FIT_KEYS, "[fit]")
    preset = model_cfg.get("preset", "mas10_system")
    builders = {k: getattr(pj.presets, k) for k in ("mas10_system", "mas10_tank_system")}
    if preset not in builders:
        raise PamjaxInputError(f"[model] preset must be one of {sorted(builders)}, got {preset!r}")
    model = builders[preset](**model_cfg.get("options", {}))
    overrides = model_cfg.get("set", {})
    if overrides:
        space = pj.ParameterSpace(model, list(overrides))
        model = space.with_values(np.concatenate([np.ravel(v) for v in overrides.values()]))
    if "free" not in fit_cfg:
        raise PamjaxInputError("[fit] needs 'free': the list of parameter paths to fit")
    experiments = [_experiment(e, k, path.parent, fit_cfg) for k, e in enumerate(cfg.get("experiment", []))]
    if not experiments:
        raise PamjaxInputError("the config needs at least one [[experiment]]")
    options = {k: fit_cfg[k] for k in ("max_steps", "rtol", "atol") if k in fit_cfg}
    return model, experiments, fit_cfg["free"], options, fit_cfg.get("out")


def _signal(spec, rec, where):
    import pamjax as pj

    if spec == "recorded" or (isinstance(spec, dict) and spec.get("kind") == "recorded"):
        period = spec.get("period") if isinstance(spec, dict) else None
        return pj.Sampled(rec.t, rec["command"], period=period)
    if not isinstance(spec, dict) or spec.get("kind") not in _SIGNALS:
        raise PamjaxInputError(f"{where} signal must be 'recorded' or a table with kind in {sorted(_SIGNALS)}, got {spec!r}")
    kwargs = {k: v for k, v in spec.items() if k != "kind"}
    try:
        return getattr(pj, spec["kind"])(**kwargs)
    except TypeError as err:
        raise PamjaxInputError(f"{where} signal: {err}") from err


def _experiment(e, k, root, fit_cfg):
    import pamjax as pj

    where = f"[[experiment]] #{k + 1}"
    _check_keys(e, _EXPERIMENT_KEYS, where)
    if "file" not in e:
        raise PamjaxInputError(f"{where} needs 'file' (a CSV or NPZ recording, relative to the config)")
    rec = pj.Recording.load(root / e["file"], rename=e.get("rename"))
    if "t_end" in e:
        rec = rec.window(None, float(e["t_end"]))
    if "filter_hz" in e:
        rec = rec.filtered(float(e["filter_hz"]))
    if "rate" in e:
        rec = rec.resampled(float(e["rate"]))
    build = pj.TankFromModel(e["tank_volume"]) if "tank_volume" in e else None
    return pj.Experiment(
        rec, _signal(e.get("signal", "recorded"), rec, where), channels=e.get("channels"), scales=e.get("scales"),
        build=build, initial=e.get("initial"), name=e.get("name", rec.name), max_steps=e.get("max_steps", 200_000),
        validation_fraction=fit_cfg.get("validation_fraction", 0.0),
    )


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
        axes[0, j].set(title=f"{e.name}: {c}")
        if hasattr(e, "split_time") and float(e.split_time) < t[-1]:
            for ax in axes[:, j]:
                ax.axvline(float(e.split_time), color="C3", lw=0.8, ls="--")
        axes[1, j].plot(t, pred - data, lw=0.8)
        axes[1, j].set(xlabel="t [s]", ylabel=f"model − data ({c})")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def run(args):
    import pamjax as pj

    model, experiments, free, options, out_cfg = load_config(args.config)
    out = pathlib.Path(args.out or out_cfg or f"results/{pathlib.Path(args.config).stem}")
    result_path = out / "fit.json"
    if result_path.exists() and not args.overwrite:
        raise SystemExit(f"{result_path} exists; pass --overwrite to replace it")
    print(f"fitting {len(free)} parameter entries to {len(experiments)} experiments "
          f"({', '.join(e.name for e in experiments)})", flush=True)
    res = pj.fit(model, experiments, free, progress=not args.quiet, out=result_path, overwrite=args.overwrite, **options)
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
    return 0
