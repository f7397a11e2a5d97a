"""ISO 6358 flow whose sonic conductance C and critical ratio b depend on the upstream pressure (paper 001, Tables 1-2).

C(p_up) and b(p_up) are monotone-safe piecewise-cubic Hermite interpolants (PCHIP, Fritsch-Carlson slopes with
SciPy's `PchipInterpolator` rules): C¹ in the pressure, and on each table interval the curve never leaves the range
of its two end values, so an interpolated C stays > 0 and b stays in (0, 1) whenever the table's entries do. Beyond
the first and last table pressure the end values are held (no extrapolation).
All pressures are ABSOLUTE [Pa].
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.custom_types import Table
from .._core.errors import PamjaxInputError, check_finite, check_in_open_interval, check_positive, concrete_values
from .._core.fitting import parameter, positive, ratio
from .._core.units import check_absolute_pressure, check_sonic_conductance
from .._papers import paper001
from .gas import (
    DEFAULT_LAMINAR_RATIO,
    ISO8778_DENSITY,
    ISO8778_TEMPERATURE,
    AbstractRestriction,
    Air,
    check_laminar_ratio,
    ellipse_flow_fraction,
    orient,
)
from .smooth import safe_divide


def check_table_axis(x, name):
    """A 1-D, finite, strictly increasing table axis with at least two entries; `PamjaxInputError` otherwise."""
    v = concrete_values(x)
    if v is None:
        return
    if v.ndim != 1 or v.size < 2:
        raise PamjaxInputError(f"{name} must be a 1-D table axis with at least 2 entries, got shape {v.shape}")
    check_finite(v, name)
    if not np.all(np.diff(v) > 0):
        bad = int(np.argmin(np.diff(v) > 0))
        raise PamjaxInputError(
            f"{name} must be strictly increasing (a monotonic table); {name}[{bad + 1}] = {v[bad + 1]} does not "
            f"exceed {name}[{bad}] = {v[bad]}"
        )


def _pchip_slopes(x, y):
    """Knot slopes of the monotone PCHIP interpolant (SciPy `PchipInterpolator._find_derivatives`, in JAX)."""
    h = jnp.diff(x)
    m = jnp.diff(y) / h
    if x.shape[0] == 2:
        return jnp.stack([m[0], m[0]])
    m0, m1 = m[:-1], m[1:]
    h0, h1 = h[:-1], h[1:]
    w1 = 2.0 * h1 + h0
    w2 = h1 + 2.0 * h0
    flat = (jnp.sign(m0) != jnp.sign(m1)) | (m0 == 0) | (m1 == 0)
    safe_m0 = jnp.where(flat, 1.0, m0)
    safe_m1 = jnp.where(flat, 1.0, m1)
    inner = jnp.where(flat, 0.0, (w1 + w2) / (w1 / safe_m0 + w2 / safe_m1))

    def edge(h0, h1, m0, m1):
        d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        d = jnp.where(jnp.sign(d) != jnp.sign(m0), 0.0, d)
        return jnp.where((jnp.sign(m0) != jnp.sign(m1)) & (jnp.abs(d) > 3.0 * jnp.abs(m0)), 3.0 * m0, d)

    first = edge(h[0], h[1], m[0], m[1])
    last = edge(h[-1], h[-2], m[-1], m[-2])
    return jnp.concatenate([first[None], inner, last[None]])


# Tables up to this many rows find the interval by comparing the query with every inner knot (a handful of operations);
# longer ones by `jnp.searchsorted` (a loop in the compiled program). Inside a vector field, differentiated for a
# Rosenbrock step, each loop costs compilation: the ISO 6358 regulator's solve compiles ~15 % faster this way
# (docs/performance.md, "Compilation").
_COMPARE_ALL_ROWS = 128


def pchip_table(x, y):
    """The PCHIP interpolant through (`x`, `y`) as a (6, n - 1) table: per interval its left and right knot, the
    values there and the slopes there (what `pchip_at` reads)."""
    x = jnp.asarray(x, dtype=float)
    y = jnp.asarray(y, dtype=float)
    d = _pchip_slopes(x, y)
    return jnp.stack([x[:-1], x[1:], y[:-1], y[1:], d[:-1], d[1:]])


def pchip_at(table, xq):
    """The interpolant of `pchip_table` at `xq`; end values held outside [x₀, x_n]."""
    knots = table[0]
    lo, hi = knots[0], table[1, -1]
    # not jnp.clip: its derivative AT a bound is 1/2 (JAX splits a tie of max/min), which halved a calibration's gain
    # at exactly 0 V and 10 V (pj.linearise: 0.505 instead of 1.01 bar/V). At the table's ends the one-sided
    # (interior) slope is the interpolant's own; beyond them the held end value has slope 0.
    xq = jnp.where(xq < lo, lo, jnp.where(xq > hi, hi, xq))
    if knots.shape[0] <= _COMPARE_ALL_ROWS:  # the interval [x_i, x_i+1) holding xq (the last one closed)
        i = jnp.sum(knots[1:] <= jnp.expand_dims(xq, -1), axis=-1)
    else:
        i = jnp.clip(jnp.searchsorted(knots, xq, side="right") - 1, 0, knots.shape[0] - 1)
    # the interval's ends, values and slopes in one gather (indexing each array apart makes six)
    picked = (jax.lax.dynamic_index_in_dim(table, i, axis=1, keepdims=False) if jnp.ndim(i) == 0
              else jnp.take(table, i, axis=1))
    x0, x1, y0, y1, d0, d1 = picked
    h = x1 - x0
    s = (xq - x0) / h
    h00 = (1.0 + 2.0 * s) * (1.0 - s) ** 2
    h10 = s * (1.0 - s) ** 2
    h01 = s * s * (3.0 - 2.0 * s)
    h11 = s * s * (s - 1.0)
    return h00 * y0 + h10 * h * d0 + h01 * y1 + h11 * h * d1


def pchip(x, y, xq):
    """Monotone PCHIP interpolant through (`x`, `y`) evaluated at `xq`; end values held outside [x₀, x_n]."""
    return pchip_at(pchip_table(x, y), xq)


class PreparesTables(eqx.Module):
    """A part whose interpolants' tables (`pchip_table`: the slopes at the knots) can be computed once, ahead of a
    solve's loop, instead of at every evaluation of the vector field: `prepared()` returns that form of it (the same
    values; a solve calls it through `prepared_tables`). The tables depend on the part's parameters, which a fit may
    trace, so they are computed inside the solve's program, never stored with the model."""

    def prepared(self):
        return self


def prepared_tables(tree):
    """`tree` (a system) with every `PreparesTables` part replaced by its `prepared()` form. Called once per solve,
    before its loop: a regulator's four C/b interpolants and its calibration were otherwise differentiated and
    compiled afresh at every stage of every step (docs/performance.md, "Compilation")."""

    def is_part(x):
        return isinstance(x, PreparesTables)

    return jtu.tree_map(lambda x: x.prepared() if is_part(x) else x, tree, is_leaf=is_part)


class TabulatedISO6358Restriction(AbstractRestriction, PreparesTables):
    """ISO 6358 flow (paper 001 eq. 13-14, with ISO 6358's divisor 1 − b that eq. 13 omits in print) with C and b
    tabulated against upstream pressure.

    ṁ = ρ₀ C(p_up) p_up sqrt(T₀/T) φ(p_down/p_up; b(p_up)), ρ₀ = 1.185 kg/m³, T₀ = 293.15 K (ISO 8778); φ the
    quarter-ellipse with a laminar branch above 0.999 (ISO 6358-1:2013). For a regulator, charging tables are indexed
    by the supply (upstream) pressure (paper 001 Table 1), discharging tables by the outlet/tank pressure, which is
    the upstream pressure of the exhaust flow (Table 2).

    **Arguments:**

    - `pressure`: table axis p_up [Pa abs], strictly increasing.
    - `sonic_conductance`: C at each table pressure [m³/(s Pa)] (paper 001 gives m³/(s bar): divide by 1e5), > 0
      and at most 1e-5, a DN50 pipe's order (above it, a C still in m³/(s bar) is refused).
    - `critical_ratio`: b at each table pressure [-], in (0, 1).
    - `laminar_ratio`: start of the laminar branch [-]; 0.999 (ISO 6358-1:2013); in (max b, 1).
    """

    pressure: Table = parameter(unit="Pa abs", shape="table")
    sonic_conductance: Table = positive(unit="m³/(s Pa)", shape="table")
    critical_ratio: Table = ratio(unit="-", shape="table")
    laminar_ratio: float = eqx.field(static=True, default=DEFAULT_LAMINAR_RATIO)

    def __check_init__(self):
        name = type(self).__name__
        check_table_axis(self.pressure, f"{name}.pressure")
        check_positive(self.pressure, f"{name}.pressure")
        check_absolute_pressure(self.pressure, f"{name}.pressure")  # upstream pressures in bar (1.9, 2.9) refused
        for field in ("sonic_conductance", "critical_ratio"):
            if jnp.shape(getattr(self, field)) != jnp.shape(self.pressure):
                raise PamjaxInputError(
                    f"{name}.{field} must have the shape of {name}.pressure {jnp.shape(self.pressure)}, "
                    f"got {jnp.shape(getattr(self, field))}"
                )
        check_positive(self.sonic_conductance, f"{name}.sonic_conductance (C)")
        check_sonic_conductance(self.sonic_conductance, f"{name}.sonic_conductance (C)")  # m³/(s bar) refused
        check_in_open_interval(self.critical_ratio, 0.0, 1.0, f"{name}.critical_ratio (b)")
        # in (max b, 1), as ISO6358Restriction's: at or below b the law had no subsonic branch (moved silently)
        check_laminar_ratio(self.laminar_ratio, self.critical_ratio, name)

    def conductance(self, upstream_pressure):
        """C(p_up) [m³/(s Pa)] at the upstream pressure [Pa abs]."""
        return pchip(self.pressure, self.sonic_conductance, upstream_pressure)

    def ratio(self, upstream_pressure):
        """b(p_up) [-] at the upstream pressure [Pa abs]."""
        return pchip(self.pressure, self.critical_ratio, upstream_pressure)

    def prepared(self):
        return PreparedTabulatedRestriction(self.pressure, self.sonic_conductance, self.critical_ratio,
                                            self.laminar_ratio, pchip_table(self.pressure, self.sonic_conductance),
                                            pchip_table(self.pressure, self.critical_ratio))

    def mass_flow(self, p1, p2, air: Air):
        p_up, ratio, direction = orient(p1, p2)
        phi = ellipse_flow_fraction(ratio, self.ratio(p_up), self.laminar_ratio)
        sonic = ISO8778_DENSITY * self.conductance(p_up) * p_up * jnp.sqrt(ISO8778_TEMPERATURE / air.temperature)
        return direction * sonic * phi


class PreparedTabulatedRestriction(TabulatedISO6358Restriction):
    """A `TabulatedISO6358Restriction` with its C and b interpolants' tables computed (`prepared()`, inside a
    solve); the same flow."""

    conductance_table: Table | None = None
    ratio_table: Table | None = None

    def prepared(self):
        return self

    def conductance(self, upstream_pressure):
        return pchip_at(self.conductance_table, upstream_pressure)

    def ratio(self, upstream_pressure):
        return pchip_at(self.ratio_table, upstream_pressure)


def volumetric_flow_anr(mass_flow):
    """Mass flow [kg/s] → volumetric flow at ISO 8778 reference conditions (ANR) [m³/s]."""
    return safe_divide(mass_flow, ISO8778_DENSITY)


def paper001_charging_restriction():
    """Supply → outlet path of the VPPM regulator, C and b of paper 001 Table 1 (tank charging) against upstream
    (supply) pressure; bar → Pa and m³/(s bar) → m³/(s Pa)."""
    return _table_restriction(paper001.CHARGING_TABLE, "upstream_pressure_bar")


def paper001_discharging_restriction():
    """Outlet → exhaust path of the VPPM regulator, C and b of paper 001 Table 2 (tank discharging) against the tank
    (upstream) pressure; bar → Pa and m³/(s bar) → m³/(s Pa)."""
    return _table_restriction(paper001.DISCHARGING_TABLE, "tank_pressure_bar")


def _table_restriction(table, pressure_key):
    """A `TabulatedISO6358Restriction` from one of paper 001's C/b tables, its pressure column `pressure_key` [bar]."""
    return TabulatedISO6358Restriction(
        pressure=np.asarray(table[pressure_key]) * 1e5,
        sonic_conductance=np.asarray(table["sonic_conductance_m3_per_s_bar"]) / 1e5,
        critical_ratio=np.asarray(table["critical_ratio"]),
    )
