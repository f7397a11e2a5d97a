"""Paper 000, eq. 12-13 and Figs. 8-9: the averaged ("analytic") valve, m1…m9 of the 2nd-order bi-polynomial.

`fits/averaged_valve.py`'s two routes: (1) eq. 13 fitted to the switching valve's cycle-averaged flow on a (duty,
pressure) grid; (2) the paper's own procedure, noisy constant-volume tank runs filtered, differentiated and turned into
mass flow by eq. 12 (Fig. 8's estimates), the surface fitted (Fig. 9). Both scored against the cycle-averaged flow on
the valve's usable 10-90 % duty, in % of the flow range, beside the paper's fit to its measurements.
"""

from pamjax.gallery import Result, Row
from pamjax.gallery.procedures import averaged_valve as av

PAPER = "000"
TITLE = "Averaged valve, eq. 13 bi-polynomial (eq. 12-13, Figs. 8-9)"
COVERS = ("eq. 12", "eq. 13", "Fig. 8", "Fig. 9")


def run(out, quick=False):
    report, plot_args = av.compute(quick)
    av.plot(out / "averaged_valve.png", *plot_args)
    d, t = report["cycle_average_fit"], report["tank_procedure"]
    rows = [
        Row("eq. 12, Fig. 8", "mass flow from filtered, differentiated tank pressure (eq. 12), the paper's procedure",
            "surface of estimates over duty and pressure", f"{'4' if quick else '8'} duties × charge/discharge, "
            "1 kHz, 2 kPa noise, Butterworth 20 Hz", figure="averaged_valve.png"),
        Row("eq. 13, Fig. 9", "bi-polynomial m1…m9: max error / RMSE, % of the flow range",
            "4.13 % / 1.16 % (fit to its measurements)",
            f"tank procedure {t['max_error_percent']:.1f} % / {t['rmse_percent']:.2f} %; direct fit to the cycle "
            f"average {d['max_error_percent']:.1f} % / {d['rmse_percent']:.2f} %", figure="averaged_valve.png"),
    ]
    return Result(rows, report, paper=report["paper"])


if __name__ == "__main__":
    from pamjax.gallery import script_main

    script_main(__name__)
