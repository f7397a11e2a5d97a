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


def test_simulate_closed_loop_runs_the_parameter_checks_simulate_runs(model):
    """A plant or controller changed with `eqx.tree_at` skipped its constructor's checks, and `simulate_closed_loop`
    ran none of `simulate`'s: payload_mass = -9.6 returned inf positions, duty limits (-0.5, 1.5) fed the valve a
    duty of 1.5. Refused by name before any solve, as `simulate` refuses them."""
    from helpers import counted_compilations

    bad_plant = eqx.tree_at(lambda lp: lp.plant.payload_mass, ClosedLoop(model, PIController(), REF), -9.6)
    bad_limits = ClosedLoop(model, eqx.tree_at(lambda c: (c.duty_min, c.duty_max), PIController(), (-0.5, 1.5)), REF)
    with counted_compilations() as compiled:
        with pytest.raises(pamjax.PamjaxInputError, match=r"payload_mass must be > 0 and finite, got -9\.6"):
            simulate_closed_loop(bad_plant, 0.1)
        with pytest.raises(pamjax.PamjaxInputError, match=r"PIController\.duty_min must be in \[0, 1\].*-0\.5"):
            simulate_closed_loop(bad_limits, 0.1)
        with pytest.raises(pamjax.PamjaxInputError, match=r"payload_mass must be > 0"):  # tuning checks it too
            pamjax.tune_controller(bad_plant, ("proportional_gain",), 0.1)
    assert compiled == [], compiled


def test_tune_controller_refuses_duty_limits_and_bias_and_tunes_integer_gains(model):
    """Tuning ("duty_max",) moved it from 0.9 to 2.99 (Adam on its logarithm knows no upper bound): the duty limits
    and the bias are refused as no gains. Integer gains (PIController(proportional_gain=30), which the controller
    and the loop take) were refused as not "real-valued": tuned as floats."""
    from helpers import counted_compilations

    loop = ClosedLoop(model, PIController(duty_max=0.9), REF)
    with counted_compilations() as compiled:
        for name in ("duty_max", "duty_min", "bias"):
            with pytest.raises(pamjax.PamjaxInputError, match=rf"'{name}' is no gain: the duty limits are bounds in"):
                pamjax.tune_controller(loop, ("proportional_gain", name), 0.2, steps=1)
        # a PID's sensor noise was "tuned" down (a better sensor, not a better controller): refused as the others
        noisy = ClosedLoop(model, pamjax.PIDController(measurement_noise=1e-4), REF)
        for name in ("measurement_noise", "sample_time"):
            with pytest.raises(pamjax.PamjaxInputError, match=rf"'{name}' is no gain: the sensor's noise and sampling"):
                pamjax.tune_controller(noisy, ("proportional_gain", name), 0.2, steps=1)
    assert compiled == [], compiled
    integer = ClosedLoop(model, PIController(proportional_gain=30), REF)
    tuned, history = pamjax.tune_controller(integer, ("proportional_gain",), 0.2, steps=1)
    assert history[0][1] == pytest.approx((30.0,), rel=1e-12) and all(np.isfinite(rmse) for rmse, _ in history)
    assert jnp.issubdtype(tuned.controller.proportional_gain.dtype, jnp.floating)


def test_simulate_closed_loop_checks_its_start_state(model):
    """`y0` ran unchecked: a plant pressure of 3.0 (bar) and a position of 30 (mm) gave inf, a NaN pressure inf, and
    a plain plant state a raw AttributeError. Refused as `simulate` refuses them in its y0 (named y0.plant...), a plant
    state with the way to make a loop state of it, before any solve."""
    from helpers import counted_compilations

    loop = ClosedLoop(model, PIController(), REF)
    cases = [
        (model.initial_state(pressure=3.0, position=0.0), r"y0\.plant\.pressure is 3 Pa at most: that looks like bar"),
        (model.initial_state(pressure=3e5, position=30.0), r"y0\.plant\.position = 30 m.*mm"),
        (model.initial_state(pressure=float("nan"), position=0.0), r"y0\.plant\.pressure must be finite"),
    ]
    starts = [(loop.initial_state(plant_state=plant_state), match) for plant_state, match in cases]
    plant_state = model.initial_state(pressure=3e5)
    late_duty = eqx.tree_at(lambda y: y.duty, loop.initial_state(), 1.5)
    with counted_compilations() as compiled:
        for y0, match in starts:
            with pytest.raises(pamjax.PamjaxInputError, match=match):
                simulate_closed_loop(loop, 0.1, y0=y0)
        with pytest.raises(pamjax.PamjaxInputError, match=r"y0 must be a ClosedLoopState .*got MuscleState.*"
                                                          r"loop\.initial_state\(plant_state=\.\.\.\)"):
            simulate_closed_loop(loop, 0.1, y0=plant_state)
        with pytest.raises(pamjax.PamjaxInputError, match=r"y0\.duty .* must be in \[0\.0, 1\.0\], got 1\.5"):
            simulate_closed_loop(loop, 0.1, y0=late_duty)
    assert compiled == [], compiled


def test_a_failed_closed_loop_solve_raises_and_a_period_in_ms_is_refused(model):
    """A period's failed solve (max_steps=5) returned inf positions with only `result` 1; `simulate` raises. Now a
    `PamjaxSolveError` names the first failed period and the fix; throw=False returns the trajectory with its status.
    A period of 20.0 (20 ms meant) ran 20 s on one duty: refused by magnitude."""
    loop = ClosedLoop(model, PIController(), REF)
    with pytest.raises(pamjax.PamjaxSolveError, match=r"period starting at t = 0 s: .*maximum number of .*steps.*"
                                                      r"Raise max_steps \(now 5 solver steps per period\)"):
        simulate_closed_loop(loop, 0.04, max_steps=5)
    traj = simulate_closed_loop(loop, 0.04, max_steps=5, throw=False)
    assert int(traj.result) != 0 and not np.all(np.isfinite(np.asarray(traj.position)))
    with pytest.raises(pamjax.PamjaxInputError, match=r"ClosedLoop\.period is 20\.0 s.*looks like milliseconds"):
        ClosedLoop(model, PIController(), REF, period=20.0)


def test_several_gains_or_durations_where_the_loop_takes_one_are_named(model):
    """A PI with proportional_gain = [25, 30] failed deep inside the solve ("incompatible shapes for broadcasting"),
    a duration np.array([1.0]) with a raw TypeError: refused, naming them, before any solve."""
    from helpers import counted_compilations

    pair = ClosedLoop(model, PIController(proportional_gain=np.array([25.0, 30.0])), REF)
    one = ClosedLoop(model, PIController(), REF)
    with counted_compilations() as compiled:
        with pytest.raises(pamjax.PamjaxInputError, match=r"one duty per period, its parameters proportional_gain "
                                                          r"\(shape \(2,\)\) hold several values"):
            simulate_closed_loop(pair, 0.1)
        with pytest.raises(pamjax.PamjaxInputError, match=r"duration must be a finite number > 0, got array"):
            simulate_closed_loop(one, np.array([0.1]))
    assert compiled == [], compiled


def test_a_sample_on_the_window_start_to_round_off_is_in_the_window(model):
    """The sample times are period starts plus offsets, a sum XLA fuses into an FMA in one program and not in another
    (0.18 + 0.02 = 0.19999999999999998, fused 0.2): with `t >= start` the sample on start = 0.2 s was in the value's
    window and not in the reverse-mode gradient's (tune_controller's gradient 0.29 % off forward mode and central
    differences, 25 periods of 20 ms, XLA's default flags). A sample one rounding before `start` is in the window now,
    as is the one on it; a sample before it is not."""
    traj = simulate_closed_loop(ClosedLoop(model, PIController(), REF), 0.1)  # t = 2, 4, ..., 100 ms
    t = np.asarray(traj.t)
    start = t[24]  # 50 ms, the end of the third period
    nudged = t.copy()
    nudged[24] = np.nextafter(start, 0.0)  # the same sample, its time one rounding lower
    exact = [float(v) for v in _tracking_error(traj, np.asarray(start))]
    assert [float(v) for v in _tracking_error(eqx.tree_at(lambda tr: tr.t, traj, jnp.asarray(nudged)),
                                              np.asarray(start))] == exact
    later = [float(v) for v in _tracking_error(traj, np.asarray(0.5 * (t[24] + t[25])))]
    e = np.asarray(traj.reference - traj.position)
    np.testing.assert_allclose(exact, [np.sqrt(np.mean(e[24:] ** 2)), np.max(np.abs(e[24:]))], rtol=1e-12)
    np.testing.assert_allclose(later, [np.sqrt(np.mean(e[25:] ** 2)), np.max(np.abs(e[25:]))], rtol=1e-12)


def test_a_gain_named_twice_or_a_start_state_of_another_plant_is_refused(plant):
    """tune_controller(("proportional_gain", "proportional_gain")) ran and reported two values for one gain; a start
    state of the identified plant (a stick-slip friction leaf) given to a loop on the smooth plant, or to `simulate`,
    failed with a raw pytree ValueError. Both refused by name before any solve."""
    from helpers import counted_compilations

    identified = presets.mas10_system("pwm", friction="karnopp")
    other = identified.initial_state()
    loop = ClosedLoop(plant, PIController(), REF)
    y0 = loop.initial_state(plant_state=other)
    wrong = (r"must be a state of the system \(MuscleSystem\): "
             r"a MuscleState with leaves \(pressure, position, velocity\)")
    with counted_compilations() as compiled:
        with pytest.raises(pamjax.PamjaxInputError, match=r"gains names 'proportional_gain' more than once"):
            pamjax.tune_controller(loop, ("proportional_gain", "proportional_gain"), 0.1)
        with pytest.raises(pamjax.PamjaxInputError, match=r"y0\.plant " + wrong + r".*got a MuscleState with leaves "
                                                          r"\(pressure, position, velocity, friction\)"):
            simulate_closed_loop(loop, 0.1, y0=y0)
        with pytest.raises(pamjax.PamjaxInputError, match=r"y0 " + wrong):
            pamjax.simulate(plant, pamjax.Constant(0.5), np.linspace(0.0, 0.1, 3), y0=other)
    assert compiled == [], compiled


def test_a_10_ms_period_runs_at_default_tolerances(model):
    """An averaged-valve loop at a 10 ms period failed from t = 0.06 s ("minimum step size reached", raising max_steps
    no help): diffrax's first step of a period solve is a fixed 0.01 s, which ended 1 ULP short of the period's end
    (0.06 + 0.01 < 0.07), and the 1.4e-17 s sliver to it fell below dtmin. It runs, and agrees with a tight solve."""
    loop = ClosedLoop(model, PIController(), REF, period=0.01)
    default, tight = (simulate_closed_loop(loop, 0.1, rtol=tol, atol=tol)  # arrays: one program for both
                      for tol in (np.asarray(1e-6), np.asarray(1e-9)))
    assert int(default.result) == 0 and int(tight.result) == 0
    np.testing.assert_allclose(default.position, tight.position, rtol=0, atol=1e-6)


def test_tune_controller_refuses_what_simulate_closed_loop_refuses(model):
    """tune_controller skipped simulate_closed_loop's checks of the loop: a reference outside the stroke (0.5 m, or
    mm typed as m) was tuned on silently (RMSE of metres, zero gradient, gains unchanged), a PI whose integral gain
    holds two values failed with a raw JAX TypeError. Refused as simulate_closed_loop refuses them, before any solve."""
    from helpers import counted_compilations

    two = ClosedLoop(model, PIController(integral_gain=jnp.array([150.0, 100.0])), REF)
    with counted_compilations() as compiled:
        for reference in (pamjax.Constant(0.5), pamjax.Sine(30.0, 10.0, 0.2)):
            with pytest.raises(pamjax.PamjaxInputError, match=r"reference must stay inside the muscle's stroke"):
                pamjax.tune_controller(ClosedLoop(model, PIController(), reference), ("proportional_gain",), 0.1)
        with pytest.raises(pamjax.PamjaxInputError, match=r"one duty per period, its parameters integral_gain"):
            pamjax.tune_controller(two, ("proportional_gain",), 0.1)
    assert compiled == [], compiled


def test_equivalent_duty_names_a_missing_air_and_a_string_flow_and_a_loop_one_period(model):
    """equivalent_duty(valve, 1e-3, 3e5, None) was a raw AttributeError, mass_flow="1e-3" a raw TypeError; a
    ClosedLoop with period=[0.02, 0.01] was built, and simulate_closed_loop then blamed its controller for giving
    several duties. Each named."""
    valve = model.valve
    with pytest.raises(pamjax.PamjaxInputError, match=r"equivalent_duty: air must be .*Air.*got NoneType"):
        equivalent_duty(valve, 1e-3, 3e5, None)
    with pytest.raises(pamjax.PamjaxInputError, match=r"equivalent_duty: mass_flow must be a real number .*'1e-3'"):
        equivalent_duty(valve, "1e-3", 3e5, model.air)
    with pytest.raises(pamjax.PamjaxInputError, match=r"equivalent_duty: pressure must be a real number"):
        equivalent_duty(valve, 1e-3, "3e5", model.air)
    with pytest.raises(pamjax.PamjaxInputError, match=r"ClosedLoop\.period must be one number \[s\].*shape \(2,\)"):
        ClosedLoop(model, PIController(), REF, period=jnp.array([0.02, 0.01]))
