"""`pamjax simulate CONFIG.toml`: simulate any model (a preset, or a model file such as the `model.json` that
`pamjax fit` writes) driven by any input (a signal, or the command channel of a recording); write the trajectory as
CSV with units in the header (readable by `pamjax.Recording.load`) and a figure. `docs/cli.md`.

    [model]
    file = "results/fit_example/model.json"   # or preset = "mas10_system", options = {...}, set = {...}
    [input]
    signal = { kind = "Triangle", low = 0.05, high = 0.95, frequency = 0.25 }
    # file = "bench.csv"                       # a recording: its command drives the model (signal = "recorded"),
    #                                          # its other channels are drawn beside the simulation
    [simulate]
    t_end = 8.0                                # s (default: the recording's end)
    dt = 0.01                                  # s between output rows (default 0.01 s, or the recording's times)
    initial = { pressure = 101325.0 }          # keyword arguments of the system's initial_state
"""

import pathlib
from typing import NamedTuple

import numpy as np

from .._core.csvio import write_table
from .._core.errors import PamjaxInputError
from .._solve.simulate import resolve_stepping, validate
from . import bands, schema
from .config import build_model, build_signal, check_end, check_initial, is_recorded, load_recording, read_toml
from .kinds import DUTY, command_of
from .out import OutputFolder

OUTPUTS = ("trajectory.csv", "trajectory.png")
DEFAULT_DT = 0.01  # s: 100 rows per second, the rate of paper 000's figures
LONG_ROWS = 100_000  # a run with more output rows than this is announced before it starts (it takes a while)
MAX_ROWS = 2_000_000  # a larger CSV (hundreds of MB) is more likely a unit slip (t_end in ms) than a wish
_UNITS = {"t": "s", "command": "1", "pressure": "Pa abs", "position": "m", "velocity": "m/s", "force": "N",
          "friction_force": "N", "mass_flow": "kg/s", "inlet_flow": "kg/s", "volume": "m^3"}


def command_unit(system):
    """The command's unit: a duty ratio ("1") for a valve's [0, 1], volts for a regulator's 0-10 V reference (paper
    001, Sect. 2), as `pamjax sweep` tells them apart (`kinds.command_of`)."""
    return "1" if command_of(system) is DUTY else "V"


def add_arguments(parser):
    parser.add_argument("config", help="TOML file: [model], [input], [simulate] tables (docs/cli.md)")
    parser.add_argument("--out", default=None, help="output folder (default results/simulate-<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace trajectory.csv/png in --out")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")
    bands.add_arguments(parser)  # --band, --band-method, --band-level, --band-samples, --band-seed


class Run(NamedTuple):
    """What a simulate config describes: the config and its folder, the model, the system it simulates (the model, or
    a tank test of its valve), the signal, the output times, `pamjax.simulate`'s keyword arguments and the recording
    that drives it (or None)."""

    cfg: dict
    root: pathlib.Path
    model: object
    system: object
    signal: object
    ts: object
    kwargs: dict
    recording: object


def validate_config(cfg):
    """Check every table, key and value type (nothing built, nothing read)."""
    schema.validate_simulate(cfg)


def load(path):
    """The run a simulate config describes, read in one pass: read → validate all → build the model → build the
    run (`build_run`) and check it (the signal's range, the initial state), all before the output folder."""
    path = pathlib.Path(path)
    _not_a_model_file(path)
    cfg = read_toml(path)
    schema.validate_simulate(cfg)
    model = build_model(cfg.get("model", {}), path.parent)
    run = build_run(cfg, model, path.parent)
    validate(run.system, run.signal, run.ts, run.kwargs.get("y0"))  # signal range, initial state
    if run.recording is not None and not is_recorded(cfg["input"].get("signal", "recorded")):
        _warn_against_command(run)
    resolve_stepping(run.system, run.kwargs.get("stepping", "auto"))  # "grid" with a switching valve, ...
    return run


def _warn_against_command(run):
    """A typed signal beside a recording whose command column it contradicts: the recording drawn beside the
    simulation is of another run than the one simulated, said (was: drawn without a word, its misfit read as the
    model's). Not refused, as `pamjax fit` does: a what-if input beside a recording is a use."""
    import warnings

    from .._fit.recording import PamjaxDataWarning
    from .config import check_against_command

    try:
        check_against_command(run.signal, run.recording, "[input] signal", run.system)
    except PamjaxInputError as err:
        text = str(err).split(": the model would be driven")[0]
        warnings.warn(f"pamjax simulate: {text}: the recording drawn beside the simulation ran another command; write "
                      "signal = \"recorded\" to simulate the recorded run", PamjaxDataWarning, stacklevel=2)


def build_run(cfg, model, root):
    """The `Run` of a validated config and its model: the system, its `initial` keys checked against it, then the
    recording read (if any), the signal, the output times (a `t_end` past the recording refused where its command
    drives the model or its times are the rows: `check_end`) and the solver's settings."""
    import jax.numpy as jnp

    import pamjax as pj

    inp, sim = cfg.get("input", {}), cfg.get("simulate", {})
    system = pj.TankFromModel(sim["tank_volume"])(model) if "tank_volume" in sim else model
    if not isinstance(system, pj.AbstractSystem):
        raise PamjaxInputError(f"[model] must describe a system (MuscleSystem, TankSystem, ...) to simulate, got a "
                               f"{type(system).__name__} (a {type(system).__name__} alone has no dynamics)")
    check_initial(system, sim.get("initial", {}), "[simulate] initial")
    recording = load_recording(inp, root) if "file" in inp else None
    signal = build_signal(inp.get("signal", "recorded"), "[input]", recording)
    t0 = float(sim.get("t0", recording.t[0] if recording is not None else 0.0))
    t_end = float(sim.get("t_end", recording.t[-1] if recording is not None else 0.0))
    if not t_end > t0:
        raise PamjaxInputError(f"[simulate] t_end ({t_end} s) must exceed t0 ({t0} s)")
    driven = is_recorded(inp.get("signal", "recorded"))
    if recording is not None and "t0" in sim and driven:
        from .config import check_start

        check_start(recording, t0, "[simulate] t0")
    if recording is not None and "t_end" in sim and (driven or "dt" not in sim):  # was: rows ending at its end
        check_end(recording, t_end, "[simulate] t_end", "its command drives the model and ends there" if driven else
                  "the output rows are its times and end there (give dt to simulate the signal past it)")
    if recording is not None and "dt" not in sim:
        ts = recording.t[(recording.t >= t0) & (recording.t <= t_end)]
    else:
        ts = output_times(t0, t_end, float(sim.get("dt", DEFAULT_DT)), exact_end="t_end" in sim)
    kwargs = {k: sim[k] for k in ("stepping", "substeps", "grid_step", "rtol", "atol", "max_steps") if k in sim}
    if "solver" in sim:
        import diffrax as dfx

        kwargs["solver"] = pj.Rodas5() if sim["solver"] == "Rodas5" else getattr(dfx, sim["solver"])()
    if sim.get("initial"):
        kwargs["y0"] = system.initial_state(**sim["initial"])
    return Run(cfg, pathlib.Path(root), model, system, signal, jnp.asarray(ts), kwargs, recording)


def output_times(t0, t_end, dt, exact_end=True):
    """The output rows t0, t0 + dt, ..., t_end [s]: `dt` apart (a CSV that stands in for a recording is uniformly
    sampled: `Recording.sample_rate`, its filters) and ending at `t_end`, as `pamjax.simulate_discrete`'s grid
    covers its `t_end`. A `dt` that does not divide t_end - t0 is refused (t_end 1.0, dt 0.3 ended the CSV at 0.9 s
    without a word), with a dt that does; not `exact_end` (t_end defaulted to a recording's end, which a resampling
    dt seldom divides), the rows end at the last one within it."""
    steps = (t_end - t0) / dt
    rows = int(np.floor(steps + 1e-9)) + 1
    if rows > MAX_ROWS:
        raise PamjaxInputError(f"[simulate] t_end = {t_end} s at dt = {dt} s would write {rows:,} rows (more than "
                               f"{MAX_ROWS:,}); raise dt, or check t_end is in seconds")
    if rows < 2:
        raise PamjaxInputError(f"[simulate] dt = {dt} s leaves fewer than two output times in [{t0}, {t_end}] s")
    if exact_end and abs(steps - round(steps)) > 1e-9 * max(steps, 1.0):
        last, fits = t0 + dt * (rows - 1), (t_end - t0) / np.ceil(steps)
        raise PamjaxInputError(f"[simulate] dt = {dt:g} s does not divide t_end - t0 = {t_end - t0:g} s: the rows "
                               f"would end at {last:g} s, short of t_end; set dt = {fits:.6g} (or another divisor), "
                               f"or t_end = {last:g} or {last + dt:g}")
    return t0 + dt * np.arange(rows)


def columns_of(traj, command="1"):
    """The trajectory's channels as CSV columns (name → array) and their units, in the order of `_UNITS` (docs/cli.md:
    t, command, pressure, position, velocity, force, friction_force, mass_flow, volume), then any others."""
    cols = {"t": np.asarray(traj.t)}
    channels = traj.channels()
    for c in [c for c in _UNITS if c in channels] + [c for c in channels if c not in _UNITS]:
        cols[c] = np.asarray(traj.channel(c))
    return cols, {c: command if c == "command" else _UNITS.get(c, "") for c in cols}


PLOT_POINTS = 100_000  # a figure's width holds ~1,000 pixels: more points than this are drawn as their envelope


def _envelope(t, y):
    """(t, y) to draw: as given up to `PLOT_POINTS`, else the minimum and maximum of each of `PLOT_POINTS / 2`
    bins (a 19,000 s run's 1.9 M rows look the same, and are drawn in a fraction of the time and memory)."""
    t, y = np.asarray(t), np.asarray(y)
    if t.size <= PLOT_POINTS:
        return t, y
    bins = PLOT_POINTS // 2
    n = t.size // bins * bins
    tb, yb = t[:n].reshape(bins, -1), y[:n].reshape(bins, -1)
    lo, hi = np.nanargmin(np.where(np.isnan(yb), np.inf, yb), axis=1), np.nanargmax(np.where(np.isnan(yb), -np.inf,
                                                                                                 yb), axis=1)
    rows = np.arange(bins)
    first, second = np.minimum(lo, hi), np.maximum(lo, hi)  # in time order within the bin
    ts = np.stack([tb[rows, first], tb[rows, second]], axis=1).ravel()
    ys = np.stack([yb[rows, first], yb[rows, second]], axis=1).ravel()
    return np.concatenate([ts, t[n:]]), np.concatenate([ys, y[n:]])


def plot(path, traj, recording=None, title="", command="1"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("pressure", 1e-6, "pressure [MPa abs]")]
    if traj.position is not None:
        panels += [("position", 1e3, "position [mm]"), ("force", 1.0, "muscle force [N]")]
    panels.append(("command", 1.0, "command [V]" if command == "V" else "command (duty)"))
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 2.3 * len(panels)), sharex=True, squeeze=False)
    t = np.asarray(traj.t)
    for ax, (c, scale, label) in zip(axes[:, 0], panels):
        if recording is not None and c in recording.channels and c != "command":
            ax.plot(*_envelope(recording.t, recording[c] * scale), ".", ms=2, color="0.6", label="recording")
        ax.plot(*_envelope(t, np.asarray(traj.channel(c)) * scale), lw=0.9, label="simulation")
        ax.set(ylabel=label)
    axes[0, 0].set_title(title)
    axes[-1, 0].set(xlabel="t [s]")
    if recording is not None:
        axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def _not_a_model_file(path):
    """`pamjax simulate model.json`: a model file where the config belongs is named, with the config it needs."""
    path = pathlib.Path(path)
    if path.suffix.lower() != ".json" or not path.is_file():
        return
    raise PamjaxInputError(
        f"{path} is a JSON file; pamjax simulate reads a TOML config that names the model file, the input and the "
        f"horizon, e.g. a file sim.toml beside it holding\n  [model]\n  file = \"{path.name}\"\n  [input]\n  signal "
        "= { kind = \"Triangle\", low = 0.05, high = 0.95, frequency = 0.25 }\n  [simulate]\n  t_end = 8.0\nand "
        "then: pamjax simulate sim.toml (docs/cli.md)")


def run(args):
    import pamjax as pj

    r = load(args.config)
    system, signal, ts, kwargs, recording = r.system, r.signal, r.ts, r.kwargs, r.recording
    band_source = bands.check_simulate(args, r)  # --band: a fitted model file, before the output folder
    out = args.out or f"results/simulate-{pathlib.Path(args.config).stem}"
    outputs = [o for o in OUTPUTS if not (args.no_plot and o.endswith(".png"))]
    with OutputFolder(out, "pamjax simulate", outputs, overwrite=args.overwrite,
                      stale=OUTPUTS) as folder:
        if len(ts) > LONG_ROWS:  # a run of minutes: say so before it starts
            print(f"pamjax simulate: solving {float(ts[-1] - ts[0]):g} s ({len(ts):,} output times) ...", flush=True)
        traj = pj.simulate(system, signal, ts, **kwargs)
        cols, units = columns_of(traj, command_unit(system))
        summary = ", ".join(f"{c} {np.min(v):.6g} … {np.max(v):.6g} {units[c]}" for c, v in cols.items()
                            if c in ("pressure", "position"))
        print(f"pamjax simulate: {type(system).__name__}, {len(ts)} output times over "
              f"{float(ts[-1] - ts[0]):g} s, {int(traj.num_steps)} solver steps; {summary}")
        comment = f"pamjax simulate {args.config}: {type(system).__name__}; pressures absolute"
        figure = lambda p: plot(p, traj, recording, str(args.config), units["command"])  # noqa: E731
        if band_source is not None:  # --band: <channel>_lower / _upper columns, the band drawn in the figure
            comment, figure = bands.add_to_simulation(args, r, band_source, traj, cols, units, comment)
        written = [folder.write("trajectory.csv", lambda p: write_table(p, cols, units, comment))]
        if not args.no_plot:
            try:
                written.append(folder.write("trajectory.png", figure))
            except ModuleNotFoundError:
                print("no figure: matplotlib is not installed (pip install matplotlib)")
        print("wrote " + ", ".join(str(p) for p in written if p is not None))
        return 1 if folder.failed else 0
