"""`sweep`: equals a loop of `simulate`; per-point status; reductions; chunking; bad input.

References are independent: each point is re-simulated with `simulate` (adaptive Tsit5, tight tolerances), and the
reductions are recomputed with NumPy from whole trajectories.
"""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import pamjax
from pamjax import presets
from pamjax._sweep.reductions import FinalValue, FourierCoefficient, WindowMean
from pamjax._sweep.sweep import sweep

TS = np.linspace(0.0, 1.0, 21)


@eqx.filter_jit
def _initial_state(system, pressure):
    """`system.initial_state(pressure=...)` as one program (system and pressure its arguments): eagerly, its
    equilibrium solve compiles some forty one-operation programs."""
    return system.initial_state(pressure=pressure)


def _reference(system, duty, ts, pressure=None):
    """The independent reference: `simulate` (adaptive, rtol = atol = 1e-10) from `system.initial_state(pressure)`
    (atmospheric by default, as `simulate`'s own default y0), passed explicitly and on output grids of TS's length
    so that this module's references on the averaged MAS-10 share one compiled solve."""
    p0 = system.air.atmospheric_pressure if pressure is None else pressure
    y0 = _initial_state(system, jnp.asarray(p0, dtype=float))
    # np.float64: the duty strongly typed whether given as a Python or a NumPy number (one argument type)
    return pamjax.simulate(system, pamjax.Constant(np.float64(duty)), ts, y0=y0, rtol=1e-10, atol=1e-10)


@pytest.fixture(scope="module")
def averaged():
    return presets.mas10_system(valve="averaged")


@pytest.mark.parametrize("method", ["ros2", "rk4"])
def test_sweep_equals_loop_of_simulate(averaged, method):
    duties = np.array([0.2, 0.5, 0.8])
    masses = np.array([5.0, 9.6, 12.0])
    result = sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": duties, "payload_mass": masses},
                   method=method, channels=("pressure", "position"))
    assert result.method == method and np.all(result.succeeded)
    for i, (u, m) in enumerate(zip(duties, masses)):
        # float(m): a Python number, weakly typed in the system as the preset's default mass is (a NumPy scalar
        # would be strongly typed, a different argument type, and the reference solve would compile again)
        ref = _reference(presets.mas10_system(valve="averaged", payload_mass=float(m)), u, TS)
        if method == "rk4":  # at its stability limit (~1.5 ms) RK4 resolves the stick-slip transients: < 0.1 um
            # here (0.34 um at duties 0.9-1.0, docs/sweeps.md); the default step's check keeps that step (2.5/λ of
            # the lightest payload's friction, λ ≈ 16/(1e-3 · 5) /s)
            assert result.dt > 0.9 * 2.5 / (16.0 / (1e-3 * 5.0))
            np.testing.assert_allclose(result["position"][i], ref.position, rtol=0, atol=1e-7)
            np.testing.assert_allclose(result["pressure"][i], ref.pressure, rtol=0, atol=0.1)
        else:  # ROS2 at 5 ms smears the transients (tens of um); once settling the error shrinks (2 um at 1 s)
            np.testing.assert_allclose(result["position"][i, -1], ref.position[-1], rtol=0, atol=1e-5)
            np.testing.assert_allclose(result["pressure"][i, -1], ref.pressure[-1], rtol=0, atol=10.0)


@pytest.mark.parametrize("method", ["rodas5a", "rk4", "adaptive"])
def test_a_step_commands_jump_is_a_step_boundary(averaged, method):
    """A `Step`'s jump was stepped over (and a step ending on it read the command after it): Step(0.3, 0.8, t) on the
    averaged MAS-10 was 815 Pa and 34 um off a tight `simulate` with "rodas5a" (the jump on an output time), 2.2 kPa
    and 94 um with "rk4", 17 Pa with "adaptive", status 0. Each lane's jump is now a step boundary, as `simulate`'s."""
    times = np.array([0.2, 0.2123])  # on an output time of TS, and between two
    result = sweep(averaged, pamjax.Step(0.3, 0.8, 0.5), TS, {"signal.time": times}, method=method,
                   dt=1.5e-3 if method == "rk4" else None, channels=("pressure", "position"), progress=False)
    assert np.all(result.succeeded)
    for i, t in enumerate(times):
        ref = pamjax.simulate(averaged, pamjax.Step(0.3, 0.8, np.float64(t)), TS, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(result["pressure"][i], ref.pressure, rtol=0, atol=5.0)
        np.testing.assert_allclose(result["position"][i], ref.position, rtol=0, atol=5e-7)


@pytest.mark.parametrize("period", [None, 0.05])
def test_a_swept_sampled_tables_hold_changes_are_step_boundaries(averaged, period):
    """A sweep's lanes receive a `Sampled` table traced, and its hold changes were then no step boundaries: a factory
    scaling a 4-sample duty table on the averaged MAS-10 was 0.16 kPa off a tight `simulate` with "rodas5a", 0.93 kPa
    latched per period, status 0. Every time a traced table's held value may change (with `period`: the instant the
    latch reads the period's sample) is now one, as a swept `Step`'s time is."""
    times, base = np.array([0.0, 0.33, 0.61, 0.87]), np.array([0.9, 0.2, 0.8, 0.3])
    scales = np.array([0.6, 1.0])
    result = sweep(averaged, lambda v: pamjax.Sampled(times, base * v["scale"], period=period), TS,
                   {"scale": scales}, method="rodas5a", channels=("pressure", "position"), progress=False)
    assert np.all(result.succeeded)
    for i, scale in enumerate(scales):
        ref = pamjax.simulate(averaged, pamjax.Sampled(times, base * scale, period=period), TS, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(result["pressure"][i], ref.pressure, rtol=0, atol=10.0)
        np.testing.assert_allclose(result["position"][i], ref.position, rtol=0, atol=1e-6)


def test_the_step_cap_of_a_periodic_signal_reads_each_points_signal(averaged):
    """The 1/100-of-a-period cap read the frequency from a swept key named "frequency" only: a factory reading "f"
    took ROS2's 5 ms default at 20 Hz (7.7 kPa off a tight `simulate` at 8 Hz, status 0). Each point's signal's own
    `cycle_frequency()` now sets it, whatever the key."""
    result = sweep(averaged, lambda v: pamjax.Sine(0.5, 0.3, v["f"]), np.linspace(0.0, 0.1, 3),
                   {"f": np.array([8.0, 20.0])}, method="ros2", channels=("pressure",), progress=False)
    assert result.dt <= 1.0 / (100 * 20.0) * (1 + 1e-9)


def test_the_default_rk4_step_is_checked_against_its_half():
    """RK4's default step, its stability limit on the Jacobians at the initial states, missed a plant that stiffens
    as it moves: the averaged valve filling the MAS-10's test tank (its flow stiffens as the pressure nears the
    supply) took the output spacing, 50 ms, and was 7 kPa off a tight `simulate` at duty 1, status 0 (paper 001's
    VPPM-regulated DMSP-40: 9.3 kPa). The default is now halved until RK4 at it and at half of it agree."""
    tank = presets.mas10_tank_system(valve="averaged")
    duties = np.array([0.3, 1.0])
    result = sweep(tank, pamjax.Constant(0.5), TS, {"signal.value": duties}, method="rk4", channels=("pressure",),
                   progress=False)
    assert np.all(result.succeeded) and result.dt < 0.05
    for i, u in enumerate(duties):
        ref = pamjax.simulate(tank, pamjax.Constant(np.float64(u)), TS, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(result["pressure"][i], ref.pressure, rtol=0, atol=100.0)


def test_rodas5a_rejects_a_step_across_a_velocity_reversal(averaged):
    """The default "rodas5a" accepted steps through the payload's velocity reversals that were thousands of times its
    tolerance off: the Jacobian at the sliding start has none of the friction's stiffness (~1,700 /s in its 1 mm/s
    band), the last three stages (all at the step's end) settle on the same wrong value, and the embedded estimate
    they give is small. Under these sines (outputs every 20 ms) the lanes were 49 and 23 um, 243 and 118 Pa off a
    tight `simulate`, status 0 (64.5 um and 237 Pa over 8 s under a 2.6 Hz sine). Each step's midpoint defect is now
    checked too (`pamjax._solve.rodas.rodas5_step_defect`): 0.06 um and 0.4 Pa."""
    ts = np.linspace(0.0, 0.4, 21)
    offsets, amplitudes, frequencies = np.array([0.634, 0.566]), np.array([0.281, 0.267]), np.array([6.665, 7.034])
    result = sweep(averaged, pamjax.Sine(0.5, 0.1, 1.0), ts, {"signal.offset": offsets, "signal.amplitude": amplitudes,
                   "signal.frequency": frequencies}, channels=("pressure", "position"), progress=False)
    assert result.method == "rodas5a" and np.all(result.succeeded)
    for i, (offset, amplitude, frequency) in enumerate(zip(offsets, amplitudes, frequencies)):
        ref = pamjax.simulate(averaged, pamjax.Sine(offset, amplitude, frequency), ts, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(result["position"][i], ref.position, rtol=0, atol=1e-6)
        np.testing.assert_allclose(result["pressure"][i], ref.pressure, rtol=0, atol=5.0)


def test_error_controlled_ros2_settles_on_the_steady_state(averaged):
    """method="ros2a" (per-lane error control, rtol = atol = 1e-3 on the scaled state) is for steady-state maps: after
    5 s it is within tens of Pa and um of a tight adaptive solve (its local error per step is 1e-3 of the state scale:
    100 Pa, 10 um); the slowly creeping friction state keeps some duties from settling exactly."""
    duties = np.array([0.05, 0.3, 0.6, 0.95])
    ts = np.linspace(0.0, 5.0, 11)
    result = sweep(averaged, pamjax.Constant(0.5), ts, {"signal.value": duties}, method="ros2a",
                   channels=("pressure", "position"), reduce=FinalValue())
    assert result.method == "ros2a" and np.all(result.succeeded)
    ts_ref = np.linspace(0.0, 5.0, TS.size)  # the reference's final state at 5 s does not depend on its output grid
    for i, u in enumerate(duties):
        ref = _reference(averaged, u, ts_ref)
        assert abs(result["pressure"][i] - float(ref.pressure[-1])) < 50.0
        assert abs(result["position"][i] - float(ref.position[-1])) < 5e-5


def test_pwm_sweep_and_grid_shape():
    system = presets.mas10_system(valve="pwm")
    ts = np.linspace(0.0, 0.3, 7)
    duties, supplies = np.array([0.3, 0.7]), np.array([5e5, 6.5e5, 7e5])
    result = sweep(system, pamjax.Constant(0.5), ts,
                   {"signal.value": duties[:, None], "valve.supply_pressure": supplies[None, :]},
                   channels=("pressure",))
    assert result.method == "rk4" and result["pressure"].shape == (2, 3, 7)
    for i, j in [(0, 0), (1, 2)]:
        valve = presets.mas10_valve()
        sys_ij = pamjax.MuscleSystem(valve=type(valve)(**{**valve.__dict__, "supply_pressure": supplies[j]}),
                                     muscle=system.muscle, friction=system.friction)
        ref = pamjax.simulate(sys_ij, pamjax.Constant(duties[i]), ts, rtol=1e-10, atol=1e-10, max_steps=10**6)
        # RK4 at 5 edge widths (0.5 ms): a few Pa (benchmarks/RESULTS.md, ## sweep)
        np.testing.assert_allclose(result["pressure"][i, j], ref.pressure, rtol=0, atol=20.0)


def test_a_pwm_sweep_latches_the_duty_pair_as_simulate_does():
    # The smoothed PWM valve's fixed-step lanes read one duty as held over both periods: at duty 0.95 the first
    # period started open (simulate: the valve is off before the run) and a period after one above 90 % lost the
    # open state carried from it: 12 kPa off at 10 ms at Constant(0.95), 10-15 kPa along a 1 Hz triangle.
    tank = presets.mas10_tank_system("pwm")
    ts = np.linspace(0.0, 0.2, 21)
    duties = np.array([0.5, 0.95])
    result = sweep(tank, pamjax.Constant(0.5), ts, {"signal.value": duties}, channels=("pressure",))
    for i, u in enumerate(duties):
        ref = pamjax.simulate(tank, pamjax.Constant(u), ts, rtol=1e-10, atol=1e-10, max_steps=10**6)
        np.testing.assert_allclose(result["pressure"][i], ref.pressure, rtol=0, atol=20.0)


def test_status_per_point_with_injected_failure(averaged):
    # A viscous coefficient of 1e6 N s/m gives the eigenvalue -C_f/M ~ -1e5 /s: RK4 at 1 ms overflows there.
    # (A tiny velocity_width would not do: tanh saturates, so RK4 chatters but stays bounded.)
    widths = np.array([250.0, 1e6, 250.0])
    over = {"friction.viscous_coefficient": widths, "signal.value": np.array([0.3, 0.3, 0.7])}
    result = sweep(averaged, pamjax.Constant(0.5), TS, over, method="rk4", dt=1e-3)
    assert result.status.tolist() == [0, 1, 0]
    assert np.all(np.isnan(result["position"][1]))
    # the same points with the failing one made healthy: the same batch shape, so the same compiled program
    alone = sweep(averaged, pamjax.Constant(0.5), TS, {**over, "friction.viscous_coefficient": widths[[0, 0, 2]]},
                  method="rk4", dt=1e-3)
    assert alone.status.tolist() == [0, 0, 0]
    np.testing.assert_array_equal(result["position"][[0, 2]], alone["position"][[0, 2]])


def test_the_reported_step_is_the_step_taken(averaged):
    # No step is longer than the spacing of `ts` (0.05 s here): a dt of 1 s was reported as 1 s, so halving it to
    # check the result changed nothing, unseen. The result's dt is the step taken.
    over = {"signal.value": np.array([0.3, 0.7])}
    long = sweep(averaged, pamjax.Constant(0.5), TS, over, method="rk4", dt=1.0, progress=False)
    spaced = sweep(averaged, pamjax.Constant(0.5), TS, over, method="rk4", dt=0.05, progress=False)
    assert long.dt == pytest.approx(0.05) and spaced.dt == pytest.approx(0.05)
    np.testing.assert_array_equal(long["pressure"], spaced["pressure"])


def test_reductions_match_numpy(averaged):
    ts = np.linspace(0.0, 2.0, 401)  # RK4: the reductions do not depend on the scheme (RODAS5 compiles 4x longer)
    over = {"signal.frequency": np.array([1.0, 2.5]), "signal.amplitude": np.array([0.2, 0.3])}
    signal = pamjax.Sine(0.5, 0.2, 1.0)
    full = sweep(averaged, signal, ts, over, channels=("position", "command"), method="rk4")
    for reduce, numpy_reduce in [
        (FinalValue(), lambda y, f: y[-1]),
        # the trapezoid rule over the window (a plain mean of its samples counted one phase twice)
        (WindowMean(0.5), lambda y, f: np.trapezoid(y[ts >= 1.5 - 1e-12], ts[ts >= 1.5 - 1e-12]) / 0.5),
        (FourierCoefficient(2), lambda y, f: 2 * np.mean((y * np.exp(-2j * np.pi * f * ts))[ts > 2.0 - 2 / f + 1e-9])),
    ]:
        reduced = sweep(averaged, signal, ts, over, reduce=reduce, channels=("position", "command"), method="rk4")
        for i, f in enumerate(over["signal.frequency"]):
            for c in ("position", "command"):
                np.testing.assert_allclose(reduced[c][i], numpy_reduce(full[c][i], f), rtol=1e-10, atol=1e-14)
    # the command's harmonic is the sine itself: amplitude A, phase -pi/2 (sin = cos shifted); read from the loop's
    # last sweep, FourierCoefficient(2)'s (a sweep of the command channel alone would compile the same program again)
    assert isinstance(reduce, FourierCoefficient)
    harmonic = reduced["command"]
    np.testing.assert_allclose(np.abs(harmonic), over["signal.amplitude"], rtol=1e-9)
    np.testing.assert_allclose(np.angle(harmonic), -np.pi / 2, atol=1e-9)


def test_chunks_equal_one_call_and_report_progress(averaged):
    duties = np.linspace(0.1, 0.9, 5)
    lines = []
    chunked = sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": duties}, reduce=FinalValue(), chunk_size=2,
                    progress=lines.append)
    whole = sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": duties}, reduce=FinalValue())
    assert len(lines) == 3 and "chunk 3/3" in lines[-1]
    for c in whole.channels:
        np.testing.assert_array_equal(chunked[c], whole[c])
    # a NumPy integer is a chunk size ("must be a positive integer, got 2" before); a bool is not
    numpy_chunks = sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": duties}, reduce=FinalValue(),
                         chunk_size=np.int64(2), progress=False)
    np.testing.assert_array_equal(numpy_chunks["pressure"], chunked["pressure"])


def test_default_chunk_size_per_platform():
    from pamjax._sweep.sharding import default_chunk_size

    assert default_chunk_size(100, 102, "cpu") == 100
    assert default_chunk_size(100_000, 102, "cpu") == 8192
    # accelerators: the whole batch while its outputs stay within 1 GiB per device
    assert default_chunk_size(100_000, 4, "gpu") == 100_000
    assert default_chunk_size(10**8, 4, "gpu") == 2**30 // (8 * 64)
    assert default_chunk_size(10**8, 5000, "gpu", n_devices=2) == 2 * 2**30 // (8 * 5000)
    assert default_chunk_size(10**8, 10**8, "tpu") == 8192  # never below the CPU chunk


def test_initial_state_path_and_factory(averaged):
    p0 = np.array([2e5, 4e5])
    result = sweep(averaged, lambda v: pamjax.Constant(v["duty"]), TS, {"y0.pressure": p0, "duty": [0.4, 0.6]},
                   channels=("pressure",))
    np.testing.assert_allclose(result["pressure"][:, 0], p0)
    ref = _reference(averaged, 0.6, TS, pressure=4e5)
    np.testing.assert_allclose(result["pressure"][1], ref.pressure, atol=2.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(over={"valve.nonexistent": [1.0]}), "valve.nonexistent"),
        (dict(over={"payload_mass": [1.0, -2.0]}), "payload_mass"),
        (dict(over={"signal.value": [0.5, 1.5]}), r"\[0.0, 1.0\]"),
        (dict(over={"signal.value": [0.5, np.nan]}), "finite"),
        (dict(over={"signal.value": [0.1, 0.2], "payload_mass": [1.0, 2.0, 3.0]}), "broadcast"),
        (dict(over={"signal.value": [0.5]}, dt=-1.0), "dt"),
        (dict(over={"signal.value": [0.5]}, method="euler"), "method"),
        (dict(over={"signal.value": [0.5]}, chunk_size=0), "chunk_size"),
        (dict(over={"signal.value": [0.5]}, channels=("altitude",)), "altitude"),
        (dict(over={"signal.value": [0.5]}, ts=[0.0, 1.0, 0.5]), "ts"),
        (dict(over={}), "over"),
        # a swept start pressure is checked as `simulate` checks y0.pressure (it gave NaN outputs with status 2)
        (dict(over={"y0.pressure": [2e5, -1e5]}),
         r"over\['y0.pressure'\] must be an ABSOLUTE pressure > 0 \[Pa\], point 1 is -100000.0"),
        (dict(over={"y0.pressure": [0.0]}), r"over\['y0.pressure'\] must be an ABSOLUTE pressure > 0"),
        (dict(over={"y0.pressure": [1.01325]}), r"over\['y0.pressure'\] is 1.01325 Pa at most: that looks like bar"),
        (dict(over={"y0.pressure": [-1.0]}, y0=pamjax.MuscleState(pressure=2e5, position=0.0, velocity=0.0)),
         r"over\['y0.pressure'\] must be an ABSOLUTE pressure > 0"),
        (dict(over={"signal.value": [0.5]}, y0=pamjax.MuscleState(pressure=-1e5, position=0.0, velocity=0.0)),
         r"y0.pressure must be an ABSOLUTE pressure > 0"),
        # a swept start position is checked as `simulate` checks y0.position (mm, outside the stroke: solved before,
        # the payload flung from the stops)
        (dict(over={"y0.position": [0.0, 0.5]}),
         r"over\['y0.position'\] = 0.5 at point 1 m lies outside the stroke its system allows"),
        (dict(over={"y0.position": [30.0]}), r"y0.position = 30 m: more than 1 m; that looks like mm"),
        (dict(over={"y0.pressure": [2e5]}, y0=pamjax.MuscleState(pressure=2e5, position=0.5, velocity=0.0)),
         r"y0.position = 0.5 m lies outside the stroke"),
        (dict(over={"y0.position": [0.01, -0.5]}, y0=pamjax.MuscleState(pressure=2e5, position=0.0, velocity=0.0)),
         r"over\['y0.position'\] = -0.5 at point 1 m lies outside the stroke"),
        # raw IndexError / "Need at least one array to stack" / "unknown channel 'p'" before
        (dict(over={"signal.value": []}), r"over\['signal.value'\] holds no values"),
        (dict(over={"signal.value": [0.5]}, channels=()), r"channels must be None or a non-empty sequence"),
        # a raw TypeError after the first chunk had run
        (dict(over={"signal.value": [0.5]}, progress="yes"), r"progress must be True, False or a callable"),
        (dict(over={"signal.value": [0.5]}, channels="pressure"),
         r"channels must be None or a non-empty sequence of channel names such as \('pressure',\)"),
        # a signal without a frequency: AttributeError 'Constant' object has no attribute 'frequency' before
        (dict(over={"signal.value": [0.5]}, reduce=FourierCoefficient(2)),
         r"FourierCoefficient needs the signal's frequency: the signal Constant has none .* "
         r"FourierCoefficient\(2, frequency=\.\.\.\)"),
        (dict(over={"signal.value": [0.5]}, chunk_size=True), r"chunk_size must be a positive integer .*got True"),
        # solver settings a method would ignore (a tolerance with RK4 changed nothing, unseen), an unknown option (a
        # raw TypeError after the planning), a dt with "adaptive" (result.dt NaN)
        (dict(over={"signal.value": [0.5]}, solve_options={"rtol": 1e-12}),
         r"solve_options \['rtol'\] go to method='adaptive' only; method='auto' takes none"),
        (dict(over={"signal.value": [0.5]}, method="rk4", solve_options={"bogus": 1}), r"method='rk4' takes none"),
        (dict(over={"signal.value": [0.5]}, method="adaptive", solve_options={"rtoll": 1e-9}),
         r"unknown solve_options \['rtoll'\]; valid: .*'rtol'"),
        (dict(over={"signal.value": [0.5]}, method="adaptive", dt=0.5), r"dt is the step of the fixed-step methods"),
        # a window longer than the 1 s run: the mean of the whole run before, without a word
        (dict(over={"signal.value": [0.5]}, reduce=WindowMean(5.0)),
         r"WindowMean\(5.0\) needs a window of 5 s, longer than the run \(ts\[-1\] - ts\[0\] = 1 s\)"),
    ],
)
def test_bad_input_is_named(averaged, kwargs, match):
    kwargs = dict(kwargs)
    ts = kwargs.pop("ts", TS)
    with pytest.raises(pamjax.PamjaxInputError, match=match):
        sweep(averaged, pamjax.Constant(0.5), ts, **kwargs)


def test_a_fourier_window_sampled_unevenly_is_refused(averaged):
    """The coefficient's sum weighs every sample alike, the integral's rule on even steps only: output times denser
    in half of the window gave a quietly wrong coefficient; refused before any solve, naming the steps."""
    ts = np.concatenate([np.linspace(0.0, 1.5, 151), np.linspace(1.505, 2.0, 100)])  # 10 ms, then 5 ms
    with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient\(1\) needs output times that sample its "
                                                      r"window evenly .* from 0.005 to 0.01 s"):
        sweep(averaged, pamjax.Sine(0.5, 0.2, 1.0), ts, {"signal.frequency": [1.0]}, reduce=FourierCoefficient(1),
              progress=False)


def test_a_fourier_window_longer_than_the_run_or_a_bad_frequency_is_refused(averaged):
    """On a 1 s run `FourierCoefficient(4)` at 1 Hz equalled `FourierCoefficient(1)`, a frequency of 0 gave twice the
    mean and -1 zeros; now each is refused before any solve, at every swept point's frequency."""
    sine = pamjax.Sine(0.5, 0.2, 1.0)
    with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient\(4\) at 1 Hz needs a window of 4 s, "
                                                      r"longer than the run"):
        sweep(averaged, sine, TS, {"signal.frequency": [1.0]}, reduce=FourierCoefficient(4), progress=False)
    with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient\(1\) at 0.5 Hz needs a window of 2 s"):
        sweep(averaged, sine, TS, {"signal.frequency": [2.0, 0.5]}, reduce=FourierCoefficient(1), progress=False)
    # a signal factory's frequencies, read from the signals it makes
    with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient\(1\) at 0.5 Hz"):
        sweep(averaged, lambda v: pamjax.Sine(0.5, 0.2, float(v["f"])), TS, {"f": [2.0, 0.5]},
              reduce=FourierCoefficient(1), progress=False)
    with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient\(1\) at 0.5 Hz"):
        sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": [0.5]},
              reduce=FourierCoefficient(1, frequency=0.5), progress=False)
    for bad in (0.0, -1.0, float("nan"), float("inf"), True):
        with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient.frequency must be a frequency > 0"):
            FourierCoefficient(1, frequency=bad)
    for bad in (0, -2, 1.5, True, float("nan")):
        with pytest.raises(pamjax.PamjaxInputError, match=r"FourierCoefficient.periods must be a whole number"):
            FourierCoefficient(bad)
    # windows that fit are accepted, to the rounding of a span: the checks alone (no sweep compiled)
    lanes = lambda: [(averaged, pamjax.Sine(0.5, 0.2, np.array([1.0, 3.0])))]  # noqa: E731
    for reduce in (WindowMean(1.0), WindowMean(1.0 + 1e-12), FourierCoefficient(1),
                   FourierCoefficient(2, frequency=2.0), FinalValue()):
        reduce.check(TS, lanes)


def test_flow_surface_equals_cycle_average_and_cli_writes_outputs(tmp_path):
    from pamjax._cli.main import main
    from pamjax._sweep.maps import flow_surface

    valve, air = presets.mas10_valve(), pamjax.Air()
    u, p = np.array([0.05, 0.5, 0.95]), np.array([1.5e5, 4e5])
    surface = flow_surface(valve, u, p, air)
    # the scalar cycle average, jitted once (eagerly each of its operations compiles a program of its own)
    cycle_average = eqx.filter_jit(pamjax.cycle_averaged_flow)
    for i, j in [(0, 0), (1, 1), (2, 0)]:
        np.testing.assert_allclose(surface[i, j], cycle_average(valve, u[i], p[j], air, 400), rtol=1e-12)
    assert abs(surface[0, 0]) < 1e-3 * abs(surface[1, 0] - surface[2, 0]) or surface[0, 0] < 0  # dead band: exhausts
    config = tmp_path / "fs.toml"
    config.write_text('kind = "flow_surface"\n[sweep]\ncommands = [0.2, 0.8]\npressures = [2e5, 5e5]\n')
    assert main(["sweep", str(config), "--out", str(tmp_path / "out"), "--no-plot"]) == 0
    data = np.load(tmp_path / "out" / "sweep.npz")
    np.testing.assert_allclose(data["mass_flow_kg_s"], flow_surface(valve, [0.2, 0.8], [2e5, 5e5], air).ravel())
    assert (tmp_path / "out" / "sweep.csv").read_text().startswith("duty,pressure_pa_abs,mass_flow_kg_s")
    # an averaged valve has no PWM period to average over: named (it was a TypeError deep in the traced surface),
    # and a number of phases that is no positive int
    with pytest.raises(pamjax.PamjaxInputError, match=r"the flow surface is a switching valve.s .* AveragedValve"):
        flow_surface(presets.mas10_system("averaged").valve, u, p, air)
    with pytest.raises(pamjax.PamjaxInputError, match=r"samples must be a positive integer"):
        flow_surface(valve, u, p, air, samples=0)


def test_paper_001s_systems_sweep_and_a_joints_pairs_are_named():
    # Sweeps of a regulated muscle crashed with an AttributeError (the lanes read `state.pressure`, which its state
    # keeps in its regulator's); a joint's default channels stacked its muscles' pairs with scalars (a ValueError).
    # The lanes now read the pressure from the system's outputs; a joint's default channels are its scalar ones, and
    # a pair asked for is refused by name.
    import pamjax as pj
    from pamjax._sweep.lanes import channel_shapes
    from pamjax._sweep.plan import make_plan, structure

    muscle = pj.presets.dmsp40_muscle()
    regulated = pj.RegulatedMuscleSystem(pj.ISO6358Regulator(), muscle)
    # its start pressure swept too: "y0.pressure" is `initial_state(pressure=...)` (the regulated muscle's state keeps
    # it in the regulator's: the path was refused, and "y0.regulator.pressure" crashed in `initial_state`)
    volts, starts = np.array([1.0, 3.0]), np.array([1.2e5, 2.5e5])
    r = sweep(regulated, pj.Constant(0.0), TS, {"signal.value": volts, "y0.pressure": starts}, reduce=FinalValue(),
              progress=False)
    assert np.all(r.status == 0)
    for k, (v, p0) in enumerate(zip(volts, starts)):
        traj = pj.simulate(regulated, pj.Constant(float(v)), TS, y0=regulated.initial_state(pressure=p0), rtol=1e-9,
                           atol=1e-9)
        assert abs(r["pressure"][k] - float(traj.pressure[-1])) < 10.0  # Pa: rodas5a at 1e-5 of 1 bar
        assert abs(r["position"][k] - float(traj.position[-1])) < 1e-6
    with pytest.raises(pj.PamjaxInputError, match=r"without a y0, a swept start names a number RegulatedMuscleSystem"
                                                  r".initial_state takes \(y0.pressure, y0.position, y0.velocity\)"):
        make_plan(regulated, pj.Constant(0.0), structure(regulated, None)[0], {"y0.regulator.pressure": starts},
                  y0_given=False)
    joint = pj.AntagonisticJoint(pj.ISO6358Regulator(), pj.ISO6358Regulator(), muscle, muscle)
    signal = pj.VoltagePair(pj.Constant(3.0), pj.Constant(1.5))
    # the joint's channels as a sweep sees them (traced, not solved: a joint's sweep compiles for ~20 s here; by hand
    # its default-channel sweep equalled simulate's angle to 1e-8 rad)
    plan, values, _ = make_plan(joint, signal, structure(joint, None)[0], {"signal.flexor.value": volts})
    shapes = channel_shapes(joint, signal, None, plan, {k: jnp.asarray(v.reshape(-1)[0]) for k, v in values.items()},
                            0.0)
    assert [c for c, shape in shapes.items() if shape == ()] == ["angle", "angular_velocity"]
    assert shapes["pressure"] == (2,)
    with pytest.raises(pj.PamjaxInputError, match=r"channel 'pressure' of this system has shape \(2,\) per point; a "
                                                  r"sweep maps scalar channels: choose among \['angle'"):
        sweep(joint, signal, TS, {"signal.flexor.value": volts}, channels=("pressure",), progress=False)


def test_a_window_of_no_length_is_refused():
    # WindowMean(0.0) (the trapezoid weights of no interval) gave 0/0 = NaN in every lane with status 0
    for bad in (0.0, -1.0, float("nan"), "1 s"):
        with pytest.raises(pamjax.PamjaxInputError, match=r"WindowMean.window must be a duration > 0"):
            WindowMean(bad)
    assert WindowMean(2).window == 2


def test_bad_devices_are_named(averaged):
    """A Mesh without its one "batch" axis, a string, a device listed twice: raw JAX errors before (one of them "this
    is a bug in pamjax")."""
    import jax
    from jax.sharding import Mesh

    device = jax.devices()[0]
    cases = [(Mesh(np.array([device]), ("x",)), r"a Mesh must have exactly one axis, named 'batch'.*\('x',\)"),
             (Mesh(np.array([device]).reshape(1, 1), ("batch", "model")), r"\('batch', 'model'\)"),
             ("cpu", r"devices must be None .*a non-empty list of jax.Device .*got 'cpu'"),
             ([], r"devices must be None"), ([0], r"devices must be None"),
             ([device, device], r"devices lists a device more than once")]
    for devices, match in cases:
        with pytest.raises(pamjax.PamjaxInputError, match=match):
            sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": [0.5]}, devices=devices, progress=False)


def test_local_shards_saved_and_loaded_merge_into_the_whole_result(averaged, tmp_path):
    """docs/distributed.md's gather="local" recipe saved points/position/status only, which merge_sweep_shards (it
    takes SweepResults) could not join: `SweepResult.save` writes what it needs, `SweepResult.load` reads it."""
    over = {"signal.value": np.array([[0.2, 0.4], [0.6, 0.8]])}
    local = sweep(averaged, pamjax.Constant(0.5), TS, over, reduce=FinalValue(), gather="local", progress=False)
    whole = sweep(averaged, pamjax.Constant(0.5), TS, over, reduce=FinalValue(), progress=False)
    paths = []
    for k, keep in enumerate((local.points % 2 == 0, local.points % 2 == 1)):  # two processes' shards, emulated
        shard = pamjax.SweepResult(over={n: v[keep] for n, v in local.over.items()}, t=local.t,
                                   channels=local.channels, outputs={c: v[keep] for c, v in local.outputs.items()},
                                   status=local.status[keep], dt=local.dt, method=local.method,
                                   points=local.points[keep], batch_shape=local.batch_shape)
        paths.append(shard.save(tmp_path / f"map-{k}.npz"))
    merged = pamjax.merge_sweep_shards(pamjax.SweepResult.load(p) for p in paths)
    assert (merged.method, merged.dt, merged.channels) == (whole.method, whole.dt, whole.channels)
    np.testing.assert_array_equal(merged.over["signal.value"], over["signal.value"])
    np.testing.assert_array_equal(merged.status, whole.status)
    for c in whole.channels:
        np.testing.assert_array_equal(merged[c], whole[c])
    assert pamjax.SweepResult.load(whole.save(tmp_path / "whole")).points is None  # a whole result, no ".npz" added


def _shard(result, keep):
    """The points `keep` of a gather="local" result, as one process's shard holds them (its identity kept)."""
    return pamjax.SweepResult(over={k: v[keep] for k, v in result.over.items()}, t=result.t, channels=result.channels,
                              outputs={c: v[keep] for c, v in result.outputs.items()}, status=result.status[keep],
                              dt=result.dt, method=result.method, points=result.points[keep],
                              batch_shape=result.batch_shape, reduction=result.reduction, identity=result.identity)


def test_shards_of_different_sweeps_are_refused_naming_what_differs(averaged, tmp_path):
    """Only batch shape, channels, times and method were compared: a FinalValue shard joined a WindowMean(0.5) one,
    duties 0.2-0.8 joined a quarter of them, RK4 at 1 ms joined RK4 at 0.5 ms (reported 1 ms), all silently; other
    swept paths were a raw KeyError, a trajectory shard with a reduced one a NumPy ValueError. Each shard now
    carries the sweep's identity (saved and loaded), and what differs is named."""
    duties = np.linspace(0.2, 0.8, 4)

    def local(values, reduce=FinalValue()):
        return sweep(averaged, pamjax.Constant(0.5), TS, {"signal.value": values}, reduce=reduce, gather="local",
                     progress=False)

    def saved(shard, name):
        return pamjax.SweepResult.load(shard.save(tmp_path / name))

    final = local(duties)
    head, tail = final.points < 2, final.points >= 2
    a = saved(_shard(final, head), "a.npz")
    assert (a.identity, a.reduction) == (final.identity, "FinalValue()") and a.identity.startswith("system=")
    whole = pamjax.merge_sweep_shards([a, saved(_shard(final, tail), "b.npz")])  # one sweep's shards: joined
    np.testing.assert_array_equal(whole["pressure"], final["pressure"][np.argsort(final.points)])
    assert whole.identity == final.identity
    one_sweep = r"shards must come from one sweep: shard 1 differs from shard 0 in "
    with pytest.raises(pamjax.PamjaxInputError, match=one_sweep + r"the swept values \(over\) \(identity digests "):
        pamjax.merge_sweep_shards([a, saved(_shard(local(duties / 4), tail), "c.npz")])
    with pytest.raises(pamjax.PamjaxInputError, match=one_sweep + r"reduce \(WindowMean\(window=0.5\) vs "
                                                                  r"FinalValue\(\)\)"):
        pamjax.merge_sweep_shards([a, saved(_shard(local(duties, WindowMean(0.5)), tail), "d.npz")])
    # what a shard holds is compared, identity or not (a shard built by hand, or a file saved before identities)
    b = dataclasses.replace(_shard(final, tail), identity=None, reduction=None)
    trajectories = {c: np.repeat(v[:, None], TS.size, axis=1) for c, v in b.outputs.items()}
    for other, match in [(dataclasses.replace(b, dt=b.dt / 2), rf"dt \({b.dt / 2!r} s vs {b.dt!r} s\)"),
                         (dataclasses.replace(b, over={"payload_mass": np.ones(2)}),
                          r"swept paths \(over\) \(\['payload_mass'\] vs \['signal.value'\]\)"),
                         (dataclasses.replace(b, outputs=trajectories), r"shape per point of outputs\['pressure'\] "
                                                                        r".*\(\(21,\) vs \(\)\)")]:
        with pytest.raises(pamjax.PamjaxInputError, match=one_sweep + match):
            pamjax.merge_sweep_shards([a, other])
    legacy = saved(b, "legacy.npz")  # a file without identity still loads and merges (unchecked beyond what it holds)
    assert "identity" not in np.load(tmp_path / "legacy.npz").files and legacy.identity is None
    np.testing.assert_array_equal(pamjax.merge_sweep_shards([a, legacy])["pressure"], whole["pressure"])


def test_save_refuses_to_replace_a_file_and_load_names_a_file_it_did_not_write(tmp_path):
    """`save` replaced an existing file silently (a second map under one name lost the first); `load` of the CLI's
    column file `sweep.npz` was a raw KeyError('channels')."""
    def result(duties):
        return pamjax.SweepResult(over={"signal.value": np.asarray(duties)}, t=np.array([0.0, 1.0]),
                                  channels=("pressure",), outputs={"pressure": np.array([2e5, 3e5])},
                                  status=np.zeros(2, dtype=int), dt=0.01, method="rk4")

    path = result([0.2, 0.4]).save(tmp_path / "map.npz")
    with pytest.raises(FileExistsError, match=r"map.npz exists; pass overwrite=True"):
        result([0.6, 0.8]).save(path)
    np.testing.assert_array_equal(pamjax.SweepResult.load(path).over["signal.value"], [0.2, 0.4])
    result([0.6, 0.8]).save(path, overwrite=True)
    np.testing.assert_array_equal(pamjax.SweepResult.load(path).over["signal.value"], [0.6, 0.8])
    cli = tmp_path / "sweep.npz"
    np.savez(cli, duty=np.array([0.2, 0.5]), pressure_pa_abs=np.array([2e5, 4e5]), status=np.zeros(2))
    np.save(tmp_path / "one.npy", np.zeros(3))
    (tmp_path / "map.csv").write_text("t,pressure\n0,2e5\n")
    for name, why in [("sweep.npz", r": it has no 't', 'dt', 'method', 'channels'"), ("one.npy", "one array"),
                      ("map.csv", "not an NPZ archive")]:
        with pytest.raises(pamjax.PamjaxInputError, match=rf"{name} is not a file SweepResult.save wrote.*{why}.*"
                                                          r"`pamjax sweep` command line .* read it with np.load"):
            pamjax.SweepResult.load(tmp_path / name)


def test_an_adaptive_lane_sets_the_status_codes_of_the_other_methods(averaged, monkeypatch):
    """`method="adaptive"` never set status 2 (an absolute pressure <= 0), which the status table promises for every
    method, and gave a state that became NaN (solve's RESULT_NONFINITE) status 3, not 1. The lane's solve is replaced
    by trajectories with those faults (a real adaptive solve keeps the pressure of this plant positive)."""
    from pamjax._solve.trajectory import RESULT_NONFINITE
    from pamjax._sweep import lanes

    class Faulty:
        def __init__(self, pressure, result):
            self.pressure, self.result = jnp.asarray(pressure, dtype=float), jnp.asarray(result)

        def channel(self, name):
            return self.pressure

    ts = jnp.array([0.0, 0.5, 1.0])
    for pressure, result, status in [([2e5, 3e5, 4e5], 0, 0), ([2e5, -1e3, 4e5], 0, 2),
                                     ([2e5, np.nan, np.nan], RESULT_NONFINITE, 1), ([2e5, 3e5, np.inf], 1, 3)]:
        monkeypatch.setattr(lanes, "solve", lambda *a, traj=Faulty(pressure, result), **k: traj)
        _, got = lanes._lane_adaptive(averaged, pamjax.Constant(0.5), None, ts, ("pressure",), None, {})
        assert int(got) == status, (pressure, result)
