"""C_v and b_v of both paths of paper 000's on/off valve (eq. 11) from constant-volume tank tests (Figs. 11-12):
a 5e-5 m³ tank charged from atmosphere (path 1→2, inflate) and discharged from the 0.65 MPa supply (path 2→3,
exhaust) at PWM duty 0.25, 0.50 and 0.75 (50 Hz, 2 ms switching delays), pressure compared over 2 s.

    python fits/valve_tank.py --data synthetic   # pamjax's own simulation of Table 1's values, 2 kPa noise, seeded
    python fits/valve_tank.py --data bench       # E1_u*/E2_u* of the hybrid bench (pamjax/data)

The valve is the switching valve with exact edges, integrated on the PWM-synchronous grid (`stepping="pwm"`; residuals
smooth in C_v, b_v). Start: C_v 30 % high, b_v 30 % low. Writes `fit.json`, `summary.json` and `valve_tank.png`
(tank pressure, data and model, as in Figs. 11-12) to `--out` (default results/valve_tank_<data>).
Options: `--rate` Hz (default 100), `--quick` (0.5 s per run), `--overwrite`.
"""

import argparse
import json
import pathlib

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import bench_folder, json_text, refuse_existing  # noqa: E402
from pamjax.gallery.procedures.bench import tank_model  # noqa: E402

TABLE_1 = {"valve.inflate.discharge_coefficient": 0.36, "valve.inflate.critical_ratio": 0.28,
           "valve.exhaust.discharge_coefficient": 0.39, "valve.exhaust.critical_ratio": 0.49}  # paper 000, Table 1
FREE = list(TABLE_1)
NOISE = 2e3  # Pa: the bench's pressure noise (meta.json "noise")
DUTIES = (0.25, 0.50, 0.75)


def check_rate(ap, rate, horizon, bench):
    """`--rate` [Hz]: finite, giving at least two samples per run (a solve starts at the first), and for the bench's
    recordings at most their own rate (resampling only decimates); `ap.error` (exit status 2) otherwise."""
    if not (np.isfinite(rate) and rate * horizon >= 1.0):
        ap.error(f"--rate must be a finite number >= {1.0 / horizon:g} Hz (at least two samples in each {horizon:g} s "
                 f"run), got {rate:g}")
    if bench is not None:
        t = pj.Recording.load(bench / "E1_u0.25.npz").t
        own = 1.0 / float(np.min(np.diff(t)))
        if rate > own * (1 + 1e-9):
            ap.error(f"--rate must be at most the bench recordings' own {own:.6g} Hz (resampling decimates), "
                     f"got {rate:g}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", choices=("synthetic", "bench"), default="synthetic")
    ap.add_argument("--rate", type=float, default=100.0, help="samples per second compared [Hz]")
    ap.add_argument("--quick", action="store_true", help="0.5 s per run (a smoke run)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None)
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args()
    out = pathlib.Path(args.out or f"results/valve_tank_{args.data}")
    bench = bench_folder()
    horizon = 0.5 if args.quick else 2.0
    check_rate(ap, args.rate, horizon, bench if args.data == "bench" else None)
    # all three up front: pj.fit refuses fit.json only after the recordings are made, and not the other two
    refuse_existing("valve_tank.py", [out / "fit.json", out / "summary.json", out / "valve_tank.png"], args.overwrite)
    P = json.loads((bench / "meta.json").read_text())["params"]
    truth = tank_model(P, *TABLE_1.values())
    ts = np.arange(0.0, horizon + 1e-9, 1.0 / args.rate)

    experiments = []
    for k, (kind, p0) in enumerate((("E1", P["p_atm"]), ("E2", P["p_s"]))):
        for j, u in enumerate(DUTIES):
            name = f"{kind}_u{u:.2f}"
            if args.data == "bench":
                rec = pj.Recording.load(bench / f"{name}.npz").window(0.0, horizon).resampled(args.rate)
            else:
                rec = pj.synthetic_recording(truth, pj.Constant(u), ts, noise=dict(pressure=NOISE),
                                             channels=["pressure"], y0=truth.initial_state(p0),
                                             seed=args.seed + 3 * k + j, name=name, stepping="pwm", substeps=32)
            experiments.append(pj.Experiment(rec, pj.Constant(u), channels=["pressure"], scales=dict(pressure=NOISE),
                                             initial=dict(pressure=p0), name=name, stepping="pwm"))

    space = pj.ParameterSpace(truth, FREE)
    true_values = np.asarray(space.initial_values())
    start = space.with_values(true_values * np.array([1.3, 0.7, 1.3, 0.7]))
    res = pj.fit(start, experiments, FREE, out=out / "fit.json", overwrite=args.overwrite)

    rel = (np.asarray(res.values) - true_values) / true_values
    z = (np.asarray(res.values) - true_values) / np.asarray(res.standard_errors)
    print(f"\n{args.data} data: status {res.status}, {res.iterations} iterations, cost {res.initial_cost:.4g} → "
          f"{res.cost:.4g} ({res.num_residuals} residuals), fit {res.fit_s:.1f} s + compile {res.compile_s:.1f} s")
    print(res.table(TABLE_1))
    for lbl, r, zz in zip(res.labels, rel, z):
        print(f"  {lbl:<40} fitted − true {100 * r:+7.2f} %   {zz:+6.2f} std err")
    for name, chans in res.channel_errors.items():
        e = chans["pressure"]
        print(f"  {name}  pressure RMSE {e['rmse'] / 1e3:.2f} kPa ({e['rmse_percent']:.2f} % of range)")
    summary = dict(data=args.data, quick=args.quick, rate=args.rate, status=res.status, true=TABLE_1,
                   fitted=dict(zip(res.labels, res.values)), standard_errors=dict(zip(res.labels, res.standard_errors)),
                   relative_error=dict(zip(res.labels, rel.tolist())), z=dict(zip(res.labels, z.tolist())),
                   max_relative_error_percent=float(100 * np.max(np.abs(rel))))
    (out / "summary.json").write_text(json_text(summary, indent=1))
    plot(out / "valve_tank.png", res.model, experiments)
    print(f"max |fitted − true| = {summary['max_relative_error_percent']:.2f} %; wrote {out}/fit.json, summary.json, "
          "valve_tank.png")


def plot(path, model, experiments):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    predicted = pj.predictions(model, experiments)  # one program for every run (one per run compiles each anew)
    for e, p in zip(experiments, predicted):
        ax = axes[0] if e.name.startswith("E1") else axes[1]
        line = ax.plot(e.times, np.asarray(e.data["pressure"]) / 1e5, ".", ms=2, label=f"{e.name} data")[0]
        ax.plot(e.times, np.asarray(p["pressure"]) / 1e5, "-", color=line.get_color(), lw=0.9)
    axes[0].set(xlabel="t [s]", ylabel="tank pressure [bar abs]", title="charge (path 1→2): data dots, model lines")
    axes[1].set(xlabel="t [s]", title="discharge (path 2→3)")
    for ax in axes:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
