"""Gas properties and compressible flow laws through pneumatic restrictions.

All pressures are ABSOLUTE [Pa]. Every law here is written for one restriction between port 1 (pressure `p1`) and
port 2 (pressure `p2`); it returns the mass flow 1 → 2 in kg/s, negative when the flow reverses (p2 > p1). As the
pressure ratio tends to 1 each law switches to a linear ("laminar") branch, as ISO 6358-1:2013 does for
p_down/p_up > 0.999, so the slope at equal pressures is finite and the flow and its gradient are finite for every
input, equal pressures included.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.custom_types import RealScalar
from .._core.errors import PamjaxInputError, check_count, check_in_open_interval, check_positive, concrete_values
from .._core.fitting import bounded, parameter, positive, ratio
from .._core.units import ATMOSPHERE, ISO8778_DENSITY, ISO8778_TEMPERATURE, check_sonic_conductance
from .._papers import paper000
from .smooth import safe_divide, safe_sqrt

# ISO 6358-1:2013, clause 3: flow is treated as laminar (linear in Δp) for p_down/p_up above 0.999.
DEFAULT_LAMINAR_RATIO = 0.999
# J/(kg K): a gas's R = 8.314 J/(mol K) / M spans 4124 (hydrogen, M = 2 g/mol) to 57 (sulphur hexafluoride, 146 g/mol);
# air's is 287.05. Below 20 it is no gas's: 0.287 is air's in kJ/(kg K) (a tank then fills to 126 kPa, not 429 kPa).
GAS_CONSTANT_RANGE = (20.0, 5000.0)
# A discharge or flow coefficient: the effective over the geometric area, in (0, 1] (its check) and fitted through a
# logistic over (0, 1) (`pamjax._core.fitting.bounded`): in log space it converged at 1.105, a restriction refused.
FLOW_COEFFICIENT_RANGE = (0.0, 1.0)
# κ = c_p/c_v of an ideal gas: 5/3 monatomic to 1 for a gas of many degrees of freedom (air 1.4); `Air` accepts the
# open interval, and a fit moves κ through a logistic over it.
HEAT_CAPACITY_RATIO_RANGE = (1.0, 2.0)
# the polytropic index n of a chamber (paper 000 eq. 12, 15; paper 001 eq. 3, 12): 1 isothermal (paper 001) to 1.4
# adiabatic (air); outside, n = 0 freezes a chamber's pressure and n < 0 drives it below vacuum. The systems accept
# the open interval, and a fit moves n through a logistic over it.
POLYTROPIC_RANGE = (0.99, 1.41)


def _first_outside(x, lo, hi):
    """The first concrete, finite, positive value of `x` outside [lo, hi] (as a float), or None (traced values are
    not checked: a fit may move them; the sign and finiteness are `check_positive`'s)."""
    v = concrete_values(x)
    if v is None:
        return None
    bad = v[np.isfinite(v) & (v > 0) & ((v < lo) | (v > hi))]
    return float(bad.flat[0]) if bad.size else None


def check_gas_constant(x, name):
    """Refuse a specific gas constant no gas has (`GAS_CONSTANT_RANGE`, J/(kg K)): kJ/(kg K) or the molar 8.314."""
    lo, hi = GAS_CONSTANT_RANGE
    r = _first_outside(x, lo, hi)
    if r is not None:
        likely = ("kJ/(kg K) (air: 0.287 kJ/(kg K) is 287.05 J/(kg K)) or the molar gas constant J/(mol K) (divide "
                  "8.314 by the molar mass in kg/mol)" if r < lo else "another unit")
        raise PamjaxInputError(f"{name} = {r:g} J/(kg K): no gas has a specific gas constant outside [{lo:g}, {hi:g}] "
                               f"J/(kg K); that looks like {likely} (pamjax takes J/(kg K): air 287.05)")


# m²: an orifice's effective area above this is no pneumatic valve's (paper 000's: 3.14e-6 m², 2 mm across; 1e-2 m²
# is 113 mm across): 3.14 (mm²) typed as m² failed after 200,000 steps with a "stiff" hint. A restriction's own
# check, not the generic by-name table of `pamjax._core.units` (a user component's `area` may be a plate's 2 m²).
MAX_ORIFICE_AREA = 1e-2


def check_orifice_area(x, name):
    """Refuse an orifice area above `MAX_ORIFICE_AREA` [m²]: mm² or cm² typed as m² (concrete values only)."""
    a = _first_outside(x, 0.0, MAX_ORIFICE_AREA)
    if a is not None:
        raise PamjaxInputError(f"{name} = {a:g} m²: more than {MAX_ORIFICE_AREA:g} m² (an orifice 113 mm across); that "
                               "looks like mm² or cm² (pamjax takes SI units: m²; paper 000's valve: 3.14e-6 m²)")


# A coefficient from this up to 100 looks like percent (36 for 0.36); just above 1 (1.10) it is a coefficient a
# little too high, for which "write 0.011" was misleading.
PERCENT_FROM = 2.0


def check_flow_coefficient(x, name, what):
    """Refuse a discharge or flow coefficient outside `FLOW_COEFFICIENT_RANGE`, (0, 1] (`what`: the ratio it is);
    from `PERCENT_FROM` (2) up to 100 it looks like percent (concrete values only: a fit may move them)."""
    check_positive(x, name)
    lo, hi = FLOW_COEFFICIENT_RANGE
    c = _first_outside(x, lo, hi)
    if c is not None:
        raise PamjaxInputError(f"{name} must lie in ({lo:g}, {hi:g}] ({what}, at most {hi:g}), got {c:g}"
                               + (f"; that looks like percent: write {c / 100:g}" if PERCENT_FROM <= c <= 100
                                  else ""))


def check_laminar_ratio(laminar_ratio, critical_ratio, name, critical_name=None):
    """Refuse a laminar ratio outside (b, 1) for the critical ratio b (`critical_name`, by default `name`'s
    critical_ratio; concrete values only). At or below b the law had no subsonic branch: the start of the laminar
    line was silently moved to b + 1e-6 (`ellipse_flow_fraction`)."""
    check_in_open_interval(laminar_ratio, 0.0, 1.0, f"{name}.laminar_ratio")
    b = concrete_values(critical_ratio)
    if b is not None and np.any(b >= laminar_ratio):
        critical_name = critical_name or f"{name}.critical_ratio"
        raise PamjaxInputError(
            f"{name}.laminar_ratio ({laminar_ratio:g}) must exceed the critical ratio, {critical_name} "
            f"({float(np.max(b)):.10g}): the laminar branch runs from it to r = 1, above the subsonic branch (ISO "
            f"6358-1:2013: {DEFAULT_LAMINAR_RATIO}); raise laminar_ratio or lower the critical ratio")


def check_restriction(part, name, example):
    """Refuse a part that is no `AbstractRestriction` (a number, None, a string: each ended as a raw AttributeError
    or TypeError inside the solve), naming it (`example`: what to write)."""
    if not isinstance(part, AbstractRestriction):
        raise PamjaxInputError(f"{name} must be an AbstractRestriction (e.g. {example}), got {type(part).__name__} "
                               f"{part!r:.60}")


class Air(eqx.Module):
    """Ideal-gas properties of the working air.

    **Arguments:**

    - `gas_constant`: specific gas constant R [J/(kg K)]; 287 (paper 000, Table 1). Within `GAS_CONSTANT_RANGE`
      (20-5000 J/(kg K), every gas's; refused otherwise: 0.287 is kJ/(kg K)).
    - `temperature`: air temperature T [K]; 293 (paper 000, Table 1).
    - `heat_capacity_ratio`: κ [-]; 1.4 (paper 000, eq. 10 text). In `HEAT_CAPACITY_RATIO_RANGE`, (1, 2).
    - `atmospheric_pressure`: p_atm [Pa abs]; 101325 (ISO 2533 standard atmosphere). The gauge reference of the
      force laws and the exhaust pressure of the valves.
    """

    gas_constant: RealScalar = positive(paper000.GAS_CONSTANT, unit="J/(kg K)")
    temperature: RealScalar = positive(paper000.TEMPERATURE, unit="K")
    heat_capacity_ratio: RealScalar = bounded(paper000.HEAT_CAPACITY_RATIO, bounds=HEAT_CAPACITY_RATIO_RANGE, unit="-")
    atmospheric_pressure: RealScalar = positive(ATMOSPHERE, unit="Pa abs")

    def __check_init__(self):
        check_positive(self.gas_constant, "Air.gas_constant")
        check_gas_constant(self.gas_constant, "Air.gas_constant")
        check_positive(self.temperature, "Air.temperature")
        check_in_open_interval(self.heat_capacity_ratio, *HEAT_CAPACITY_RATIO_RANGE, "Air.heat_capacity_ratio")
        check_positive(self.atmospheric_pressure, "Air.atmospheric_pressure")


def orient(p1, p2):
    """Upstream/downstream split: returns (p_up, ratio p_down/p_up in [0, 1], direction ±1)."""
    forward = p1 >= p2
    p_up = jnp.where(forward, p1, p2)
    p_down = jnp.where(forward, p2, p1)
    # Pressures outside the physical range (the solver may try them) are clipped for the ratio only. (Below 1 Pa the
    # ratio is then p_down < 1 at equal pressures: a flow with no pressure difference, ~1e-9 kg/s at 0.5 Pa. Written
    # as a ratio of 1 for p_up above 1e-100 Pa it made the MAS-10's PWM sweep 4x slower on the CPU, XLA's threads
    # idle: the near-vacuum case is left as it was.)
    p_up_safe = jnp.maximum(p_up, 1.0)
    ratio = safe_divide(p_down, p_up_safe)
    # where, not clip: jnp.clip's gradient is halved at the bound, and ratio = 1 exactly at equal pressures.
    ratio = jnp.where(ratio > 1.0, 1.0, jnp.where(ratio < 0.0, 0.0, ratio))
    direction = jnp.where(forward, 1.0, -1.0)
    return jnp.maximum(p_up, 0.0), ratio, direction


def ellipse_flow_fraction(ratio, critical_ratio, laminar_ratio=DEFAULT_LAMINAR_RATIO):
    """Normalised flow φ(r) of the quarter-ellipse law (paper 000 eq. 11; ISO 6358 with exponent ½).

    φ = 1 for r ≤ b (choked), φ = sqrt(1 - ((r - b)/(1 - b))²) for b < r ≤ r_lam, and a straight line from
    φ(r_lam) to 0 at r = 1 (laminar branch, finite slope).

    **Arguments:** `ratio` r = p_down/p_up in [0, 1]; `critical_ratio` b in (0, 1); `laminar_ratio` r_lam in (b, 1).

    The restrictions refuse a concrete r_lam <= b (`check_laminar_ratio`). A b that is traced (a fit moves it) or that
    depends on the pressure (`TabulatedISO6358Restriction`'s b(p_up), checked against r_lam at its table's points
    only) may still reach r_lam: there the branch starts a thousandth of the way from b to 1 instead, so that it
    exists (r_lam < 1) for every b < 1. (b + 1e-6 did not: above b = 1 − 1e-6 the branch vanished and the slope at
    equal pressures was 0.)
    """
    b = critical_ratio
    r_lam = jnp.maximum(laminar_ratio, b + 1e-3 * (1.0 - b))

    def ellipse(r):
        z = jnp.clip((r - b) / (1.0 - b), 0.0, 1.0)
        return safe_sqrt(1.0 - z * z)

    phi_lam = ellipse(r_lam)
    laminar = phi_lam * (1.0 - ratio) / (1.0 - r_lam)
    return jnp.where(ratio > r_lam, laminar, jnp.where(ratio <= b, 1.0, ellipse(ratio)))


def nozzle_flow_parameter(ratio, kappa, gas_constant, laminar_ratio=DEFAULT_LAMINAR_RATIO):
    """C_m(r) of the isentropic nozzle (paper 000 eq. 10) [sqrt(K)/ ... = s·sqrt(K)/m], laminar above r_lam."""
    r_cr = (2.0 / (kappa + 1.0)) ** (kappa / (kappa - 1.0))
    choked = jnp.sqrt(kappa / gas_constant * (2.0 / (kappa + 1.0)) ** ((kappa + 1.0) / (kappa - 1.0)))

    def subsonic(r):
        r = jnp.clip(r, 1e-12, 1.0)
        return safe_sqrt(
            2.0 * kappa / (gas_constant * (kappa - 1.0)) * (r ** (2.0 / kappa) - r ** ((kappa + 1.0) / kappa))
        )

    # NozzleRestriction refuses r_lam <= MAX_NOZZLE_CRITICAL_RATIO, above every accepted κ's r_cr: a guard only
    r_lam = jnp.maximum(laminar_ratio, r_cr + 1e-3 * (1.0 - r_cr))
    laminar = subsonic(r_lam) * (1.0 - ratio) / (1.0 - r_lam)
    return jnp.where(ratio > r_lam, laminar, jnp.where(ratio <= r_cr, choked, subsonic(ratio)))


class AbstractRestriction(eqx.Module):
    """A pneumatic restriction (valve path, orifice, silencer) between two ports.

    A restriction is defined by its flow law `mass_flow`; nothing else is asked of it.
    """

    @abc.abstractmethod
    def mass_flow(self, p1, p2, air: Air):
        """The mass flow from port 1 to port 2 [kg/s] for ABSOLUTE port pressures `p1`, `p2` [Pa]; negative when
        p2 > p1. Finite, with finite gradients, for all finite inputs (equal pressures included)."""


class EllipseRestriction(AbstractRestriction):
    """Sonic/quarter-ellipse flow law of paper 000, eq. 11 (refs. [7, 27]).

    ṁ = C_v A p_up / sqrt(R T) · φ(p_down/p_up; b_v), with φ from `ellipse_flow_fraction`.

    **Arguments:**

    - `discharge_coefficient`: C_v [-] in (0, 1] (Table 1: 0.36 inflate 1→2, 0.39 exhaust 2→3).
    - `critical_ratio`: b_v [-] in (0, 1) (Table 1: 0.28 inflate, 0.49 exhaust).
    - `area`: effective orifice area A [m²] (Table 1: 3.14e-6).
    - `laminar_ratio`: start of the laminar branch [-]; 0.999 (ISO 6358-1:2013).
    """

    discharge_coefficient: RealScalar = bounded(bounds=FLOW_COEFFICIENT_RANGE, unit="-")
    critical_ratio: RealScalar = ratio(unit="-")
    area: RealScalar = positive(paper000.VALVE_AREA, unit="m²")
    laminar_ratio: float = eqx.field(static=True, default=DEFAULT_LAMINAR_RATIO)

    def __check_init__(self):
        check_flow_coefficient(self.discharge_coefficient, "EllipseRestriction.discharge_coefficient",
                               "C_v, the effective over the geometric area")
        check_in_open_interval(self.critical_ratio, 0.0, 1.0, "EllipseRestriction.critical_ratio")
        check_positive(self.area, "EllipseRestriction.area")
        check_orifice_area(self.area, "EllipseRestriction.area")  # 3.14 (mm²) for 3.14e-6 m² refused
        check_laminar_ratio(self.laminar_ratio, self.critical_ratio, "EllipseRestriction")

    def mass_flow(self, p1, p2, air: Air):
        p_up, ratio, direction = orient(p1, p2)
        phi = ellipse_flow_fraction(ratio, self.critical_ratio, self.laminar_ratio)
        sonic = self.discharge_coefficient * self.area * p_up / jnp.sqrt(air.gas_constant * air.temperature)
        return direction * sonic * phi


class ISO6358Restriction(AbstractRestriction):
    """ISO 6358 flow law with sonic conductance C and critical pressure ratio b (paper 001, eq. 1-2, 13-14).

    ṁ = ρ₀ C p_up sqrt(T₀/T) · φ(p_down/p_up; b), ρ₀ = 1.185 kg/m³ and T₀ = 293.15 K (ISO 8778).
    Paper 001's eq. 1 as printed subtracts b from the pressures, and its eq. 13 omits ISO 6358's divisor 1 − b (as
    printed the flow would not vanish at equal pressures); the standard ratio form ((r − b)/(1 − b)) is used.

    **Arguments:**

    - `sonic_conductance`: C [m³/(s Pa)] (paper 001 tabulates it in m³/(s bar): divide by 1e5); above 1e-5, a DN50
      pipe's order, it is refused as a C left in m³/(s bar) (`pamjax._core.units.MAX_SONIC_CONDUCTANCE`).
    - `critical_ratio`: b [-] in (0, 1).
    - `laminar_ratio`: start of the laminar branch [-]; 0.999 (ISO 6358-1:2013).
    """

    sonic_conductance: RealScalar = positive(unit="m³/(s Pa)")
    critical_ratio: RealScalar = ratio(unit="-")
    laminar_ratio: float = eqx.field(static=True, default=DEFAULT_LAMINAR_RATIO)

    def __check_init__(self):
        check_positive(self.sonic_conductance, "ISO6358Restriction.sonic_conductance")
        check_sonic_conductance(self.sonic_conductance, "ISO6358Restriction.sonic_conductance")  # m³/(s bar) refused
        check_in_open_interval(self.critical_ratio, 0.0, 1.0, "ISO6358Restriction.critical_ratio")
        check_laminar_ratio(self.laminar_ratio, self.critical_ratio, "ISO6358Restriction")

    def mass_flow(self, p1, p2, air: Air):
        p_up, ratio, direction = orient(p1, p2)
        phi = ellipse_flow_fraction(ratio, self.critical_ratio, self.laminar_ratio)
        sonic = ISO8778_DENSITY * self.sonic_conductance * p_up * jnp.sqrt(ISO8778_TEMPERATURE / air.temperature)
        return direction * sonic * phi


# The nozzle's critical ratio (2/(κ+1))^(κ/(κ−1)) falls from e^(−1/2) = 0.6065 as κ → 1 to 0.444 at κ = 2 (air's 1.4:
# 0.528); `Air` accepts κ in (1, 2), so a laminar ratio above this one lies above every gas's critical ratio.
MAX_NOZZLE_CRITICAL_RATIO = float(np.exp(-0.5))


class NozzleRestriction(AbstractRestriction):
    """Isentropic convergent nozzle, paper 000 eq. 10: ṁ = A p_up C_q C_m(r) / sqrt(T_up).

    **Arguments:**

    - `flow_coefficient`: C_q [-] in (0, 1] (the effective over the geometric area; 36 or 5 refused).
    - `area`: A [m²].
    - `laminar_ratio`: start of the laminar branch [-]; 0.999 (ISO 6358-1:2013). Above `MAX_NOZZLE_CRITICAL_RATIO`
      (0.607), the critical ratio of every gas `Air` accepts (κ in (1, 2)), so that the subsonic branch exists.
    """

    flow_coefficient: RealScalar = bounded(bounds=FLOW_COEFFICIENT_RANGE, unit="-")
    area: RealScalar = positive(paper000.VALVE_AREA, unit="m²")
    laminar_ratio: float = eqx.field(static=True, default=DEFAULT_LAMINAR_RATIO)

    def __check_init__(self):
        check_flow_coefficient(self.flow_coefficient, "NozzleRestriction.flow_coefficient",
                               "C_q, the effective over the geometric area")
        check_positive(self.area, "NozzleRestriction.area")
        check_orifice_area(self.area, "NozzleRestriction.area")
        # the critical ratio is Air's (κ), unknown here: above the largest any accepted κ gives
        check_laminar_ratio(self.laminar_ratio, MAX_NOZZLE_CRITICAL_RATIO, "NozzleRestriction",
                            "the nozzle's at κ → 1, e^(-1/2) (air's: 0.528)")

    def mass_flow(self, p1, p2, air: Air):
        p_up, ratio, direction = orient(p1, p2)
        cm = nozzle_flow_parameter(ratio, air.heat_capacity_ratio, air.gas_constant, self.laminar_ratio)
        return direction * self.area * p_up * self.flow_coefficient * cm / jnp.sqrt(air.temperature)


class PorousRestriction(AbstractRestriction):
    """A porous element (a sintered exhaust silencer) in isothermal compressible Darcy flow: ṁ = K (p1² − p2²).

    Darcy's law q = κ S Δp / (μ H) for gas at the mean density p̄/(R T) integrates to ṁ = κ S (p1² − p2²)/(2 μ H R T),
    so K lumps permeability κ, area S, thickness H and viscosity μ. Laminar throughout: linear in Δp near equal
    pressures (finite slope, no switch), quadratic in pressure level, which is why a silencer barely throttles a
    high-pressure exhaust and slows the last part of a discharge (paper 000, Fig. 12 text).

    **Arguments:** `permeance` K [kg/(s Pa²)] (see `pamjax.presets.MAS10_SILENCER_PERMEANCE` for a derived value).
    """

    permeance: RealScalar = parameter(unit="kg/(s Pa²)")

    def __check_init__(self):
        check_positive(self.permeance, "PorousRestriction.permeance")

    def mass_flow(self, p1, p2, air: Air):
        return self.permeance * (p1 - p2) * (p1 + p2)


# Bisection halvings SeriesRestriction needs: the bracket [p2, p1], up to 5e6 Pa wide (`MAX_ABSOLUTE_PA`), shrinks to
# 5e6 / 2^50 = 4e-9 Pa, float64's spacing there (9e-10 Pa). Measured on the MAS-10 exhaust port and silencer (both
# orders, 1.02-50 bar): 40 halvings agree with 200 to 4e-16, 35 only to 1.5e-9 (the final Newton step from a point
# across a branch switch), 10 to 2e-6, 1 gave 13 times the flow and 0 the wrong sign.
MIN_SERIES_ITERATIONS = 50


class SeriesRestriction(AbstractRestriction):
    """Two restrictions in series (e.g. the valve's exhaust port and a silencer), combined into one.

    The intermediate pressure p_m solves ṁ_first(p1, p_m) = ṁ_second(p_m, p2) (the numerical method of
    ISO 6358-3:2014). It is bracketed between p1 and p2 and found by bisection; a final Newton step carries the
    implicit-function derivative, so gradients with respect to both restrictions' parameters are exact.

    **Arguments:** `first` (port 1 side) and `second` (port 2 side): any `AbstractRestriction`; `iterations`: the
    bisection's halvings, an int of at least `MIN_SERIES_ITERATIONS` (default 60).
    """

    first: AbstractRestriction
    second: AbstractRestriction
    iterations: int = eqx.field(static=True, default=60)

    def __check_init__(self):
        check_restriction(self.first, "SeriesRestriction.first", "EllipseRestriction(0.39, 0.49, 3.14e-6)")
        check_restriction(self.second, "SeriesRestriction.second", "presets.mas10_silencer()")
        check_count(self.iterations, "SeriesRestriction.iterations",
                    f"an int of at least {MIN_SERIES_ITERATIONS} (bisection halvings; default 60)")
        if self.iterations < MIN_SERIES_ITERATIONS:
            raise PamjaxInputError(
                f"SeriesRestriction.iterations must be at least {MIN_SERIES_ITERATIONS}, got {self.iterations}: "
                "fewer halvings leave the intermediate pressure unconverged (0 gave the flow the wrong sign, 1 a "
                "flow 13 times too large, 10 one 2e-6 off on the MAS-10 exhaust and silencer); default 60")

    def intermediate_pressure(self, p1, p2, air: Air):
        """Pressure between the two restrictions [Pa abs]."""

        def residual(pm):
            return self.first.mass_flow(p1, pm, air) - self.second.mass_flow(pm, p2, air)

        lo0 = jax.lax.stop_gradient(jnp.minimum(p1, p2))
        hi0 = jax.lax.stop_gradient(jnp.maximum(p1, p2))
        frozen = jax.lax.stop_gradient(self)

        def frozen_residual(pm):
            return frozen.first.mass_flow(p1, pm, air) - frozen.second.mass_flow(pm, p2, air)

        def body(_, bounds):
            lo, hi = bounds
            mid = 0.5 * (lo + hi)
            # residual is decreasing in pm: positive means the root lies above mid.
            above = jax.lax.stop_gradient(frozen_residual(mid)) > 0
            return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

        lo, hi = jax.lax.fori_loop(0, self.iterations, body, (lo0, hi0))
        pm = jax.lax.stop_gradient(0.5 * (lo + hi))
        # elementwise d residual / d pm (each pressure's residual depends on its own pm only): jax.grad needs one
        # scalar output and refused arrays of pressures, which every other restriction takes
        _, slope = jax.jvp(frozen_residual, (pm,), (jnp.ones_like(pm),))
        slope = jnp.where(slope < 0, slope, -1e-30)
        return pm - safe_divide(residual(pm), jax.lax.stop_gradient(slope))

    def mass_flow(self, p1, p2, air: Air):
        pm = self.intermediate_pressure(p1, p2, air)
        return self.first.mass_flow(p1, pm, air)


def series_equivalent(restriction: SeriesRestriction, air: Air, upstream_pressure=6e5):
    """Equivalent (C_v·A, b) of a series combination, read off its flow curve at `upstream_pressure` [Pa abs].

    Returns `(sonic_mass_flow_per_pressure, critical_ratio)`: ṁ_choked / p_up [kg/(s Pa)] and the largest ratio at
    which the flow is still within 0.1 % of its choked value.
    """
    ratios = jnp.linspace(0.0, 0.999, 2000)
    flows = jax.vmap(lambda r: restriction.mass_flow(upstream_pressure, r * upstream_pressure, air))(ratios)
    choked = flows[0]
    still_choked = flows >= choked * (1 - 1e-3)
    b = jnp.max(jnp.where(still_choked, ratios, 0.0))
    return choked / upstream_pressure, b
