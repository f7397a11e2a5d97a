"""`pamjax demo`: paper 000's experiments with the MAS-10 preset (valve tests, Figs. 11-12; system tests, 13-14);
writes each trajectory as CSV (units in the header, readable by `pamjax.Recording.load`) and a figure."""

import os
import time

import jax.numpy as jnp
import numpy as np

from .. import presets
from .._physics.signals import Constant, Triangle
from .._solve.simulate import simulate

DUTIES = (0.25, 0.5, 0.75)  # paper 000, Figs. 11-12
TRIANGLES = ((0.08, 25.0), (0.25, 8.0))  # Hz, s: paper 000, Figs. 13-14
VALVES = ("pwm", "averaged")
FIGURE = "paper000_experiments.png"


def add_arguments(parser):
    parser.add_argument("--out", default="pamjax-demo", help="output folder for the CSV files and the figure")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of an earlier demo in --out")
    parser.add_argument("--no-plot", action="store_true", help="skip the figure (no matplotlib needed)")


def experiment_names():
    """The names of the demo's runs (each written as `<name>.csv`)."""
    tanks = [f"tank_{kind}_{valve}_{duty}" for valve in VALVES for duty in DUTIES for kind in ("inflate", "deflate")]
    return tanks + [f"triangle_{f}_{valve}" for f, _ in TRIANGLES for valve in VALVES]


def run_experiments(progress=print):
    """Run the demo's experiments; returns a dict name → (Trajectory, description)."""
    results = {}
    tank_ts = jnp.linspace(0.0, 2.0, 401)
    for valve in VALVES:
        for duty in DUTIES:
            system = presets.mas10_tank_system(valve=valve)
            t = time.perf_counter()
            inflate = simulate(system, Constant(duty), tank_ts)
            deflate = simulate(system, Constant(duty), tank_ts, y0=system.initial_state(presets.SUPPLY_PRESSURE))
            progress(
                f"  tank, {valve:8s} valve, duty {duty:.2f}: inflate to {float(inflate.pressure[-1]) / 1e5:.2f} bar"
                f", deflate to {float(deflate.pressure[-1]) / 1e5:.2f} bar abs ({time.perf_counter() - t:.1f} s)"
            )
            results[f"tank_inflate_{valve}_{duty}"] = inflate
            results[f"tank_deflate_{valve}_{duty}"] = deflate
    for frequency, horizon in TRIANGLES:
        ts = jnp.linspace(0.0, horizon, int(horizon * 100) + 1)
        for valve in VALVES:
            system = presets.mas10_system(valve=valve)
            t = time.perf_counter()
            traj = simulate(system, Triangle(0.05, 0.95, frequency), ts)
            x = np.asarray(traj.position) * 1e3
            progress(
                f"  muscle + 9.6 kg, triangle {frequency} Hz, {valve:8s} valve: displacement {x.min():.1f} … "
                f"{x.max():.1f} mm, {int(traj.num_steps)} steps ({time.perf_counter() - t:.1f} s)"
            )
            results[f"triangle_{frequency}_{valve}"] = traj
    return results


def plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    for ax, kind, title in (
        (axes[0, 0], "inflate", "Fig. 11: inflating a 50 cm³ tank"),
        (axes[0, 1], "deflate", "Fig. 12: deflating a 50 cm³ tank"),
    ):
        for duty, color in zip((0.25, 0.5, 0.75), ("C0", "C1", "C2")):
            for valve, style in (("pwm", "-"), ("averaged", "--")):
                tr = results[f"tank_{kind}_{valve}_{duty}"]
                ax.plot(
                    tr.t,
                    (np.asarray(tr.pressure) - 101325) / 1e6,
                    style,
                    color=color,
                    label=f"u = {duty:.2f}, {'switching' if valve == 'pwm' else 'averaged'}",
                )
        ax.set(title=title, xlabel="time [s]", ylabel="pressure [MPa, gauge]")
        ax.legend(fontsize=7)
    for ax, frequency in ((axes[1, 0], 0.08), (axes[1, 1], 0.25)):
        for valve, style in (("pwm", "-"), ("averaged", "--")):
            tr = results[f"triangle_{frequency}_{valve}"]
            ax.plot(
                tr.t,
                np.asarray(tr.position) * 1e3,
                style,
                label="switching valve" if valve == "pwm" else "averaged valve",
            )
        ax2 = ax.twinx()
        ax2.plot(tr.t, tr.command, ":", color="gray")
        ax2.set_ylabel("duty ratio [-]", color="gray")
        ax.set(
            title=f"Fig. {13 if frequency == 0.08 else 14}: triangle duty 0.05-0.95 at {frequency} Hz, 9.6 kg",
            xlabel="time [s]",
            ylabel="displacement [mm]",
        )
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120, format="png")
    plt.close(fig)


def run(args):
    from .._core.csvio import write_table
    from .out import OutputFolder
    from .simulate import columns_of

    outputs = [f"{name}.csv" for name in experiment_names()] + ([] if args.no_plot else [FIGURE])
    with OutputFolder(args.out, "pamjax demo", outputs, overwrite=args.overwrite,
                      stale=[FIGURE]) as folder:  # an earlier demo's figure, which a --no-plot run does not replace
        print("pamjax demo: paper 000 (Festo MAS-10-300, MHE2 valve at 50 Hz, 0.65 MPa abs supply), preset "
              "parameters")
        results = run_experiments()
        for name, traj in results.items():
            cols, units = columns_of(traj)
            comment = f"pamjax demo: {name} (paper 000 preset); pressures absolute"
            folder.write(f"{name}.csv", lambda p, cols=cols, units=units, c=comment: write_table(p, cols, units, c))
        print(f"wrote {len(results)} trajectories to {args.out}/<run>.csv (t [s], command, pressure [Pa abs], ...)")
        if not args.no_plot:
            try:
                folder.write(FIGURE, lambda p: plot(results, p))
                print(f"figure: {os.path.join(args.out, FIGURE)}")
            except ModuleNotFoundError:
                print("no figure: matplotlib is not installed (pip install matplotlib)")
        return 1 if folder.failed else 0
