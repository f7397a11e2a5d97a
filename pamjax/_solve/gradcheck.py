"""Gradient checks: autodiff (forward and reverse mode) against finite differences, per parameter: central ones,
one-sided ones for a parameter on the edge of its valid range.

Used by `tests/reliability/` and `benchmarks/reliability.py`; public so users can check their own losses.
"""

import inspect
from collections.abc import Callable, Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.flatten_util import ravel_pytree

from .._core.custom_types import PyTreeLike, RealArrayLike, RealScalarLike
from .._core.errors import PamjaxInputError
from .checks import check_parameters


def parameter_names(tree):
    """Dotted path of every scalar in the inexact-array leaves of `tree` (array elements get `[i]`)."""
    params, _ = eqx.partition(tree, eqx.is_inexact_array)
    names = []
    for path, leaf in jtu.tree_flatten_with_path(params)[0]:
        base = jtu.keystr(path).lstrip(".")
        size = int(np.size(leaf))
        names += [base] if size == 1 else [f"{base}[{i}]" for i in range(size)]
    return names


# Relative steps of the finite differences, a 1-2-5 ladder over four decades. A loss computed by an adaptive solve
# is smooth in θ only down to the solver's noise: a change of θ changes the accepted step sequence, and the loss
# jumps by about the solve's error (2e-11 of the loss at rtol = 1e-12 over 20 PWM periods of the MAS-10: rms 4e-10
# off the gradient's tangent line within ±2e-6 relative of F_c, while the step count varies 6,077-6,095). A central
# difference with step h θ then errs by noise / (h θ) plus its truncation ∝ h²: for parameters of small influence
# (F_c, C_f, a2, b) the noise dominates below h ≈ 1e-4 (1e-3 off at 1e-5, 1e-6), while a strongly nonlinear one
# (the PWM frequency over 20 periods) needs h ≤ 1e-5. No single step serves all, so each parameter keeps the most
# consistent pair of neighbours on this ladder. Measured (benchmarks/reliability.py, 20 sets x 33 parameters):
# steps (1e-4, 1e-5, 1e-6) failed 4 sets (worst 1.1e-3, F_c; 14 pairs inconclusive); this ladder passes all, worst
# judged error 5.2e-5, one pair inconclusive (set 4's PWM frequency, 9e-4 of the largest scaled sensitivity: noise
# reaches it before its curvature lets go). A finer ladder (adding 5e-6, 2e-6) found a coincident noisy pair there.
RELATIVE_STEPS = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 1e-6)
# A parameter at 0 has no magnitude of its own to step by (h·0 = 0) or to scale its sensitivity with (0 · ∂L/∂θ = 0,
# which passed any gradient): it takes this one instead (`zero_scale`), the size of a change that matters, in its own
# unit. 1 suits a pure number (a duty, an offset of order 1); a dimensional parameter at 0 (an internal volume of
# 0 m³, an outlet flow of 0 kg/s) needs its natural size given (1e-4 m³, 1e-3 kg/s).
ZERO_SCALE = 1.0
SIDES = {0: "central", 1: "forward", -1: "backward"}


def gradient_check(loss: Callable[[PyTreeLike, Literal["forward", "reverse"]], RealScalarLike], tree: PyTreeLike, *,
                   relative_steps: Sequence[float] = RELATIVE_STEPS,
                   floor: RealScalarLike = 1e-3, zero_scale: RealArrayLike = ZERO_SCALE) -> dict[str, np.ndarray]:
    """Compare d loss / d θ from forward mode, reverse mode and finite differences for every scalar θ in the
    inexact-array leaves of `tree`.

    `loss(tree, adjoint)` returns a scalar; `adjoint` is "forward" or "reverse" (pass it on to `simulate`/`solve`).
    Finite differences use steps h·m for each h in `relative_steps` (default `RELATIVE_STEPS`, a ladder from 1e-2 to
    1e-6), m = |θ|, or `zero_scale` (default `ZERO_SCALE` = 1; a number, or one per parameter) for a parameter at 0;
    the estimate kept per parameter is the mean of the most consistent pair of neighbouring steps. A wide ladder
    matters for losses computed by adaptive solves: the loss is smooth only down to the solver's noise (its step
    sequence changes with θ), so small steps measure the noise (noise / step) and large ones the curvature; the
    consistent pair lies between, at a different step for each parameter.

    Differences are central, (L(θ + s) − L(θ − s)) / 2s, where both perturbed trees pass their components' checks
    (`__check_init__`, as `simulate` applies them); a parameter on the edge of its valid range (a volume of 0, a
    calibration's voltage at 10 V) is differenced one-sidedly into it, (∓3 L(θ) ± 4 L(θ ± s) ∓ L(θ ± 2s)) / 2s
    (second order); one that cannot be moved either way at any step is named (`PamjaxInputError`), before any
    difference is computed.

    Errors are measured on scaled sensitivities s = m ∂L/∂θ, relative to max(|s_fd|, `floor`·max|s_fd|), so that
    parameters with negligible influence are not judged on round-off.

    Returns a dict of NumPy arrays: `names`, `forward`, `reverse`, `finite_difference`, `fd_consistency`,
    `error_fd` (autodiff reverse vs FD) and `error_modes` (forward vs reverse), both relative as described, and
    `error_modes_normwise` = max|s_fwd − s_rev| / max|s_rev| (forward vs reverse relative to the gradient's size);
    `difference`: per parameter "central", "forward" or "backward" (at the kept pair).
    """
    _check_loss(loss)
    steps = _check_steps(relative_steps)
    floor = _check_floor(floor)
    params, static = eqx.partition(tree, eqx.is_inexact_array)
    flat, unravel = ravel_pytree(params)
    names = np.asarray(parameter_names(tree))
    theta = np.asarray(flat)
    if theta.size == 0:
        raise PamjaxInputError("gradient_check: tree has no parameter to check: its leaves hold no floating-point "
                               "array (a Python float or an int is not one); pass e.g. {'a': jnp.asarray(2.0)} or a "
                               "model, whose parameters are float64 arrays")
    magnitude = _magnitudes(theta, zero_scale)

    def f(vector, adjoint):
        return loss(eqx.combine(unravel(vector), static), adjoint)

    def passes(vector):
        try:
            check_parameters(eqx.combine(unravel(jnp.asarray(vector)), static), "tree")
        except PamjaxInputError:
            return False
        return True

    check_parameters(eqx.combine(unravel(flat), static), "tree")  # the tree itself must pass
    sides = _sides(passes, theta, magnitude, steps, names)
    value, reverse = jax.jit(jax.value_and_grad(lambda v: f(v, "reverse")))(flat)
    _check_finite_at(value, "the loss", names)
    reverse = np.asarray(reverse)
    _check_finite_at(reverse, "its reverse-mode gradient", names)
    forward = np.asarray(jax.jit(jax.jacfwd(lambda v: f(v, "forward")))(flat))
    _check_finite_at(forward, "its forward-mode gradient", names)
    estimates = _estimates(jax.jit(jax.vmap(lambda v: f(v, "reverse"))), theta, magnitude, steps, sides)
    fd, consistency, best = _kept(estimates)
    _check_finite_at(fd, "its finite differences (the loss at every perturbed tree)", names)
    s_fd, s_rev, s_fwd = magnitude * fd, magnitude * reverse, magnitude * forward
    denominator = np.maximum(np.abs(s_fd), floor * np.max(np.abs(s_fd)))
    denominator_modes = np.maximum(np.abs(s_rev), floor * np.max(np.abs(s_rev)))
    return dict(
        names=names,
        forward=forward,
        reverse=reverse,
        finite_difference=fd,
        fd_consistency=consistency,
        error_fd=np.abs(s_rev - s_fd) / denominator,
        error_modes=np.abs(s_fwd - s_rev) / denominator_modes,
        error_modes_normwise=np.max(np.abs(s_fwd - s_rev)) / max(np.max(np.abs(s_rev)), 1e-300),
        difference=np.asarray([SIDES[int(sides[k, i])] for i, k in enumerate(best)]),
    )


def _check_loss(loss):
    """`loss` a function of (tree, adjoint): refused by name before anything is evaluated (one of the tree alone
    failed with Python's raw TypeError from inside JAX's trace)."""
    if not callable(loss):
        raise PamjaxInputError(f"gradient_check: loss must be a function loss(tree, adjoint) -> scalar, got "
                               f"{type(loss).__name__}")
    try:
        signature = inspect.signature(loss)
    except (TypeError, ValueError):  # a builtin or C function: nothing to read, its call names itself
        return
    try:
        signature.bind(None, "reverse")
    except TypeError:
        raise PamjaxInputError(f"gradient_check: loss must take two arguments, loss(tree, adjoint), adjoint "
                               f"\"forward\" or \"reverse\" (pass it on to simulate/solve), got loss{signature}: e.g. "
                               "lambda tree, adjoint: my_loss(tree)") from None


def _check_steps(relative_steps):
    """`relative_steps` as a 1-D float array: at least one step, each a finite number in (0, 1) (a step of 0 divided
    0 by 0; none at all was reported as every parameter "cannot be perturbed either way")."""
    try:
        h = np.asarray(relative_steps, dtype=float)
    except (TypeError, ValueError):
        h = None
    if h is None or h.ndim != 1 or h.size == 0 or not np.all(np.isfinite(h) & (h > 0) & (h < 1)):
        raise PamjaxInputError(f"gradient_check: relative_steps must be one or more finite numbers in (0, 1), the "
                               f"steps relative to each parameter's magnitude (default RELATIVE_STEPS, 1e-2 to 1e-6), "
                               f"got {relative_steps!r}")
    return h


def _check_floor(floor):
    """`floor` a finite number >= 0 (NaN gave every error NaN)."""
    if isinstance(floor, (bool, np.bool_, str)) or np.ndim(floor) != 0:
        value = float("nan")
    else:
        try:
            value = float(floor)
        except (TypeError, ValueError):
            value = float("nan")
    if not (np.isfinite(value) and value >= 0):
        raise PamjaxInputError(f"gradient_check: floor must be a finite number >= 0 (the fraction of the largest "
                               f"scaled sensitivity below which errors are judged absolutely, default 1e-3), got "
                               f"{floor!r}")
    return value


def _check_finite_at(values, what, names):
    """`PamjaxInputError` where the loss, or a derivative of it, is not finite: every error compared with it was
    NaN, silently."""
    values = np.asarray(values)
    if np.all(np.isfinite(values)):
        return
    where = "" if values.ndim == 0 else f" for {', '.join(str(n) for n in names[~np.isfinite(values)])}"
    raise PamjaxInputError(f"gradient_check: {what} is not finite at `tree`{where} ({values!r}): nothing to compare; "
                           "check the loss there (a failed solve? simulate(..., throw=True) says why)")


def _magnitudes(theta, zero_scale):
    """Each parameter's scale m: |θ|, or `zero_scale` where θ = 0 (checked: > 0 and finite, one or one per θ)."""
    scale = np.asarray(zero_scale, dtype=float)
    if scale.shape not in ((), theta.shape) or not np.all(np.isfinite(scale) & (scale > 0)):
        raise PamjaxInputError(f"zero_scale must be > 0 and finite, one number or one per parameter ({theta.size}), "
                               f"got {zero_scale!r}")
    return np.where(theta != 0, np.abs(theta), np.broadcast_to(scale, theta.shape))


def _sides(passes, theta, magnitude, relative_steps, names):
    """(steps, n): per step and parameter, how it is differenced: 0 central, +1 forward, −1 backward, NaN not at
    all (no valid pair). `passes(vector)`: whether the tree at `vector` passes its components' checks. A valid range
    is an interval: from the largest offset that passes, every smaller one on that side does too."""
    h = np.asarray(relative_steps, dtype=float)
    sides = np.full((h.size, theta.size), np.nan)
    for i in range(theta.size):
        ok = {}
        for sign in (1.0, -1.0):
            offsets = sign * magnitude[i] * np.concatenate([h, 2.0 * h])
            ok[sign] = np.zeros(offsets.size, dtype=bool)
            for j in np.argsort(-np.abs(offsets)):
                vector = theta.copy()
                vector[i] += offsets[j]
                if passes(vector):
                    ok[sign] = np.abs(offsets) <= np.abs(offsets[j])
                    break
        n = h.size
        plus, minus = ok[1.0], ok[-1.0]
        sides[:, i] = np.where(plus[:n] & minus[:n], 0.0, np.where(plus[:n] & plus[n:], 1.0,
                                                                    np.where(minus[:n] & minus[n:], -1.0, np.nan)))
    stuck = [str(names[i]) for i in range(theta.size) if np.all(np.isnan(sides[:, i]))]
    if stuck:
        raise PamjaxInputError(
            f"gradient_check: {', '.join(stuck)} cannot be perturbed either way (every step of relative_steps × its "
            "magnitude leaves what its component accepts): leave it out of `tree` (keep it in the loss' closure)"
        )
    return sides


def _estimates(f_batched, theta, magnitude, relative_steps, sides):
    """(steps, n) finite-difference derivatives: each step's 2n perturbed trees and θ itself in one batch."""
    n = theta.size
    estimates = []
    for k, h in enumerate(relative_steps):
        step, side = h * magnitude, np.nan_to_num(sides[k], nan=0.0)
        first = np.where(side == 0, 1.0, side)  # central: +s, −s; one-sided: ±s, ±2s
        second = np.where(side == 0, -1.0, 2.0 * side)
        usable = ~np.isnan(sides[k])
        perturb = np.concatenate([np.diag(np.where(usable, first * step, 0.0)),
                                  np.diag(np.where(usable, second * step, 0.0)), np.zeros((1, n))])
        try:
            values = np.asarray(f_batched(jnp.asarray(theta[None, :] + perturb)))
        except jax.errors.JaxRuntimeError as err:  # a refusal the components' checks do not make (the loss' own)
            refusal = [line.strip() for line in str(err).splitlines() if "must be" in line][:1]
            raise PamjaxInputError(f"gradient_check: the loss failed at a tree perturbed by relative step {h:g}"
                                   + (f": {refusal[0].split('Error: ')[-1]}" if refusal else "")) from None
        plus, other, base = values[:n], values[n:2 * n], values[-1]
        central = (plus - other) / (2 * step)
        one_sided = side * (-3.0 * base + 4.0 * plus - other) / (2 * step)
        estimates.append(np.where(usable, np.where(side == 0, central, one_sided), np.nan))
    return np.stack(estimates)


def _kept(estimates):
    """(fd, consistency, step index) per parameter: the mean of the most consistent pair of neighbouring steps (both
    usable), or the first usable estimate where no pair is."""
    n = estimates.shape[1]
    columns = np.arange(n)
    first = np.argmax(~np.isnan(estimates), axis=0)
    if estimates.shape[0] == 1:
        return estimates[0], np.zeros(n), first
    gaps = np.abs(np.diff(estimates, axis=0))  # consistency of neighbouring steps
    gaps = np.where(np.isnan(gaps), np.inf, gaps)
    best = np.argmin(gaps, axis=0)
    paired = np.isfinite(gaps[best, columns])
    fd = np.where(paired, 0.5 * (estimates[best, columns] + estimates[np.minimum(best + 1, len(estimates) - 1),
                                                                          columns]), estimates[first, columns])
    consistency = np.where(paired, gaps[best, columns], np.inf) / np.maximum(np.abs(fd), 1e-300)
    return fd, consistency, np.where(paired, best, first)
