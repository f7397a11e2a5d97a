"""Friction of the muscle-payload motion: paper 000's Coulomb + viscous model (eq. 8-9) and a bristle model.

`force(v, z)` is the friction force [N] opposing the velocity `v` [m/s]; `z` is the friction's own state (None for
memoryless models) with rate `state_rate(v, z)`.
"""

import abc

import equinox as eqx
import jax.numpy as jnp

from .._core.custom_types import RealScalar
from .._core.errors import check_nonnegative, check_positive
from .._core.fitting import positive
from .._core.units import check_plausible
from .._papers import datasheets, paper000
from .smooth import smooth_sign


class AbstractFriction(eqx.Module):
    """Friction model: `initial_state()`, `state_rate(v, z)`, `force(v, z)` [N] (positive opposes positive v).

    A *hybrid* friction (`hybrid = True`, e.g. `KarnoppFriction`) has discrete modes (stuck / sliding) held in its
    state `z` and switched at events; the systems that use it expose those events to the fixed-grid integrator
    (`pamjax._solve.grid`), which locates them inside the step. Smooth frictions have `hybrid = False`.

    What the workflows ask of every friction besides its force: paper 000's eq. 8-9 levels of steady sliding,
    `coulomb_force` F_c [N] (the level at vanishing speed) and `viscous_coefficient` C_f [N s/m] (the slope at speed),
    which a controller compensates (`SlidingModeController`), and `smoothing_width()`.
    """

    coulomb_force: eqx.AbstractVar[RealScalar]
    viscous_coefficient: eqx.AbstractVar[RealScalar]
    hybrid = False

    def smoothing_width(self):
        """The velocity [m/s] over which the friction's direction is smoothed (a smooth sign or |v| of that width:
        `velocity_width`), whose F_c/width is a stiff rate on a light payload (a solver's hint names it); None for a
        friction that smooths nothing: one that switches direction at events (a hybrid one), or `BristleFriction`,
        whose |v| is exact."""
        return None

    def is_stuck(self, z):
        """Whether the friction holds the payload still (a hybrid friction's stuck mode); False for smooth ones."""
        return False

    def initial_state(self, velocity=0.0):
        """The friction's own state at the start of a run moving at `velocity` [m/s] (None: memoryless)."""
        return None

    def state_rate(self, v, z):
        return None

    def steady_state(self, v):
        """The friction state at steady sliding with constant velocity `v` ≠ 0 [m/s], where a friction knows it in
        closed form or better than by Newton from rest (`pamjax.bench.steady_friction_force`); None: not provided."""
        return None

    @abc.abstractmethod
    def force(self, v, z):
        """The friction force [N] at velocity `v` [m/s] and friction state `z`, positive opposing positive `v`. A hybrid
        friction gives its sliding force here (the system holds a stuck payload itself)."""


class CoulombViscousFriction(AbstractFriction):
    """Paper 000, eq. 8-9: F = F_c sign(v) + C_f v, with sign(v) ≈ tanh(v / `velocity_width`).

    A smooth sign cannot hold a load still: under a net force ΔF < F_c the payload creeps at
    v ≈ w·atanh(ΔF/F_c). Use `BristleFriction` where sticking matters.

    **Arguments:**

    - `coulomb_force`: F_c [N]; 16 (paper 000: half the 32 N hysteresis loop width).
    - `viscous_coefficient`: C_f [N s/m]; see `pamjax.presets` for the derivation of the default.
    - `velocity_width`: w [m/s]; 1e-3.
    """

    coulomb_force: RealScalar = positive(paper000.COULOMB_FORCE, unit="N")
    viscous_coefficient: RealScalar = positive(datasheets.MAS10_VISCOUS_COEFFICIENT, unit="N s/m")
    # m/s: a numerical smoothing width (paper 000's eq. 8 has a sharp sign), small against the 10-30 mm/s mean
    # speeds of its triangle runs (~60 mm per half period at 0.08-0.25 Hz); it sets the stiffness F_c/(w M) at rest
    # (docs/performance.md), so it is not made smaller.
    velocity_width: RealScalar = positive(1e-3, unit="m/s")

    def __check_init__(self):
        check_nonnegative(self.coulomb_force, "CoulombViscousFriction.coulomb_force")
        check_nonnegative(self.viscous_coefficient, "CoulombViscousFriction.viscous_coefficient")
        check_positive(self.velocity_width, "CoulombViscousFriction.velocity_width")
        check_plausible(self.velocity_width, "CoulombViscousFriction.velocity_width")  # 1 (mm/s) for 1e-3

    def smoothing_width(self):
        return self.velocity_width

    def force(self, v, z):
        del z
        return self.coulomb_force * smooth_sign(v, self.velocity_width) + self.viscous_coefficient * v


class BristleFriction(AbstractFriction):
    """Dahl/LuGre-type bristle friction with viscous damping (state z = bristle deflection [m]).

    ż = v − σ0 |v| z / F_c,  F = σ0 z + σ1 ż + C_f v.

    Under a net force below F_c the bristles deflect elastically (z ≤ F_c/σ0) and hold the payload still, where a
    smooth sign lets it creep (paper 000 names its simple hysteresis model the main error on the way down). At
    steady sliding z = F_c sign(v)/σ0 exactly, so F = F_c sign(v) + C_f v (eq. 8-9) at every speed.

    |v| is exact, not smoothed: the steady deflection is (F_c/σ0)·|v|/|v|ₛ for a smoothed |v|ₛ, and a smooth |v|ₛ
    that vanishes at rest (no creep there) has zero slope at 0, so |v|/|v|ₛ → ∞ at a creep: sqrt(v² + w²) − w with
    w = 1e-5 m/s made the steady force 17.7 N at 0.1 mm/s, 38.6 N at 10 µm/s and 321 N at 1 µm/s against
    F_c = 16 N, the deflection 20 F_c/σ0 (a |v|ₛ ≥ |v| instead, sqrt(v² + w²), relaxes the bristles at rest and lets
    the payload creep at ~w). The kink at v = 0 multiplies z·0, so the rate stays Lipschitz and the solution C¹:
    measured on the MAS-10 (averaged valve, an 8 s triangle of duty 0-1 at 0.25 Hz) the adaptive solve takes the
    same steps (557 against 552, 89 against 85 rejected), and forward-mode derivatives of the position in F_c and
    σ0 (rtol = atol = 1e-11) agree with central differences (steps 1e-3 of the value) to 1.4e-6 and 9e-6 of their
    largest value, as the smoothed law's did (1.7e-6, 1.3e-5). The
    slope of |v| at v = 0 is taken as 0 (`v·sign(v)`), the mean of its two sides, as the smoothed law had it: a
    linearisation at rest has the bristle spring without a branch.

    **Arguments:** `coulomb_force` F_c [N] (16), `bristle_stiffness` σ0 [N/m] (1e5: 0.16 mm pre-sliding at F_c),
    `bristle_damping` σ1 [N s/m] (2·sqrt(σ0·9.6 kg) ≈ 2000 would be critical; 500), `viscous_coefficient`
    C_f [N s/m] (250), `velocity_width` [m/s] (1e-5): the width |v| was once smoothed over, kept so that calls and
    model files that give it still work (checked as before: more than 0.05 m/s looks like mm/s); the law no longer
    reads it.
    """

    coulomb_force: RealScalar = positive(paper000.COULOMB_FORCE, unit="N")
    bristle_stiffness: RealScalar = positive(1e5, unit="N/m")
    bristle_damping: RealScalar = positive(500.0, unit="N s/m")
    viscous_coefficient: RealScalar = positive(datasheets.MAS10_VISCOUS_COEFFICIENT, unit="N s/m")
    velocity_width: RealScalar = positive(1e-5, unit="m/s")

    def __check_init__(self):
        check_positive(self.coulomb_force, "BristleFriction.coulomb_force")
        check_positive(self.bristle_stiffness, "BristleFriction.bristle_stiffness")
        check_nonnegative(self.bristle_damping, "BristleFriction.bristle_damping")
        check_nonnegative(self.viscous_coefficient, "BristleFriction.viscous_coefficient")
        check_positive(self.velocity_width, "BristleFriction.velocity_width")
        check_plausible(self.velocity_width, "BristleFriction.velocity_width")  # 1 (mm/s) for 1e-3 m/s

    def smoothing_width(self):
        return None  # |v| is exact: nothing smoothed (the stiff rate F_c/(w M) a hint would name does not exist)

    def initial_state(self, velocity=0.0):
        return jnp.zeros(())  # undeflected bristles

    def state_rate(self, v, z):
        speed = v * jnp.sign(v)  # |v|, with slope 0 at v = 0 (jnp.abs has slope 1 there: one branch)
        return v - self.bristle_stiffness * speed * z / self.coulomb_force

    def force(self, v, z):
        return self.bristle_stiffness * z + self.bristle_damping * self.state_rate(v, z) + self.viscous_coefficient * v


class KarnoppFriction(AbstractFriction):
    """Exact stick-slip Coulomb + viscous friction (Karnopp 1985), paper 000's eq. 8-9 with a true sign.

    Sliding (mode z = ±1, the direction of motion): F = F_c z + C_f v, the sign held fixed between events, so the
    vector field stays smooth inside every step. Stuck (z = 0): the payload holds still (ẋ = 0, ẍ = 0) while the net
    force on it stays within ±F_c; the friction force is then whatever balances it. Mode switches are events located
    inside the step by the fixed-grid integrator (`pamjax._solve.grid`): sliding → the velocity reaches 0, then stuck if
    |F_net| ≤ F_c, else sliding the other way; stuck → |F_net| reaches F_c, then sliding in the direction of F_net.
    Their times carry derivatives (implicit function theorem), so fits get the exact gradients of the sharp model.

    This is the friction of the hybrid reference bench (`pamjax/data/hybrid-reference-bench/meta.json`: "exact Karnopp
    stick-slip"). It needs fixed-grid stepping (`simulate(..., stepping="pwm")` for a switching valve,
    `stepping="grid"` otherwise), which `stepping="auto"` chooses; an adaptive diffrax solve cannot switch its modes and
    is refused.

    **Arguments:**

    - `coulomb_force`: F_c [N]; 16 (paper 000: half the 32 N hysteresis loop width).
    - `viscous_coefficient`: C_f [N s/m]; 250 (see `pamjax.presets`).
    """

    coulomb_force: RealScalar = positive(paper000.COULOMB_FORCE, unit="N")
    viscous_coefficient: RealScalar = positive(datasheets.MAS10_VISCOUS_COEFFICIENT, unit="N s/m")

    hybrid = True

    def __check_init__(self):
        check_nonnegative(self.coulomb_force, "KarnoppFriction.coulomb_force")
        check_nonnegative(self.viscous_coefficient, "KarnoppFriction.viscous_coefficient")

    def initial_state(self, velocity=0.0):
        """Stuck at rest (the bench's runs start so); a run that starts moving (a recording started mid-run) slides in
        the direction of its velocity."""
        return jnp.sign(jnp.asarray(velocity, dtype=float))

    def state_rate(self, v, z):
        return jnp.zeros_like(z)  # the mode changes only at events

    def is_stuck(self, z):
        return jnp.abs(z) < 0.5

    def force(self, v, z):
        """Sliding friction [N]; in the stuck mode the system holds the payload and this is not used."""
        return self.coulomb_force * z + self.viscous_coefficient * v

    def mode_after_event(self, z, net_force):
        """The mode after an event of mode `z` under a net driving force [N] at zero velocity. From stuck: the net
        force has reached ±F_c, so the payload slides in its direction (deciding by |F| ≤ F_c again would keep it
        stuck wherever the located event time falls a rounding error short). From sliding (it came to rest): stuck
        within ±F_c, else sliding the other way."""
        slide = jnp.where(net_force >= 0, 1.0, -1.0)
        after_rest = jnp.where(jnp.abs(net_force) <= self.coulomb_force, 0.0, slide)
        return jnp.where(self.is_stuck(z), slide, after_rest)
