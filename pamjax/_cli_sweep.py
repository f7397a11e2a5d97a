"""`pamjax sweep CONFIG.toml`: run a steady-state map, flow surface or frequency response; write NPZ, CSV, figure.

Config (see `examples/sweep_*.toml`); every key is checked before anything runs, and a key the chosen `kind` does
not use is an error listing the ones it does:

    kind = "steady_state"            # or "flow_surface", "frequency_response"
    [system]                         # paper 000's MAS-10 preset (flow_surface: its MHE2 valve alone)
    valve = "pwm"                    # "pwm" (smoothed switching) or "averaged" (eq. 13)
    payload_mass = 9.6               # kg
    [sweep]
    commands = { start = 0.0, stop = 1.0, num = 101 }   # duty ratios (or a list)
    horizon = 5.0                    # s; window = 1.0 s averaged at the end
"""

import argparse
import csv
import os
import time

import numpy as np

from . import presets
from ._cli_fit import check_keys, read_toml
from ._distributed import join_for_cli
from ._errors import PamjaxInputError
from ._sweep_maps import flow_surface, frequency_response, steady_state_map

KINDS = ("steady_state", "flow_surface", "frequency_response")
_TOP_KEYS = {"kind", "system", "sweep"}
_SOLVER_KEYS = {"method", "dt", "chunk_size"}  # passed to pamjax.sweep
# [system] and [sweep] keys each kind uses (defaults in run_config, each with its source)
_SYSTEM_KEYS = {
    "flow_surface": {"supply_pressure"},
    "steady_state": {"valve", "payload_mass"},
    "frequency_response": {"valve", "payload_mass"},
}
_SWEEP_KEYS = {
    "flow_surface": {"commands", "pressures"},
    "steady_state": {"commands", "horizon", "window", "sample_interval"} | _SOLVER_KEYS,
    "frequency_response": {"frequencies", "offset", "amplitude", "settle_periods", "periods",
                           "samples_per_period"} | _SOLVER_KEYS,
}
_AXES = {"commands", "pressures", "frequencies"}
# sweeps step on a fixed grid: the smoothed-edge switching valve or eq. 13; the exact-edge valve needs `simulate`
_VALVES = ("pwm", "averaged")
_AXIS_KEYS = {"start", "stop", "num", "log"}
OUTPUTS = ("sweep.npz", "sweep.csv", "sweep.png")
DEFAULT_CPU_DEVICES = os.cpu_count() or 1  # --cpu-devices: one XLA CPU device per core


def add_arguments(parser):
    parser.add_argument("config", help="TOML file describing the sweep (examples/sweep_*.toml)")
    parser.add_argument("--out", default=None, help="output folder (default results/sweep-<config name>)")
    parser.add_argument("--overwrite", action="store_true", help="replace existing sweep.npz/csv/png in --out")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure")
    parser.add_argument("--cpu-devices", type=_positive_int, default=DEFAULT_CPU_DEVICES,
                        help="on CPU, split the processor into this many XLA devices and shard the sweep over them "
                             "(default: one per core; 1: a single device). No effect on GPU/TPU runs")
    parser.add_argument("--distributed", action="store_true",
                        help="join a multi-process run (JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID, "
                             "or SLURM/Open MPI) and spread the sweep over every process's devices (--cpu-devices "
                             "per process); process 0 writes the outputs (docs/distributed.md)")


def _use_cpu_devices(count):
    """Split the CPU into `count` XLA devices, so that `sweep` shards its batch over every core. JAX takes the
    device count only before its backend starts; importing pamjax and parsing the command line start nothing."""
    import jax

    try:
        jax.config.update("jax_num_cpu_devices", count)
    except RuntimeError:  # JAX already ran in this process (main() called from Python): its devices stay
        pass


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"--cpu-devices must be an integer >= 1, got {text!r}")
    return value


def validate_config(config):
    """Check every table and key of a parsed sweep config for its `kind` (nothing is built or solved)."""
    check_keys(config, _TOP_KEYS, "sweep config")
    kind = config.get("kind")
    if kind not in KINDS:
        raise PamjaxInputError(f"kind must be one of {list(KINDS)}, got {kind!r}")
    check_keys(config.get("system", {}), _SYSTEM_KEYS[kind], f"[system] (kind = {kind!r})")
    sw = config.get("sweep", {})
    check_keys(sw, _SWEEP_KEYS[kind], f"[sweep] (kind = {kind!r})")
    for name in _AXES & set(sw):
        _axis(sw[name], name)
    valve = config.get("system", {}).get("valve", "pwm")
    if kind != "flow_surface" and valve not in _VALVES:
        raise PamjaxInputError(f"[system] valve must be one of {list(_VALVES)}, got {valve!r}")


def _axis(spec, name):
    if isinstance(spec, list) and spec and all(isinstance(v, int | float) for v in spec):
        return np.asarray(spec, dtype=float)
    if isinstance(spec, dict) and {"start", "stop", "num"} <= set(spec):
        check_keys(spec, _AXIS_KEYS, f"[sweep] {name}")
        space = np.geomspace if spec.get("log", False) else np.linspace
        return space(float(spec["start"]), float(spec["stop"]), int(spec["num"]))
    raise PamjaxInputError(f"[sweep] {name} must be a non-empty list of numbers or a table "
                           f"{{start, stop, num[, log]}}, got {spec!r}")


def _write_csv(path, columns):
    names = list(columns)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in zip(*(np.ravel(columns[n]) for n in names)):
            writer.writerow([f"{v:.10g}" for v in row])


def run_config(config, progress=print):
    """Validate and run a parsed config; returns (columns for CSV/NPZ: name -> 1-D array with units in the name,
    plot spec). Defaults: paper 000's MAS-10 preset (pwm valve, 9.6 kg payload, 0.65 MPa abs supply)."""
    validate_config(config)
    kind = config["kind"]
    sys_cfg, sw = config.get("system", {}), config.get("sweep", {})
    options = {k: sw[k] for k in _SOLVER_KEYS if k in sw}
    if kind == "flow_surface":
        valve = presets.mas10_valve(supply_pressure=float(sys_cfg.get("supply_pressure", presets.SUPPLY_PRESSURE)))
        u = _axis(sw.get("commands", {"start": 0, "stop": 1, "num": 41}), "commands")
        default_p = {"start": 101325.0, "stop": float(valve.supply_pressure), "num": 41}  # p_atm (ISO 2533) … p_s
        p = _axis(sw.get("pressures", default_p), "pressures")
        air = presets.Air()
        flow = flow_surface(valve, u, p, air)
        uu, pp = np.meshgrid(u, p, indexing="ij")
        return dict(duty=uu.ravel(), pressure_pa_abs=pp.ravel(), mass_flow_kg_s=flow.ravel()), ("surface", u, p, flow)
    system = presets.mas10_system(valve=sys_cfg.get("valve", "pwm"),
                                  payload_mass=float(sys_cfg.get("payload_mass", presets.PAYLOAD_MASS)))
    if kind == "steady_state":
        u = _axis(sw.get("commands", {"start": 0, "stop": 1, "num": 101}), "commands")
        kwargs = {k: float(sw[k]) for k in ("horizon", "window", "sample_interval") if k in sw}
        r = steady_state_map(system, u, progress=progress, **kwargs, **options)  # defaults: _sweep_maps
        cols = dict(duty=u, pressure_pa_abs=r["pressure"], position_m=r["position"], status=r.status)
        return cols, ("steady", u, r)
    f = _axis(sw.get("frequencies", {"start": 0.05, "stop": 5.0, "num": 16, "log": True}), "frequencies")
    kwargs = {k: float(sw[k]) for k in ("offset", "amplitude") if k in sw}
    kwargs.update({k: int(sw[k]) for k in ("settle_periods", "periods", "samples_per_period") if k in sw})
    fr = frequency_response(system, f, progress=progress, **kwargs, **options)  # defaults: _sweep_maps
    cols = dict(frequency_hz=f, position_gain_m=fr["position"]["gain"], position_phase_deg=fr["position"]["phase"],
                pressure_gain_pa=fr["pressure"]["gain"], pressure_phase_deg=fr["pressure"]["phase"],
                status=fr["result"].status)
    return cols, ("bode", f, fr)


def plot(spec, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kind = spec[0]
    if kind == "surface":
        _, u, p, flow = spec
        fig, ax = plt.subplots(figsize=(7, 5))
        for j in range(0, len(p), max(1, len(p) // 8)):
            ax.plot(u, flow[:, j] * 1e3, label=f"p = {(p[j] - 101325) / 1e6:.2f} MPa gauge")
        ax.set(xlabel="duty ratio u [-]", ylabel="cycle-averaged mass flow [g/s]",
               title="Averaged flow surface of the switching valve (chamber held at p)")
        ax.legend(fontsize=7)
    elif kind == "steady":
        _, u, r = spec
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
        a1.plot(u, (r["pressure"] - 101325) / 1e6)
        a1.set(ylabel="pressure [MPa gauge]", title="Steady state against constant duty")
        a2.plot(u, r["position"] * 1e3)
        a2.set(xlabel="duty ratio u [-]", ylabel="displacement [mm]")
        for a in (a1, a2):
            a.axvspan(0, 0.1, color="gray", alpha=0.15)
            a.axvspan(0.9, 1.0, color="gray", alpha=0.15)
    else:
        _, f, fr = spec
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
        a1.loglog(f, fr["position"]["gain"] * 1e3)
        a1.set(ylabel="gain [mm per unit duty]", title="Frequency response: duty → displacement")
        a2.semilogx(f, fr["position"]["phase"])
        a2.set(xlabel="frequency [Hz]", ylabel="phase [deg]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args):
    _use_cpu_devices(args.cpu_devices)
    writes = join_for_cli(args.distributed)  # before JAX starts; False on processes other than 0
    config = read_toml(args.config)  # run_config validates it before anything runs
    name = os.path.splitext(os.path.basename(args.config))[0]
    out = args.out or os.path.join("results", f"sweep-{name}")
    for existing in OUTPUTS:
        if os.path.exists(os.path.join(out, existing)) and not args.overwrite:
            raise SystemExit(f"{os.path.join(out, existing)} exists; pass --overwrite to replace it")
    start = time.perf_counter()
    columns, spec = run_config(config)
    if not writes:
        return 0
    import jax

    devices = jax.devices()
    print(f"pamjax sweep: {config['kind']}, {len(next(iter(columns.values())))} rows in "
          f"{time.perf_counter() - start:.1f} s on {len(devices)} {devices[0].platform} device(s)")
    os.makedirs(out, exist_ok=True)
    np.savez(os.path.join(out, "sweep.npz"), **columns)
    _write_csv(os.path.join(out, "sweep.csv"), columns)
    print(f"wrote {out}/sweep.npz and sweep.csv (columns: {', '.join(columns)})")
    if not args.no_plot:
        plot(spec, os.path.join(out, "sweep.png"))
        print(f"figure: {out}/sweep.png")
    failed = int(np.sum(columns.get("status", np.zeros(1)) != 0))
    if failed:
        print(f"warning: {failed} sweep points failed (status != 0; their outputs are NaN)")
    return 0
