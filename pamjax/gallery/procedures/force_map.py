"""The real Festo DMSP-20-300 force map (Martens & Boblan, Actuators 2017, 6(4), 33, Appendix A1; CC BY 4.0;
`pamjax/data/README.md`) and the steps that derive paper 000's eq. 7 from it: the map itself (`load_map`), eq. 7's
start model for a fit (`eq7_start`), and the preset derivation (`force_map_shape`, `scaled_muscle`,
`virtual_work_volume`; `pamjax/presets.py` items 1-2). Command lines: `fits/static_force.py`,
`fits/derive_presets.py`; in the gallery: `p000_01_force_laws`, `p000_02_static_force`.
"""

import importlib.resources
import pathlib

import numpy as np

import pamjax as pj
from pamjax import presets

DATA = pathlib.Path(str(importlib.resources.files("pamjax") / "data" / "DMSP-20-300_force_map_long.csv"))
L0 = 0.300  # m, nominal length (type code DMSP-20-300)
MAP_L0 = L0
AUTHORS_MAX_ERROR_PERCENT = 2.35  # Martens & Boblan 2017: their model's maximum error on this muscle
P_MAX = 6e5  # Pa gauge, paper 000
MAX_CONTRACTION = 0.25  # datasheet
P = np.polynomial.polynomial


def load_map():
    """The map's isometric points: x [m] (contraction), p [Pa abs] (the file's gauge pressures + 1 atm), F [N]."""
    rows = np.loadtxt(DATA, delimiter=",", comments="#", skiprows=2)
    length, pressure_gauge, force = rows[:, 0], rows[:, 2], rows[:, 3]
    return L0 - length, pressure_gauge + 101325.0, force


def start_muscle(force_law):
    """DMSP-20-300 start: the MAS-10 preset's shape (itself derived from this map) scaled to 1460 N at 6 bar."""
    return pj.Muscle(force_law=force_law, volume_law=pj.LinearVolume(1e-4, 1e-3), min_position=0.0, max_position=0.08)


def eq7_start():
    """Eq. 7 start model for the DMSP-20-300 (the MAS-10 preset's shape scaled to its 1460 N at 6 bar) and its free
    parameters (k2 fixed: only k0/k2 and k1/k2 are identifiable)."""
    scale = 1460.1 / presets.MAS10_MAX_FORCE_COEFFICIENTS[0]
    model = start_muscle(pj.PolynomialForce(np.asarray(presets.MAS10_MAX_FORCE_COEFFICIENTS) * scale,
                                            presets.MAS10_K0 * scale, presets.MAS10_K1 * scale, 1e5))
    return model, ["force_law.max_force_coefficients", "force_law.k0", "force_law.k1"]


def force_map_shape(path=DATA):
    """(quartic F_max(ε) coefficients [N], line of ∂F/∂p in ε [N/Pa]) of the DMSP-20-300 map."""
    length, _, pressure, force = np.genfromtxt(path, delimiter=",", skip_header=2).T
    eps, fmax, slope = [], [], []
    for ell in np.unique(length)[::-1]:
        sel = (length == ell) & (force > 0)
        if sel.sum() < 2:
            continue
        c1, c0 = np.polyfit(pressure[sel], force[sel], 1)
        eps.append((MAP_L0 - ell) / MAP_L0)
        fmax.append(c0 + c1 * P_MAX)
        slope.append(c1)
    quartic = P.polyfit(np.append(eps, MAX_CONTRACTION), np.append(fmax, 0.0), 4)
    return quartic, P.polyfit(eps, slope, 1)


def scaled_muscle(force_at_zero, nominal_length, path=DATA):
    """a0…a4 [N/mⁱ], k0 [N], k1 [N/m] for a muscle of this family (k2 = 1e5 Pa)."""
    quartic, slope_line = force_map_shape(path)
    scale = force_at_zero / quartic[0]
    a = quartic * scale / nominal_length ** np.arange(5)
    k0 = slope_line[0] * 1e5 * scale
    k1 = -slope_line[1] / nominal_length * 1e5 * scale
    return a, k0, k1


def virtual_work_volume(a_eps, nominal_length, n=201):
    """(ε grid, V − v0 on it) [m³] from F_max(ε) coefficients [N] by cumulative trapezoid."""
    eps = np.linspace(0.0, MAX_CONTRACTION, n)
    integrand = P.polyval(eps, a_eps) / P_MAX * nominal_length  # dV/dε = L0 F/p
    dv = np.concatenate([[0.0], np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(eps))])
    return eps, dv
