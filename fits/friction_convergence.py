"""How close the smooth friction models come to exact stick-slip, and at what cost: paper 000's triangle runs (E3, E4
of a bench directory) simulated with the bench's true parameters under every friction model pamjax has.

    python fits/friction_convergence.py [--data DIR] [--out DIR] [--quick] [--overwrite]

- `KarnoppFriction` (exact stick-slip, events located inside the step of the PWM-synchronous grid, K = 16): the
  reference; its RMSE against the recordings is reported in units of their noise (1.00 = the model error is lost in
  the noise).
- `CoulombViscousFriction` (eq. 8-9 with sign(v) ≈ tanh(v/w)) for widths w from 10 mm/s down to 0.1 mm/s, adaptive
  Tsit5 (the switching valve's default) at rtol 1e-6 with the valve's latched exact edges (ScheduledValve): error
  against the reference, and the solver's steps.
- `BristleFriction` (Dahl-type: stuck elastically) for bristle stiffnesses σ0 from 1e4 to 1e6 N/m, same solver.

Writes OUT/friction_convergence.json and .png (error against width / stiffness, with step counts). Reads the bench's
`params` (true parameters): this is a study of model error, not a fit.
"""

import argparse
import json
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import pamjax as pj  # noqa: E402
from pamjax.gallery import bench_folder, json_text, refuse_existing  # noqa: E402

DEFAULT_DATA = bench_folder()  # the hybrid bench recordings shipped with pamjax (pamjax/data/)


def true_system(P, friction, mode="smooth"):
    valve = pj.OnOffValve(inflate=pj.EllipseRestriction(P["Cv12"], P["b12"], P["A"]),
                          exhaust=pj.EllipseRestriction(P["Cv23"], P["b23"], P["A"]), supply_pressure=P["p_s"],
                          pwm_frequency=P["f_pwm"], switch_on_delay=P["t_on"], switch_off_delay=P["t_off"], mode=mode)
    muscle = pj.Muscle(
        force_law=pj.PolynomialForce(np.array([P[f"a{i}"] for i in range(5)]), P["k0"], P["k1"], P["k2"], P["p_max"]),
        volume_law=pj.LinearVolume(P["v0"], P["v1"]), min_position=P["x_min"], max_position=P["x_max"])
    return pj.MuscleSystem(valve=valve, muscle=muscle, payload_mass=P["M"], gravity=P["g"], friction=friction,
                           air=pj.Air(P["R"], P["T"], P["kappa"], P["p_atm"]))


def rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--out", default="results/friction_convergence")
    ap.add_argument("--quick", action="store_true", help="E4 only, three widths")
    ap.add_argument("--overwrite", action="store_true", help="replace existing results in --out")
    args = ap.parse_args()
    data, out = pathlib.Path(args.data), pathlib.Path(args.out)
    runs = ["E4"] if args.quick else ["E3", "E4"]
    missing = [name for name in ("meta.json", *(f"{r}.npz" for r in runs)) if not (data / name).is_file()]
    if missing:  # before --out is made (a missing folder left an empty one behind)
        ap.error(f"--data {data} must be a bench directory holding meta.json and {', '.join(f'{r}.npz' for r in runs)}"
                 f"; {', '.join(missing)} not found there")
    refuse_existing("friction_convergence.py", [out / "friction_convergence.json", out / "friction_convergence.png"],
                    args.overwrite)
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((data / "meta.json").read_text())
    P, noise = meta["params"], meta["noise"]
    widths = [1e-2, 1e-3, 1e-4] if args.quick else [1e-2, 3e-3, 1e-3, 3e-4, 1e-4]
    stiffnesses = [1e4, 1e5] if args.quick else [1e4, 1e5, 1e6]
    rows = []
    for name in runs:
        e = meta["experiments"][name]
        rec = pj.Recording.load(data / f"{name}.npz")
        signal = pj.Triangle(e["lo"], e["hi"], e["f_tri"])
        karnopp = true_system(P, pj.KarnoppFriction(P["Fc"], P["Cf"]))
        t0 = time.perf_counter()
        ref = pj.simulate(karnopp, signal, rec.t)
        x_ref, p_ref = np.asarray(ref.position), np.asarray(ref.pressure)
        rows.append(dict(run=name, model="karnopp", setting=16, steps=int(ref.num_steps),
                         x_vs_data=rms(x_ref - rec["position"]) / noise["x_std_m"],
                         p_vs_data=rms(p_ref - rec["pressure"]) / noise["p_std_Pa"], x_err_mm=0.0, p_err_kpa=0.0,
                         seconds=time.perf_counter() - t0))
        models = [("coulomb", w, pj.CoulombViscousFriction(P["Fc"], P["Cf"], velocity_width=w)) for w in widths]
        models += [("bristle", s, pj.BristleFriction(coulomb_force=P["Fc"], viscous_coefficient=P["Cf"],
                                                     bristle_stiffness=s, bristle_damping=2 * np.sqrt(s * P["M"])))
                   for s in stiffnesses]
        for kind, setting, friction in models:
            system = true_system(P, friction, mode="exact")
            t0 = time.perf_counter()
            traj = pj.simulate(system, signal, rec.t, max_steps=2_000_000, throw=False)
            ok = int(traj.result) == 0
            x, p = np.asarray(traj.position), np.asarray(traj.pressure)
            rows.append(dict(run=name, model=kind, setting=setting, steps=int(traj.num_steps), ok=ok,
                             x_vs_data=rms(x - rec["position"]) / noise["x_std_m"] if ok else None,
                             p_vs_data=rms(p - rec["pressure"]) / noise["p_std_Pa"] if ok else None,
                             x_err_mm=1e3 * rms(x - x_ref) if ok else None,
                             p_err_kpa=1e-3 * rms(p - p_ref) if ok else None,
                             seconds=time.perf_counter() - t0))
            print(rows[-1], flush=True)
    (out / "friction_convergence.json").write_text(json_text(rows, indent=1))
    print(f"\n{'run':<5}{'model':<9}{'setting':>10}{'steps':>9}{'x err mm':>10}{'p err kPa':>10}{'x/noise':>9}"
          f"{'p/noise':>9}")
    for r in rows:
        fmt = lambda v, f: (format(v, f) if v is not None else "failed")  # noqa: E731
        print(f"{r['run']:<5}{r['model']:<9}{r['setting']:>10.3g}{r['steps']:>9}{fmt(r['x_err_mm'], '>10.4f')}"
              f"{fmt(r['p_err_kpa'], '>10.3f')}{fmt(r['x_vs_data'], '>9.3f')}{fmt(r['p_vs_data'], '>9.3f')}")
    plot(out / "friction_convergence.png", rows, runs)
    print(f"wrote {out}/friction_convergence.json and .png")


def plot(path, rows, runs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, kind, label in ((axes[0], "coulomb", "velocity width w [m/s]"),
                            (axes[1], "bristle", "bristle stiffness σ0 [N/m]")):
        twin = ax.twinx()
        for run, style in zip(runs, ("o-", "s--")):
            sel = [r for r in rows if r["run"] == run and r["model"] == kind and r.get("ok", True)]
            s = [r["setting"] for r in sel]
            ax.loglog(s, [r["x_err_mm"] for r in sel], style, label=f"{run} position error [mm]")
            twin.semilogx(s, [r["steps"] for r in sel], style, color="gray", alpha=0.6, label=f"{run} steps")
        ax.axhline(0.046, color="k", lw=0.6, ls=":", label="0.046 mm (≤ 1.1× the 0.1 mm noise)")
        ax.set(xlabel=label, ylabel="RMS position error against exact stick-slip [mm]",
               title=f"{kind} friction vs exact stick-slip (Karnopp)")
        twin.set_ylabel("adaptive solver steps (gray)")
        ax.legend(fontsize=7, loc="lower left" if kind == "coulomb" else "upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
