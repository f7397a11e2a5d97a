"""A chamber's pressure and mass balance: paper 000 eq. 15 (pressure rate) and paper 001 eq. 3 / eq. 11 (the flow a
chamber takes). Shared by the regulators and the systems."""

from .gas import Air


def pressure_rate(mass_flow, pressure, volume, volume_rate, polytropic_index, air: Air):
    """Paper 000 eq. 15: ṗ = n R T ṁ / V − n p V̇ / V [Pa/s] (n = 1.4 adiabatic, 1.0 isothermal)."""
    return polytropic_index * (air.gas_constant * air.temperature * mass_flow - pressure * volume_rate) / volume


def chamber_flow(volume, volume_rate, pressure, pressure_rate, air, polytropic_index=1.0):
    """Paper 001 eq. 3 / eq. 11: q = (V ṗ + p V̇) / (n R T) [kg/s] into a chamber (n = κ = 1: isothermal)."""
    return (volume * pressure_rate + pressure * volume_rate) / (polytropic_index * air.gas_constant * air.temperature)
