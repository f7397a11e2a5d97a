"""Pneumatic artificial muscles: static force laws, chamber volume and physical stroke limits.

Convention: `x` is the muscle's displacement [m], positive = shortening (payload up), 0 at nominal length.
Force laws take the GAUGE pressure p_g = p − p_atm [Pa] (paper 000 eq. 7: p_max = 0.6 MPa is gauge); the
`Muscle` wrapper takes the absolute chamber pressure and does the conversion.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.arrays import as_array
from .._core.custom_types import Array, Real, RealScalar, RealScalarLike, RealVector
from .._core.errors import PamjaxInputError, check_finite, check_in_open_interval, check_positive, concrete_values
from .._core.fitting import bounded, parameter, polynomial, positive
from .._core.units import check_plausible, check_setting
from .._papers import paper000
from .smooth import smooth_relu, smooth_step


class AbstractForceLaw(eqx.Module):
    """Static contractile force F(x, p_g) [N] of a muscle at displacement `x` [m] and GAUGE pressure `p_g` [Pa].
    It may be negative (the law extrapolated past slack); `Muscle.force` applies the slack."""

    @abc.abstractmethod
    def static_force(self, x, gauge_pressure):
        """The contractile force [N] at displacement `x` [m] (positive = shortening) and GAUGE pressure [Pa], before
        the slack (it may be negative); smooth in both arguments."""


class PolynomialForce(AbstractForceLaw):
    """Paper 000, eq. 7: F = F_max(x) − (p_max − p_g)(k0 − k1 x)/k2, F_max(x) = a0 + a1 x + … + a4 x⁴.

    Only k0/k2 and k1/k2 are identifiable (a fit must hold one of k0, k1, k2 fixed).

    **Arguments:**

    - `max_force_coefficients`: (a0, …, a4) [N, N/m, N/m², N/m³, N/m⁴]: the force at `max_pressure`.
    - `max_pressure`: p_max, GAUGE [Pa]; 0.6 MPa (paper 000).
    - `k0` [N], `k1` [N/m], `k2` [Pa].
    """

    # fitted as F_max at Chebyshev nodes over the muscle's stroke (well conditioned), reported as a0…a4:
    max_force_coefficients: RealVector = eqx.field(converter=as_array,
                                                  metadata=polynomial("a{i}", "stroke", unit="N/m^i"))
    k0: RealScalar = positive(unit="N")
    k1: RealScalar = parameter(unit="N/m")
    k2: RealScalar = positive(unit="Pa")
    max_pressure: RealScalar = positive(paper000.MAX_PRESSURE, unit="Pa gauge")

    def __check_init__(self):
        if jnp.shape(self.max_force_coefficients) != (5,):
            raise PamjaxInputError(
                "PolynomialForce.max_force_coefficients must hold a0…a4 (shape (5,)), got shape "
                f"{jnp.shape(self.max_force_coefficients)}"
            )
        check_finite(self.max_force_coefficients, "PolynomialForce.max_force_coefficients")
        check_finite(self.k0, "PolynomialForce.k0")
        check_finite(self.k1, "PolynomialForce.k1")
        check_positive(self.k2, "PolynomialForce.k2")
        check_positive(self.max_pressure, "PolynomialForce.max_pressure")
        if concrete_values(self.max_pressure) is not None:  # 6 (bar) for 6e5 Pa refused, as a config refuses it
            check_setting("max_pressure", self.max_pressure, "PolynomialForce:")
        _check_pressure_slope(self.k0, self.k2)

    def max_force(self, x):
        """F_max(x) [N], the force at p_max."""
        return jnp.polyval(self.max_force_coefficients[::-1], x)

    def pressure_slope(self, x):
        """∂F/∂p_g = (k0 − k1 x)/k2 [N/Pa]."""
        return (self.k0 - self.k1 * x) / self.k2

    def static_force(self, x, gauge_pressure):
        return self.max_force(x) - (self.max_pressure - gauge_pressure) * self.pressure_slope(x)


# m², the largest slope ∂F/∂p_g = k0/k2 of eq. 7 at x = 0 (a muscle's effective area): 0.1 m² is 60 kN at 6 bar, ten
# times Festo's strongest muscle (DMSP-40: 6000 N at 6 bar, k0/k2 = 9.8e-3 m²; the MAS-10's 630 N: 1.03e-3 m²). k2 in
# bar, kPa or MPa (6 for 6e5 Pa: 17 m² with the MAS-10's k0) is far above it; only k0/k2 is identifiable, so the
# check is on the ratio, whatever convention fixes k2 (pamjax's: 1e5 Pa).
MAX_PRESSURE_SLOPE = 0.1


def _check_pressure_slope(k0, k2):
    """Refuse eq. 7's slope k0/k2 [m²] above `MAX_PRESSURE_SLOPE` (concrete values only): k2 not in Pa."""
    k0, k2 = concrete_values(k0), concrete_values(k2)
    if k0 is None or k2 is None or not (np.all(np.isfinite(k0)) and np.all(k2 > 0)):
        return  # traced (a fit's trial values), or refused by the checks above
    slope = float(np.max(np.abs(k0) / k2))
    if slope > MAX_PRESSURE_SLOPE:
        raise PamjaxInputError(
            f"PolynomialForce.k2 = {float(np.min(k2)):g} Pa gives eq. 7 a slope k0/k2 = {slope:g} N/Pa (m²) at x = 0: "
            f"more than {MAX_PRESSURE_SLOPE:g} m², 60 kN at 6 bar (Festo's strongest muscle, the DMSP-40, has "
            "9.8e-3 m²); that looks like k2 in bar, kPa or MPa (pamjax takes Pa: 1 bar is 1e5)"
        )


def _check_braid(strand_length, nominal_length, name):
    """Refuse a braid whose strand b_s is not longer than the muscle at nominal length L0 (eq. 1, L = b_s cos θ:
    cos θ ≥ 1 has no braid angle), concrete values only."""
    b, length = strand_length, nominal_length
    if not isinstance(b, jax.core.Tracer) and not isinstance(length, jax.core.Tracer) and not bool(b > length):
        raise PamjaxInputError(f"{name}.strand_length ({b}) must exceed nominal_length ({length}): eq. 1, "
                               "L = b_s cos θ")


class ChouHannafordForce(AbstractForceLaw):
    """Paper 000, eq. 5 (Chou & Hannaford): F = (π D0²/4) p_g (3 cos²θ − 1), with cos θ = L/b_s, L = L0 − x and
    D0 = b_s/(n_s π) (eq. 1-2).

    **Arguments:** `strand_length` b_s [m], `turns` n_s [-], `nominal_length` L0 [m].
    """

    strand_length: RealScalar = positive(unit="m")
    turns: RealScalar = positive(unit="-")
    nominal_length: RealScalar = positive(unit="m")

    def __check_init__(self):
        check_positive(self.strand_length, "ChouHannafordForce.strand_length")
        check_positive(self.turns, "ChouHannafordForce.turns")
        check_positive(self.nominal_length, "ChouHannafordForce.nominal_length")
        check_plausible(self.nominal_length, "ChouHannafordForce.nominal_length")  # 400 (mm) for 0.4 m refused
        check_plausible(self.strand_length, "ChouHannafordForce.strand_length")  # 390 (mm) for 0.39 m refused
        _check_braid(self.strand_length, self.nominal_length, "ChouHannafordForce")  # cos θ = 1.5 gave 88 N

    def static_force(self, x, gauge_pressure):
        cos_theta = (self.nominal_length - x) / self.strand_length
        d0 = self.strand_length / (self.turns * jnp.pi)
        return jnp.pi * d0**2 / 4.0 * gauge_pressure * (3.0 * cos_theta**2 - 1.0)


class TonduLopezForce(AbstractForceLaw):
    """Paper 000, eq. 6 (Tondu & Lopez): F = π r0² p_g [a(1 − k ε)² − b], a = 3/tan²θ0, b = 1/sin²θ0,
    ε = x/L0. `correction` k = 1 is eq. 6 as printed; k > 1 is Tondu & Lopez's correction for the real muscle's
    smaller stroke (paper 000 ref. [21]).

    **Arguments:** `radius` r0 [m], `braid_angle` θ0 [rad], `nominal_length` L0 [m], `correction` k [-].
    """

    radius: RealScalar = positive(unit="m")
    braid_angle: RealScalar = parameter(unit="rad")
    nominal_length: RealScalar = positive(unit="m")
    correction: RealScalar = parameter(1.0, unit="-")

    def __check_init__(self):
        check_positive(self.radius, "TonduLopezForce.radius")
        check_plausible(self.radius, "TonduLopezForce.radius")  # 5 (mm) for 5e-3 m gave 2.4e8 N, not 240 N
        check_positive(self.nominal_length, "TonduLopezForce.nominal_length")
        check_plausible(self.nominal_length, "TonduLopezForce.nominal_length")
        check_positive(self.correction, "TonduLopezForce.correction")
        v = self.braid_angle
        if not isinstance(v, jax.core.Tracer) and not bool(jnp.all((v > 0) & (v < jnp.pi / 2))):
            raise PamjaxInputError(f"TonduLopezForce.braid_angle must lie in (0, π/2) rad, got {v}")

    def static_force(self, x, gauge_pressure):
        a = 3.0 / jnp.tan(self.braid_angle) ** 2
        b = 1.0 / jnp.sin(self.braid_angle) ** 2
        eps = x / self.nominal_length
        return jnp.pi * self.radius**2 * gauge_pressure * (a * (1.0 - self.correction * eps) ** 2 - b)


class AbstractVolume(eqx.Module):
    """Chamber volume V(x) [m³] of a muscle at displacement `x` [m]."""

    @abc.abstractmethod
    def volume(self, x):
        """The chamber volume [m³] at displacement `x` [m]: positive over the stroke, smooth (its slope dV/dx is taken
        by autodiff, paper 000 eq. 15)."""


class LinearVolume(AbstractVolume):
    """Paper 000, eq. 14: V = v0 + v1 x. **Arguments:** `v0` [m³], `v1` [m²]."""

    v0: RealScalar = positive(unit="m³")
    v1: RealScalar = positive(unit="m²")

    def __check_init__(self):
        check_positive(self.v0, "LinearVolume.v0")
        check_plausible(self.v0, "LinearVolume.v0")  # the MAS-10's 0.02356 (litres) refused: no muscle holds 20 l
        check_positive(self.v1, "LinearVolume.v1")  # declared positive (fitted in log space): V grows as x does

    def volume(self, x):
        return self.v0 + self.v1 * x


# m², the widest bore a muscle's chamber has, for the volume at nominal length V0 against its length L0: π/4 · (0.2 m)²,
# a muscle 20 cm across, five times Festo's widest (40 mm: the DMSP-40's V0/L0 = π/4 · (40 mm)² = 1.26e-3 m²). A
# volume in litres or cm³ typed as m³ (the DMSP-40's 0.5 l as 0.5) is a thousand times or more its bore times L0.
MAX_BORE_AREA = 0.25 * np.pi * 0.2**2


def _check_bore(volume, nominal_length, name):
    """Refuse a volume at nominal length [m³] that needs a bore wider than `MAX_BORE_AREA` over `nominal_length`
    [m] (concrete values only): litres or cm³ typed as m³."""
    v, length = concrete_values(volume), concrete_values(nominal_length)
    if v is None or length is None or not np.all(np.isfinite(v)) or not np.all(length > 0):
        return
    bore = float(np.max(v / length))
    if bore > MAX_BORE_AREA:
        raise PamjaxInputError(
            f"{name} = {float(np.max(v)):g} m³ over a nominal length of {float(np.max(length)):g} m needs a bore of "
            f"{bore:g} m² = π/4 · ({(4 * bore / np.pi) ** 0.5:.3g} m)², more than a muscle 20 cm across "
            f"({MAX_BORE_AREA:.3g} m²); that looks like litres or cm³ (pamjax takes m³: 0.5 l is 5e-4 m³)"
        )


class CubicVolume(AbstractVolume):
    """Paper 001, eq. 4: V = a ε³ + b ε² + c ε + d with contraction ratio ε = x / L0.

    **Arguments:** `coefficients` (d, c, b, a) [m³], lowest order first; `nominal_length` L0 [m].
    """

    coefficients: Real[Array, "4"] = parameter(unit="m³", shape="array")
    nominal_length: RealScalar = positive(unit="m")

    def __check_init__(self):
        if jnp.shape(self.coefficients) != (4,):
            raise PamjaxInputError(
                f"CubicVolume.coefficients must hold (d, c, b, a), shape (4,), got {jnp.shape(self.coefficients)}"
            )
        check_finite(self.coefficients, "CubicVolume.coefficients")
        check_positive(self.coefficients[0], "CubicVolume.coefficients[0] (volume at nominal length)")
        check_positive(self.nominal_length, "CubicVolume.nominal_length")
        check_plausible(self.nominal_length, "CubicVolume.nominal_length")
        _check_bore(self.coefficients[0], self.nominal_length, "CubicVolume.coefficients[0] (volume at nominal length)")

    def volume(self, x):
        return jnp.polyval(self.coefficients[::-1], x / self.nominal_length)


class BraidVolume(AbstractVolume):
    """Paper 000, eq. 3: the volume of an ideal cylindrical braid, V = b_s³/(4π n_s²) cos θ sin²θ, with
    cos θ = L/b_s (eq. 1) and L = L0 − x; that is V = L (b_s² − L²)/(4π n_s²).

    The volume of `ChouHannafordForce` (eq. 5): p_g dV/dx = −p_g dV/dL is its force (eq. 4, virtual work).

    **Arguments:** `strand_length` b_s [m] (> L0 + max stretch: cos θ < 1), `turns` n_s [-], `nominal_length` L0 [m].
    `BraidVolume.from_datasheet(L0, D0, max_contraction)` derives b_s, n_s from a datasheet.
    """

    strand_length: RealScalar = positive(unit="m")
    turns: RealScalar = positive(unit="-")
    nominal_length: RealScalar = positive(unit="m")

    def __check_init__(self):
        check_positive(self.strand_length, "BraidVolume.strand_length")
        check_positive(self.turns, "BraidVolume.turns")
        check_positive(self.nominal_length, "BraidVolume.nominal_length")
        check_plausible(self.nominal_length, "BraidVolume.nominal_length")
        check_plausible(self.strand_length, "BraidVolume.strand_length")  # 390 (mm) for 0.39 m refused
        _check_braid(self.strand_length, self.nominal_length, "BraidVolume")

    @classmethod
    def from_datasheet(cls, nominal_length: RealScalarLike, diameter: RealScalarLike,
                       max_contraction: RealScalarLike) -> "BraidVolume":
        """The braid of a muscle of `nominal_length` L0 [m] and inner `diameter` D0 [m] at L0 whose eq. 5 force
        vanishes at `max_contraction` ε_max [-] (cos²θ = 1/3 there): b_s = √3 (1 − ε_max) L0 (eq. 1),
        n_s = b_s sin θ0 / (π D0) (eq. 2), cos θ0 = L0/b_s. For the MAS-10-300 (0.3 m, 10 mm, 25 %, datasheet):
        b_s = 0.390 m, θ0 = 39.7°, n_s = 7.9."""
        check_positive(nominal_length, "BraidVolume.from_datasheet nominal_length")
        check_positive(diameter, "BraidVolume.from_datasheet diameter")
        limit = 1.0 - 1.0 / 3.0**0.5  # b_s > L0
        check_in_open_interval(max_contraction, 0.0, limit, "BraidVolume.from_datasheet max_contraction")
        b = 3.0**0.5 * (1.0 - max_contraction) * nominal_length
        sin_theta = (1.0 - (nominal_length / b) ** 2) ** 0.5
        return cls(b, b * sin_theta / (jnp.pi * diameter), nominal_length)

    def volume(self, x):
        length = self.nominal_length - x
        return length * (self.strand_length**2 - length**2) / (4.0 * jnp.pi * self.turns**2)


STROKE_NODES = 33  # evenly spaced points of the stroke where a muscle's volume must be > 0 (eq. 15 divides by V(x))


class AbstractMuscle(eqx.Module):
    """What the workflows ask of a muscle (a force map, a controller, an experiment design, a bench's stops): its
    stroke limits `min_position`, `max_position` [m] (x, positive = contraction), its `static_force` (the force law
    before the slack, may be negative) and `force` [N] at ABSOLUTE pressure, its `volume` [m³] and `volume_slope`
    dV/dx [m²]. `Muscle` is pamjax's."""

    min_position: eqx.AbstractVar[jax.Array]
    max_position: eqx.AbstractVar[jax.Array]

    @abc.abstractmethod
    def static_force(self, x, pressure, air):
        """The force law [N] at displacement `x` [m] and ABSOLUTE `pressure` [Pa], before the slack (may be < 0)."""

    @abc.abstractmethod
    def force(self, x, pressure, air):
        """The contractile force [N] ≥ 0 at displacement `x` [m] and ABSOLUTE `pressure` [Pa]."""

    @abc.abstractmethod
    def volume(self, x):
        """The chamber volume [m³] at displacement `x` [m]."""

    @abc.abstractmethod
    def volume_slope(self, x):
        """dV/dx [m²] at displacement `x` [m]."""

    def smallest_volume(self):
        """min V(x) [m³] over `STROKE_NODES` points of the stroke, concrete or traced: what must stay > 0 (eq. 15
        divides by it; `Muscle` checks it when built, and a fit refuses a trial step where it is not,
        `pamjax._fit.problem`)."""
        return jnp.min(self.volume(jnp.linspace(self.min_position, self.max_position, STROKE_NODES)))


class Muscle(AbstractMuscle):
    """A pneumatic muscle: force law + volume + stroke limits.

    `force(x, p, air)` = smooth_relu(F_static(x, p − p_atm), `slack_width`): a muscle pulls but cannot push.

    **Arguments:**

    - `force_law`: an `AbstractForceLaw`; `volume_law`: an `AbstractVolume`.
    - `min_position`, `max_position`: physical limits of x [m] (most stretched, most contracted), where the end
      stops act.
    - `slack_width`: [N]; smoothing of the slack (error ≤ width·ln 2 at the slack point); 1 N.
    """

    force_law: AbstractForceLaw
    volume_law: AbstractVolume
    min_position: RealScalar = parameter(unit="m")
    max_position: RealScalar = parameter(unit="m")
    slack_width: RealScalar = positive(1.0, unit="N")

    def __check_init__(self):
        for name, law, base, example in (("force_law", self.force_law, AbstractForceLaw, "PolynomialForce"),
                                         ("volume_law", self.volume_law, AbstractVolume, "LinearVolume")):
            if not isinstance(law, base):  # (None ended as an AttributeError inside the solve)
                raise PamjaxInputError(f"Muscle.{name} must be an {base.__name__} (e.g. {example}), got "
                                       f"{type(law).__name__}")
        check_finite(self.min_position, "Muscle.min_position")
        check_finite(self.max_position, "Muscle.max_position")
        check_positive(self.slack_width, "Muscle.slack_width")
        lo, hi = self.min_position, self.max_position
        if not isinstance(lo, jax.core.Tracer) and not isinstance(hi, jax.core.Tracer):
            lo, hi = np.asarray(lo), np.asarray(hi)  # concrete: checked in NumPy (eager JAX compiles each operation)
            if not bool(hi > lo):
                raise PamjaxInputError(f"Muscle.max_position ({hi}) must exceed Muscle.min_position ({lo})")
            # eq. 15 divides by V(x): the volume must stay positive over the whole stroke, not only V(0) = v0.
            concrete = not any(isinstance(a, jax.core.Tracer) for a in jax.tree_util.tree_leaves(self.volume_law))
            law = jax.tree_util.tree_map(np.asarray, self.volume_law) if concrete else self.volume_law
            v = law.volume(np.linspace(lo, hi, STROKE_NODES))
            if not isinstance(v, jax.core.Tracer) and not bool(np.all(np.asarray(v) > 0)):
                raise PamjaxInputError(
                    f"Muscle.volume_law gives a volume <= 0 inside the stroke [min_position, max_position] = "
                    f"[{float(lo):.4g}, {float(hi):.4g}] m (smallest {float(np.min(np.asarray(v))):.3g} m³); check "
                    "its coefficients (v0, v1, ...) and the stroke limits"
                )

    @property
    def stroke(self):
        """(min_position, max_position) [m]: the range of x (where a fit places the force law's nodes)."""
        return self.min_position, self.max_position

    def static_force(self, x, pressure, air):
        """Eq. 7 (or the chosen law) at absolute `pressure` [Pa], before the slack: may be negative."""
        return self.force_law.static_force(x, pressure - air.atmospheric_pressure)

    def force(self, x, pressure, air):
        """Contractile force [N] ≥ 0 at displacement `x` [m] and ABSOLUTE pressure [Pa]."""
        return smooth_relu(self.static_force(x, pressure, air), self.slack_width)

    def volume(self, x):
        """Chamber volume [m³]."""
        return self.volume_law.volume(x)

    def volume_slope(self, x):
        """dV/dx [m²], by autodiff."""
        return jax.grad(self.volume_law.volume)(jnp.asarray(x, dtype=float))

    def stiffness(self, x, pressure, air):
        """∂F/∂x at constant pressure [N/m] (paper 001 eq. 9's isobaric term), by autodiff."""
        return jax.grad(self.force, argnums=0)(jnp.asarray(x, dtype=float), pressure, air)


# m, the widest smoothing of an end stop's contact: δ of a fraction of a millimetre (1e-4 by default) to a few mm. The
# contact's spring k δ softplus(−d/δ) reaches a distance d into the stroke: at δ = 5 mm with the default 1e6 N/m it
# already pushes 90 N (the MAS-10's 9.6 kg payload) 20 mm inside the stops, at 0.1 (0.1 mm typed as m) 21 kN mid-stroke.
MAX_END_STOP_WIDTH = 5e-3


class EndStops(eqx.Module):
    """Stiff, damped contact at the stroke limits [x_min, x_max] of a muscle, smooth at contact.

    F = −k·relu_δ(x − x_max) + k·relu_δ(x_min − x) − c v (s_δ(x − x_max) + s_δ(x_min − x)).

    **Arguments:** `stiffness` k [N/m] (1e6: 0.6 mm penetration under the MAS-10's 630 N), `damping` c [N s/m]
    (6e3 ≈ critical for 9.6 kg on k), `width` δ [m] (1e-4; at most `MAX_END_STOP_WIDTH`, 5 mm).
    """

    stiffness: RealScalar = positive(1e6, unit="N/m")
    damping: RealScalar = positive(6e3, unit="N s/m")
    width: RealScalar = bounded(1e-4, bounds=(0.0, MAX_END_STOP_WIDTH), unit="m")  # fitted: never past the check

    def __check_init__(self):
        check_positive(self.stiffness, "EndStops.stiffness")
        check_positive(self.damping, "EndStops.damping")
        check_positive(self.width, "EndStops.width")
        width = concrete_values(self.width)
        if width is not None and np.any(width > MAX_END_STOP_WIDTH):
            raise PamjaxInputError(
                f"EndStops.width = {float(np.max(width)):g} m: more than {MAX_END_STOP_WIDTH:g} m, the widest a stop's "
                "contact is smoothed over (a fraction of a millimetre to a few mm; the MAS-10's whole stroke is "
                "95 mm); that looks like mm (pamjax takes m: 0.1 mm is 1e-4)"
            )

    def force(self, x, v, x_min, x_max):
        over = x - x_max
        under = x_min - x
        spring = -self.stiffness * smooth_relu(over, self.width) + self.stiffness * smooth_relu(under, self.width)
        contact = smooth_step(over, self.width) + smooth_step(under, self.width)
        return spring - self.damping * v * contact


def stroke_root(residual, live, lo, hi):
    """The root in [lo, hi] of `residual(model, x)`, decreasing in the shortening x [m]: 60 bisection steps on the
    gradient-stopped `live` model, then one Newton step on `live` itself, so the root carries the implicit
    derivative. Returns `(x, interior, newton, (lo, hi))`: the bisection point, whether it lies strictly inside the
    stroke with a negative slope (else the root is at a limit), the Newton-corrected root and the (stopped) limits.
    Shared by the payload and load equilibria of the muscle systems."""
    frozen = jax.lax.stop_gradient(live)
    lo0, hi0 = jax.lax.stop_gradient(lo), jax.lax.stop_gradient(hi)

    def body(_, bounds):
        a, b = bounds
        mid = 0.5 * (a + b)
        above = jax.lax.stop_gradient(residual(frozen, mid)) > 0
        return jnp.where(above, mid, a), jnp.where(above, b, mid)

    a, b = jax.lax.fori_loop(0, 60, body, (lo0, hi0))
    x = 0.5 * (a + b)
    slope = jax.grad(lambda q: residual(frozen, q))(x)
    interior = (x > lo0 + 1e-9) & (x < hi0 - 1e-9) & (slope < 0)
    newton = x - residual(live, x) / jnp.where(interior, slope, -1.0)
    return x, interior, newton, (lo0, hi0)
