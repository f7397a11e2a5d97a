"""`pamjax design CONFIG.toml`: design a PWM duty experiment (`pamjax.design`) as a TOML config describes; write the
signal as CSV (`t [s]`, `duty [-]`, one row per PWM period, the predicted standard errors in comment lines), the
result as JSON and a figure. Config format: docs/identifiability.md and `examples/design_example.toml`."""

import pathlib

import numpy as np

from .._core.errors import PamjaxInputError
from .._core.units import check_setting
from .config import build_model, check_keys, read_toml, require, validate_model_table
from .fit import load_config
from .out import OutputFolder

_TOP_KEYS = {"model", "design"}
OUTPUTS = ("design.csv", "design.json", "design.png")
# [design] keys: `free`, `duration`, `noise` (required), `prior` / `baseline` (fit configs whose experiments are the
# information in hand / the experiment to beat), `initial` (a constant duty, or the CSV of an earlier design to
# start from), `tank_volume` (design a constant-volume tank test of the model's valve: build=TankFromModel, as a fit
# experiment's `tank_volume`), `out`, and the keyword arguments of `pamjax.design` below.
_DESIGN_ARGS = ("channels", "start", "rate", "criterion", "subset", "duty_band", "stroke_margin", "max_pressure",
                "max_duty_step", "parametrisation", "knots", "steps", "seed", "baseline_margin")
_DESIGN_KEYS = {"free", "duration", "noise", "prior", "baseline", "initial", "tank_volume", "out", *_DESIGN_ARGS}


def add_arguments(parser):
    parser.add_argument("config", help="TOML file: [model] and [design] tables (docs/identifiability.md)")
    parser.add_argument("--out", default=None, help="output folder (default: [design] out, else "
                                                    "results/<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace existing results")
    parser.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")


def load(path):
    """Parse and check a design config; returns (model, free, duration, keyword arguments of `design`, out).
    Every key is checked, and the prior and baseline configs loaded, before anything is solved."""
    path = pathlib.Path(path)
    cfg = read_toml(path)
    check_keys(cfg, _TOP_KEYS, str(path))
    table = cfg.get("design")
    if table is None:
        raise PamjaxInputError(f"{path} needs a [design] table (free, duration, noise, ...)")
    check_keys(table, _DESIGN_KEYS, "[design]")
    for key in ("free", "duration", "noise"):
        if key not in table:
            raise PamjaxInputError(f"[design] needs '{key}'")
    validate_model_table(cfg.get("model", {}))
    model = build_model(cfg.get("model", {}), path.parent)
    kwargs = {k: table[k] for k in _DESIGN_ARGS if k in table}
    for key in ("prior", "baseline"):
        if key in table:
            _, experiments, *_ = load_config(path.parent / table[key])
            kwargs[key] = experiments
    if "initial" in table:
        kwargs["initial"] = _initial(table["initial"], path.parent)
    if "duty_band" in kwargs:
        kwargs["duty_band"] = tuple(kwargs["duty_band"])
    if "tank_volume" in table:  # a tank test of the model's valve, as a fit experiment's tank_volume
        import pamjax as pj

        require(table["tank_volume"], "positive number", "[design] tank_volume", "5e-5 (m³)")
        check_setting("tank_volume", table["tank_volume"], "[design]")
        kwargs["build"] = pj.TankFromModel(float(table["tank_volume"]))
    return model, table["free"], float(table["duration"]), dict(noise=table["noise"], **kwargs), table.get("out")


def _initial(value, root):
    """`initial = 0.6` (a constant duty) or `initial = "earlier/design.csv"` (its duty column, one per period)."""
    import pamjax as pj

    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return pj.Constant(float(value))
    if isinstance(value, str):
        return np.asarray(pj.Recording.load(root / value)["duty"])
    raise PamjaxInputError(f"[design] initial must be a constant duty or a design CSV path, got {value!r}")


def run(args):
    import pamjax as pj

    model, free, duration, kwargs, out_cfg = load(args.config)
    out = pathlib.Path(args.out or out_cfg or f"results/{pathlib.Path(args.config).stem}")
    outputs = [o for o in OUTPUTS if not (args.no_plot and o.endswith(".png"))]
    with OutputFolder(out, "pamjax design", outputs, overwrite=args.overwrite) as folder:
        res = pj.design(model, free, duration, progress=not args.quiet, **kwargs)
        print(f"{res.message}; {res.criterion} criterion {res.objective[0]:.4f} → {res.objective[1]:.4f} "
              f"({res.design_s:.1f} s, of which {res.compile_s:.1f} s to the first iteration)")
        print(res.table())
        if not res.constraints["feasible"]:
            print("WARNING: the design violates a constraint:", res.constraints)
        written = [folder.write("design.csv", lambda p: res.to_csv(p, overwrite=True)),
                   folder.write("design.json", lambda p: res.to_json(p, overwrite=True))]
        if not args.no_plot:
            try:
                written.append(folder.write("design.png", res.plot))
            except ModuleNotFoundError:
                print("no figure: matplotlib is not installed (pip install matplotlib)")
        print("wrote " + ", ".join(str(p) for p in written if p is not None))
        return 1 if folder.failed else 0
