"""Paper 000's averaged ("analytic") valve, eq. 13, and the cycle average of a switching valve it is fitted to."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._core.arrays import as_array, device_array
from ..._core.custom_types import Array, FloatArray, Real, RealArrayLike, RealVectorLike
from ..._core.errors import PamjaxInputError, check_finite, check_positive, concrete_values
from ..._core.fitting import labelled
from ..._core.units import check_absolute_pressure
from ..gas import Air
from ..smooth import safe_divide, safe_sqrt
from .base import AbstractSwitchingValve, AbstractValve


class AveragedValve(AbstractValve):
    """Paper 000's averaged ("analytic") valve, eq. 13: the PWM cycle-averaged mass flow as a 2nd-order
    bi-polynomial in the duty ratio u and the chamber pressure.

    ṁ_eq(u, p) = Σᵢⱼ m[i, j] uⁱ pᵍʲ, i, j ∈ {0, 1, 2}, with p_g = p − p_atm the GAUGE chamber pressure [Pa]
    (paper 000's Fig. 8 plots relative pressure). The paper's m1…m9 are `coefficients` flattened row-wise:
    m1 = m[0,0], m2 = m[0,1], m3 = m[0,2], m4 = m[1,0], …, m9 = m[2,2]. SI units: m[i, j] in kg/(s Paʲ).

    **Arguments:** `coefficients` (3, 3) array (see `pamjax.presets` for the derived defaults).
    """

    coefficients: Real[Array, "3 3"] = eqx.field(converter=as_array, metadata=labelled("m{n}", unit="kg/(s Pa^j)"))

    def __check_init__(self):
        if jnp.shape(self.coefficients) != (3, 3):
            raise PamjaxInputError(
                "AveragedValve.coefficients must have shape (3, 3) (m1…m9 row-wise), "
                f"got {jnp.shape(self.coefficients)}"
            )
        check_finite(self.coefficients, "AveragedValve.coefficients")

    @classmethod
    def from_m(cls, m: RealVectorLike) -> "AveragedValve":
        """Build from the paper's flat m1…m9 (SI units, gauge pressure in Pa)."""
        m = jnp.asarray(m)
        if m.shape != (9,):
            raise PamjaxInputError(f"AveragedValve.from_m needs 9 coefficients m1…m9, got shape {m.shape}")
        return cls(m.reshape(3, 3))

    averaged = True

    def mass_flow(self, t, command, pressure, air: Air):
        del t
        p_gauge = pressure - air.atmospheric_pressure
        m = self.coefficients
        # Horner sums, not u_powers @ m @ p_powers: the same polynomial in fewer operations, which XLA fuses into the
        # batched sweeps' step (benchmarks/sweep.py: 75 → 69 ms per 1,024-lane sweep, docs/performance.md).
        c = [m[i, 0] + p_gauge * (m[i, 1] + p_gauge * m[i, 2]) for i in range(3)]
        return c[0] + command * (c[1] + command * c[2])

    def command_for_flow(self, mass_flow, pressure, air: Air):
        """The duty u ∈ [0, 1] whose averaged flow (eq. 13) is `mass_flow` [kg/s] at chamber `pressure` [Pa abs]: the
        increasing root of c₂u² + c₁u + c₀ = ṁ, cᵢ = Σⱼ m[i, j] p_gʲ, written
        u = 2(ṁ − c₀) / (c₁ + √(c₁² + 4c₂(ṁ − c₀))), stable as c₂ → 0. Where no root in [0, 1] reaches ṁ: the duty
        in [0, 1] whose flow comes nearest, among the ends 0 and 1, the parabola's vertex −c₁/(2c₂) where it lies
        inside (the flow's extreme there: at high chamber pressure the preset's outflow peaks at u ≈ 0.95, and
        duty 1 flows less) and the other root."""
        p_gauge = pressure - air.atmospheric_pressure
        c0, c1, c2 = self.coefficients @ jnp.stack([jnp.ones_like(p_gauge), p_gauge, p_gauge * p_gauge])
        demand = mass_flow - c0
        discriminant = c1 * c1 + 4.0 * c2 * demand
        real = discriminant >= 0
        # denominators kept off 0 by 1e-12 kg/s (flows are ~1e-3): finite values and gradients in every candidate
        root = safe_divide(2.0 * demand, c1 + safe_sqrt(discriminant), tiny=1e-12)
        other = safe_divide(2.0 * demand, c1 - safe_sqrt(discriminant), tiny=1e-12)  # the decreasing root
        vertex = jnp.broadcast_to(safe_divide(-c1, 2.0 * c2, tiny=1e-12), root.shape)
        candidates = jnp.clip(jnp.stack([root, other, jnp.zeros_like(root), jnp.ones_like(root), vertex]), 0.0, 1.0)
        miss = jnp.abs(c0 + candidates * (c1 + candidates * c2) - mass_flow)
        miss = miss.at[:2].set(jnp.where(real, miss[:2], jnp.inf))  # no real roots: only the extremes count
        # the first nearest: the increasing root wherever it reaches ṁ (eq. 13's inverse, as before)
        return jnp.take_along_axis(candidates, jnp.argmin(miss, axis=0)[None], axis=0)[0]


def cycle_averaged_flow(valve: AbstractSwitchingValve, command: RealArrayLike, pressure: RealArrayLike, air: Air,
                        samples: int = 4000) -> FloatArray:
    """PWM-period average of an on/off valve's flow [kg/s] into a chamber held at `pressure` [Pa abs], for duty
    `command` (paper 000's "equivalent mass flow"; midpoint rule over `samples` phases of one period).

    Elementwise: `command` and `pressure` broadcast against each other, one average per pair (the mean is over the
    phases only). Checked as `flow_surface` checks them (`check_cycle_average`): a switching valve, duties within its
    `command_range`, finite ABSOLUTE pressures and an int `samples` >= 1; traced values (jit, vmap, grad) have no
    value to check. Shapes that do not broadcast are refused by name (they were a raw ValueError)."""
    check_cycle_average(valve, command, pressure, samples, ("command", "pressure", "samples"), "the cycle average")
    check_broadcastable(("command", "pressure"), (command, pressure), "cycle_averaged_flow",
                        "one duty per pressure, or one of them a scalar; a duty × pressure grid is flow_surface, or "
                        "command[:, None] with pressure[None, :]")
    phases = (jnp.arange(samples) + 0.5) / samples * valve.period

    def average(u, p):  # one duty and pressure (a valve's opening reads a duty pair of shape (2,) as (u_k, u_k-1))
        return jnp.mean(jax.vmap(lambda t: valve.mass_flow(t, u, p, air))(phases), axis=0)

    if jnp.ndim(command) == 0 and jnp.ndim(pressure) == 0:
        return average(command, pressure)
    u, p = jnp.broadcast_arrays(jnp.asarray(command, dtype=float), jnp.asarray(pressure, dtype=float))
    flows = jax.vmap(average)(u.ravel(), p.ravel())
    return flows.reshape(u.shape + flows.shape[1:])


def check_switching_valve(valve, what):
    """`valve` a switching valve (`what`, e.g. "the cycle average", is its flow averaged over a PWM period), else a
    `PamjaxInputError` naming it and what to pass."""
    if not (isinstance(valve, AbstractSwitchingValve) and valve.switches):
        raise PamjaxInputError(f"valve: {what} is a switching valve's flow averaged over a PWM period; "
                               f"{type(valve).__name__} does not switch (an averaged valve's flow is its own "
                               "mass_flow(t, command, pressure, air): evaluate that directly; a switching one: e.g. "
                               "presets.mas10_valve())")


def check_broadcastable(names, values, where, expected):
    """`values` (named `names`) of shapes that broadcast against each other (an elementwise function of them), else
    a `PamjaxInputError` naming `where`, each argument's shape and what is `expected`. Shapes only: traced values are
    checked too."""
    shapes = [tuple(np.shape(v)) for v in values]
    try:
        np.broadcast_shapes(*shapes)
    except ValueError:
        given = " and ".join(f"{n} of shape {s}" for n, s in zip(names, shapes))
        raise PamjaxInputError(f"{where}: {given} do not broadcast against each other (the function is elementwise: "
                               f"{expected})") from None


def check_cycle_average(valve, commands, pressures, samples, names, what):
    """The checks of a cycle average (`cycle_averaged_flow`, `flow_surface`), on concrete values before anything is
    traced: a switching valve (`what`, e.g. "the flow surface", is its flow averaged over a PWM period), a positive
    int of phases per period, duties within the valve's `command_range` (percent named), finite, positive, ABSOLUTE
    pressures [Pa] (bar and gauge named). `names`: the (commands, pressures, samples) arguments' names, as the
    `PamjaxInputError` names them; traced values have no value to check."""
    command_name, pressure_name, samples_name = names
    check_switching_valve(valve, what)
    if not (isinstance(samples, (int, np.integer)) and not isinstance(samples, (bool, np.bool_)) and samples >= 1):
        raise PamjaxInputError(f"{samples_name} must be a positive integer (phases per PWM period), got {samples!r}")
    u = concrete_values(commands)
    lo, hi = valve.command_range
    if u is not None and not np.all((u >= lo) & (u <= hi)):  # NaN too
        bad = u[~((u >= lo) & (u <= hi))]
        hint = "; that looks like percent (duty 0.5 is 50 %)" if hi == 1.0 and np.any(bad > hi) else ""
        raise PamjaxInputError(f"{command_name} must lie in [{lo}, {hi}] (the valve's command_range, the duty ratio), "
                               f"got {np.array2string(bad, threshold=6)}{hint}")
    if concrete_values(pressures) is not None:
        check_positive(pressures, f"{pressure_name} (absolute) [Pa]")
        check_absolute_pressure(pressures, pressure_name)


def fit_averaged_valve(valve: AbstractSwitchingValve, air: Air, commands: RealArrayLike | None = None,
                       pressures: RealArrayLike | None = None,
                       pin_endpoints: bool = True) -> tuple[AveragedValve, dict[str, float]]:
    """Least-squares fit of eq. 13's m1…m9 to the cycle-averaged flow of an on/off valve over a (duty, pressure)
    grid (duty 0…1, pressure p_atm…p_supply by default). Returns `(AveragedValve, report)`, the report holding the
    max error and RMSE in kg/s and in % of the flow range (paper 000: 4.13 % and 1.16 %).

    With `pin_endpoints` (default) the fit is constrained to zero flow where the physical valve has none: duty 0 at
    atmospheric pressure and duty 1 at supply pressure. Without it the unconstrained biquadratic charges a tank
    above the supply pressure at high duty (and below atmosphere at low duty).

    A grid given is checked: `commands` 1-D, finite, within the valve's `command_range` (duty 0…1, not percent), at
    least three distinct duties (eq. 13 is quadratic in u);
    `pressures` 1-D, finite, ABSOLUTE [Pa] (not bar or gauge), at least two distinct ones above atmosphere (eq. 13 is
    quadratic in the pressure); `PamjaxInputError` naming the argument otherwise."""
    # the valve first: the default grid reads its supply pressure (an AveragedValve ended as a raw AttributeError)
    check_switching_valve(valve, "fit_averaged_valve fits eq. 13 to the cycle average, which")
    # a user's grid (NumPy or a list) and the fitted coefficients are put on the device without compiling
    # (`device_array`; `jnp.asarray` of a NumPy array compiles a small program per shape)
    if commands is None:
        commands = jnp.linspace(0.0, 1.0, 41)
    else:
        commands = _grid(commands, "commands", valve.command_range)
        if np.unique(commands).size < 3:
            raise PamjaxInputError(f"commands must hold at least three distinct duties: eq. 13 is quadratic in the "
                                   f"duty u; got {commands}")
        commands = device_array(commands)
    if pressures is None:
        pressures = jnp.linspace(air.atmospheric_pressure, valve.supply_pressure, 41)
    else:
        pressures = _grid(pressures, "pressures")
        check_absolute_pressure(pressures, "pressures")
        atmosphere = float(air.atmospheric_pressure)
        if np.unique(pressures[pressures > atmosphere]).size < 2:
            raise PamjaxInputError(f"pressures must hold at least two distinct pressures above atmosphere "
                                   f"({atmosphere:g} Pa abs): eq. 13 is quadratic in the gauge pressure; got "
                                   f"{pressures}")
    coef, max_error, rmse, span = (np.asarray(x) for x in
                                   _fit_coefficients(valve, air, commands, device_array(pressures), pin_endpoints))
    fitted = AveragedValve(device_array(coef))
    report = dict(
        max_error=float(max_error),
        rmse=float(rmse),
        max_error_percent=float(100 * max_error / span),
        rmse_percent=float(100 * rmse / span),
        flow_range=float(span),
    )
    return fitted, report


def _grid(values, name, bounds=None):
    """A fit grid as a 1-D, non-empty, finite NumPy array (within `bounds` if given); `PamjaxInputError` naming it."""
    v = np.asarray(values, dtype=float)
    if v.ndim != 1 or v.size == 0:
        raise PamjaxInputError(f"{name} must be a 1-D, non-empty grid, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise PamjaxInputError(f"{name} must be finite (no NaN or inf), got {v}")
    if bounds is not None and not np.all((v >= bounds[0]) & (v <= bounds[1])):
        hint = "; that looks like percent" if bounds == (0.0, 1.0) and np.max(v) > 1.0 else ""
        raise PamjaxInputError(f"{name} must lie within the valve's command range [{bounds[0]:g}, {bounds[1]:g}] "
                               f"(the duty ratio), got [{np.min(v):g}, {np.max(v):g}]{hint}")
    return v


@eqx.filter_jit
def _fit_coefficients(valve, air, commands, pressures, pin_endpoints):
    """`fit_averaged_valve`'s grid, least squares and errors as one compiled program (one per grid shape; run
    eagerly, each operation of the flow law and the fit compiled a program of its own: ~110 per call): (m1…m9 as
    3 × 3, max |error|, RMSE, flow range)."""
    uu, pp = jnp.meshgrid(commands, pressures, indexing="ij")
    flows = jax.vmap(jax.vmap(lambda u, p: cycle_averaged_flow(valve, u, p, air)))(uu, pp)
    pg = (pp - air.atmospheric_pressure).ravel()
    u = uu.ravel()
    p_scale = jnp.max(jnp.abs(pg))  # conditioning: fit in p / p_scale, then convert to SI
    pn = pg / p_scale
    design = jnp.stack([u**i * pn**j for i in range(3) for j in range(3)], axis=1)
    if pin_endpoints:

        def row(u, p):
            pn = (p - air.atmospheric_pressure) / p_scale
            return jnp.stack([u**i * pn**j for i in range(3) for j in range(3)])

        constraints = jnp.stack([row(0.0, air.atmospheric_pressure), row(1.0, valve.supply_pressure)])
        _, _, vt = jnp.linalg.svd(constraints)
        null = vt[constraints.shape[0] :].T  # (9, 7): coefficients satisfying both constraints exactly
        z, *_ = jnp.linalg.lstsq(design @ null, flows.ravel())
        coef = null @ z
    else:
        coef, *_ = jnp.linalg.lstsq(design, flows.ravel())
    coef = coef.reshape(3, 3) / p_scale ** jnp.arange(3)[None, :]
    fitted = AveragedValve(coef)
    err = jax.vmap(lambda u, p: fitted.mass_flow(0.0, u, p, air))(u, pp.ravel()) - flows.ravel()
    return coef, jnp.max(jnp.abs(err)), jnp.sqrt(jnp.mean(err**2)), jnp.max(flows) - jnp.min(flows)
