"""Closed-loop control (issue 6): PI and sliding mode controllers, the sampled-data loop, gradient tuning.

Oracles: a NumPy transcription of the clamped discrete PI; the closed-form quadratic root of eq. 13; an open-loop
`simulate` replay of the duties the closed loop chose; central finite differences for the gain gradient. Horizons are
short (≤ 1.5 s) to keep the suite fast.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import initial_state

import pamjax
from pamjax import presets
from pamjax._control.closed_loop import ClosedLoop, run_closed_loop, simulate_closed_loop
from pamjax._control.controllers import PIController, SlidingModeController, equivalent_duty, reference_derivatives
from pamjax._control.tuning import tracking_rmse

REF = pamjax.Sine(0.03, 0.01, 1.0 / (2 * np.pi))  # paper 000: 0.03 + 0.01 sin(t) m

# Called eagerly, each operation of these compiles a program of its own: jitted once, the times, duties and pressures
# as array arguments (a Python float would be a constant of the program).
_mass_flow = eqx.filter_jit(lambda valve, u, p, air: valve.mass_flow(0.0, u, p, air))
_equivalent_duty = eqx.filter_jit(equivalent_duty)
_reference_derivatives = eqx.filter_jit(reference_derivatives)
_tracking_error = eqx.filter_jit(lambda traj, start: traj.tracking_error(start))


@pytest.fixture(scope="module")
def plant():
    return presets.mas10_system("pwm")


@pytest.fixture(scope="module")
def model():
    return presets.mas10_system("averaged")


def numpy_pi(errors, kp, ki, u0, period):
    """Independent transcription of a clamped (conditional-integration) discrete PI."""
    integral, duties = 0.0, []
    for e in errors:
        candidate = integral + period * e
        raw = u0 + kp * e + ki * candidate
        if not ((raw > 1 and e > 0) or (raw < 0 and e < 0)):
            integral = candidate
        duties.append(min(max(u0 + kp * e + ki * integral, 0.0), 1.0))
    return np.array(duties)


def test_pi_matches_numpy_transcription():
    rng = np.random.default_rng(0)
    errors = np.concatenate([rng.normal(0, 0.01, 50), np.full(30, 0.05), np.full(30, -0.05)])  # incl. saturation
    pi = PIController()
    update = eqx.filter_jit(pi.update)  # one program for the 110 updates (eagerly, each operation compiles its own)
    state, duties = pi.initial_state(), []
    plant_state = initial_state(presets.mas10_system("pwm"))
    for e in errors:
        ps = eqx.tree_at(lambda s: s.position, plant_state, np.asarray(0.03 - e))
        duty, state = update(0.0, (jnp.asarray(0.03),), ps, state, 0.02)
        duties.append(float(duty))
    np.testing.assert_allclose(duties, numpy_pi(errors, 25.0, 150.0, 0.5, 0.02), rtol=0, atol=1e-12)
    assert min(duties) == 0.0 and max(duties) == 1.0  # both saturations visited


def test_equivalent_duty_inverts_eq13(model):
    valve, air = model.valve, model.air
    for p in (1.2e5, 3e5, 5e5):
        for u in (0.05, 0.3, 0.7, 0.95):
            flow = _mass_flow(valve, np.asarray(u), np.asarray(p), air)
            assert abs(float(_equivalent_duty(valve, flow, np.asarray(p), air)) - u) < 1e-9
        # Out of reach: saturates, never NaN.
        assert float(_equivalent_duty(valve, np.asarray(1.0), np.asarray(p), air)) == 1.0
        assert float(_equivalent_duty(valve, np.asarray(-1.0), np.asarray(p), air)) == 0.0


def test_reference_derivatives_of_sine():
    r = _reference_derivatives(REF, np.asarray(0.7))
    np.testing.assert_allclose(
        [float(a) for a in r],
        [0.03 + 0.01 * np.sin(0.7), 0.01 * np.cos(0.7), -0.01 * np.sin(0.7), -0.01 * np.cos(0.7)],
        rtol=1e-12,
    )


def test_closed_loop_equals_open_loop_replay(plant):
    """The plant inside the loop is the plant `simulate` integrates: replaying the chosen duties open loop (at tight
    tolerance) gives the same positions. Tolerance 0.05 mm: the loop integrates at rtol = atol = 1e-6 (scaled)."""
    # 1.5 s from the loop's own rest state, passed explicitly: the same run structure (PI, 75 periods, y0 given) as the
    # PI run of test_sliding_mode_beats_pi_on_switching_plant, so the module compiles that closed loop once
    loop = ClosedLoop(plant, PIController(), REF)
    traj = simulate_closed_loop(loop, 1.5, y0=initial_state(loop))
    signal = pamjax.Sampled(np.asarray(traj.period_start), np.asarray(traj.duty), period=0.02)
    ts = np.concatenate([[0.0], np.asarray(traj.t)])
    replay = pamjax.simulate(plant, signal, ts, rtol=1e-8, atol=1e-8, max_steps=100_000)
    assert int(traj.result) == 0
    np.testing.assert_allclose(np.asarray(replay.position)[1:], traj.position, atol=5e-5)


def test_sliding_mode_beats_pi_on_switching_plant(plant, model):
    """Started on the reference (pressure for x = 0.03 m), the SMC tracks the 1 rad/s sine with a smaller RMSE
    than the paper's PI over 1.5 s; both succeed. A broken equivalent control (sign or eq. 13 inverse) fails this."""
    y0 = initial_state(plant, pressure=np.asarray(4.3e5))
    errs = {}
    for name, ctl in (("pi", PIController()), ("smc", SlidingModeController(model))):
        loop = ClosedLoop(plant, ctl, REF)
        traj = simulate_closed_loop(loop, 1.5, y0=loop.initial_state(y0))
        errs[name] = float(_tracking_error(traj, np.asarray(0.5))[0])
        assert int(traj.result) == 0
    assert errs["smc"] < 0.5 * errs["pi"], errs


def test_gain_gradient_matches_finite_difference(plant):
    """d RMSE / d K_P through the whole sampled-data loop vs a central difference (rel. 2 %: the adaptive solver's
    step choices make the loss piecewise smooth at the 1e-6 tolerance level)."""
    y0 = initial_state(plant, pressure=np.asarray(4.3e5))

    def loss(kp):
        loop = ClosedLoop(plant, PIController(proportional_gain=kp), REF)
        return tracking_rmse(loop, 25, 0.0, y0=loop.initial_state(y0), samples_per_period=4, rtol=1e-8, atol=1e-8)

    # one compiled value-and-gradient for the gradient and both differences (eager calls re-trace the loop each time)
    value_and_grad = jax.jit(jax.value_and_grad(loss))
    grad = float(value_and_grad(jnp.asarray(25.0))[1])
    h = 0.5
    fd = (float(value_and_grad(jnp.asarray(25.0 + h))[0]) - float(value_and_grad(jnp.asarray(25.0 - h))[0])) / (2 * h)
    assert abs(grad - fd) <= 0.02 * abs(fd) + 1e-9, (grad, fd)


def test_vmap_over_plants_matches_loop(plant):
    masses = np.asarray([8.0, 11.0])
    plants = eqx.filter_jit(eqx.filter_vmap(lambda m: eqx.tree_at(lambda p: p.payload_mass, plant, m)))(masses)
    y0 = initial_state(plant, pressure=np.asarray(4.3e5))

    # jitted: eagerly, every call re-traces the loop's scan and compiles it anew (and each operation around it)
    @eqx.filter_jit
    def rmse(p):
        loop = ClosedLoop(p, PIController(), REF)
        return run_closed_loop(loop, 10, y0=loop.initial_state(y0)).tracking_error(0.0)[0]

    batched = eqx.filter_jit(eqx.filter_vmap(rmse))(plants)
    single = [rmse(eqx.tree_at(lambda p: p.payload_mass, plant, m)) for m in masses]
    np.testing.assert_allclose(batched, single, rtol=1e-6)


@pytest.mark.parametrize(
    "make",
    [
        lambda m: PIController(proportional_gain=-1.0),
        lambda m: PIController(integral_gain=-5.0),
        lambda m: PIController(duty_max=1.2),
        lambda m: PIController(duty_min=0.6, duty_max=0.4),
        lambda m: SlidingModeController(m, bandwidth=-1.0),
        lambda m: SlidingModeController(presets.mas10_system("pwm")),  # needs an averaged-valve model
    ],
)
def test_bad_controller_input_raises(make, model):
    with pytest.raises(pamjax.PamjaxInputError):
        make(model)


def test_bad_reference_and_plant_raise(plant):
    with pytest.raises(pamjax.PamjaxInputError, match="stroke"):
        simulate_closed_loop(ClosedLoop(plant, PIController(), pamjax.Sine(0.07, 0.02, 0.1)), 0.1)
    with pytest.raises(pamjax.PamjaxInputError, match="duration"):
        simulate_closed_loop(ClosedLoop(plant, PIController(), REF), -1.0)
    with pytest.raises(pamjax.PamjaxInputError, match="smooth"):  # exact edges run on the fixed grid, not adaptively
        ClosedLoop(presets.mas10_system("exact"), PIController(), REF, stepping="adaptive")


def test_a_second_tuning_compiles_nothing_new_and_starts_from_its_own_gains(model):
    """`tune_controller` of another loop of the same structure (other gains) reuses the first call's program (a
    closure jitted per call compiled anew each time, ~3.7 s), and each run's first RMSE is its own loop's."""
    from helpers import counted_compilations

    def loop(kp):
        return ClosedLoop(model, PIController(proportional_gain=kp), REF)

    pamjax.tune_controller(loop(25.0), ("proportional_gain",), 0.2, steps=1)
    with counted_compilations() as compiled:
        _, history = pamjax.tune_controller(loop(40.0), ("proportional_gain",), 0.2, steps=1)
    assert compiled == [], compiled
    assert history[0][1] == (40.0,)
    own = float(jax.jit(lambda: tracking_rmse(loop(40.0), 10, 0.0, samples_per_period=5))())
    assert history[0][0] == pytest.approx(own, rel=1e-9)


def test_error_window_at_or_after_the_end_raises(model):
    """A window start at or after the run's end left the window empty: RMSE 0/0 = NaN and a 0 peak, and
    `tune_controller` ran every step on NaN. Refused, naming `start` and the run's end; a start inside still works."""
    traj = simulate_closed_loop(ClosedLoop(model, PIController(), REF), 0.1)  # 5 periods: ends at 0.1 s
    for start in (0.1, 5.0):
        with pytest.raises(pamjax.PamjaxInputError, match=r"start = .* 0\.1 s"):
            traj.tracking_error(start=start)
    # the last period starts at 0.08 s: a later start leaves no period start in estimation_error's window
    for start in (0.09, 5.0):
        with pytest.raises(pamjax.PamjaxInputError, match=r"start = .* 0\.1 s"):
            traj.estimation_error(start)
    rmse, peak = traj.tracking_error(start=0.095)
    assert np.isfinite(float(rmse)) and float(peak) > 0
    assert all(np.isfinite(float(v)) for v in traj.estimation_error(0.08).values())
    from helpers import counted_compilations

    loop = ClosedLoop(model, PIController(), REF)
    with counted_compilations() as compiled, pytest.raises(pamjax.PamjaxInputError, match=r"start = 5\.0 s.*0\.2 s"):
        pamjax.tune_controller(loop, ("proportional_gain",), 0.2, start=5.0, steps=1)
    assert compiled == [], compiled  # refused before any solve


def test_fits_control_refuses_a_duration_inside_the_window_and_describes_itself(monkeypatch, capsys):
    """`fits/control.py --duration 3` crashed with "All-NaN slice" (every figure is over t >= 5 s); now an argparse
    error names --duration. Its --help showed the docstring's first line, cut mid-sentence; now the whole sentence."""
    import importlib.util
    import pathlib
    import sys

    path = pathlib.Path(__file__).resolve().parents[1] / "fits" / "control.py"
    spec = importlib.util.spec_from_file_location("fits_control_under_test", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    monkeypatch.setattr(sys, "argv", ["control.py", "--duration", "3", "--out", "unused"])
    with pytest.raises(SystemExit) as exit_info:
        script.main()
    assert exit_info.value.code == 2 and "--duration" in capsys.readouterr().err
    monkeypatch.setattr(sys, "argv", ["control.py", "--help"])
    with pytest.raises(SystemExit):
        script.main()
    assert "the SMC fed by an extended Kalman filter from the bench's noisy sensors." in " ".join(
        capsys.readouterr().out.split())


def test_a_period_other_than_the_switching_valves_is_refused_whatever_the_stepping(plant, model):
    """The smoothed PWM valve (stepping "adaptive") latches one duty per 20 ms PWM period: a 10 ms controller period
    was accepted and every second duty silently dropped (only stepping "pwm" checked it). Refused with the same
    message; the valve's own period, and any period of an averaged valve, still work."""
    assert ClosedLoop(plant, PIController(), REF).stepping == "adaptive"
    for stepping in ("auto", "adaptive", "pwm"):
        with pytest.raises(pamjax.PamjaxInputError, match=r"ClosedLoop\.period \(0\.01 s\) must be the valve's PWM"):
            ClosedLoop(plant, PIController(), REF, period=0.01, stepping=stepping)
    assert float(ClosedLoop(plant, PIController(), REF, period=0.02).period) == 0.02
    assert float(ClosedLoop(model, PIController(), REF, period=0.01).period) == 0.01


@pytest.mark.parametrize("kwargs, match", [
    (dict(rtol=-1.0), "rtol must be a finite number > 0"),
    (dict(rtol=np.nan), "rtol must be a finite number > 0"),
    (dict(atol=0.0), "atol must be a finite number > 0"),
    (dict(max_steps=0), "max_steps must be an int >= 1"),
    (dict(max_steps=10.5), "max_steps must be an int >= 1"),
])
def test_simulate_closed_loop_refuses_bad_solver_settings(plant, kwargs, match):
    """`rtol=-1` ran silently; `atol=0` and `max_steps=0` returned inf positions with only `result` 1. Refused before
    any solve, as `pamjax.simulate` refuses them."""
    from helpers import counted_compilations

    loop = ClosedLoop(plant, PIController(), REF)
    with counted_compilations() as compiled, pytest.raises(pamjax.PamjaxInputError, match=match):
        simulate_closed_loop(loop, 0.1, **kwargs)
    assert compiled == [], compiled


def test_tune_controller_refuses_bad_settings_before_any_solve(model):
    """`steps=-1` returned [] (then `fits/control.py` failed on history[0]), `samples_per_period=0` a raw IndexError,
    a gain that is no float parameter (the SMC's `model`, the PID's static `seed`) raw TypeErrors, a NaN learning rate
    ran on. Each refused, naming the argument, before any solve."""
    from helpers import counted_compilations

    from pamjax._control.pid import PIDController

    loop = ClosedLoop(model, PIController(), REF)
    cases = [
        (loop, ("proportional_gain",), dict(steps=-1), "steps must be an int >= 0"),
        (loop, ("proportional_gain",), dict(steps=1.5), "steps must be an int >= 0"),
        (loop, ("proportional_gain",), dict(samples_per_period=0), "samples_per_period must be an int >= 1"),
        (loop, ("proportional_gain",), dict(learning_rate=float("nan")), "learning_rate must be a finite number > 0"),
        (loop, ("proportional_gain",), dict(learning_rate=-0.1), "learning_rate must be a finite number > 0"),
        (loop, ("no_such_gain",), {}, r"gain 'no_such_gain' must name a positive, real-valued parameter"),
        (loop, "proportional_gain", {}, "gains must be a non-empty tuple"),
        (ClosedLoop(model, SlidingModeController(model), REF), ("model",), {},
         r"gain 'model' must name a positive, real-valued parameter of the SlidingModeController, got MuscleSystem"),
        (ClosedLoop(model, PIDController(seed=3), REF), ("seed",), {},
         r"gain 'seed' must name a positive, real-valued parameter of the PIDController"),
    ]
    with counted_compilations() as compiled:
        for lp, gains, kwargs, match in cases:
            with pytest.raises(pamjax.PamjaxInputError, match=match):
                pamjax.tune_controller(lp, gains, 0.1, **kwargs)
    assert compiled == [], compiled


def test_fits_control_refuses_negative_tune_steps(monkeypatch, capsys, tmp_path):
    """`fits/control.py --tune-steps -1` ran every simulation, then crashed with an IndexError on the tuning's empty
    history; now an argparse error names --tune-steps before any work."""
    import importlib.util
    import pathlib
    import sys

    path = pathlib.Path(__file__).resolve().parents[1] / "fits" / "control.py"
    spec = importlib.util.spec_from_file_location("fits_control_tune_steps", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "out"
    monkeypatch.setattr(sys, "argv", ["control.py", "--tune-steps", "-1", "--out", str(out)])
    with pytest.raises(SystemExit) as exit_info:
        script.main()
    assert exit_info.value.code == 2 and "--tune-steps" in capsys.readouterr().err
    assert not out.exists()
