"""Gradient checks: autodiff (forward and reverse mode) against central finite differences, per parameter.

Used by `tests/reliability/` and `benchmarks/reliability.py`; public so users can check their own losses.
"""

from collections.abc import Callable, Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jax.flatten_util import ravel_pytree

from .._core.custom_types import PyTreeLike, RealScalarLike


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


def gradient_check(loss: Callable[[PyTreeLike, Literal["forward", "reverse"]], RealScalarLike], tree: PyTreeLike, *,
                   relative_steps: Sequence[float] = RELATIVE_STEPS,
                   floor: RealScalarLike = 1e-3) -> dict[str, np.ndarray]:
    """Compare d loss / d θ from forward mode, reverse mode and central finite differences for every scalar θ in the
    inexact-array leaves of `tree`.

    `loss(tree, adjoint)` returns a scalar; `adjoint` is "forward" or "reverse" (pass it on to `simulate`/`solve`).
    Finite differences use steps h·max(|θ|, 1e-12) for each h in `relative_steps` (default `RELATIVE_STEPS`, a
    ladder from 1e-2 to 1e-6); the estimate kept per parameter is the mean of the most consistent pair of
    neighbouring steps. A wide ladder matters for losses computed by adaptive solves: the loss is smooth only down
    to the solver's noise (its step sequence changes with θ), so small steps measure the noise (noise / step) and
    large ones the curvature; the consistent pair lies between, at a different step for each parameter.

    Errors are measured on scaled sensitivities s = θ ∂L/∂θ, relative to max(|s_fd|, `floor`·max|s_fd|), so that
    parameters with negligible influence are not judged on round-off.

    Returns a dict of NumPy arrays: `names`, `forward`, `reverse`, `finite_difference`, `fd_consistency`,
    `error_fd` (autodiff reverse vs FD) and `error_modes` (forward vs reverse), both relative as described, and
    `error_modes_normwise` = max|s_fwd − s_rev| / max|s_rev| (forward vs reverse relative to the gradient's size).
    """
    params, static = eqx.partition(tree, eqx.is_inexact_array)
    flat, unravel = ravel_pytree(params)

    def f(vector, adjoint):
        return loss(eqx.combine(unravel(vector), static), adjoint)

    reverse = np.asarray(jax.jit(jax.grad(lambda v: f(v, "reverse")))(flat))
    forward = np.asarray(jax.jit(jax.jacfwd(lambda v: f(v, "forward")))(flat))
    f_batched = jax.jit(jax.vmap(lambda v: f(v, "reverse")))
    theta = np.asarray(flat)
    n = theta.size
    magnitude = np.maximum(np.abs(theta), 1e-12)
    estimates = []
    for h in relative_steps:
        step = h * magnitude
        perturb = np.concatenate([np.diag(step), -np.diag(step)])
        values = np.asarray(f_batched(jnp.asarray(theta[None, :] + perturb)))
        estimates.append((values[:n] - values[n:]) / (2 * step))
    estimates = np.stack(estimates)  # (steps, n)
    if len(relative_steps) > 1:
        gaps = np.abs(np.diff(estimates, axis=0))  # consistency of neighbouring steps
        best = np.argmin(gaps, axis=0)
        fd = 0.5 * (estimates[best, np.arange(n)] + estimates[best + 1, np.arange(n)])
        consistency = gaps[best, np.arange(n)] / np.maximum(np.abs(fd), 1e-300)
    else:
        fd, consistency = estimates[0], np.zeros(n)
    s_fd, s_rev, s_fwd = theta * fd, theta * reverse, theta * forward
    denominator = np.maximum(np.abs(s_fd), floor * np.max(np.abs(s_fd)))
    denominator_modes = np.maximum(np.abs(s_rev), floor * np.max(np.abs(s_rev)))
    return dict(
        names=np.asarray(parameter_names(tree)),
        forward=forward,
        reverse=reverse,
        finite_difference=fd,
        fd_consistency=consistency,
        error_fd=np.abs(s_rev - s_fd) / denominator,
        error_modes=np.abs(s_fwd - s_rev) / denominator_modes,
        error_modes_normwise=np.max(np.abs(s_fwd - s_rev)) / max(np.max(np.abs(s_rev)), 1e-300),
    )
