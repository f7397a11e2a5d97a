"""Gradients through the whole smooth-PWM muscle simulation against central finite differences.

One seeded parameter set here (CI); `benchmarks/reliability.py` runs 20 and reports the pass fraction.
Tolerance: 1e-4 relative on scaled sensitivities θ ∂L/∂θ (see `pamjax._solve.gradcheck.gradient_check`) at solver
rtol = atol = 1e-10, for every physical parameter including the duty and the switching delays; forward and reverse
mode agree within 1e-6. Numerical smoothing widths (edge_width, velocity_width, slack_width, end-stop width) are
settings, not physical parameters: their finite differences are dominated by the adaptive step pattern.
"""

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
