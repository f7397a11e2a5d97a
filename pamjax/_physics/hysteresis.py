"""Hysteresis that changes branch: the normalised Bouc–Wen law and the muscle friction built on it.

Paper 000 models its muscle's hysteresis as a constant offset, F_c sign(ẋ) (eq. 8-9), and names the consequence: its
largest errors are on the way down, because "the model does not take into account the real transition between the
inflating and deflating curves". `CoulombViscousFriction`, `KarnoppFriction` and `BristleFriction` all flip between
the loop's branches at once (the bristles within F_c/σ0 = 0.16 mm). `BoucWenFriction` moves between them over a
displacement of its own, `transition_length`, and is rate independent: a loop has the same shape at any slow speed.

Why Bouc–Wen and not a generalised Maxwell-slip model: one state instead of one per element, three shape numbers with
separate roles (branch offset F_c, transition length δ, corner sharpness n) instead of two per element, and no
exchange symmetry between elements (a Maxwell-slip fit can swap any two elements, so its likelihood has as many equal
optima as orderings and its profiles are flat along them). The normalised form (Ikhouane & Rodellar, "Systems with
Hysteresis", Wiley 2007, ch. 2) removes the classic Bouc–Wen redundancy (A, β, γ and the scale of z trade against
each other) by pinning the state's bounds to ±δ, so that F_c is the branch offset exactly. It contains Dahl's model
(n = 1, β = 1), i.e. `BristleFriction` without its damping term, as a limit.
"""

import equinox as eqx
import jax.numpy as jnp

from .._core.arrays import as_scalar
from .._core.custom_types import RealScalar
from .._core.errors import (
    check_in_closed_interval,
    check_nonnegative,
    check_positive,
)
from .._core.fitting import positive, ratio
from .._core.units import check_plausible
from .._papers import datasheets, paper000
from .friction import AbstractFriction
from .smooth import smooth_abs

EXPONENT_BOUNDS = (1.0, 10.0)  # n: ≥ 1 keeps the law continuously differentiable at u = 0; 10 is a corner already
def exponent_field(default):
    """A Bouc–Wen exponent n [-]: fitted through a logistic onto `EXPONENT_BOUNDS`."""
    return eqx.field(converter=as_scalar, default=default,
                     metadata=dict(transform="logistic", bounds=EXPONENT_BOUNDS, unit="-"))


def abs_power(u, n):
    """|u|ⁿ with finite gradients everywhere, in `u` and in `n` (0 at u = 0; the "double where" trick)."""
    nonzero = u != 0
    safe = jnp.where(nonzero, jnp.abs(u), 1.0)
    return jnp.where(nonzero, safe**n, 0.0)


def bouc_wen_rate(rate, u, exponent, shape, rate_width):
    """Normalised Bouc–Wen: δ u̇ for a driving rate ẋ = `rate` (any unit) and the state u ∈ [−1, 1],

        δ u̇ = ẋ − (1 − β) ẋ |u|ⁿ − β |ẋ| u |u|ⁿ⁻¹

    (the caller divides by its transition length δ, in the unit of the driving quantity). On a branch (ẋ u > 0)
    it is ẋ (1 − |u|ⁿ), so u saturates at sign(ẋ); after a reversal (ẋ u < 0) it is ẋ (1 + (2β − 1)|u|ⁿ), a
    straight line for β = ½. |ẋ| is `smooth_abs(ẋ, rate_width)`, so the law is smooth in ẋ; `exponent` n ≥ 1,
    `shape` β ∈ (0, 1].
    """
    a = abs_power(u, exponent)
    return rate - (1.0 - shape) * rate * a - shape * smooth_abs(rate, rate_width) * u * abs_power(u, exponent - 1.0)


class BoucWenFriction(AbstractFriction):
    """Friction with a branch transition (normalised Bouc–Wen): state z [m], the hysteretic displacement, |z| ≤ δ
    while it moves faster than its `velocity_width` (at a creep the smoothed |ẋ| lets it pass δ: `steady_state`).

    u = z/δ,  ż = ẋ − (1 − β) ẋ |u|ⁿ − β |ẋ| u |u|ⁿ⁻¹,  F = F_c u + C_f ẋ.

    Sliding on a branch, u = sign(ẋ) and F = F_c sign(ẋ) + C_f ẋ: paper 000's eq. 8-9. After a reversal the force
    leaves its branch with stiffness F_c/δ and reaches the other branch after about 2δ of travel (the sharper, the
    larger n). As δ → 0 it is paper 000's constant offset; n = 1, β = 1 is Dahl's model (`BristleFriction` with
    σ0 = F_c/δ and no bristle damping). At rest it holds the payload elastically (no creep).

    **Arguments:**

    - `coulomb_force`: F_c [N], the branch offset; 16 (paper 000: half the 32 N loop width, Figs. 3-5).
    - `transition_length`: δ [m]; 2e-3 (assumed: paper 000 gives no loop shape; a transition over ≈ 2δ = 4 mm,
      5 % of the MAS-10's 75 mm stroke; a fit parameter, identified in `pamjax/gallery/scripts/p000_12_hysteresis.py`);
      at most 0.1 m (`pamjax._core.units`' plausibility table).
    - `exponent`: n [-] in [1, 10]; 2 (assumed, between Dahl's 1 and a sharp corner; fitted through a logistic).
    - `shape`: β [-] in (0, 1]; ½ (the force leaves a branch along a straight line, Ikhouane & Rodellar's
      normalised form with β = γ).
    - `viscous_coefficient`: C_f [N s/m]; 250 (`pamjax.presets`, item 4).
    - `velocity_width`: [m/s] smoothing |ẋ|; 1e-5 (numerical, as `BristleFriction`'s); at most
      0.05 m/s.
    """

    coulomb_force: RealScalar = positive(paper000.COULOMB_FORCE, unit="N")
    transition_length: RealScalar = positive(2e-3, unit="m")  # assumed (see the docstring)
    exponent: RealScalar = exponent_field(2.0)  # assumed (see the docstring)
    shape: RealScalar = ratio(0.5, unit="-")
    viscous_coefficient: RealScalar = positive(datasheets.MAS10_VISCOUS_COEFFICIENT, unit="N s/m")
    velocity_width: RealScalar = positive(1e-5, unit="m/s")

    def __check_init__(self):
        check_nonnegative(self.coulomb_force, "BoucWenFriction.coulomb_force")
        check_positive(self.transition_length, "BoucWenFriction.transition_length")
        check_plausible(self.transition_length, "BoucWenFriction.transition_length")  # 3.5 (mm) for 3.5e-3 m
        check_in_closed_interval(self.exponent, *EXPONENT_BOUNDS, "BoucWenFriction.exponent")
        check_positive(self.shape, "BoucWenFriction.shape")
        check_in_closed_interval(self.shape, 0.0, 1.0, "BoucWenFriction.shape")
        check_nonnegative(self.viscous_coefficient, "BoucWenFriction.viscous_coefficient")
        check_positive(self.velocity_width, "BoucWenFriction.velocity_width")
        check_plausible(self.velocity_width, "BoucWenFriction.velocity_width")  # 1 (mm/s) for 1e-3 m/s

    def smoothing_width(self):
        return self.velocity_width

    def initial_state(self, velocity=0.0):
        """At rest: the virgin state z = 0, halfway between the branches (a fit may start elsewhere: y0); a run that
        starts moving (a recording started mid-run) on the branch of its velocity (`steady_state`)."""
        return self.steady_state(velocity)  # 0 at rest

    def state_rate(self, v, z):
        u = z / self.transition_length
        return bouc_wen_rate(v, u, self.exponent, self.shape, self.velocity_width)

    def force(self, v, z):
        return self.coulomb_force * z / self.transition_length + self.viscous_coefficient * v

    def steady_state(self, v):
        """z where ż = 0 at constant velocity v ≠ 0, on the branch of v: ẋ − |u|ⁿ ((1 − β) ẋ + β |ẋ|ₛ sign u) = 0 gives
        |u|ⁿ = |v| / ((1 − β)|v| + β |v|ₛ), |v|ₛ the smoothed |v| (`smooth_abs`): sign(v) for |v| ≫ the smoothing
        width, above it at a creep (|v|ₛ < |v|: 1.025 at 1e-4 m/s, 1.38 at 1e-6 m/s with the defaults). In closed
        form (three Newton steps from sign(v) had not converged at a creep: 2.6 instead of 1.38). At v = 0 every z is
        at rest and the two branches' limits differ in sign: z = 0, between them (the state at rest of
        `initial_state`; the level's 0/0 there was NaN), with finite gradients."""
        v = jnp.asarray(v, dtype=float)
        moving = v != 0
        safe = jnp.where(moving, v, 1.0)  # the "double where": no 0/0 in the value or the gradient at v = 0
        speed = jnp.abs(safe)
        level = speed / ((1.0 - self.shape) * speed + self.shape * smooth_abs(safe, self.velocity_width))
        u = jnp.where(moving, jnp.sign(safe) * level ** (1.0 / self.exponent), 0.0)
        return u * self.transition_length
