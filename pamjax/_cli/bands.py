"""`--band` of `pamjax simulate` and `pamjax sweep`: a confidence band of the fitted model's prediction, from the
covariance its model file carries (`pamjax fit` writes it into `model.json`'s provenance; a model file written
before that is read with the `fit.json` beside it). docs/cli.md, docs/fitting.md ("Bands on predictions").

Checked before any work: the config's model is a fitted model file (`[model] file`, not a preset or `[system]`),
the file carries a covariance, and neither `[model] set` nor `[sweep] over` changes a fitted parameter (the band is
of the fitted values). The CSV gains `<column>_lower` and `<column>_upper` per output, in the column's unit, with
`#` lines saying what the band is; the figure draws it shaded.
"""

import argparse
import contextlib
import pathlib
import warnings

import numpy as np

from .._bands.band import METHODS, prediction_band, z_of
from .._bands.maps import flow_surface_band, frequency_response_band, steady_state_band
from .._bands.uncertainty import PamjaxBandWarning, propagation, read_uncertainty
from .._core.errors import PamjaxInputError
from .._fit.parameters import split_path
from .._systems.base import AbstractMuscleSystem
from .kinds import commands

DEFAULT_LEVEL = 0.95  # the two-sided 95 % band (z = 1.96), the usual default for confidence bands
DEFAULT_SAMPLES = 200  # draws: the 2.5 % quantile then scatters by ~0.19 σ (docs/fitting.md)


def _level(text):
    try:
        value = float(text)
        z_of(value)
    except (ValueError, PamjaxInputError):
        raise argparse.ArgumentTypeError(f"--band-level must be a confidence level in (0, 1), e.g. 0.95, got "
                                         f"{text!r}") from None
    return value


def int_at_least(option, minimum):
    """An argparse `type` for `option`: an integer >= `minimum`, else an error naming the option and the value."""

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{option} must be an integer >= {minimum}, got {text!r}")
        return value

    return parse


def add_arguments(parser):
    group = parser.add_argument_group("confidence band of a fitted model (docs/fitting.md, 'Bands on predictions')")
    group.add_argument("--band", action="store_true",
                       help="add a confidence band from the fit's covariance ([model] file = the model.json of "
                            "pamjax fit): <column>_lower/_upper columns and the band drawn in the figure")
    group.add_argument("--band-method", choices=METHODS, default="linear",
                       help="linear (delta method; default) or samples (parameter draws, each simulated)")
    group.add_argument("--band-level", type=_level, default=DEFAULT_LEVEL, help="confidence level (default 0.95)")
    group.add_argument("--band-samples", type=int_at_least("--band-samples", 20), default=DEFAULT_SAMPLES,
                       help=f"draws for --band-method samples (default {DEFAULT_SAMPLES})")
    group.add_argument("--band-seed", type=int_at_least("--band-seed", 0), default=0,  # refused before the run
                       help="seed of the draws, an integer >= 0 (default 0)")


def _touches(key, entry):
    """Whether setting parameter `key` changes the fitted free entry `entry` (same leaf, overlapping elements)."""
    path = entry if isinstance(entry, str) else entry["path"]
    (a, ia), (b, ib) = split_path(key), split_path(path)
    return a == b and (ia is None or ib is None or ia == ib)


def fitted_source(config, root, command, model, changed=()):
    """The model file whose covariance the band propagates, and its `FitUncertainty`; a `PamjaxInputError` naming
    what to change when the config's model is not a fitted model file, `changed` (the `set` and `over` paths)
    touches a fitted parameter, the fit left a combination undetermined, or `model` (built from the config) does not
    hold the fitted values."""
    model_cfg = config.get("model")
    if model_cfg is None or "file" not in model_cfg:
        what = ("[system] (paper 000's preset)" if model_cfg is None else
                f"[model] preset = {model_cfg.get('preset', 'mas10_system')!r}")
        raise PamjaxInputError(f"{command} --band: {what} is not a fitted model; --band needs [model] file = the "
                               "model.json that pamjax fit writes (it carries the fit's covariance)")
    path = pathlib.Path(root) / model_cfg["file"]
    uncertainty = read_uncertainty(path)
    block, _ = uncertainty.plant()
    for where, keys in (("[model] set", model_cfg.get("set", {})), *changed):
        for key in keys:
            hit = next((label for label, entry in zip(block.labels, block.paths) if _touches(key, entry)), None)
            if hit is None:
                hit = next((p for p in block.paths if _touches(key, p)), None)
            if hit is not None:
                raise PamjaxInputError(f"{command} --band: {where} changes {key!r}, a parameter the fit determined "
                                       f"({hit}); the band is of the fitted values: remove it from {where}, or run "
                                       "without --band")
    try:
        with _quiet():
            propagation(uncertainty, model, check_values=True)  # identifiable, and the file's values are the fit's
    except PamjaxInputError as err:
        raise PamjaxInputError(f"{command} --band: {err}") from None
    return path, uncertainty


@contextlib.contextmanager
def _quiet():
    """The band's warnings are printed as its notes (one line each), not as Python warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PamjaxBandWarning)
        yield


def _options(args):
    return dict(level=args.band_level, method=args.band_method, samples=args.band_samples, seed=args.band_seed)


def report(band, source, command):
    """Print what the band is, and return the same as CSV comment lines."""
    lines = [f"band from the covariance of {source}",  # the API's advice in the command's own words
             *band.describe().replace("use method='samples'", "use --band-method samples").splitlines()]
    for line in lines:
        print(f"{command}: {line}")
    return "\n".join(lines)


# -- simulate --------------------------------------------------------------------------------------------------
class _Trajectory:
    """`pamjax simulate`'s solve as a traced prediction of the model (a tank test of its valve, the initial state
    recomputed from each parameter point, failed solves as NaN)."""

    def __init__(self, signal, ts, kwargs, tank_volume, initial, channels):
        self.signal, self.ts, self.kwargs = signal, ts, {k: v for k, v in kwargs.items() if k != "y0"}
        self.tank_volume, self.initial, self.channels = tank_volume, dict(initial or {}), tuple(channels)

    def __call__(self, model):
        import pamjax as pj

        system = pj.TankFromModel(self.tank_volume)(model) if self.tank_volume is not None else model
        y0 = system.initial_state(**self.initial) if self.initial else None
        traj = pj.simulate(system, self.signal, self.ts, y0=y0, throw=False, adjoint="forward", **self.kwargs)
        return {c: traj.channel(c) for c in self.channels}


def check_simulate(args, run):
    """Before the output folder: the fitted model file and its covariance (`run`: what `simulate.load` built); a
    solve the band can trace."""
    if not args.band:
        return None
    source = fitted_source(run.cfg, run.root, "pamjax simulate", run.model)
    from .._solve.simulate import resolve_stepping

    if run.system.valve.exact_edges and resolve_stepping(run.system, run.kwargs.get("stepping", "auto")) == "adaptive":
        raise PamjaxInputError("pamjax simulate --band: the exact-edge valve's solve computes its switching times "
                               "before it starts and cannot be differentiated or batched; set [simulate] stepping = "
                               "\"pwm\" (the PWM-synchronous grid integrates the exact-edge model, differentiably)")
    return source


def add_to_simulation(args, run, source, traj, cols, units, comment):
    """The band of `pamjax simulate`'s trajectory (`run`: what `simulate.load` built): `<channel>_lower` / `_upper`
    columns added to `cols` (and their units to `units`); returns (the CSV comment with the band's description, the
    figure writer)."""
    from . import band_figures

    sim = run.cfg.get("simulate", {})
    channels = [c for c in cols if c not in ("t", "command")]
    predict = _Trajectory(run.signal, run.ts, run.kwargs, sim.get("tank_volume"), sim.get("initial"), channels)
    path, uncertainty = source
    with _quiet():
        band = prediction_band(uncertainty, predict, model=run.model, **_options(args))
    for c in channels:
        cols[f"{c}_lower"], cols[f"{c}_upper"] = band.lower[c], band.upper[c]
        units[f"{c}_lower"] = units[f"{c}_upper"] = units[c]
    note = report(band, path, "pamjax simulate")
    title = f"{args.config}: {100 * band.level:g} % band ({band.method})"
    return comment + "\n" + note, lambda p: band_figures.trajectory(p, traj, band, run.recording, title)


# -- sweep -----------------------------------------------------------------------------------------------------
# sweep.csv column of each banded output: steady state, frequency response (gain, phase), flow surface
SWEEP_COLUMNS = {"pressure": "pressure_pa_abs", "position": "position_m", "position_gain": "position_gain_m",
                 "position_phase": "position_phase_deg", "pressure_gain": "pressure_gain_pa",
                 "pressure_phase": "pressure_phase_deg", "mass_flow": "mass_flow_kg_s"}


def check_sweep(args, config, root, model):
    """Before the output folder: the fitted model file and its covariance, `set` and `over` not on a fitted
    parameter."""
    if not args.band:
        return None
    if getattr(args, "distributed", False):
        raise PamjaxInputError("pamjax sweep --band runs its band's sweeps in one process: drop --distributed (the "
                               "band of a map is a few sweeps of the map's size)")
    over = config.get("sweep", {}).get("over", {})
    return fitted_source(config, root, "pamjax sweep", model, changed=(("[sweep] over", over),))


def _one_map(config, model, uncertainty, options, axis):
    """The band of one map of `model`: output name → (lower, upper) flat in the CSV's row order."""
    kind, sw = config["kind"], config.get("sweep", {})
    solver = {k: sw[k] for k in ("dt", "chunk_size") if k in sw} | (
        {"scheme": sw["method"]} if "method" in sw else {})
    if kind == "flow_surface":
        from .._core.units import ATMOSPHERE

        u = commands(config.get("sweep", {}), model, 41)
        p = axis("pressures", {"start": ATMOSPHERE, "stop": float(model.valve.supply_pressure), "num": 41})
        band = flow_surface_band(uncertainty, u, p, model=model, **options)
    elif kind == "steady_state":
        u = commands(config.get("sweep", {}), model, 101)
        kwargs = {k: float(sw[k]) for k in ("horizon", "window", "sample_interval") if k in sw}
        band = steady_state_band(uncertainty, u, model=model, progress=False, **kwargs, **solver, **options)
    else:
        f = axis("frequencies", {"start": 0.05, "stop": 5.0, "num": 16, "log": True})
        kwargs = {k: float(sw[k]) for k in ("offset", "amplitude") if k in sw}
        kwargs.update({k: int(sw[k]) for k in ("settle_periods", "periods", "samples_per_period") if k in sw})
        channels = ("position", "pressure") if isinstance(model, AbstractMuscleSystem) else ("pressure",)  # sweep.csv
        band = frequency_response_band(uncertainty, f, model=model, channels=channels, progress=False, **kwargs,
                                       **solver, **options)
    return band


def add_to_sweep(args, config, model, source, spec, columns):
    """The band of `pamjax sweep`'s map (every point of a `[sweep] over` grid): `<column>_lower` / `_upper` columns
    added to `columns`; returns (the CSV comment, the figure writer)."""
    import itertools

    from . import band_figures
    from .config import apply_set
    from .kinds import axis as axis_values

    sw = config.get("sweep", {})

    def axis(name, default):  # a [sweep] axis's values (validated with the config)
        return axis_values(sw.get(name, default), name)

    path, uncertainty = source
    over = config.get("sweep", {}).get("over", {})
    paths = list(over)
    grid = list(itertools.product(*[axis(f"over.{p}", over[p]) for p in paths])) or [()]
    options = _options(args)
    extra, maps = {}, []
    with _quiet():
        for point in grid:
            point_model = apply_set(model, dict(zip(paths, point)), "[sweep] over") if paths else model
            band = _one_map(config, point_model, uncertainty, options, axis)
            maps.append(band)
            for name, lower in band.lower.items():
                column = SWEEP_COLUMNS.get(name, name)
                if column not in columns:  # a channel the map does not write (a steady tank's zero flow)
                    continue
                extra.setdefault(f"{column}_lower", []).append(np.ravel(lower))
                extra.setdefault(f"{column}_upper", []).append(np.ravel(band.upper[name]))
    columns.update({k: np.concatenate(v) for k, v in extra.items()})
    comment = report(maps[0], path, "pamjax sweep")
    if paths:
        comment += f"\none band per point of the [sweep] over grid ({len(grid)} points)"
    return comment, lambda p: band_figures.sweep(p, spec, maps, columns)
