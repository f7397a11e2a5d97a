"""Paper 000: a Festo MAS-10-300 muscle lifting 9.6 kg through a Festo MHE2 3/2 on/off valve driven by 50 Hz PWM.

Every number the paper prints that pamjax uses, with where it is printed. Pressures ABSOLUTE [Pa] unless a name says
GAUGE; SI units throughout.
"""

# --- Table 1: valve paths (ISO 6358-style sonic/quarter-ellipse law, eq. 11) and air ---------------------------
VALVE_AREA = 3.14e-6  # m², Table 1 ("valve diameter", an area)
INFLATE_DISCHARGE_COEFFICIENT = 0.36  # C_v(1→2), Table 1
EXHAUST_DISCHARGE_COEFFICIENT = 0.39  # C_v(2→3), Table 1
INFLATE_CRITICAL_RATIO = 0.28  # b_v(1→2), Table 1
EXHAUST_CRITICAL_RATIO = 0.49  # b_v(2→3), Table 1
GAS_CONSTANT = 287.0  # J/(kg K), R of air, Table 1
TEMPERATURE = 293.0  # K, T, Table 1
HEAT_CAPACITY_RATIO = 1.4  # κ, eq. 10 text
POLYTROPIC_INDEX = 1.4  # n of eq. 15 (adiabatic), eq. 12 and 15 text

# --- "System Setup" and "Analytic valve model" -------------------------------------------------------------------
SUPPLY_PRESSURE = 6.5e5  # Pa abs, "System Setup" (0.65 MPa abs.; the "6.5 MPa" of the valve section is a typo)
PWM_FREQUENCY = 50.0  # Hz, "System Setup"
SWITCH_DELAY = 2e-3  # s, MHE2 switching time ≈ 2 ms ("Analytic valve model"): 10-90 % usable duty at 50 Hz
PAYLOAD_MASS = 9.6  # kg, "System Setup"
GRAVITY = 9.81  # m/s², eq. 16
MAX_PRESSURE = 6e5  # Pa GAUGE, p_max of eq. 7
COULOMB_FORCE = 16.0  # N, half of the 32 N hysteresis loop width (Figs. 3-5)
SAMPLE_TIME = 1e-4  # s, the dSpace controller's 0.1 ms sampling time ("PI-Control"; eq. 17-21's T_s)

# --- "PI-Control" --------------------------------------------------------------------------------------------------
PI_PROPORTIONAL_GAIN = 25.0  # 1/m, P = 25
PI_INTEGRAL_GAIN = 150.0  # 1/(m s), I = 150
