"""Legal inputs that once failed with a hint blaming `max_steps` (issue 15): they solve, or fail with the real cause
and the setting that fixes it (`pamjax._solve_hints`), and following that advice works.

- the exact-edge valve at duty 0 and 1 (fictitious edges: jump times one rounding error apart) and on a triangle
  (a step clipped to a hair before a jump, then below `dtmin`): solve, and agree with the PWM-synchronous grid;
- a 1 g payload with the switching valve: stiff; the message names payload_mass, the friction and Rodas5;
- a long PWM run: the default step budget grows with the horizon; an explicit small budget is named with the budget
  the run needs, and that budget suffices."""

import re

import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import PamjaxSolveError, presets
from pamjax._solve_hints import default_max_steps


@pytest.mark.parametrize("signal, horizon", [(pamjax.Constant(0.0), 2.5), (pamjax.Constant(1.0), 2.5),
                                             (pamjax.Triangle(0.05, 0.95, 0.25), 5.2)], ids=["duty 0", "duty 1",
                                                                                              "triangle"])
def test_exact_edge_valve_solves_at_every_duty(signal, horizon):
    ts = jnp.linspace(0.0, horizon, int(horizon * 20) + 1)
    exact = pamjax.simulate(presets.mas10_system("exact"), signal, ts)
    grid = pamjax.simulate(presets.mas10_system("exact"), signal, ts, stepping="pwm")  # exact edges, fixed steps
    assert bool(exact.succeeded)
    # Both integrate the exact-edge valve; 0.2 mm bounds the adaptive solve's rtol = 1e-6 plus the grid's K = 16.
    # Compared after the first second: at duty 1 the adaptive model's valve is open from t = 0, the grid's opens
    # after its 2 ms switching delay (it carries the valve state across periods), 1.2 mm apart for ~0.2 s.
    later = np.asarray(ts) >= 1.0
    np.testing.assert_allclose(exact.position[later], grid.position[later], rtol=0, atol=2e-4)


def test_a_stiff_payload_is_named_with_the_solver_that_handles_it():
    system = presets.mas10_system("pwm", payload_mass=1e-3)  # 1 g: legal, and stiff against 16 N of friction
    ts = jnp.linspace(0.0, 0.5, 11)
    with pytest.raises(PamjaxSolveError) as info:
        pamjax.simulate(system, pamjax.Constant(0.5), ts, max_steps=20_000)
    message = str(info.value)
    assert "The system is stiff: its fastest mode (mostly the velocity)" in message
    assert "payload_mass = 0.001 kg" in message and "Pass solver=pamjax.Rodas5()" in message
    assert "Try increasing `max_steps`" not in message  # the old, wrong advice
    traj = pamjax.simulate(system, pamjax.Constant(0.5), ts, solver=pamjax.Rodas5(), max_steps=20_000)
    assert bool(traj.succeeded) and np.all(np.isfinite(np.asarray(traj.position)))


def test_the_fixed_grid_names_the_substeps_a_stiff_system_needs():
    system = presets.mas10_system("pwm", payload_mass=1e-3)
    with pytest.raises(PamjaxSolveError, match=r"substeps >= [\d,]+ would be stable, too many: use "
                                               r"stepping='adaptive' with solver=pamjax\.Rodas5\(\)"):
        pamjax.simulate(system, pamjax.Constant(0.5), jnp.linspace(0.0, 0.1, 3), stepping="pwm")


def test_the_step_budget_grows_with_the_horizon_and_a_small_one_is_named_with_what_suffices():
    pwm, averaged = presets.mas10_system("pwm"), presets.mas10_system("averaged")
    assert default_max_steps(pwm, 0.0, 25.0) == 200_000  # paper 000's runs keep the old budget (one compilation)
    assert default_max_steps(pwm, 0.0, 1000.0) >= 64 * 50 * 1000  # 50,000 PWM periods
    assert default_max_steps(averaged, 0.0, 1000.0) >= 1000 * 1000
    ts = jnp.linspace(0.0, 8.0, 9)
    with pytest.raises(PamjaxSolveError) as info:
        pamjax.simulate(pwm, pamjax.Constant(0.5), ts, max_steps=2_000)
    message = str(info.value)
    assert "stiff" not in message and "or stepping='pwm'" in message
    needed = int(re.search(r"pass max_steps=([\d,]+)", message).group(1).replace(",", ""))
    assert needed > 2_000
    assert bool(pamjax.simulate(pwm, pamjax.Constant(0.5), ts, max_steps=needed).succeeded)  # the advice suffices


@pytest.mark.slow
def test_a_thousand_second_pwm_run_solves_with_the_default_budget():
    traj = pamjax.simulate(presets.mas10_system("pwm"), pamjax.Constant(0.5), jnp.linspace(0.0, 1000.0, 11))
    assert bool(traj.succeeded) and int(traj.num_steps) > 200_000  # beyond the old fixed budget
    assert 0.02 < float(traj.position[-1]) < 0.07  # settled mid-stroke at duty 0.5 (m)
