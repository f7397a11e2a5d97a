"""Paper 001: a Festo VPPM proportional pressure regulator (0-10 V reference) feeding a Festo DMSP-40-400 muscle.

Every number the paper prints that pamjax uses, with where it is printed. Pressures ABSOLUTE [Pa] unless a name says
GAUGE; eq. 5-8 are printed in V, bar (gauge) and l/min; the SI conversions live beside their use.
"""

# --- air (eq. 1-3 text) ----------------------------------------------------------------------------------------------
GAS_CONSTANT = 286.9  # J/(kg K), R
TEMPERATURE = 298.0  # K, T
POLYTROPIC_INDEX = 1.0  # n = κ = 1: isothermal chambers (eq. 3, 12)

# --- the VPPM (Sect. 2-3) ------------------------------------------------------------------------------------------
VOLTAGE_RANGE = (0.0, 10.0)  # V, reference range (Sect. 2)
SUPPLY_PRESSURE = 7e5  # Pa abs (Sect. 3)
HYSTERESIS = 5e3  # Pa, the 50 mbar maximal pressure hysteresis (Sect. 2)
ACCURACY = 0.02  # -, "standard accuracy 2 %" (Sect. 2; of the full scale assumed, as regulator data sheets state it)
REGULATION_RANGE = (2e3, 10e5)  # Pa GAUGE, "pressure regulation range 0.02-10 bars" (Sect. 2)
OPERATING_MODES = ("fast", "universal", "precise")  # Sect. 2; eq. 6 was identified in "universal" (Sect. 3)
TANK_VOLUME = 0.04  # m³, the charge/discharge tank (Sect. 3, appendix)

# --- identified transfer functions (Sect. 5) ---------------------------------------------------------------------
EQ6_GAIN = 1.01  # bar/V, static gain of G_Vref (eq. 6)
EQ6_TIME_CONSTANTS = (0.041, 0.023)  # s, poles of G_Vref and G_Qin (eq. 6, 7)
EQ7_GAIN = -0.922  # bar per l/min, static gain of G_Qin (eq. 7; l/min at ISO 8778 reference conditions assumed)
EQ7_CANCELLED_TIME_CONSTANT = 0.927  # s, the pole-zero pair eq. 7 cancels (kept out of the state: unobservable)

# --- the muscle set-up (Sect. 4) -----------------------------------------------------------------------------------
LOAD_FORCE = 893.0  # N, the hanging load (a 91.3 kg subject)
SUBJECT_MASS = 91.3  # kg, Sect. 4
DMSP40_NOMINAL_LENGTH = 0.4  # m, DMSP-40-400 (Sect. 4, data sheet)
DMSP40_RATED_FORCE = 6000.0  # N at 6 bar and 0 % contraction (Sect. 4, data sheet)
DMSP40_MAX_CONTRACTION = 0.25  # -, 25 % of the nominal length (Sect. 4, data sheet)

# --- Fig. 7: the square-wave reference ---------------------------------------------------------------------------
SQUARE_WAVE_HIGH = 3.0  # V, 0-3 V
SQUARE_WAVE_FREQUENCY = 1.5  # Hz

# --- Tables 1-2: ISO 6358 C and b of the regulator's paths against pressure (C in m³/(s bar)) ----------------------
CHARGING_TABLE = dict(  # Table 1: tank charging, indexed by the upstream (supply) pressure
    upstream_pressure_bar=(1.946, 2.954, 3.964, 4.983, 5.991, 6.943),
    critical_ratio=(0.6624, 0.5972, 0.5674, 0.5541, 0.5308, 0.5328),
    sonic_conductance_m3_per_s_bar=(1.6668e-04, 2.1299e-04, 6.4101e-04, 7.8871e-04, 7.7140e-04, 7.0564e-04),
)
DISCHARGING_TABLE = dict(  # Table 2: tank discharging, indexed by the tank (upstream) pressure
    tank_pressure_bar=(1.8964, 2.7350, 3.9706, 4.9714, 5.9744, 6.8439),
    critical_ratio=(0.7464, 0.6709, 0.6177, 0.5940, 0.5782, 0.5683),
    sonic_conductance_m3_per_s_bar=(0.0002, 0.0003, 0.0007, 0.0008, 0.0009, 0.0007),
)

# --- results the paper reports in numbers (Sect. 6), compared in the gallery ---------------------------------------
FIG5_VOLUME_SHARE = 0.10  # -, "the contribution of dV_PAM is about 10 % of the total output flow rate" (Fig. 5)
FIG6_INLET_OUTLET_DIFFERENCE = 0.20  # -, "a difference of around 20 % between the valve inlet and outlet flow rates"
PEAK_INFLOW = {3.0: 2.79, 5.0: 4.34}  # l/min at 3 V and 5 V reference (Sect. 6.1)
FIG11_MSE = dict(voltage_only=0.1663, global_model=0.0499)  # bar² (Fig. 11: P_sim1 eq. 6 alone, P_sim2 eq. 5)
FIG7_MSE = {1.5: 0.304, 1.0: 0.3183, 0.7: 0.2270}  # bar², eq. 6 vs the closed-port runs at 1.5, 1, 0.7 Hz (Fig. 7)
