"""Festo data sheets, the DMSP-20-300 force map, and the model numbers derived from them.

Paper 000 gives no numbers for a0…a4, k0…k2, m1…m9, v0, v1 or C_f; paper 001 none for the DMSP-40's force law or
volume. They are derived from the data sheets and the measured DMSP-20-300 force map (Martens & Boblan, Actuators
2017, CC BY 4.0; bundled in `pamjax/data/`) as the docstring of `pamjax.presets` explains item by item ("item n"
below); `tests/test_presets.py` and `fits/derive_presets.py` re-run the derivation. Assumed numbers say so.
"""

# --- Festo MAS-10-300 (data sheet) ---------------------------------------------------------------------------------
MAS10_NOMINAL_LENGTH = 0.3  # m
MAS10_INNER_DIAMETER = 0.01  # m
MAS10_MAX_CONTRACTION = 0.25  # -, 25 % of the nominal length
MAS10_RATED_FORCE = 630.0  # N at 6 bar and 0 % contraction

# --- MAS-10-300 model numbers, derived (presets items 1-6) ---------------------------------------------------------
MAS10_MAX_FORCE_COEFFICIENTS = (  # item 1
    630.0,  # a0 [N]: data sheet 630 N at 6 bar, 0 % contraction
    -2.13454122e04,  # a1 [N/m]  } DMSP-20-300 force-map shape (Martens & Boblan 2017),
    5.41182050e05,  # a2 [N/m²] } scaled to 630 N and the 300 mm length
    -8.18503719e06,  # a3 [N/m³]
    4.35960743e07,  # a4 [N/m⁴]
)
MAS10_K0 = 102.844885  # N, slope of F in p at x = 0 times k2 (DMSP-20 map, scaled; item 1)
MAS10_K1 = 1127.520188  # N/m, decrease of that slope per metre of contraction (DMSP-20 map, scaled; item 1)
MAS10_K2 = 1e5  # Pa, fixed by convention (k0, k1, k2 are not separately identifiable; item 1)
MAS10_V0 = 2.3561945e-05  # m³, π/4 · (10 mm)² · 300 mm (data-sheet geometry; item 2)
MAS10_V1 = 4.1558930e-04  # m², virtual-work volume slope of the force map (item 2)
MAS10_MIN_POSITION = -0.02  # m, assumed stretch limit (paper 000 Fig. 3 shows stretch but no number; item 6)
MAS10_MAX_POSITION = 0.075  # m, 25 % of 300 mm (data-sheet maximum contraction; item 6)
MAS10_VISCOUS_COEFFICIENT = 250.0  # N s/m, ≈ 0.4 of critical damping of 9.6 kg on ≈ 1e4 N/m (item 4)
# m1…m9 of eq. 13 (SI: kg/s, gauge pressure in Pa), row-wise m[i, j] for u^i p^j (item 3).
MAS10_AVERAGED_VALVE = (
    (0.000000000000e00, -7.181961484418e-09, 3.579264316813e-15),
    (1.735650319051e-03, 1.083465634502e-08, -9.704130366914e-15),
    (6.335335758663e-04, 2.128659784083e-09, -1.228195803324e-14),
)
MAS10_SILENCER_PERMEANCE = 1.9557e-14  # kg/(s Pa²), exhaust silencer: 98 % of the choked exhaust flow at 0.65 MPa
#                                        passes (paper 000's "almost negligible" at high pressure; item 5)
HYBRID_BENCH_TANK_VOLUME = 5e-5  # m³, paper 000's valve-test tank: the paper gives none; the hybrid bench uses 5e-5
PI_BIAS = 0.5  # -, duty offset of the hybrid bench's PI runs (`meta.json`)

# --- DMSP-40-400 (paper 001), derived the same way -----------------------------------------------------------------
DMSP40_MAX_FORCE_COEFFICIENTS = (
    6000.0,  # a0 [N]: data sheet 6000 N at 6 bar, 0 % contraction (paper 001)
    -1.52467230e05,  # a1..a4: DMSP-20-300 map shape scaled to 6000 N and 400 mm
    2.89918955e06,
    -3.28863101e07,
    1.31372099e08,
)
DMSP40_K0 = 979.475097  # N (DMSP-20 map slope, scaled)
DMSP40_K1 = 8053.715626  # N/m
DMSP40_K2 = 1e5  # Pa, fixed by convention (as MAS10_K2)
DMSP40_VOLUME_CUBIC = (  # (d, c, b, a) of paper 001 eq. 4 in ε = x/L0 [m³]; virtual work of the force map, d = cylinder
    5.0265482e-04,  # π/4 · (40 mm)² · 400 mm
    3.48212e-03,
    -8.86154e-03,
    5.61662e-03,
)
DMSP40_MIN_POSITION = -0.02  # m, assumed as for the MAS-10
# N s/m, ASSUMED (paper 001 gives no friction; fits and the gallery use this value): a damping ratio
# C/(2 sqrt(K M)) of 0.77 for the M = 893 N / 9.81 = 91.0 kg load at 3 bar gauge, where this preset holds it at
# x = 35.7 mm with K = 4.20e4 N/m (pamjax.muscle_stiffness, eq. 9, closed chamber n = 1); 1.03 on the isobaric
# stiffness 2.31e4 N/m (pressure_slope=0), 0.50 on a round 1e5 N/m. (The comment here claimed "≈ 0.2 of critical
# damping on ≈ 1e5 N/m": an arithmetic slip, 3000 / (2 sqrt(1e5 · 91.0)) = 0.50.)
DMSP40_VISCOUS_COEFFICIENT = 3000.0

# --- Festo VPPM-6L (paper 001's regulator): what its data sheet [29] would give, not available here -----------------
# Paper 001 quotes from it: 0.02-10 bar, 2 % accuracy, 50 mbar maximal hysteresis, modes fast/universal/precise
# (`paper001`). Everything below is derived or assumed, as marked.
VPPM_INTERNAL_VOLUME = 2.06e-4  # m³, DERIVED from paper 001 Fig. 6: the regulator volume (at the outlet pressure)
#   for which the inlet flow exceeds the outlet flow by 20 % (1 − ∫q_out/∫q_in over the charging phases) with the
#   DMSP-40 preset under 893 N, 0-3 V at 1.5 Hz for 2 s (`pamjax/gallery/scripts/p001_01_muscle_flow.py` re-derives it,
#   tests/test_regulator_vppm.py checks it); 41 % of the muscle's 0.50 L, far more than a G1/8 regulator body is
#   likely to hold (no volume is given): read it as everything between the seats and the muscle, tubing included.
VPPM_MODE_FACTORS = {  # ASSUMED: (factor on eq. 6's time constants, factor on the main stage's full-opening error)
    "universal": (1.0, 1.0),  # the mode paper 001 used (Sect. 3): eq. 6 and the 50 mbar as identified
    "fast": (0.5, 2.0),  # Festo's names promise a faster response at less accuracy; the factor 2 is an assumption
    "precise": (2.0, 0.5),  # more accuracy at a slower response; the factor 2 is an assumption
}
