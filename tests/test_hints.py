"""Legal inputs that once failed with a hint blaming `max_steps` (issue 15): they solve, or fail with the real cause
and the setting that fixes it (`pamjax._solve.hints`), and following that advice works.

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
from pamjax._solve.hints import default_max_steps


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


# -- advice that cannot work is never given (issue 33) ----------------------------------------------------------
def test_negative_inflow_is_named_instead_of_a_step_the_run_already_takes():
    # a model file with a valve coefficient's sign flipped: the run failed with "pass grid_step=0.076 or less" at
    # grid_step=0.001, which cannot help: the valve empties the chamber below zero pressure whatever the step
    import equinox as eqx

    system = presets.mas10_system("averaged", friction="karnopp")
    flipped = eqx.tree_at(lambda s: s.valve.coefficients, system, system.valve.coefficients.at[1, 0].set(-0.0017))
    ts = jnp.linspace(0.0, 2.0, 21)
    with pytest.raises(PamjaxSolveError) as info:
        pamjax.simulate(flipped, pamjax.Triangle(0.05, 0.95, 0.25), ts)
    text = str(info.value)
    assert "takes air OUT of the chamber" in text and "negative inflow" in text and "valve.coefficients" in text
    assert "grid_step=0.0" not in text.replace("grid_step=0.001)", "")  # no smaller step is offered
    assert bool(pamjax.simulate(system, pamjax.Triangle(0.05, 0.95, 0.25), ts).succeeded)  # the sign put back
    # over 0.5 s the same model "succeeded" at 6,600 Pa abs: a chamber emptied below half an atmosphere fails too
    short = jnp.linspace(0.0, 0.5, 51)
    with pytest.raises(PamjaxSolveError, match="below half an atmosphere: the valve takes air OUT"):
        pamjax.simulate(flipped, pamjax.Triangle(0.05, 0.95, 0.25), short)
    traj = pamjax.simulate(flipped, pamjax.Triangle(0.05, 0.95, 0.25), short, throw=False)
    assert int(traj.result) != 0 and np.all(np.isnan(np.asarray(traj.pressure)))


def test_a_suggested_fixed_step_works_when_applied():
    # a 1 ml tank (a pressure time constant far below the 10 ms step) on the PWM grid with 2 substeps; both remedies
    # the message offers work
    system = presets.mas10_tank_system("pwm", volume=1e-6)
    ts = jnp.linspace(0.0, 0.2, 11)
    with pytest.raises(PamjaxSolveError) as info:
        pamjax.simulate(system, pamjax.Constant(0.5), ts, stepping="pwm", substeps=2)
    text = str(info.value)
    suggested = int(re.search(r"pass substeps=([\d,]+) or more", text).group(1).replace(",", ""))
    assert suggested > 2
    assert bool(pamjax.simulate(system, pamjax.Constant(0.5), ts, stepping="pwm", substeps=suggested).succeeded)
    assert "stepping='adaptive' with solver=pamjax.Rodas5()" in text
    assert bool(pamjax.simulate(system, pamjax.Constant(0.5), ts, stepping="adaptive",
                                solver=pamjax.Rodas5()).succeeded)


def test_a_hybrid_system_is_never_told_to_use_adaptive_stepping():
    # stick-slip friction has no adaptive solve (refused); the grid's advice is a finer grid, and it works
    system = presets.mas10_system("averaged", friction="karnopp", payload_mass=0.05)
    ts = jnp.linspace(0.0, 0.2, 11)
    with pytest.raises(PamjaxSolveError) as info:
        pamjax.simulate(system, pamjax.Constant(0.5), ts, grid_step=0.02)
    text = str(info.value)
    assert "stepping='adaptive'" not in text
    step = float(re.search(r"pass grid_step=([\d.e-]+) or less", text).group(1))
    assert step < 0.02
    assert bool(pamjax.simulate(system, pamjax.Constant(0.5), ts, grid_step=step).succeeded)


def test_a_friction_states_rate_once_moving_is_in_the_suggested_step():
    # Bristle friction's state relaxes at σ0|v|/F_c: zero at rest, ~1,900 1/s at 0.3 m/s. The PWM grid's 16 substeps
    # blew up once the payload moved, and the hint, reading the modes at the start (at rest), said "not a step-size
    # problem: check the model's parameters". It now reads them moving too, and its step works.
    system = presets.mas10_system(valve="exact", friction="bristle")
    ts = jnp.linspace(0.0, 0.6, 31)
    with pytest.raises(PamjaxSolveError) as info:
        pamjax.simulate(system, pamjax.Constant(1.0), ts, stepping="pwm")
    text = str(info.value)
    assert "not a step-size problem" not in text and "once the payload moves" in text
    suggested = int(re.search(r"pass substeps=([\d,]+) or more", text).group(1).replace(",", ""))
    assert bool(pamjax.simulate(system, pamjax.Constant(1.0), ts, stepping="pwm", substeps=suggested).succeeded)
