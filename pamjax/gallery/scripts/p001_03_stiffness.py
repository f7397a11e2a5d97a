"""Paper 001, eq. 9-11 and Fig. 12: muscle stiffness, its rate of change and the valve flow along a 0-3 V, 1.5 Hz run.

`fits/stiffness.py`'s run: the DMSP-40 with 893 N fed by the physical VPPM (`ISO6358Regulator`); eq. 9 (K = −dF/dx of
the closed isothermal chamber), eq. 10 (V'ṗ + V''ẋp) and eq. 11 (q = (Vṗ + V'ẋp)/RT) by autodiff of the model's own
laws at every sample; eq. 11 checked against the delivered flow, eq. 10 against finite differences of pV'(x), and
the paper's claimed "equivalence" of eq. 10 and eq. 11 measured as a correlation. Eq. 9's K is checked against
central differences of the closed chamber's force.
"""

import diffrax as dfx

from pamjax.gallery import Result, Row
from pamjax.gallery.procedures import stiffness

PAPER = "001"
TITLE = "Muscle stiffness and its rate vs valve flow (eq. 9-11, Fig. 12)"
COVERS = ("eq. 9", "eq. 10", "eq. 11", "Fig. 12")


def run(out, quick=False):
    # two or three periods at 1.5 Hz; Tsit5 (the system is not stiff: as many steps as Rodas5, a fifth of the compile)
    r = stiffness.run(4.0 / 3.0 if quick else 2.0, solver=dfx.Tsit5())
    s = stiffness.summarise(r)
    stiffness.plot(r, out / "stiffness.png")
    k_lo, k_hi = s["stiffness_eq9_range_N_per_m"]
    rows = [
        Row("eq. 9, Fig. 12", "closed-chamber stiffness K = −dF/dx along the run", "curve only",
            f"{k_lo / 1e3:.0f}-{k_hi / 1e3:.0f} kN/m", figure="stiffness.png"),
        Row("eq. 10-11", "eq. 11 vs delivered flow; eq. 10 vs finite differences of pV'(x)",
            "eq. 10 and eq. 11 'equivalent'",
            f"eq. 11 = delivered flow to {s['eq11_vs_delivered_max_relative']:.0e}; eq. 10 = d(pV')/dt to "
            f"{100 * s['eq10_vs_finite_difference_max_relative']:.1f} % of its peak", figure="stiffness.png"),
        Row("Fig. 12", "correlation of eq. 10 (stiffness rate) with eq. 11 (valve flow)", "'equivalence evident'",
            f"{s['correlation_eq10_eq11']:.2f} (dK/dt of eq. 9 literally: {s['correlation_dK_dt_eq11']:.2f})",
            figure="stiffness.png"),
    ]
    return Result(rows, s, paper=s["paper"])


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
