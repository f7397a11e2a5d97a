"""Identification on realistic rigs nobody has seen: unseen plants logged with a real rig's nuisances, then fitted.

    python benchmarks/unseen_rigs.py [--rigs 3] [--seed 300] [--substeps 64] [--out results/unseen_rigs]

`shared/data/bench-realistic/realistic1` is one rig of this kind; further ones check the same figures (issue 29).
This script makes `--rigs` more, each in the layout and file format of realistic1, and runs `benchmarks/identify.py
--realistic ...` on them (each rig fitted by `fits/joint.py --data DIR --nuisance` from the datasheet presets, on the
CSV files as they are):

1. The plant: the truth set's parameters (hybrid-reference-bench/meta.json) with every fitted one × U(0.8, 1.2)
   (`unseen_plants.draw_params`, NumPy seed `--seed` + i).
2. The nuisances, drawn around realistic1's: each run's supply pressure 0.65 MPa × U(0.97, 1.03); a pressure sensor
   offset U(−3, 3) kPa (added to the gauge pressure) and gain U(0.99, 1.01); a position sensor offset U(−0.2, 0.2)
   mm; an acquisition delay U(0.3, 4) ms on both channels (fractional: never a whole number of samples); E4 logged
   from U(0.5, 3.5) s into its triangle run (from rest).
3. Recordings simulated by pamjax with exact stick-slip on the PWM-synchronous grid with `--substeps` RK4 nodes per
   period (four times the fits' 16), read at t − delay, through the sensors, plus the bench's noise (2 kPa, 0.1 mm),
   at 1 kHz, written as CSV: `time [s],duty [-],pressure [barg],position [mm]` (zeros on the tank rig), and
   `meta.json` with the truth under `params` and `nuisance` (read only by identify.py, to score).
4. `--payload-run KG`: one more run, E5, E3's triangle with a payload of KG kg (`payload_kg` in its meta.json entry),
   its supply pressure drawn after the rig's other draws: the rig's other runs and nuisances are those of its seed
   without it. The remedy the weak-motion warning advises where the payload rests on the upper stop.
   `--design-run DIR` records instead, as E5, the run `pamjax design` wrote into DIR (design.csv's duty, held per PWM
   period; design.json's `payload_kg`): a `"muscle_run"` with a recorded duty column and no triangle parameters.

The rigs are written under `--out` (not part of the repository). Ends with identify.py's RESULT line.
"""

import argparse
import importlib.metadata
import json
import os
import pathlib
import subprocess
import sys

os.environ.setdefault("JAX_ENABLE_COMPILATION_CACHE", "false")
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from unseen_plants import BENCH, ROOT, draw_params, truth_model  # noqa: E402

REALISTIC = ROOT / ".." / "shared" / "data" / "bench-realistic" / "realistic1"
ATMOSPHERE = 101325.0  # Pa abs (ISO 2533): the gauge reference of the files, as a logger's


def draw_nuisance(names, rng, nominal_supply):
    """The rig's nuisances (module docstring, 2.)."""
    return dict(delay_s=float(rng.uniform(0.3e-3, 4e-3)), pressure_offset_Pa=float(rng.uniform(-3e3, 3e3)),
                pressure_gain=float(rng.uniform(0.99, 1.01)), position_offset_m=float(rng.uniform(-2e-4, 2e-4)),
                supply_pressure_Pa={n: float(nominal_supply * rng.uniform(0.97, 1.03)) for n in names},
                e4_preroll_s=float(rng.uniform(0.5, 3.5)))


def _true_channels(system, signal, t_read, y0, substeps):
    """The plant's pressure and position at the times `t_read` (≥ 0; before 0: the start state)."""
    after = t_read > 0
    ts = np.concatenate([[0.0], t_read[after]])
    traj = pj.simulate(system, signal, ts, y0=y0, stepping="pwm", substeps=substeps)
    if int(traj.result) != 0:
        raise SystemExit(f"the truth's solve failed (result {int(traj.result)})")
    out = {}
    for c in ("pressure", "position"):
        if c in traj.channels():
            v = np.asarray(traj.channel(c), dtype=float)
            out[c] = v[np.cumsum(after)]  # samples before 0 (at the start, sorted first) read v[0]
    return out


def write_rig(directory, template, params, truth, nuisance, substeps, seed):
    """Simulate the runs of `template` (realistic1's meta.json) on `truth` with `nuisance` and write the rig."""
    directory.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    noise = template["noise"]
    period = float(truth.valve.period)
    experiments = {}
    for name, e in template["experiments"].items():
        design = e.get("design_csv")  # --design-run: the designed duty (read here, not written to meta.json)
        e = {k: v for k, v in e.items() if k not in ("phase_s", "design_csv")}
        supply = nuisance["supply_pressure_Pa"][name]
        fs = float(template.get("sampling_hz", 1000.0))
        t = np.arange(0.0, float(e["t_end"]) + 0.5 / fs, 1.0 / fs)
        preroll = 0.0
        if e["kind"].startswith("tank"):
            system = pj.TankFromModel(float(e["V_tank"]))(truth).with_supply_pressure(supply)
            signal = pj.Constant(float(e["u"]))
            y0 = system.initial_state(ATMOSPHERE if e["p0"] == "p_atm" else supply)
        else:
            system = truth.with_supply_pressure(supply)
            if "payload_kg" in e:  # a run with weights added (--payload-run)
                system = pj.PayloadFromModel(float(e["payload_kg"]))(system)
            if design is not None:  # the design's duty, one per PWM period (its last row: the run's end)
                rec = pj.Recording.load(design)
                signal = pj.Sampled(rec.t[:-1], np.asarray(rec["command"])[:-1], period=period)
            else:
                signal = pj.Triangle(float(e["lo"]), float(e["hi"]), float(e["f_tri"]))
            y0 = None
            if str(e.get("init", "")).startswith("unknown"):
                preroll = round(nuisance["e4_preroll_s"] / period) * period  # logging starts on a PWM period
                e["init"] = "unknown: logging started mid-way through the triangle run"
        clean = _true_channels(system, signal, t + preroll - nuisance["delay_s"], y0, substeps)
        duty = np.asarray(jax.vmap(signal)(np.floor((t + preroll) / period + 1e-9) * period))
        gauge = nuisance["pressure_gain"] * (clean["pressure"] - ATMOSPHERE) + nuisance["pressure_offset_Pa"]
        p = gauge + noise["p_std_Pa"] * rng.standard_normal(t.shape)
        if "position" in clean:
            x = clean["position"] + nuisance["position_offset_m"] + noise["x_std_m"] * rng.standard_normal(t.shape)
        else:
            x = np.zeros_like(t)  # the tank rig has no position sensor
        rows = np.column_stack([t, duty, p / 1e5, x * 1e3])
        np.savetxt(directory / f"{name}.csv", rows, delimiter=",", fmt=["%.4f", "%.6f", "%.6f", "%.5f"],
                   header="time [s],duty [-],pressure [barg],position [mm]", comments="")
        experiments[name] = e
    meta = dict(set=directory.name, experiments=experiments, noise=noise, sampling_hz=template.get("sampling_hz"),
                fitted_keys=template["fitted_keys"], params=params, nuisance=nuisance,
                generated_by=(f"benchmarks/unseen_rigs.py: pamjax {importlib.metadata.version('pamjax')}, "
                              f"PWM-synchronous grid with {substeps} RK4 nodes per period, exact stick-slip; seed "
                              f"{seed}"))
    (directory / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")


def _extra_run(args, template):
    """E5's meta.json entry: E3's triangle with `--payload-run` kg, or the design of `--design-run` (a muscle run of
    its duration, driven by its duty column, with its payload), else None."""
    if args.payload_run is not None:
        return dict(template["experiments"]["E3"], payload_kg=args.payload_run)
    if args.design_run is None:
        return None
    folder = pathlib.Path(args.design_run)
    design = json.loads((folder / "design.json").read_text())
    entry = dict(kind="muscle_run", t_end=float(design["duration"]), design_csv=str(folder / "design.csv"),
                 init="rest at equilibrium F_static(x0,p_atm)=Mg, valve off, stuck")
    if design.get("payload_kg") is not None:
        entry["payload_kg"] = float(design["payload_kg"])
    return entry


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=300, help="rig i draws with NumPy seed SEED + i")
    ap.add_argument("--substeps", type=int, default=64, help="RK4 nodes per PWM period of the simulation")
    ap.add_argument("--out", default="results/unseen_rigs")
    ap.add_argument("--no-fit", action="store_true", help="write the rigs only")
    ap.add_argument("--design-run", default=None, metavar="DIR",
                    help="also record E5, the run `pamjax design` wrote into DIR (design.csv's duty; design.json's "
                         "payload_kg where it carries one): the rig's other runs and nuisances stay those of its seed")
    ap.add_argument("--payload-run", type=float, default=None, metavar="KG",
                    help="also record E5, E3's triangle with a payload of KG kg (meta.json payload_kg): the remedy "
                         "the weak-motion warning advises; the rig's other runs and nuisances stay those of its seed")
    args = ap.parse_args(argv)
    if args.rigs < 1:
        raise SystemExit("--rigs must be >= 1")
    if args.payload_run is not None and not args.payload_run > 0:
        raise SystemExit("--payload-run must be a mass > 0 [kg]")
    if args.payload_run is not None and args.design_run is not None:
        raise SystemExit("give --payload-run or --design-run, not both (each records E5)")
    if args.design_run is not None and not (pathlib.Path(args.design_run) / "design.csv").is_file():
        raise SystemExit(f"--design-run {args.design_run}: no design.csv there (a pamjax design output folder)")
    out = pathlib.Path(args.out)
    truth_meta = json.loads((pathlib.Path(BENCH) / "meta.json").read_text())
    template = json.loads((REALISTIC / "meta.json").read_text())
    model = pj.presets.mas10_system(valve="pwm", friction="karnopp")
    bench = pj.bench.load_bench(BENCH, model)
    sets = []
    for i in range(args.rigs):
        seed = args.seed + i
        rng = np.random.default_rng(seed)
        params = draw_params(truth_meta, rng)
        nuisance = draw_nuisance(list(template["experiments"]), rng, float(model.valve.supply()))
        directory = out / f"rig{seed}"
        runs = template
        extra = _extra_run(args, template)
        if extra is not None:  # drawn after the rig's own draws, recorded last: those stay as they were
            runs = dict(template, experiments={**template["experiments"], "E5": extra})
            nuisance["supply_pressure_Pa"]["E5"] = float(model.valve.supply()) * rng.uniform(0.97, 1.03)
        write_rig(directory, runs, params, truth_model(model, bench, params), nuisance, args.substeps, seed)
        print(f"{directory}: delay {nuisance['delay_s'] * 1e3:.2f} ms, offset {nuisance['pressure_offset_Pa']:.0f} Pa, "
              f"gain {nuisance['pressure_gain']:.4f}, E4 from {nuisance['e4_preroll_s']:.2f} s", flush=True)
        sets.append(str(directory))
    if args.no_fit:
        return
    cmd = [sys.executable, str(ROOT / "benchmarks" / "identify.py"), "--sets", "--realistic", *sets, "--out",
           str(out / "fits")]
    sys.exit(subprocess.run(cmd).returncode)


if __name__ == "__main__":
    main()
