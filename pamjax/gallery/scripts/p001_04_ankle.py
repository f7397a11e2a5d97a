"""Paper 001, future work (Sect. 7): an antagonistic pair of DMSP-40 muscles, each fed by its own VPPM, on an ankle
joint; position from the pressure difference, stiffness from the sum. `fits/ankle.py`'s feed-forward demonstration
(static map → pressure pair at a 5 bar gauge sum → reference voltages) along a gait-like angle at stride frequencies
of the human gait band (0.125-1.5 Hz; `--quick`: 1.5 Hz only, two strides). The explicit Tsit5 solver takes as many
steps as the default Rodas5 here and compiles in a fifth of its time (same angle to 0.1°).
"""

import diffrax as dfx
import numpy as np

import pamjax as pj
from pamjax.gallery import Result, Row, plt, save
from pamjax.gallery.procedures import ankle

PAPER = "001"
TITLE = "Future work: antagonistic pair on an ankle joint (Sect. 7)"
COVERS = ("text: future work, antagonistic pair on an ankle joint",)


def run(out, quick=False):
    m = pj.presets.dmsp40_muscle()
    joint = pj.AntagonisticJoint(pj.ISO6358Regulator(), pj.ISO6358Regulator(), m, m)
    frequencies = (1.5,) if quick else (0.125, 0.5, 1.5)
    results = {f: ankle.run(joint, f, 5e5, solver=dfx.Tsit5()) for f in frequencies}
    numbers = {f"{f}Hz": dict(rmse_deg=float(np.degrees(r["rmse"])),
                              stiffness_N_m_per_rad=[float(r["stiffness"].min()), float(r["stiffness"].max())])
               for f, r in results.items()}
    pyplot = plt()
    fig, axes = pyplot.subplots(1, len(results), figsize=(5 * len(results), 3.5), squeeze=False)
    for ax, (f, r) in zip(axes[0], results.items()):
        ax.plot(r["t"], np.degrees(r["reference"]), "k--", label="reference")
        ax.plot(r["t"], np.degrees(r["angle"]), "C0-", label="simulated")
        ax.set(title=f"{f} Hz: RMSE {np.degrees(r['rmse']):.1f}°", xlabel="t [s]", ylabel="ankle angle [°]")
        ax.legend(fontsize=8)
    fig_name = save(fig, out, "ankle.png")
    text = ", ".join(f"{k}: {v['rmse_deg']:.1f}°" for k, v in numbers.items())
    k = [v for n in numbers.values() for v in n["stiffness_N_m_per_rad"]]
    rows = [Row("Sect. 7", "antagonistic DMSP-40 pair, feed-forward along a ±15° gait-like angle, 5 bar gauge sum",
                "proposed, not built", f"angle RMSE {text}; joint stiffness {min(k):.0f}-{max(k):.0f} N m/rad",
                figure=fig_name)]
    return Result(rows, numbers)


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
