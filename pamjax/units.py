"""Unit constants of the papers and data sheets, for scripts that convert to and from SI (pamjax itself works in SI
and absolute pressure throughout).

    import pamjax.units as u
    flow_l_per_min = mass_flow / u.FLOW_UNIT  # kg/s → l/min ANR
"""

from ._core.units import (
    ATMOSPHERE as ATMOSPHERE,  # Pa abs, ISO 2533 standard atmosphere
    BAR as BAR,  # Pa per bar
    FLOW_UNIT as FLOW_UNIT,  # kg/s per l/min ANR (ISO 8778)
    ISO8778_DENSITY as ISO8778_DENSITY,  # kg/m³, ANR reference density
    ISO8778_TEMPERATURE as ISO8778_TEMPERATURE,  # K, ANR reference temperature
    LITRE_PER_MINUTE as LITRE_PER_MINUTE,  # m³/s per l/min
    PSI as PSI,  # Pa per psi
)
