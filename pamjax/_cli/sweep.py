"""`pamjax sweep CONFIG.toml`: run a steady-state map, flow surface or frequency response of any model; write NPZ,
CSV, figure.

Config (see `examples/sweep_*.toml` and `docs/sweeps.md`); every key, value type and unit is checked before anything
runs, and a key the chosen `kind` does not use is an error listing the ones it does:

    kind = "steady_state"            # or "flow_surface", "frequency_response"
    [system]                         # paper 000's MAS-10 preset (flow_surface: its MHE2 valve alone)
    valve = "pwm"                    # "pwm" (smoothed switching) or "averaged" (eq. 13)
    payload_mass = 9.6               # kg
    # or, instead of [system], any model: a preset with options and set values, or a model file
    # [model]
    # file = "results/fit_example/model.json"
    [sweep]
    commands = { start = 0.0, stop = 1.0, num = 101 }   # duty ratios (or a list)
    horizon = 5.0                    # s; window = 1.0 s averaged at the end
    over = { "payload_mass" = [5.0, 9.6, 15.0] }        # any parameter path(s): a grid with the commands
"""

import dataclasses
import inspect
import itertools
import os
import pathlib
import re
import time

import numpy as np

from .. import presets
from .._core.csvio import write_table
from .._core.distributed import join_for_cli
from .._core.errors import PamjaxInputError
from .._core.fitting import field_units
from .._core.units import ATMOSPHERE
from .._sweep import maps
from .._sweep.maps import flow_surface, frequency_response, steady_state_map
from .._systems.base import AbstractMuscleSystem, AbstractSystem
from . import bands, schema
from .config import apply_set, build_model, read_toml
from .kinds import DUTY, axis as _axis, command_bounds, command_of, commands
from .out import OutputFolder
from .schema import SOLVER_KEYS

OUTPUTS = ("sweep.npz", "sweep.csv", "sweep.png")
DEFAULT_CPU_DEVICES = os.cpu_count() or 1  # --cpu-devices: one XLA CPU device per core


def add_arguments(parser):
    parser.add_argument("config", help="TOML file describing the sweep (examples/sweep_*.toml)")
    parser.add_argument("--out", default=None, help="output folder (default results/sweep-<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace existing sweep.npz/csv/png in --out")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")
    parser.add_argument("--cpu-devices", type=bands.int_at_least("--cpu-devices", 1), default=DEFAULT_CPU_DEVICES,
                        help="on CPU, split the processor into this many XLA devices and shard the sweep over them "
                             "(default: one per core; 1: a single device). No effect on GPU/TPU runs")
    parser.add_argument("--distributed", action="store_true",
                        help="join a multi-process run (JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID, "
                             "or SLURM/Open MPI) and spread the sweep over every process's devices (--cpu-devices "
                             "per process); process 0 writes the outputs (docs/distributed.md)")
    bands.add_arguments(parser)  # --band, --band-method, --band-level, --band-samples, --band-seed


def _use_cpu_devices(count):
    """Split the CPU into `count` XLA devices, so that `sweep` shards its batch over every core. JAX takes the
    device count only before its backend starts; importing pamjax and parsing the command line start nothing."""
    import jax

    try:
        jax.config.update("jax_num_cpu_devices", count)
    except RuntimeError:  # JAX already ran in this process (main() called from Python): its devices stay
        pass


def validate_config(config):
    """Check every table, key and value of a parsed sweep config for its `kind` (nothing is built or solved)."""
    schema.validate_sweep(config)


def load(path):
    """The sweep a config describes, read in one pass: read → validate all → build the model → check every swept
    path against it (nothing solved); returns (config, model)."""
    path = pathlib.Path(path)
    config = read_toml(path)
    return config, prepare(config, path.parent)


def build_sweep_model(config, root):
    """The swept model of a validated config: [model] (any preset or model file), else [system] (paper 000's
    preset)."""
    kind = config["kind"]
    if "model" in config:
        model = build_model(config["model"], root)
        valve = model.valve if isinstance(model, AbstractSystem) else None
        if valve is not None and valve.exact_edges and kind == "flow_surface":
            raise PamjaxInputError("[model]: kind = 'flow_surface' maps a smoothed switching valve, not the "
                                   "exact-edge one (mode = \"exact\"); use mode = \"smooth\"")
        if kind == "flow_surface" and not (valve is not None and valve.switches):
            raise PamjaxInputError(f"kind = 'flow_surface' maps a switching valve; this model's valve is a "
                                   f"{type(valve).__name__}")
        if kind != "flow_surface" and not isinstance(model, AbstractSystem):
            raise PamjaxInputError(f"kind = {kind!r} needs a system (a MuscleSystem, TankSystem, ...), got a "
                                   f"{type(model).__name__}")
        return model
    sys_cfg = config.get("system", {})
    if kind == "flow_surface":
        valve = presets.mas10_valve(supply_pressure=float(sys_cfg.get("supply_pressure", presets.SUPPLY_PRESSURE)))
        return presets.mas10_tank_system(valve=valve)
    return presets.mas10_system(valve=sys_cfg.get("valve", "pwm"),
                                payload_mass=float(sys_cfg.get("payload_mass", presets.PAYLOAD_MASS)))


def _leaf(model, path):
    obj = model
    for part in path.split("[")[0].split("."):
        obj = getattr(obj, part, None)
    return obj


def over_column(model, path):
    """`path [unit]` for a swept parameter (the unit its component's field declares; an element's with its index's
    exponents resolved, `element_unit`)."""
    from .._fit.parameters import split_path

    parts = path.split("[")[0].split(".")
    owner = _leaf(model, ".".join(parts[:-1])) if len(parts) > 1 else model
    unit = field_units(type(owner)).get(parts[-1], "") if dataclasses.is_dataclass(owner) else ""
    index = split_path(path)[1] if "[" in path else None
    unit = element_unit(unit, index) if unit and index is not None else unit
    return f"{path} [{unit}]" if unit else path


def element_unit(unit, index):
    """The unit of one element of an array whose field declares a unit with exponents named by the index,
    `i` (the first axis) and `j` (the second): `AveragedValve.coefficients`' "kg/(s Pa^j)" (eq. 13's m[i, j] multiplies
    u^i p_g^j) is "kg/s" at [1, 0], "kg/(s Pa)" at [0, 1], "kg/(s Pa^2)" at [2, 2]. A unit without them is the
    element's own."""
    names = dict(zip("ij", index))

    def power(match):
        n = names.get(match.group(2))
        if n is None:
            return match.group(0)
        return "" if n == 0 else match.group(1) if n == 1 else f"{match.group(1)}^{n}"

    unit = re.sub(r"([A-Za-z]+)\^([ij])\b", power, unit)
    unit = re.sub(r"\s+\)", ")", re.sub(r"\(\s+", "(", unit)).strip()
    return re.sub(r"\(([^\s()]+)\)", r"\1", unit)  # "kg/(s)" -> "kg/s"


def _native(config, model, paths):
    """Whether `[sweep] over` runs inside one vmapped steady-state sweep (scalar parameters), not map by map."""
    return config["kind"] == "steady_state" and bool(paths) and all(
        "[" not in p and np.ndim(_leaf(model, p)) == 0 for p in paths)


def check_over(config, model):
    """Every `[sweep] over` path must name a parameter of `model`, with the right shape and units, and every value
    must build a valid model, before anything runs (no solve: a model per point is built and checked, ~12 ms on
    the MAS-10 preset, measured).
    Run map by map, every point of the grid is checked (a map per point costs seconds); a native steady-state grid,
    every value of each path (the sweep checks their combinations itself, all points before its one solve)."""
    over = config.get("sweep", {}).get("over", {})
    if not over:
        return
    paths = list(over)
    axes = [_axis(over[p], f"over.{p}") for p in paths]
    if _native(config, model, paths):
        points = dict.fromkeys(tuple(a[0] for a in axes[:k]) + (v,) + tuple(a[0] for a in axes[k + 1:])
                               for k, axis in enumerate(axes) for v in axis)
    else:
        points = itertools.product(*axes)
    for point in points:
        apply_set(model, {p: float(v) for p, v in zip(paths, point)}, "[sweep] over")


def prepare(config, root="."):
    """Validate a parsed config and build its model, checking every swept path against it (nothing solved): `load`
    of a config already read."""
    schema.validate_sweep(config)
    model = build_sweep_model(config, root)
    check_over(config, model)
    if config["kind"] != "frequency_response":
        commands(config.get("sweep", {}), model, 1)  # within the model's command range
    check_map_settings(config, model)
    return model


def _default(function, name):
    """`pamjax._sweep.maps`'s `function`'s default for the argument `name` (read, not copied)."""
    return inspect.signature(getattr(maps, function)).parameters[name].default


FREQUENCIES = {"start": 0.05, "stop": 5.0, "num": 16, "log": True}  # Hz, [sweep] frequencies' default: paper 000's band


def check_map_settings(config, model):
    """What the maps refuse only when they start (window beyond the horizon, sample_interval beyond the window, a
    frequency response's offset ± amplitude beyond the command range), checked here with their defaults, before the
    output folder is taken (docs/cli.md: every command checks all of its config, then holds its folder; was: an
    empty output folder left behind)."""
    sw, kind = config.get("sweep", {}), config["kind"]
    if kind == "steady_state":
        horizon = float(sw.get("horizon", _default("steady_state_map", "horizon")))
        window = float(sw.get("window", _default("steady_state_map", "window")))
        if not window <= horizon:
            raise PamjaxInputError(f"[sweep] window must lie in (0, horizon = {horizon:g}] s (the last window of "
                                   f"each run is averaged), got {window:g}")
        valve = model.valve if isinstance(model, AbstractSystem) else None
        interval = sw.get("sample_interval", float(valve.period) / maps.SAMPLES_PER_PWM_PERIOD if valve is not None and
                          valve.switches else maps.SMOOTH_SAMPLE_INTERVAL)
        if not interval <= window:
            said = "" if "sample_interval" in sw else " (its default for this model's valve)"
            raise PamjaxInputError(f"[sweep] sample_interval = {interval:g} s{said} must be at most the window "
                                   f"({window:g} s): the window would hold no sample")
        if "sample_interval" in sw:  # one that aliases a switching valve's ripple, before the output folder is taken
            over = {p: _axis(v, f"over.{p}") for p, v in sw.get("over", {}).items()}
            f = maps.pwm_frequencies(model, over)
            maps.check_pwm_sampling(float(interval), float(f.max()) if f.size else 0.0)
    elif kind == "frequency_response":
        offset = float(sw.get("offset", _default("frequency_response", "offset")))
        amplitude = abs(float(sw.get("amplitude", _default("frequency_response", "amplitude"))))
        lo, hi = command_bounds(model)
        if offset - amplitude < lo - 1e-12 or offset + amplitude > hi + 1e-12:
            raise PamjaxInputError(
                f"[sweep] offset ± amplitude ({offset:g} ± {amplitude:g}: {offset - amplitude:g} … "
                f"{offset + amplitude:g}) must stay within the model's command range [{lo:g}, {hi:g}] "
                f"({'duty ratios' if command_of(model) is DUTY else 'reference voltages [V]'})")
        over = {p: _axis(v, f"over.{p}") for p, v in sw.get("over", {}).items()}
        maps.check_below_pwm_nyquist(model, _axis(sw.get("frequencies", FREQUENCIES), "frequencies"), over,
                                     "[sweep] frequencies")


def run_config(config, progress=print, root=".", model=None):
    """Validate and run a parsed config; returns (columns for CSV/NPZ: name -> 1-D array with units in the name,
    plot spec). Defaults: paper 000's MAS-10 preset (pwm valve, 9.6 kg payload, 0.65 MPa abs supply). With
    `[sweep] over`, every point of the grid of its values is mapped; the columns carry the swept values. Relative
    model files are read from `root` (the config's folder); `model`: the one `prepare` built."""
    model = prepare(config, root) if model is None else model
    over = config.get("sweep", {}).get("over", {})
    paths = list(over)
    axes = [_axis(over[p], f"over.{p}") for p in paths]
    if _native(config, model, paths):  # one vmapped sweep over over-values × commands
        return _run_one(config, model, progress, dict(zip(paths, axes)))
    columns, spec = {}, None
    for point in itertools.product(*axes):  # one map per grid point (one compilation: only values change)
        point_model = apply_set(model, dict(zip(paths, point)), "[sweep] over") if paths else model
        cols, spec = _run_one(config, point_model, progress, None)
        n = len(next(iter(cols.values())))
        for p, v in zip(paths, point):
            columns.setdefault(over_column(model, p), []).append(np.full(n, v))
        for name, values in cols.items():
            columns.setdefault(name, []).append(np.asarray(values))
    columns = {k: np.concatenate(v) for k, v in columns.items()}
    return columns, (spec if not paths else ("table", columns, [over_column(model, p) for p in paths]))


def _run_one(config, model, progress, native_over):
    """One map of `model`; `native_over` (path → axis values) is swept inside one steady-state sweep."""
    kind = config["kind"]
    sw = config.get("sweep", {})
    options = {k: sw[k] for k in SOLVER_KEYS if k in sw}
    if kind == "flow_surface":
        valve = model.valve
        u = commands(sw, model, 41)
        default_p = {"start": ATMOSPHERE, "stop": float(valve.supply_pressure), "num": 41}  # p_atm (ISO 2533) … p_s
        p = _axis(sw.get("pressures", default_p), "pressures")
        flow = flow_surface(valve, u, p, model.air)
        uu, pp = np.meshgrid(u, p, indexing="ij")
        return ({command_of(model).column: uu.ravel(), "pressure_pa_abs": pp.ravel(),
                 "mass_flow_kg_s": flow.ravel()}, ("surface", u, p, flow, command_of(model)))
    if kind == "steady_state":
        u = commands(sw, model, 101)
        kwargs = {k: float(sw[k]) for k in ("horizon", "window", "sample_interval") if k in sw}
        grid = {}  # axis k for the k-th swept path, the last axis for the commands
        for k, (path, values) in enumerate((native_over or {}).items()):
            grid[path] = np.asarray(values, dtype=float).reshape((-1,) + (1,) * (len(native_over) - k))
        r = steady_state_map(model, u, progress=progress, over=grid or None, **kwargs, **options)
        shape = np.broadcast_shapes(u.shape, *(v.shape for v in grid.values()))
        cols = {over_column(model, p): np.broadcast_to(v, shape).ravel() for p, v in grid.items()}
        cols.update({command_of(model).column: np.broadcast_to(u, shape).ravel(),
                     "pressure_pa_abs": np.ravel(r["pressure"])})
        if "position" in r.channels:
            cols["position_m"] = np.ravel(r["position"])
        cols["status"] = np.ravel(r.status)
        return cols, (("steady", u, r, command_of(model)) if not grid else ("table", cols, list(cols)[: len(grid)]))
    f = _axis(sw.get("frequencies", FREQUENCIES), "frequencies")
    kwargs = {k: float(sw[k]) for k in ("offset", "amplitude") if k in sw}
    kwargs.update({k: int(sw[k]) for k in ("settle_periods", "periods", "samples_per_period") if k in sw})
    channels = ("position", "pressure") if isinstance(model, AbstractMuscleSystem) else ("pressure",)
    fr = frequency_response(model, f, progress=progress, channels=channels, **kwargs, **options)
    cols = dict(frequency_hz=f)
    if "position" in channels:
        cols.update(position_gain_m=fr["position"]["gain"], position_phase_deg=fr["position"]["phase"])
    cols.update(pressure_gain_pa=fr["pressure"]["gain"], pressure_phase_deg=fr["pressure"]["phase"],
                status=fr["result"].status)
    return cols, ("bode", f, fr, command_of(model))


def plot(spec, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kind = spec[0]
    if kind == "surface":
        _, u, p, flow, command = spec
        fig, ax = plt.subplots(figsize=(7, 5))
        for j in range(0, len(p), max(1, len(p) // 8)):
            ax.plot(u, flow[:, j] * 1e3, label=f"p = {(p[j] - ATMOSPHERE) / 1e6:.2f} MPa gauge")
        ax.set(xlabel=command.label, ylabel="cycle-averaged mass flow [g/s]",
               title="Averaged flow surface of the switching valve (chamber held at p)")
        ax.legend(fontsize=7)
    elif kind == "steady":
        _, u, r, command = spec
        rows = 2 if "position" in r.channels else 1
        fig, axes = plt.subplots(rows, 1, figsize=(7, 3.5 * rows), sharex=True, squeeze=False)
        axes[0, 0].plot(u, (r["pressure"] - ATMOSPHERE) / 1e6)
        axes[0, 0].set(ylabel="pressure [MPa gauge]", title=f"Steady state against a constant {command.label}")
        if rows == 2:
            axes[1, 0].plot(u, r["position"] * 1e3)
            axes[1, 0].set(ylabel="displacement [mm]")
        axes[-1, 0].set(xlabel=command.label)
        for a in axes[:, 0] if command.dead_bands else ():
            a.axvspan(0, 0.1, color="gray", alpha=0.15)
            a.axvspan(0.9, 1.0, color="gray", alpha=0.15)
    elif kind == "bode":
        _, f, fr, command = spec
        channel = "position" if "position" in fr else "pressure"
        scale, unit = (1e3, "mm") if channel == "position" else (1e-5, "bar")
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
        a1.loglog(f, fr[channel]["gain"] * scale)
        a1.set(ylabel=f"gain [{unit} per {command.unit}]", title=f"Frequency response: {command.column} → {channel}")
        a2.semilogx(f, fr[channel]["phase"])
        a2.set(xlabel="frequency [Hz]", ylabel="phase [deg]")
    else:  # a grid over parameters: one line per swept point against the map's own axis
        _, cols, swept = spec
        x_name = next(c for c in cols if c not in swept)
        y_names = [c for c in cols if c not in swept and c != x_name and c != "status"][:2]
        fig, axes = plt.subplots(len(y_names), 1, figsize=(7, 3.5 * len(y_names)), sharex=True, squeeze=False)
        keys = list(zip(*(cols[c] for c in swept)))
        for point in dict.fromkeys(keys):
            sel = np.array([k == point for k in keys])
            label = ", ".join(f"{c} = {v:g}" for c, v in zip(swept, point))
            for ax, y in zip(axes[:, 0], y_names):
                ax.plot(cols[x_name][sel], cols[y][sel], label=label)
                ax.set(ylabel=y)
        axes[-1, 0].set(xlabel=x_name)
        axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120, format="png")
    plt.close(fig)


def _savez(path, columns):
    with open(path, "wb") as f:
        np.savez(f, **columns)


def run(args):
    _use_cpu_devices(args.cpu_devices)
    writes = join_for_cli(args.distributed)  # before JAX starts; False on processes other than 0
    config, model = load(args.config)  # before the output folder is touched
    band_source = bands.check_sweep(args, config, pathlib.Path(args.config).parent, model)  # --band: a fitted model
    if not writes:  # another process of a distributed run: its share of the work, no files
        run_config(config, model=model)
        return 0
    name = os.path.splitext(os.path.basename(args.config))[0]
    out = args.out if args.out is not None else os.path.join("results", f"sweep-{name}")  # "": OutputFolder refuses
    outputs = [o for o in OUTPUTS if not (args.no_plot and o.endswith(".png"))]
    with OutputFolder(out, "pamjax sweep", outputs, overwrite=args.overwrite,
                      stale=OUTPUTS) as folder:
        start = time.perf_counter()
        columns, spec = run_config(config, model=model)
        import jax

        devices = jax.devices()
        print(f"pamjax sweep: {config['kind']}, {len(next(iter(columns.values())))} rows in "
              f"{time.perf_counter() - start:.1f} s on {len(devices)} {devices[0].platform} device(s)")
        comment, figure = None, lambda p: plot(spec, p)  # noqa: E731
        if band_source is not None:  # --band: <column>_lower / _upper columns, the band drawn in the figure
            comment, figure = bands.add_to_sweep(args, config, model, band_source, spec, columns)
        folder.write("sweep.npz", lambda p: _savez(p, columns))
        folder.write("sweep.csv", lambda p: write_table(p, columns, {}, comment))
        print(f"wrote {out}/sweep.npz and sweep.csv (columns: {', '.join(columns)})")
        if not args.no_plot:
            try:
                folder.write("sweep.png", figure)
                print(f"figure: {out}/sweep.png")
            except ModuleNotFoundError:
                print("no figure: matplotlib is not installed (pip install matplotlib)")
        failed = int(np.sum(columns.get("status", np.zeros(1)) != 0))
        if failed:
            print(f"warning: {failed} sweep points failed (status != 0; their outputs are NaN)")
        return 1 if folder.failed else 0
