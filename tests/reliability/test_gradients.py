"""Gradients through the whole smooth-PWM muscle simulation against central finite differences.

One seeded parameter set here (CI); `benchmarks/reliability.py` runs 20 and reports the pass fraction.
Tolerance: 1e-4 relative on scaled sensitivities θ ∂L/∂θ (see `pamjax._solve.gradcheck.gradient_check`) at solver
rtol = atol = 1e-10, for every physical parameter including the duty and the switching delays; forward and reverse
mode agree within 1e-6. Numerical smoothing widths (edge_width, velocity_width, slack_width, end-stop width) are
settings, not physical parameters: their finite differences are dominated by the adaptive step pattern.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from pamjax._solve.gradcheck import gradient_check
from pamjax._solve.simulate import solve

from .helpers import NUMERICAL_SETTINGS, random_pwm_problem


@pytest.mark.slow
def test_every_parameter_gradient_matches_finite_differences():
    system, signal = random_pwm_problem(seed=0)
    ts = jnp.linspace(0.0, 0.4, 21)  # 20 PWM periods at 50 Hz

    def loss(tree, adjoint):
        s, u = tree
        traj = solve(s, u, ts, None, 0.0, rtol=1e-10, atol=1e-10, adjoint=adjoint, max_steps=100_000)
        return jnp.mean((traj.position / 1e-2) ** 2) + jnp.mean((traj.pressure / 1e5) ** 2)

    report = gradient_check(loss, (system, signal))
    physical = np.array([not any(k in n for k in NUMERICAL_SETTINGS) for n in report["names"]])
    worst = np.argmax(np.where(physical, report["error_fd"], 0.0))
    assert report["error_fd"][physical].max() < 1e-4, (report["names"][worst], report["error_fd"][worst])
    assert report["error_modes"].max() < 1e-6
    # the duty and the switching delays are among the checked parameters and matter
    for name in ("[1].value", "[0].valve.switch_on_delay", "[0].valve.switch_off_delay"):
        i = list(report["names"]).index(name)
        assert abs(report["reverse"][i]) > 0


def test_finite_differences_see_through_solver_noise():
    """The finite-difference reference itself, on a loss with a known gradient and the noise of an adaptive solve:
    jumps of 3e-11 of the loss per parameter wherever it crosses a fine grid (1e-7 of itself), as an accepted step
    sequence changes with θ (measured on the MAS-10 at rtol 1e-12 over 20 PWM periods: 2e-11 rms, 3e-11 at most).
    Steps of 1e-4..1e-6 θ measured the noise (here 2e-4 off; in benchmarks/reliability.py up to 1e-3 on parameters
    of small influence, 4 of 20 sets failed); the default ladder keeps each parameter's consistent pair, between the
    noise and the curvature (here 2e-5)."""
    theta0 = jnp.array([15.8, 290.0, 0.4, 6.4e5])  # F_c-, C_f-, b- and a2-like magnitudes
    weight = jnp.array([1e-3, 5e-4, 2e-2, 1.0])  # scaled sensitivities θ ∂L/∂θ relative to the loss' size ~1

    def loss(theta, adjoint):
        u = theta / theta0
        smooth = 1.0 + jnp.sum(weight * (u - 1.0)) + 0.3 * jnp.sum(weight * (u - 1.0) ** 2) + 0.5 * (u[2] - 1.0) ** 3
        jumps = jnp.sin(1e4 * jnp.floor(u / 1e-7))  # piecewise constant: no derivative, a new value every 1e-7
        return smooth * (1.0 + 3e-11 * jnp.sum(jumps))

    report = gradient_check(loss, theta0)
    np.testing.assert_allclose(report["reverse"] * theta0, weight, rtol=1e-9)  # the exact gradient at θ0
    assert report["error_fd"].max() < 1e-4, report["error_fd"]


def test_friction_gradients_through_an_adaptive_pwm_solve():
    """Fast version of the benchmark's check on the parameters it failed on (set 7: F_c, C_f), 5 PWM periods at
    rtol = atol = 1e-12: reverse mode against central differences within 1e-4 (with steps 1e-4..1e-6 θ: F_c off by
    2.5e-4, the solver's noise), and against forward mode."""
    system, signal = random_pwm_problem(seed=7)
    ts = jnp.linspace(0.0, 0.1, 6)

    def loss(tree, adjoint):
        s = eqx.tree_at(lambda s: (s.friction.coulomb_force, s.friction.viscous_coefficient), system, tree)
        traj = solve(s, signal, ts, None, 0.0, rtol=1e-12, atol=1e-12, adjoint=adjoint, max_steps=100_000)
        return jnp.mean((traj.position / 1e-2) ** 2) + jnp.mean((traj.pressure / 1e5) ** 2)

    report = gradient_check(loss, (system.friction.coulomb_force, system.friction.viscous_coefficient))
    assert report["error_fd"].max() < 1e-4, report["error_fd"]
    assert report["error_modes"].max() < 1e-6
    assert np.all(np.abs(report["reverse"]) > 0)
