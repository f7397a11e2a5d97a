"""`pamjax design CONFIG.toml`: design a PWM duty experiment (`pamjax.design_experiment`) as a TOML config describes;
write the signal as CSV (`t [s]`, `duty [-]`, one row per PWM period, the predicted standard errors in comment lines),
the result as JSON and a figure. Config format: docs/identifiability.md and `examples/design_example.toml`."""

import pathlib
import sys
import warnings

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
# experiment's `tank_volume`), `out`, and the keyword arguments of `pamjax.design_experiment` below (`period`: the PWM
# period [s] of a model whose valve has none, e.g. an averaged valve; `min_force = false`: no force limit).
_DESIGN_ARGS = ("channels", "start", "rate", "criterion", "subset", "duty_band", "duty_margin", "stroke_margin",
                "max_pressure", "max_duty_step", "min_force", "parametrisation", "knots", "steps", "seed",
                "baseline_margin", "period")
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
    if kwargs.get("min_force") is True:
        raise PamjaxInputError("[design] min_force must be a force [N] (e.g. 20.0) or false for no limit, got true")
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
    if isinstance(value, str):  # held from each row's time: a period's duty at its start (the end row adds nothing)
        rec = pj.Recording.load(root / value)  # its `duty` column is read as channel "command"
        if "command" not in rec.channels:
            raise PamjaxInputError(f"[design] initial = {value!r} has no duty column (channels: "
                                   f"{sorted(rec.channels)}); give a design.csv of pamjax design")
        return pj.Sampled(rec.t, np.asarray(rec["command"]))
    raise PamjaxInputError(f"[design] initial must be a constant duty or a design CSV path, got {value!r}")


def run(args):
    import pamjax as pj

    from .._fit.design import check_design

    model, free, duration, kwargs, out_cfg = load(args.config)
    check_design(model, free, duration, **kwargs)  # every refusal before the output folder exists
    out = pathlib.Path(args.out or out_cfg or f"results/{pathlib.Path(args.config).stem}")
    outputs = [o for o in OUTPUTS if not (args.no_plot and o.endswith(".png"))]
    with OutputFolder(out, "pamjax design", outputs, overwrite=args.overwrite) as folder:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pj.PamjaxDesignWarning)  # reported below, as the command's outcome
            res = pj.design_experiment(model, free, duration, progress=not args.quiet, **kwargs)
        print(f"{res.message}; {res.criterion} criterion {res.objective[0]:.4f} → {res.objective[1]:.4f} "
              f"({res.design_s:.1f} s, of which {res.compile_s:.1f} s to the first iteration)")
        print(res.table())
        print(constraint_lines(res.constraints))
        written = []
        if res.feasible:
            written.append(folder.write("design.csv", lambda p: res.to_csv(p, overwrite=True)))
        written.append(folder.write("design.json", lambda p: res.to_json(p, overwrite=True)))
        if not args.no_plot:
            try:
                written.append(folder.write("design.png", res.plot))
            except ModuleNotFoundError:
                print("no figure: matplotlib is not installed (pip install matplotlib)")
        print("wrote " + ", ".join(str(p) for p in written if p is not None))
        if not res.feasible:
            print("pamjax design: FAILED: the design ends outside its limits, so no design.csv was written (a bench "
                  "must not play it; design.json and design.png show it):\n  "
                  + "\n  ".join(res.constraints["violations"])
                  + "\nRelax the limit named, start from a signal within it (initial = a constant duty), or allow "
                  "more steps", file=sys.stderr)
            return 1
        return 1 if folder.failed else 0


def constraint_lines(c):
    """The limits a design keeps, one line each (what `pamjax design` prints)."""
    lines = ["constraints:"]
    band = f"duty {c['duty_range'][0]:.4f} … {c['duty_range'][1]:.4f} within {c['duty_limits'][0]:.4g} … " \
           f"{c['duty_limits'][1]:.4g}"
    if c["switching_thresholds"]:
        band += (f" (the band {c['duty_band'][0]:g} … {c['duty_band'][1]:g} kept {c['duty_margin']:.4g} from the "
                 f"valve's switching thresholds {', '.join(f'{t:.4g}' for t in c['switching_thresholds'])}; closest "
                 f"period {c['threshold_distance']:.4g} away)")
    lines.append("  " + band)
    verified = c.get("verified") or {}
    if c["min_force"] is not None:
        f = verified.get("force_range") or c["force_range"]
        lines.append(f"  muscle force (eq. 7) >= {c['min_force']:g} N: smallest {f[0]:.1f} N")
    if c["stroke_limits"] is not None:
        x = verified.get("position_range") or c["position_range"]
        lines.append(f"  stroke {1e3 * x[0]:.2f} … {1e3 * x[1]:.2f} mm within {1e3 * c['stroke_limits'][0]:.2f} … "
                     f"{1e3 * c['stroke_limits'][1]:.2f} mm")
    if c["max_pressure"] is not None:
        p = verified.get("pressure_range") or c["pressure_range"]
        lines.append(f"  pressure up to {p[1] / 1e5:.3f} bar abs, limit {c['max_pressure'] / 1e5:.3f} bar abs")
    if c["max_duty_step"] is not None:
        lines.append(f"  duty step up to {c['largest_duty_step']:.3f}, limit {c['max_duty_step']:g}")
    lines.append("  every limit kept" if c["feasible"] else "  VIOLATED: " + "; ".join(c["violations"]))
    return "\n".join(lines)
