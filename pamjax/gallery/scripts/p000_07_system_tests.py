"""Paper 000, eq. 15-16 and Figs. 13-14: the muscle lifting 9.6 kg under a triangle duty 0.05-0.95 at 0.08 and
0.25 Hz, three models against the hybrid bench's recordings (E3, E4: exact switching, stick-slip, 0.1 mm / 2 kPa noise).

- the switching valve with the bench's true parameters and exact stick-slip (`KarnoppFriction`), integrated on the
  PWM-synchronous grid: pamjax's faithful model (what is left is noise);
- the averaged valve (eq. 13, the preset's m1…m9) with the bench's muscle and a smooth Coulomb sign: the paper's
  analytic model;
- the MAS-10 preset (datasheet-derived parameters) with the switching valve: a model that was never fitted to this
  plant.

Displacement RMSE and maximum error in % of the recorded range, as the paper reports them (RMSE 3-5 %, max ≈ 10 %).
`--quick`: the 0.08 Hz run over its first period (12.5 s) instead of its 25 s.
"""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np

import pamjax as pj
from pamjax import KarnoppFriction, presets
from pamjax.gallery import Result, Row, bench_folder, plt, save
from pamjax.gallery.procedures.bench import bench_plant

PAPER = "000"
TITLE = "Muscle and 9.6 kg under triangle duty, models vs bench (eq. 15-16, Figs. 13-14)"
COVERS = ("Fig. 13", "Fig. 14")

RUNS = {"E3": (0.08, 25.0), "E4": (0.25, 8.0)}  # Hz, s (paper 000 Figs. 13, 14; bench meta.json)
QUICK_RUNS = {"E3": (0.08, 12.5), "E4": (0.25, 8.0)}  # one period of the slow triangle


def models():
    bench = bench_plant()  # smooth valve, Coulomb + viscous, the bench's parameters
    friction = bench.friction
    return dict(
        switching=(eqx.tree_at(lambda s: s.friction, bench, KarnoppFriction(friction.coulomb_force,
                                                                            friction.viscous_coefficient)),
                   dict(stepping="pwm")),
        averaged=(eqx.tree_at(lambda s: s.valve, bench, presets.mas10_averaged_valve()),
                  dict(solver=dfx.Tsit5(), max_steps=10**6)),  # compiles far faster than the default Rodas5
        preset=(presets.mas10_system("pwm", friction=KarnoppFriction(presets.COULOMB_FORCE,
                                                                        presets.VISCOUS_COEFFICIENT)),
                dict(stepping="pwm")),
    )


def errors(model, data):
    e = model - data
    span = float(np.ptp(data))
    rmse = float(np.sqrt(np.mean(e**2)))
    return dict(rmse_percent=100 * rmse / span, max_percent=float(100 * np.max(np.abs(e)) / span), rmse_mm=1e3 * rmse)


def run(out, quick=False):
    bench = bench_folder()
    systems = models()
    runs = QUICK_RUNS if quick else RUNS
    pyplot = plt()
    fig, axes = pyplot.subplots(len(runs), 1, figsize=(10, 3.5 * len(runs)), squeeze=False)
    numbers = {}
    for ax, (name, (frequency, horizon)) in zip(axes[:, 0], runs.items()):
        rec = np.load(bench / f"{name}.npz")
        keep = rec["t"][::10] <= horizon + 1e-9  # 100 Hz
        ts, data = rec["t"][::10][keep], rec["x"][::10][keep]
        ax.plot(ts, data * 1e3, ".", color="0.6", ms=1.5, label="bench recording")
        numbers[name] = {}
        for k, (label, (system, kwargs)) in enumerate(systems.items()):
            x = np.asarray(pj.simulate(system, pj.Triangle(0.05, 0.95, frequency), jnp.asarray(ts), **kwargs).position)
            numbers[name][label] = errors(x, data)
            ax.plot(ts, x * 1e3, "-", color=f"C{k}", lw=1,
                    label=f"{label}: RMSE {numbers[name][label]['rmse_percent']:.1f} %")
        ax.set(title=f"Fig. {13 if name == 'E3' else 14}: triangle duty at {frequency} Hz, 9.6 kg ({name})",
               xlabel="t [s]", ylabel="displacement x [mm]")
        ax.legend(fontsize=8)
    fig_name = save(fig, out, "system_tests.png")

    def span(label, key):
        values = [numbers[n][label][key] for n in runs]
        return f"{min(values):.1f}-{max(values):.1f} %" if len(values) > 1 else f"{values[0]:.1f} %"

    rows = [
        Row("eq. 15-16, Figs. 13-14", f"displacement error, {' and '.join(f'{f} Hz' for f, _ in runs.values())}: "
            "RMSE and max error in % of range", "RMSE 3-5 %, max ≈ 10 % (both valve models)",
            f"switching + stick-slip, true parameters: RMSE {span('switching', 'rmse_percent')}, max "
            f"{span('switching', 'max_percent')}; averaged valve: RMSE {span('averaged', 'rmse_percent')}, max "
            f"{span('averaged', 'max_percent')}; unfitted preset: RMSE {span('preset', 'rmse_percent')}",
            figure=fig_name),
    ]
    return Result(rows, numbers, paper=dict(rmse_percent=[3, 5], max_error_percent=10))


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
