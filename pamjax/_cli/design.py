"""`pamjax design CONFIG.toml`: design a PWM duty experiment (`pamjax.design_experiment`) as a TOML config describes;
write the signal as CSV (`t [s]`, `duty [-]`, one row per PWM period, the predicted standard errors in comment lines),
the result as JSON and a figure. Config format: docs/identifiability.md and `examples/design_example.toml`."""

import pathlib
import sys
import warnings

import numpy as np

from .._core.errors import PamjaxInputError
from .._identifiability.design_result import short_label
from .._identifiability.design_setup import run_step_budget as _step_budget  # one rule for planned and designed runs
from . import schema
from .config import build_model, build_signal, read_toml
from .fit import load_config
from .out import OutputFolder

OUTPUTS = ("design.csv", "design.json", "design.png")


def add_arguments(parser):
    parser.add_argument("config", help="TOML file: [model] and [design] tables (docs/identifiability.md)")
    parser.add_argument("--out", default=None, help="output folder (default: [design] out, else "
                                                    "results/<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace existing results")
    parser.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")


def load(path):
    """A design config read in one pass: read → validate all → build the model → build the design's inputs (the
    prior and baseline fit configs, each read by `pamjax fit`'s `load_config`; the start signal; a tank test).
    Returns (model, free, duration, keyword arguments of `design`, out); nothing is solved. The limits are checked
    against the run's start by `check_design` (`run`), still before the output folder is made."""
    path = pathlib.Path(path)
    cfg = read_toml(path)
    schema.validate_design(cfg, str(path))
    model = build_model(cfg.get("model", {}), path.parent)
    table = cfg["design"]
    return model, table["free"], float(table["duration"]), build_design(table, path.parent, model), table.get("out")


def build_design(table, root, model=None):
    """The keyword arguments of `pamjax.design_experiment` a validated [design] table gives (`model`: for
    `payload_kg = "auto"`, the payload `pamjax.PayloadFromModel.advised` proposes for it)."""
    import pamjax as pj

    kwargs = {k: table[k] for k in schema.DESIGN_ARGS if k in table}
    kwargs["noise"] = table["noise"]
    for key in ("prior", "baseline"):  # fit configs: their experiments
        if key == "prior" and str(table.get(key, "")).endswith(".json"):  # a fit's fit.json: its covariance
            kwargs[key] = [str(pathlib.Path(root) / table[key])]
        elif key in table:
            try:
                _, experiments, *_ = load_config(pathlib.Path(root) / table[key])
            except PamjaxInputError as err:
                raise PamjaxInputError(f"[design] {key} = {table[key]!r}: {err}") from err
            kwargs[key] = experiments
    for key in ("prior_runs", "baseline_runs"):  # planned runs: added to the fit config's experiments, if any
        if key in table:
            runs = planned_experiments(table[key], key, table, model)
            kwargs[key[:-5]] = [*kwargs.get(key[:-5], []), *runs]
    if "initial" in table:
        kwargs["initial"] = _initial(table["initial"], root)
    if "duty_band" in kwargs:
        kwargs["duty_band"] = tuple(kwargs["duty_band"])
    if "tank_volume" in table:  # a tank test of the model's valve, as a fit experiment's tank_volume
        kwargs["build"] = pj.TankFromModel(float(table["tank_volume"]))
    if "payload_kg" in table:  # a muscle run with weights added or taken off, as a fit experiment's payload_kg
        kwargs["build"] = payload_build(table["payload_kg"], model)
    return kwargs


def planned_experiments(runs, key, table, model):
    """`prior_runs` / `baseline_runs` (runs not recorded yet: a signal and a duration each) as experiments of `model`
    (of its tank test or another payload where a run gives `tank_volume` or `payload_kg`) from the default start,
    sampled at the design's `rate` on those of its `channels` the run has (a tank test: pressure) with its `noise` as
    their scales, and the model's own prediction as their data: a design's information reads only the model's
    Jacobian along a run, never its data. One solve per run (`pamjax.synthetic_recording`)."""
    import pamjax as pj

    channels = list(table.get("channels", ("pressure", "position")))  # design_experiment's default channels
    rate = float(table.get("rate", 1000.0))  # Hz, design_experiment's default rate
    missing = [c for c in channels if c not in table["noise"]]
    if missing:
        raise PamjaxInputError(f"[design] {key}: noise has no level for channel(s) {missing}")
    out = []
    for k, run in enumerate(runs):
        name = run.get("name", f"{key}[{k}]")
        signal = build_signal(run["signal"], f"[design] {key}[{k}] signal")
        t = np.round(np.arange(0.0, float(run["duration"]) + 0.5 / rate, 1.0 / rate), 12)
        build = (pj.TankFromModel(float(run["tank_volume"])) if "tank_volume" in run  # as [design]'s own keys
                 else payload_build(run["payload_kg"], model) if "payload_kg" in run else None)
        system = model if build is None else build(model)
        rec = pj.synthetic_recording(system, signal, t, name=name)  # pressure, and position where it has one
        recorded = [c for c in channels if c in rec.channels]  # a tank test of a muscle design: its pressure
        if not recorded:
            raise PamjaxInputError(f"[design] {key}[{k}]: the run records none of the design's channels {channels} "
                                   f"(it has {sorted(rec.channels)})")
        out.append(pj.Experiment(rec, signal, channels=recorded, scales={c: float(table["noise"][c]) for c in recorded},
                                 build=build, name=name, **_step_budget(system, float(run["duration"]))))
    return out


def payload_build(value, model):
    """`payload_kg = 30.0` → `PayloadFromModel(30.0)`; "auto" → `PayloadFromModel.advised(model)` (a refusal named
    as the key's)."""
    import pamjax as pj

    if value != "auto":
        return pj.PayloadFromModel(float(value))
    try:
        return pj.PayloadFromModel.advised(model)
    except PamjaxInputError as err:
        raise PamjaxInputError(f"[design] payload_kg = \"auto\": {err}") from err


def _initial(value, root):
    """`initial = 0.6` (a constant duty) or `initial = "earlier/design.csv"` (its duty column, one per period)."""
    import pamjax as pj

    if not isinstance(value, str):
        return pj.Constant(float(value))
    try:  # a missing or unreadable file named as the key's
        rec = pj.Recording.load(pathlib.Path(root) / value)  # its `duty` column is read as channel "command"
    except (PamjaxInputError, OSError) as err:
        raise PamjaxInputError(f"[design] initial = {value!r}: {err}") from err
    if "command" not in rec.channels:  # held from each row's time: a period's duty at its start
        raise PamjaxInputError(f"[design] initial = {value!r} has no duty column (channels: "
                               f"{sorted(rec.channels)}); give a design.csv of pamjax design")
    return pj.Sampled(rec.t, np.asarray(rec["command"]))


def run(args):
    import pamjax as pj

    from .._identifiability.design import check_design

    model, free, duration, kwargs, out_cfg = load(args.config)
    check_design(model, free, duration, **kwargs)  # every refusal before the output folder exists
    out = pathlib.Path(args.out if args.out is not None else out_cfg or f"results/{pathlib.Path(args.config).stem}")
    outputs = [o for o in OUTPUTS if not (args.no_plot and o.endswith(".png"))]
    with OutputFolder(out, "pamjax design", outputs, overwrite=args.overwrite,
                      stale=OUTPUTS) as folder:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", pj.PamjaxDesignWarning)  # reported below, as the command's outcome
            res = pj.design_experiment(model, free, duration, progress=not args.quiet, **kwargs)
        for w in caught:  # what a prior fit may not hold is said here; the limits and the undetermined ones below
            if not issubclass(w.category, pj.PamjaxDesignWarning):
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
            elif ": prior " in str(w.message):
                print("warning: " + str(w.message).split(": ", 1)[1])
        print(f"{res.message}; {res.criterion} criterion {res.objective[0]:.4f} → {res.objective[1]:.4f} "
              f"({res.design_s:.1f} s, of which {res.compile_s:.1f} s to the first iteration)")
        print(res.table())
        print(constraint_lines(res.constraints))
        if res.undetermined:  # no standard error, ratio or target means anything for them
            print(f"not determined: {', '.join(res.undetermined)} (infinite predicted standard errors: the design "
                  "with the prior leaves them free; design at a converged fit, or free fewer parameters)")
        elif "target" in res.standard_errors:
            print(baseline_line(res.baseline_shortfall, kwargs.get("baseline_margin", 1.0)))
        if res.points:
            print(points_lines(res, kwargs.get("baseline_margin", 1.0)))
        if res.payload_kg is not None:
            print(f"payload: {res.payload_kg:.4g} kg (the model's: {float(model.payload_mass):g} kg): load the rig "
                  f"with it, and fit its recording with payload_kg = {res.payload_kg:.4g}")
        written, removed = [], False
        if res.feasible:
            written.append(folder.write("design.csv", lambda p: res.to_csv(p, overwrite=True)))
        elif (folder / "design.csv").exists():  # an earlier run's (--overwrite): a bench would play it as this run's
            (folder / "design.csv").unlink()
            removed = True
        written.append(folder.write("design.json", lambda p: res.to_json(p, overwrite=True)))
        if not args.no_plot:
            try:
                written.append(folder.write("design.png", res.plot))
            except ModuleNotFoundError:
                print("no figure: matplotlib is not installed (pip install matplotlib)")
        print("wrote " + ", ".join(str(p) for p in written if p is not None))
        if not res.feasible:
            gone = f"; the earlier run's {folder / 'design.csv'} was removed" if removed else ""
            print(f"pamjax design: FAILED: the design ends outside its limits, so no design.csv was written (a bench "
                  f"must not play it{gone}; design.json and design.png show it):\n  "
                  + "\n  ".join(res.constraints["violations"])
                  + "\nRelax the limit named, start from a signal within it (initial = a constant duty), or allow "
                  "more steps" + _payload_hint(model, res, kwargs), file=sys.stderr)
            return 1
        return 1 if folder.failed else 0


def _payload_hint(model, res, kwargs):
    """Where the payload passes the upper stroke limit of a run with the model's own payload and the model's muscle
    holds it on the upper stop even at atmospheric pressure (no duty brings it down): the heavier payload that
    `payload_kg = "auto"` would carry."""
    import pamjax as pj

    x, limits = res.constraints.get("position_range"), res.constraints.get("stroke_limits")
    if "build" in kwargs or x is None or limits is None or not x[1] > limits[1]:
        return ""
    try:
        held = float(model.muscle.static_force(model.muscle.max_position, model.air.atmospheric_pressure, model.air))
        mass = float(pj.PayloadFromModel.advised(model).mass)
    except (PamjaxInputError, AttributeError):  # not a muscle system, or no supply pressure of its own
        return ""
    weight = float(model.payload_mass) * float(model.gravity)
    if not (held > weight and mass > float(model.payload_mass)):
        return ""
    return (f"\nThe payload reaches the upper stop, where the model's muscle pulls {held:.0f} N even at atmospheric "
            f"pressure against its {weight:.0f} N weight, so no duty brings it down: a heavier payload does, "
            f"[design] payload_kg = \"auto\" designs the run with {mass:.3g} kg (half the muscle's pull at zero "
            "contraction and supply pressure)")


def _tolerated(verified, key, fmt, scale=1.0):
    """A note for a limit the check at the fit's resolution passes by less than its tolerance (the PWM ripple
    between the objective's samples, which the objective cannot see: `VERIFY_TOLERANCE`), so that a smallest force
    of 19.3 N under ">= 20 N" is not left beside "every limit kept" unexplained; "" where the limit holds."""
    excess = (verified.get("excess") or {}).get(key)
    if not excess:
        return ""
    tolerance = verified["tolerance"][key]
    state = "within" if excess <= tolerance else "beyond"
    return (f" (past the limit by {fmt.format(excess * scale)} at the fit's resolution, {state} the "
            f"{fmt.format(tolerance * scale)} allowed for the PWM ripple between the design's samples)")


def baseline_line(shortfall, margin, points=False):
    """Whether the design reached the baseline's standard errors over `baseline_margin` (a goal, not a limit); with
    `points`, whether every design point of a spread design reached its own (the margin at the model's point, the
    baseline's own, or over the margin if below 1, at the others)."""
    m = float(margin)
    if not points:
        goal, every, short = f"the baseline's standard errors / {m:g} (baseline_margin)", "baseline:", "baseline:"
    else:
        goal = (f"the baseline's standard errors / {m:g}" + (" at the model's point and the baseline's own at the "
                                                              "others" if m > 1 else ""))
        every, short = "baseline at every design point:", "baseline at the design points:"
    if not shortfall:
        return f"{every} every parameter of subset at or below {goal}"
    worst = " at worst" if points else ""
    hint = "" if points else " (more steps, or a smaller baseline_margin)"
    named = ", ".join(f"{k} ({v:.3f}× its target{worst})" for k, v in shortfall.items())
    return f"{short} short of {goal} on {named}; a goal, not a limit: the design is valid{hint}"


def points_lines(res, margin):
    """A spread design's points, one line each: criterion, limits and (with a baseline) the baseline's standard error
    over the design's per parameter of subset; then whether every point reached its target."""
    subset = [res.labels.index(s) for s in res.subset]
    lines = [f"design points: the model's (0) and {len(res.points) - 1} drawn from spread; the objective is the "
             "average over them (standard errors at the design's resolution)"]
    for k, point in enumerate(res.points):
        kept = point["worst_violation"] <= 1e-9
        line = f"  point {k}: criterion {point['criterion']:.4f}, " + (
            "every limit kept" if kept else f"a limit passed (worst {point['worst_violation']:.3g} mm/kPa/N)")
        errors = point["standard_errors"]
        if "baseline" in errors:
            line += "; baseline/design " + ", ".join(
                f"{short_label(res.labels[i])} {errors['baseline'][i] / errors['design'][i]:.3f}" for i in subset)
        lines.append(line)
    if "target" in res.points[0]["standard_errors"]:
        lines.append(baseline_line(res.points_shortfall, margin, points=True))
    return "\n".join(lines)


def constraint_lines(c):
    """The limits a design keeps, one line each (what `pamjax design` prints)."""
    lines = ["constraints:"]
    band = f"duty {c['duty_range'][0]:.4f} … {c['duty_range'][1]:.4f} within {c['duty_limits'][0]:.4g} … " \
           f"{c['duty_limits'][1]:.4g}"
    if c["switching_thresholds"]:
        margin = c["duty_margin"]  # one number, or one per threshold (auto, asymmetric switching times)
        kept = f"{margin:.4g}" if np.ndim(margin) == 0 else f"{', '.join(f'{m:.4g}' for m in margin)} (each its own)"
        band += (f" (the band {c['duty_band'][0]:g} … {c['duty_band'][1]:g} kept {kept} from the "
                 f"valve's switching thresholds {', '.join(f'{t:.4g}' for t in c['switching_thresholds'])}; closest "
                 f"period {c['threshold_distance']:.4g} away)")
    lines.append("  " + band)
    verified = c.get("verified") or {}
    if c["min_force"] is not None:
        free, stop = (verified.get(k, c.get(k)) for k in ("free_force_min", "stop_force_min"))
        line = f"  muscle force (eq. 7) >= {c['min_force']:g} N where the payload hangs free: " + (
            f"smallest {free:.1f} N" if free is not None else "it never does")
        if stop is not None:  # the stop carries the payload: only tension is asked (docs/identifiability.md)
            line += f"; >= 0 N on the lower stop: smallest {stop:.1f} N"
        lines.append(line + _tolerated(verified, "force", "{:.1f} N"))
    if c["stroke_limits"] is not None:
        x = verified.get("position_range") or c["position_range"]
        lines.append(f"  stroke {1e3 * x[0]:.2f} … {1e3 * x[1]:.2f} mm within {1e3 * c['stroke_limits'][0]:.2f} … "
                     f"{1e3 * c['stroke_limits'][1]:.2f} mm" + _tolerated(verified, "stroke", "{:.3f} mm", 1e3))
    if c["max_pressure"] is not None:
        p = verified.get("pressure_range") or c["pressure_range"]
        lines.append(f"  pressure up to {p[1] / 1e5:.3f} bar abs, limit {c['max_pressure'] / 1e5:.3f} bar abs"
                     + _tolerated(verified, "pressure", "{:.1f} kPa", 1e-3))
    if c["max_duty_step"] is not None:
        lines.append(f"  duty step up to {c['largest_duty_step']:.3f}, limit {c['max_duty_step']:g}")
    lines.append("  every limit kept" if c["feasible"] else "  VIOLATED: " + "; ".join(c["violations"]))
    return "\n".join(lines)
